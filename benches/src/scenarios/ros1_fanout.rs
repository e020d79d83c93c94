//! `ros1-fanout-<k>` (issue 23): the ROS 1 peer's fan-out beside esgm's `fanout-<k>`,
//! measured the same way in the same run. One roscpp `writer` process publishes a
//! small message on one topic every 2 ms to k roscpp `reader` processes (each a node
//! of its own, over TCPROS with TCP_NODELAY through a private rosmaster); a row's
//! sample is, per message, the time until the *last* reader's callback ran, from the
//! system-clock stamp the writer put in it (see `benches/ros1/ros1_pingpong.cpp`).
//! Every reader must receive every message, as in esgm's row.
//!
//! The peer program is the one `benches/ros1/build.sh` builds; without it the rows are
//! reported as skipped with that instruction.

use std::io::Read;
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context as _, bail};

use super::ipc_fanout::Fanout;
use super::ipc_payload::Kind;
use super::ros1_peer::{Guard, HOW, Master, Pinning, command, program, read_all, which};
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// How long one fan-out run may take.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// One ROS 1 fan-out (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Ros1Fanout {
    name: &'static str,
    k: usize,
    /// esgm's row with the same number of readers.
    esgm: Fanout,
}

impl Ros1Fanout {
    /// One reader.
    pub const ONE: Ros1Fanout = Ros1Fanout { name: "ros1-fanout-1", k: 1, esgm: Fanout::ONE };
    /// 8 readers.
    pub const EIGHT: Ros1Fanout = Ros1Fanout { name: "ros1-fanout-8", k: 8, esgm: Fanout::EIGHT };
    /// 32 readers.
    pub const THIRTY_TWO: Ros1Fanout =
        Ros1Fanout { name: "ros1-fanout-32", k: 32, esgm: Fanout::THIRTY_TWO };
    /// 64 readers.
    pub const SIXTY_FOUR: Ros1Fanout =
        Ros1Fanout { name: "ros1-fanout-64", k: 64, esgm: Fanout::SIXTY_FOUR };
}

impl Scenario for Ros1Fanout {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.k {
            1 => "ROS 1 roscpp: one writer, one reader process (beside fanout-1)",
            8 => "ROS 1 roscpp: one writer, 8 reader processes, until the last holds it",
            32 => "ROS 1 roscpp: one writer, 32 reader processes, until the last holds it",
            _ => "ROS 1 roscpp: one writer, 64 reader processes, until the last holds it",
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        if ctx.is_quick() && self.k > 8 {
            ctx.skip(self.name, "--quick measures 1 and 8 readers; run without --quick");
            return Ok(Vec::new());
        }
        let Some(program) = program() else {
            ctx.skip(self.name, HOW);
            return Ok(Vec::new());
        };
        if which("rosmaster").is_none() {
            ctx.skip(self.name, format!("rosmaster is not installed; {HOW}"));
            return Ok(Vec::new());
        }
        let bytes = esgm_core::codec::encoded_len(&Kind::Small.make(0)).context("sizing")?;
        let samples = ctx.samples(2_000, 100);
        let warmup = ctx.warmup(samples);
        let cores = ctx.pinning().map(|p| (p.measuring_core(), p.peer_core()));
        // A peer outside this project failing is a finding for the table, not a reason
        // to lose the rest of the run.
        let latency = match run_fanout(&program, self.k, bytes, samples, warmup, cores) {
            Ok(latency) => latency,
            Err(e) => {
                ctx.skip(self.name, format!("the ROS 1 fan-out failed: {e:#}"));
                return Ok(Vec::new());
            }
        };
        let row = latency
            .measurement(self.name, Wait::Event)
            .method(Method::SystemClock)
            .wait_strategy("block (roscpp callback queue)")
            .payload_bytes(bytes as u64)
            .baseline(self.esgm.name())
            .note(format!(
                "std_msgs/UInt8MultiArray over TCPROS (TCP_NODELAY, loopback), until the last of {} reader processes ran its callback; every reader received every message",
                self.k
            ));
        Ok(vec![row])
    }

    /// esgm's fan-out is to be faster than ROS 1's at every k: ROS 1's row over
    /// esgm's ≥ 1.
    fn targets(&self) -> Vec<Target> {
        vec![Target::at_least(self.name, self.esgm.name(), Wait::Event, 1.0)]
    }
}

/// Runs one writer and `k` readers; the time until the last reader held each measured
/// message.
fn run_fanout(
    program: &std::path::Path,
    k: usize,
    bytes: usize,
    samples: u64,
    warmup: u64,
    cores: Option<(usize, usize)>,
) -> anyhow::Result<Latency> {
    let Pinning { measuring: writer_core, peer: reader_core, master: master_cores } =
        Pinning::of(cores)?;
    let master = Master::start(master_cores)?;
    let prefix = format!("/esgm_bench_fanout_{}_{}", std::process::id(), master.port);
    let total = samples + warmup;
    let mut readers = Vec::with_capacity(k);
    for _ in 0..k {
        let mut reader = command(program, reader_core.clone());
        reader.args(["reader", &prefix, "block"]).stdout(Stdio::piped()).stderr(Stdio::null());
        master.env(&mut reader);
        let mut guard = Guard::new(reader.spawn().context("starting a ROS 1 reader")?);
        let collect = read_all(guard.child()?.stdout.take().context("reader stdout")?);
        readers.push((guard, collect));
    }
    let mut writer = command(program, writer_core);
    writer
        .args(["writer", &prefix, "block", &bytes.to_string(), &total.to_string(), &k.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    master.env(&mut writer);
    let mut writer = Guard::new(writer.spawn().context("starting the ROS 1 writer")?);
    let status = writer.wait("the ROS 1 writer", RUN_TIMEOUT)?;
    if !status.success() {
        let mut stderr = String::new();
        if let Some(mut err) = writer.child()?.stderr.take() {
            let _ = err.read_to_string(&mut stderr);
        }
        bail!("the ROS 1 writer failed ({status}): {}", stderr.trim());
    }
    // Each message's latest arrival over the readers, and whether each reader got it.
    let mut last = vec![0u64; usize::try_from(total)?];
    let mut lost = 0u64;
    for (mut guard, collect) in readers {
        guard.wait("a ROS 1 reader, after the writer's stop,", Duration::from_secs(30))?;
        let out =
            collect.join().map_err(|_| anyhow::anyhow!("a reader's output thread panicked"))?;
        let mut seen = vec![false; last.len()];
        for line in out.lines() {
            let mut parts = line.strip_prefix("h ").unwrap_or_default().split(' ');
            let seq = parts.next().and_then(|v| v.parse::<usize>().ok());
            let ns = parts.next().and_then(|v| v.trim().parse::<i64>().ok());
            if let (Some(seq), Some(ns)) = (seq, ns) {
                if seq < last.len() {
                    seen[seq] = true;
                    last[seq] = last[seq].max(u64::try_from(ns).unwrap_or(0));
                }
            }
        }
        lost += seen.iter().filter(|s| !**s).count() as u64;
    }
    if lost > 0 {
        bail!("{lost} receptions missing over {k} readers");
    }
    let mut latency = Latency::new()?;
    for ns in last.iter().skip(usize::try_from(warmup)?) {
        latency.record_ns(*ns);
    }
    if latency.is_empty() {
        bail!("no message reached every reader");
    }
    Ok(latency)
}
