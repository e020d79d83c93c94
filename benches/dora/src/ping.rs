//! The measuring node.

use std::io::Write as _;
use std::time::{Duration, Instant};

use dora_node_api::{DoraNode, EventStream, MetadataParameters, dora_core::config::DataId};

use crate::config::{Config, Wait};
use crate::inbox::{self, Got};
use crate::message;

/// How long one answer may take.
const TIMEOUT: Duration = Duration::from_secs(20);
/// How long pong has to answer the first hello before ping gives up.
const CONNECT: Duration = Duration::from_secs(20);
/// The gap before each blocking hop, as esgm-bench's `event` rows: the other side is
/// asleep when the message comes. Busy, as esgm-bench's, so ping's core stays awake.
const EVENT_GAP: Duration = Duration::from_micros(50);

/// Connects, runs warmup and measured hops, writes `r <ns>` per measured hop to the
/// output file, and tells pong to stop.
pub fn run(config: &Config) -> Result<(), String> {
    let (mut node, mut events) =
        DoraNode::init_from_env_force().map_err(|e| format!("starting the dora node: {e}"))?;
    let out = DataId::from("out".to_owned());
    let mut send = |seq: u64| -> Result<Instant, String> {
        let mut complete = None;
        node.send_output_raw(out.clone(), MetadataParameters::default(), config.bytes, |p| {
            message::fill(p, seq);
            complete = Some(Instant::now());
        })
        .map_err(|e| format!("sending {seq}: {e}"))?;
        complete.ok_or_else(|| format!("dora did not ask for the payload of {seq}"))
    };
    connect(&mut send, &mut events)?;
    let mut figures = Vec::with_capacity(config.samples as usize);
    for seq in 1..=config.warmup + config.samples {
        if config.wait == Wait::Block {
            let gap = Instant::now();
            while gap.elapsed() < EVENT_GAP {
                std::hint::spin_loop();
            }
        }
        let start = send(seq)?;
        answer(&mut events, config.wait, seq)?;
        let half = start.elapsed().as_nanos() / 2;
        if seq > config.warmup {
            figures.push(half);
        }
    }
    send(message::STOP)?;
    write(config, &figures)
}

/// Sends hellos until one is answered, then lets late answers to earlier hellos drain.
fn connect(
    send: &mut impl FnMut(u64) -> Result<Instant, String>,
    events: &mut EventStream,
) -> Result<(), String> {
    let started = Instant::now();
    loop {
        send(message::HELLO)?;
        match inbox::next(events, Wait::Block, Duration::from_millis(100)) {
            Ok(Got::Message { seq: message::HELLO, .. }) => break,
            Ok(Got::Message { seq, .. }) => return Err(format!("answer {seq} before any ping")),
            Ok(Got::Closed) => return Err("the dataflow ended before pong answered".into()),
            Err(_) if started.elapsed() < CONNECT => continue,
            Err(_) => return Err(format!("pong did not answer within {CONNECT:?}")),
        }
    }
    std::thread::sleep(Duration::from_millis(100));
    while let Ok(event) = events.try_recv() {
        drop(event);
    }
    Ok(())
}

/// Waits for the answer to `seq`, skipping late hellos.
fn answer(events: &mut EventStream, wait: Wait, seq: u64) -> Result<(), String> {
    loop {
        match inbox::next(events, wait, TIMEOUT).map_err(|e| format!("answer to {seq}: {e}"))? {
            Got::Message { seq: got, .. } if got == seq => return Ok(()),
            Got::Message { seq: message::HELLO, .. } => continue,
            Got::Message { seq: got, .. } => {
                return Err(format!("answer {got} while waiting for {seq}"));
            }
            Got::Closed => return Err(format!("the dataflow ended before answer {seq}")),
        }
    }
}

fn write(config: &Config, figures: &[u128]) -> Result<(), String> {
    let path = config.out.as_ref().ok_or("no ESGM_DORA_OUT")?;
    let file =
        std::fs::File::create(path).map_err(|e| format!("creating {}: {e}", path.display()))?;
    let mut file = std::io::BufWriter::new(file);
    for ns in figures {
        writeln!(file, "r {ns}").map_err(|e| format!("writing {}: {e}", path.display()))?;
    }
    file.flush().map_err(|e| format!("writing {}: {e}", path.display()))
}
