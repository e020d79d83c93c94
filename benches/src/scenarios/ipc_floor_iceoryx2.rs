//! `floor-iceoryx2`: the floor of a cross-process hop, raw iceoryx2.
//!
//! A fixed 64-byte `#[repr(C)]` message, sent by zero-copy publish-subscribe to a peer
//! process and back, with no esgm in the way: no encoding, no validation, no header
//! checks. The message is written into its loan before the timer starts; the hop is
//! the send and the receive (and reading the sequence number). Measured as half a round
//! trip, with both processes busy-polling `receive` (`spin`), and with both blocking on
//! an iceoryx2 event service that the sender notifies after each send (`event`) — what
//! esgm's blocking subscribers do, so this is their floor too.
//!
//! `floor-iceoryx2` uses iceoryx2's plain `ipc` service type. esgm's ports are its
//! thread-safe variant (`ipc_threadsafe`, a lock around each port, so that any thread of
//! a process may use them); `floor-iceoryx2-threadsafe` is the same hop on that variant,
//! so the lock's share of esgm's distance to the floor is known (issue 27).

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use esgm_shm::unique_domain;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{
    LogLevel, Node, NodeBuilder, ServiceName, SignalHandlingMode, ZeroCopySend, ipc,
    ipc_threadsafe, set_log_level,
};
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::Service;

use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "floor-iceoryx2";
/// The same hop on iceoryx2's thread-safe service type, esgm's.
pub const THREADSAFE: &str = "floor-iceoryx2-threadsafe";

/// The message: 64 bytes, a sequence number and a body.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("esgm-bench.Floor64.v1")]
pub struct Message {
    /// 0 for start-up pings, 1… for measured ones, `u64::MAX` to stop the peer.
    pub seq: u64,
    /// Filler up to 64 bytes.
    pub body: [u8; 56],
}

const _: () = assert!(size_of::<Message>() == 64);

const HELLO: u64 = 0;
const STOP: u64 = u64::MAX;
const HELLO_EVERY: Duration = Duration::from_millis(1);

/// See the module docs: the plain service type (`floor-iceoryx2`), or the thread-safe
/// one (`floor-iceoryx2-threadsafe`).
#[derive(Debug, Clone, Copy, Default)]
pub struct FloorIceoryx2 {
    /// On `ipc_threadsafe` rather than `ipc`.
    pub threadsafe: bool,
}

impl FloorIceoryx2 {
    /// The floor: iceoryx2's plain service type.
    pub const PLAIN: FloorIceoryx2 = FloorIceoryx2 { threadsafe: false };
    /// The same on the thread-safe type esgm uses.
    pub const THREADSAFE: FloorIceoryx2 = FloorIceoryx2 { threadsafe: true };
}

impl Scenario for FloorIceoryx2 {
    fn name(&self) -> &'static str {
        if self.threadsafe { THREADSAFE } else { NAME }
    }

    fn summary(&self) -> &'static str {
        if self.threadsafe {
            "raw iceoryx2 (thread-safe ports, as esgm's) publish-subscribe of a 64-byte struct, process -> process"
        } else {
            "raw iceoryx2 publish-subscribe of a 64-byte struct, process -> process: the floor"
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let name = self.name();
        WaitMode::SPIN_AND_BLOCK
            .iter()
            .map(|&mode| match self.threadsafe {
                false => measure::<ipc::Service>(ctx, name, mode),
                true => measure::<ipc_threadsafe::Service>(ctx, name, mode),
            })
            .collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        match self.threadsafe {
            false => pong::<ipc::Service>(role),
            true => pong::<ipc_threadsafe::Service>(role),
        }
    }
}

/// A node of service type `S`, signal handling off and iceoryx2's log cut to errors
/// (see `ipc_node`).
fn node<S: Service>() -> anyhow::Result<Node<S>> {
    set_log_level(LogLevel::Error);
    NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<S>()
        .context("could not create an iceoryx2 node")
}

/// The peer's side: answers every ping until the stop.
fn pong<S: Service>(role: &PeerRole) -> anyhow::Result<Vec<String>> {
    let node = node::<S>()?;
    let ends = Ends::open(&node, &role.domain, "pong", "ping", role.wait)?;
    let mut patience = Patience::alone();
    loop {
        let seq = ends.receive(&mut patience, "ping", |_| true)?;
        if seq == STOP {
            return Ok(Vec::new());
        }
        ends.send(ends.loan(seq)?)?;
    }
}

fn measure<S: Service>(ctx: &Context, name: &str, mode: WaitMode) -> anyhow::Result<Measurement> {
    let samples = ctx.samples(100_000, 10_000);
    let warmup = ctx.warmup(samples);
    let domain = unique_domain("esgm-bench");
    let node = node::<S>()?;
    let ends = Ends::open(&node, &domain, "ping", "pong", mode)?;
    let mut peer = ctx.spawn_peer_process(name, mode, &domain)?;
    let mut patience = Patience::for_peer(&mut peer);

    // A message sent before the peer's subscriber connected is lost: ping until it
    // answers.
    let started = Instant::now();
    loop {
        ends.send(ends.loan(HELLO)?)?;
        let answered = ends.poll(|_| true)?.is_some() || {
            std::thread::sleep(HELLO_EVERY);
            ends.poll(|_| true)?.is_some()
        };
        if answered {
            break;
        }
        patience.check("answer to the first ping", started)?;
    }

    let mut latency = Latency::new()?;
    for seq in 1..=warmup + samples {
        let message = ends.loan(seq)?;
        ctx.before_hop(mode.wait());
        let start = Instant::now();
        ends.send(message)?;
        // Answers to start-up pings may still come: only this ping's counts.
        black_box(ends.receive(&mut patience, "pong", |s| s == seq)?);
        let round_trip = start.elapsed();
        if seq > warmup {
            latency.record_half(round_trip);
        }
    }
    ends.send(ends.loan(STOP)?)?;
    peer.finish(FINISH_TIMEOUT)?;

    let row = latency
        .measurement(name, mode.wait())
        .payload_bytes(size_of::<Message>() as u64)
        .method(Method::HalfRoundTrip)
        .wait_strategy(mode.label());
    Ok(if name == NAME { row } else { row.baseline(NAME) })
}

/// One process's ends of the ping-pong: it sends on one service and receives on the
/// other; when blocking, each service has an event service beside it for wake-ups.
#[derive(Debug)]
struct Ends<S: Service> {
    publisher: Publisher<S, Message, ()>,
    subscriber: Subscriber<S, Message, ()>,
    notifier: Option<Notifier<S>>,
    listener: Option<Listener<S>>,
}

impl<S: Service> Ends<S> {
    fn open(
        node: &Node<S>,
        domain: &str,
        send_on: &str,
        receive_on: &str,
        mode: WaitMode,
    ) -> anyhow::Result<Self> {
        let data = |name: &str| -> anyhow::Result<_> {
            let service = service_name(domain, "data", name)?;
            node.service_builder(&service)
                .publish_subscribe::<Message>()
                .open_or_create()
                .with_context(|| format!("could not open the service {}", service.as_str()))
        };
        let wake = |name: &str| -> anyhow::Result<_> {
            let service = service_name(domain, "wake", name)?;
            node.service_builder(&service)
                .event()
                .open_or_create()
                .with_context(|| format!("could not open the event service {}", service.as_str()))
        };
        let publisher =
            data(send_on)?.publisher_builder().create().context("could not create a publisher")?;
        let subscriber = data(receive_on)?
            .subscriber_builder()
            .create()
            .context("could not create a subscriber")?;
        let (notifier, listener) = match mode {
            WaitMode::Spin => (None, None),
            WaitMode::Block | WaitMode::SpinThenBlock => (
                Some(wake(send_on)?.notifier_builder().create().context("notifier")?),
                Some(wake(receive_on)?.listener_builder().create().context("listener")?),
            ),
        };
        Ok(Self { publisher, subscriber, notifier, listener })
    }

    /// A loaned message with sequence `seq`, written and ready to send.
    fn loan(&self, seq: u64) -> anyhow::Result<SampleMut<S, Message, ()>> {
        let sample = self.publisher.loan_uninit().context("could not loan a message")?;
        Ok(sample.write_payload(Message { seq, body: [seq as u8; 56] }))
    }

    /// Sends, and wakes the other process if it blocks.
    fn send(&self, message: SampleMut<S, Message, ()>) -> anyhow::Result<()> {
        message.send().context("could not send a message")?;
        if let Some(notifier) = &self.notifier {
            notifier.notify().context("could not notify")?;
        }
        Ok(())
    }

    /// The sequence of the next message `wanted` says to keep (others are dropped), if
    /// one is there.
    fn poll(&self, wanted: impl Fn(u64) -> bool) -> anyhow::Result<Option<u64>> {
        while let Some(sample) = self.subscriber.receive().context("could not receive")? {
            let seq = sample.payload().seq;
            if wanted(seq) {
                return Ok(Some(seq));
            }
        }
        Ok(None)
    }

    /// Waits for the next message `wanted` keeps: spinning, or blocking on the event.
    fn receive(
        &self,
        patience: &mut Patience<'_>,
        what: &str,
        wanted: impl Fn(u64) -> bool,
    ) -> anyhow::Result<u64> {
        match &self.listener {
            None => patience.spin(what, || self.poll(&wanted)),
            // As esgm's blocking subscriber does: drain wake-ups of messages already
            // taken (else the sleep would end at once), look once more, then sleep.
            Some(listener) => patience.block(what, |slice| {
                if let Some(seq) = self.poll(&wanted)? {
                    return Ok(Some(seq));
                }
                let failed = |e| anyhow!("waiting on the event failed: {e:?}");
                listener.try_wait(|_| {}).map_err(failed)?;
                if let Some(seq) = self.poll(&wanted)? {
                    return Ok(Some(seq));
                }
                listener.timed_wait(|_| {}, slice).map_err(failed)?;
                self.poll(&wanted)
            }),
        }
    }
}

fn service_name(domain: &str, kind: &str, name: &str) -> anyhow::Result<ServiceName> {
    let text = format!("esgm-bench/{domain}/floor-{kind}/{name}");
    ServiceName::new(&text).map_err(|e| anyhow!("invalid service name {text}: {e:?}"))
}
