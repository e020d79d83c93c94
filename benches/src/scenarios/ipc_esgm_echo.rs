//! The cross-process ping-pong behind `esgm-small` and `esgm-image`.
//!
//! Two trajectories in a domain of their own, `ping` (measuring process →
//! peer) and `pong` (back), through esgm-shm's [`TrajectoryPublisher`] and
//! [`TrajectorySubscriber`]. Both processes wait with the same [`WaitMode`]. Every leg is
//! the same operation — publish a structure, the other process receives it (validated
//! in place, [`esgm_shm::Validation::InPlace`]) and reads it ([`Kind::read`]) — so half
//! the round trip is one hop, timed on the measuring process's clock.
//!
//! What is inside a hop:
//! - a small structure ([`Encode::Before`], the rows the targets are stated for): only
//!   [`esgm_shm::StructureLoan::send`] after `set_times` (the sequence number, two
//!   8-byte writes into the archive). The structure was encoded into its loan before
//!   the timer started ([`TrajectoryPublisher::loan_structure`]), by the measuring
//!   process just before (timed apart as the producer's write) and by the peer while it
//!   waited — the hop is timed from the moment the structure is complete in the loaned
//!   slice, as for an image and for the floor's message;
//! - a small structure with [`Encode::InHop`] (the `esgm-small-publish` row): the whole
//!   `publish` — loan, encode into the loan (~0.2 µs) and send — on both legs;
//! - an image: likewise only `set_times` + `send`. The pixels were written into the
//!   loan and the archive completed around them ([`esgm_shm::ImageLoan::into_structure`]) before
//!   the timer started: by the measuring process just before, timed apart as the
//!   producer's write, and by the peer after its previous reply.
//!   Before each image ping the measuring process waits (untimed) until the peer says,
//!   on a third trajectory, `ready`, that its reply frame is written and it is waiting.
//!   And the peer writes its next frame only after the measuring process says, on a
//!   fourth trajectory, `done`, that it has read the reply and stopped its timer.
//!   So every image hop starts from the state a small one starts from — the peer idle,
//!   asleep in `event` rows — and never waits for the peer to finish writing, nor for a
//!   core the peer is busy writing on (Linux likes to wake a reader on the core of the
//!   process that woke it), nor reads the reply while the peer streams its next
//!   921,600 bytes through the caches (which made the reply's hop ~0.6 µs slower).
//!
//! The sequence number travels as the structure's valid time; a reply with another
//! number (an answer to a start-up ping) is skipped. Start-up: the measuring process
//! pings until the peer answers, because a sample sent before the peer's subscriber
//! connected is lost, then lets the peer answer the start-up pings still queued.
//! Stop: a ping with sequence −1.

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use esgm_shm::{
    ReceivedSample, ShmNode, StructureLoan, TrajectoryPublisher, TrajectoryQos,
    TrajectorySubscriber, WaitStrategy, unique_domain,
};

use super::ipc_node::ipc_node;
use super::ipc_payload::protocol::{DONE, HELLO, PING, PONG, READY, STOP};
use super::ipc_payload::{IMAGE_FORMAT, IMAGE_HEIGHT, IMAGE_NAME, IMAGE_WIDTH, Kind, pattern};
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::scenario::Context;
use crate::wait_mode::WaitMode;

/// Pause between start-up pings.
const HELLO_EVERY: Duration = Duration::from_millis(1);
/// Time for the peer to answer the start-up pings still queued once it answered one.
const HELLO_SETTLE: Duration = Duration::from_millis(20);

/// What one ping-pong measured.
#[derive(Debug)]
pub struct EsgmRun {
    /// One-way latency (half round trips).
    pub one_way: Latency,
    /// Time the measuring process took to prepare each structure before its hop
    /// (for an image: loan + write every pixel in place).
    pub write: Latency,
    /// Archived size of a structure (envelope included), as the header said.
    pub payload_bytes: u64,
    /// Replies whose header said the pixels were written in place.
    pub in_place: u64,
    /// What the peer reported.
    pub peer_notes: Vec<String>,
}

/// When a small structure is encoded into its loan (images are always written before).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encode {
    /// Before the hop: loaned and encoded, then only sent when the hop starts.
    Before,
    /// Inside the hop: `publish` loans, encodes and sends.
    InHop,
}

impl Encode {
    /// The peer argument that asks for [`Encode::InHop`].
    const IN_HOP_ARG: &'static str = "encode-in-hop";

    /// What the peer of `role` was told.
    fn of(role: &PeerRole) -> Self {
        match role.arg.as_deref() {
            Some(Self::IN_HOP_ARG) => Encode::InHop,
            _ => Encode::Before,
        }
    }

    /// The peer argument that tells the peer this.
    fn arg(self) -> Option<&'static str> {
        match self {
            Encode::Before => None,
            Encode::InHop => Some(Self::IN_HOP_ARG),
        }
    }
}

/// The esgm wait strategy of a mode.
pub fn strategy(mode: WaitMode) -> WaitStrategy {
    match mode {
        WaitMode::Spin => WaitStrategy::BusySpin,
        WaitMode::Block => WaitStrategy::Block,
        WaitMode::SpinThenBlock => WaitStrategy::default(),
    }
}

/// Runs the measuring side of scenario `scenario` with `mode` in both processes, small
/// structures encoded as `encode` says.
pub fn ping_pong(
    ctx: &Context,
    scenario: &str,
    (kind, encode): (Kind, Encode),
    mode: WaitMode,
) -> anyhow::Result<EsgmRun> {
    let (full, quick) = kind.samples();
    let samples = ctx.samples(full, quick);
    let warmup = ctx.warmup(samples);

    let domain = unique_domain("esgm-bench");
    let node = ipc_node()?;
    let ping = publisher(&node, &domain, PING, kind)?;
    let pong = subscriber(&node, &domain, PONG, kind, mode)?;
    // Images only: the peer's reply frame takes as long to write as ours. Subscribed
    // before the peer starts, so that none of its signals is lost.
    let (ready, done) = match kind {
        Kind::Small => (None, None),
        Kind::Image => (
            Some(subscriber(&node, &domain, READY, Kind::Small, mode)?),
            Some(publisher(&node, &domain, DONE, Kind::Small)?),
        ),
    };
    let mut peer = ctx.spawn_peer_process_as(scenario, mode, &domain, encode.arg())?;
    let mut patience = Patience::for_peer(&mut peer);

    let started = Instant::now();
    loop {
        send(prepare(kind, encode, &ping, 0)?, &ping, HELLO)?;
        if pong
            .wait_for_sample(HELLO_EVERY)
            .context("waiting for the peer's first answer")?
            .is_some()
        {
            break;
        }
        patience.check("answer to the first ping", started)?;
    }
    // Let the peer answer the start-up pings still queued, and forget the answers, so
    // that the first measured ping finds it idle.
    std::thread::sleep(HELLO_SETTLE);
    while pong.receive().context("receiving a pong")?.is_some() {}
    // The latest start-up ping the peer said it is ready after (images only).
    let mut ready_after = HELLO - 1;
    if let Some(ready) = &ready {
        while let Some(s) = ready.receive().context("receiving the peer's ready")? {
            ready_after = ready_after.max(s.header().valid_time);
        }
    }

    let mut run = EsgmRun {
        one_way: Latency::new()?,
        write: Latency::new()?,
        payload_bytes: 0,
        in_place: 0,
        peer_notes: Vec::new(),
    };
    for i in 1..=warmup + samples {
        let seq = i as i64;
        let making = Instant::now();
        let next = prepare(kind, encode, &ping, i)?;
        let made = making.elapsed();
        if let Some(ready) = &ready {
            // Ready after answering the previous ping (or the start-up ones).
            while ready_after < seq - 1 {
                let signal = patience
                    .block("peer ready", |slice| Ok(ready.wait_for_sample(slice)?))
                    .context("waiting for the peer to be ready")?;
                ready_after = ready_after.max(signal.header().valid_time);
            }
        }

        ctx.before_hop(mode.wait());
        let start = Instant::now();
        send(next, &ping, seq)?;
        let back = patience.block("pong", |slice| reply(&pong, slice, seq))?;
        black_box(kind.read(back.structure().context("reading the pong")?)?);
        let round_trip = start.elapsed();
        if let Some(done) = &done {
            send(prepare(Kind::Small, Encode::Before, done, 0)?, done, seq)?;
        }

        if i > warmup {
            run.one_way.record_half(round_trip);
            run.write.record(made);
            run.payload_bytes = back.header().archive_len;
            run.in_place += u64::from(back.is_image_in_place());
        }
    }
    send(prepare(kind, encode, &ping, 0)?, &ping, STOP)?;
    run.peer_notes = peer.finish(FINISH_TIMEOUT)?;
    Ok(run)
}

/// The peer side: echoes every ping until the stop.
pub fn echo(role: &PeerRole, kind: Kind) -> anyhow::Result<Vec<String>> {
    let node = ipc_node()?;
    let ping = subscriber(&node, &role.domain, PING, kind, role.wait)?;
    let pong = publisher(&node, &role.domain, PONG, kind)?;
    let (ready, done) = match kind {
        Kind::Small => (None, None),
        Kind::Image => (
            Some(publisher(&node, &role.domain, READY, Kind::Small)?),
            Some(subscriber(&node, &role.domain, DONE, Kind::Small, role.wait)?),
        ),
    };
    let encode = Encode::of(role);
    let mut patience = Patience::alone();
    let (mut pings, mut early, mut last) = (0u64, 0u64, HELLO);
    loop {
        let next = prepare(kind, encode, &pong, pings)?;
        // A ping already here came while the reply was being prepared.
        let early_ping = ping.receive().context("receiving a ping")?;
        if let Some(ready) = &ready {
            send(prepare(Kind::Small, Encode::Before, ready, pings)?, ready, last)?;
        }
        let (sample, waiting) = match early_ping {
            Some(sample) => (sample, true),
            None => (patience.block("ping", |slice| Ok(ping.wait_for_sample(slice)?))?, false),
        };
        let seq = sample.header().valid_time;
        if seq == STOP {
            break;
        }
        black_box(kind.read(sample.structure().context("reading a ping")?)?);
        drop(sample);
        send(next, &pong, seq)?;
        last = seq;
        if let Some(done) = done.as_ref().filter(|_| seq > HELLO) {
            // Write the next frame only once the reply has been read.
            let mut read_up_to = HELLO;
            while read_up_to < seq {
                let signal = patience
                    .block("done", |slice| Ok(done.wait_for_sample(slice)?))
                    .context("waiting for the reply to be read")?;
                read_up_to = read_up_to.max(signal.header().valid_time);
            }
        }
        if seq > HELLO {
            pings += 1;
            early += u64::from(waiting);
        }
    }
    let mut notes = Vec::new();
    if early > 0 {
        notes.push(format!(
            "{early} of {pings} pings reached the peer before its reply was prepared (those hops \
             include part of the peer's preparation)"
        ));
    }
    Ok(notes)
}

/// Settings of both trajectories. Images get small buffers: each publisher maps
/// `max_subscribers × (buffer + borrowed) + history` chunks of a megabyte.
fn qos(kind: Kind) -> TrajectoryQos {
    match kind {
        Kind::Small => TrajectoryQos::default(),
        Kind::Image => TrajectoryQos {
            subscriber_buffer_size: 2,
            max_borrowed_samples: 2,
            max_publishers: 1,
            max_subscribers: 2,
            ..TrajectoryQos::default()
        },
    }
}

fn publisher(
    node: &ShmNode,
    domain: &str,
    trajectory: &str,
    kind: Kind,
) -> anyhow::Result<TrajectoryPublisher> {
    TrajectoryPublisher::builder(trajectory, kind.type_name())
        .domain(domain)
        .qos(qos(kind))
        .max_len(kind.max_bytes())
        .image_name(IMAGE_NAME)
        .create(node)
        .with_context(|| format!("could not publish {trajectory} in {domain}"))
}

fn subscriber(
    node: &ShmNode,
    domain: &str,
    trajectory: &str,
    kind: Kind,
    mode: WaitMode,
) -> anyhow::Result<TrajectorySubscriber> {
    TrajectorySubscriber::builder(trajectory, kind.type_name())
        .domain(domain)
        .qos(qos(kind))
        .wait_strategy(strategy(mode))
        .create(node)
        .with_context(|| format!("could not subscribe to {trajectory} in {domain}"))
}

/// A structure made and ready to send.
enum Ready<'p> {
    /// A structure encoded into its loan (a small one, or an image completed around
    /// the pixels written in place), waiting for its times.
    Loaned(StructureLoan<'p>),
    /// A small structure, encoded into a loan when sent.
    Structure(esgm_core::EntityStructure),
}

/// Makes the `i`-th structure: for an image, loans shared memory and writes every
/// pixel into it, as a camera would, then completes the archive around them.
fn prepare(
    kind: Kind,
    encode: Encode,
    publisher: &TrajectoryPublisher,
    i: u64,
) -> anyhow::Result<Ready<'_>> {
    match (kind, encode) {
        (Kind::Small, Encode::Before) => Ok(Ready::Loaned(
            publisher.loan_structure(&kind.make(i)).context("could not loan a structure")?,
        )),
        (Kind::Small, Encode::InHop) => Ok(Ready::Structure(kind.make(i))),
        (Kind::Image, _) => {
            let mut loan = publisher
                .loan_image(IMAGE_WIDTH, IMAGE_HEIGHT, IMAGE_FORMAT)
                .context("could not loan an image")?;
            let seed = i as u8;
            // Written once, in place, without zeroing first: the camera path.
            for (k, pixel) in loan.pixels_uninit_mut().iter_mut().enumerate() {
                pixel.write(pattern(k, seed));
            }
            // SAFETY: the loop above wrote every byte of the pixel range.
            unsafe { loan.assume_pixels_init() };
            let ready = loan.into_structure(IMAGE_NAME, 0, 0).context("could not complete")?;
            Ok(Ready::Loaned(ready))
        }
    }
}

/// Sends a prepared structure with sequence `seq` (as its valid and create time).
fn send(ready: Ready<'_>, publisher: &TrajectoryPublisher, seq: i64) -> anyhow::Result<()> {
    match ready {
        Ready::Loaned(mut loan) => {
            loan.set_times(seq, seq).with_context(|| format!("could not stamp {seq}"))?;
            loan.send().with_context(|| format!("could not send {seq}"))?;
        }
        Ready::Structure(mut es) => {
            es.valid_time = seq;
            es.create_time = seq;
            publisher.publish(&es).with_context(|| format!("could not publish {seq}"))?;
        }
    }
    Ok(())
}

/// The reply with sequence `seq`, if it comes within `slice`; earlier replies are
/// dropped.
fn reply(
    pong: &TrajectorySubscriber,
    slice: Duration,
    seq: i64,
) -> anyhow::Result<Option<ReceivedSample>> {
    match pong.wait_for_sample(slice).context("receiving a pong")? {
        Some(sample) if sample.header().valid_time == seq => Ok(Some(sample)),
        _ => Ok(None),
    }
}
