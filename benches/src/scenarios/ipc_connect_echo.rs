//! The cross-process ping-pong behind `connect-small` and `connect-image`: the API a
//! user calls, [`esgm_shm::ShmEsgm`] (`ShmEsgm::builder()…connect()`), on both sides.
//!
//! The measuring process starts a coordinator on a thread of its own
//! ([`Coordinator::spawn`], in a domain unique to the measurement), connects, creates
//! the primitive trajectory `ping` and starts the peer process, which connects too,
//! subscribes to `ping` ([`Esgm::get_entity_trajectory_structure`], then
//! [`EntityTrajectoryStructure::subscribe`]) and creates `pong`. Each process writes the
//! trajectory it adds to, so the coordinator places it there, and reads the other's
//! through its replica. Every leg is the same user call and the same wait: `add` of an
//! [`EntityStructure`] in one process, until the [`Subscription`] in the other has
//! returned the [`esgm_core::Sample`] and the reader has read it ([`read_value`]: the
//! `x` of a `RobotState`, a pixel at each end of an `Image`). Half the round trip is one
//! hop, timed on the measuring process's clock.
//!
//! How the subscribers wait is the row's wait ([`WaitMode`]): `spin` polls
//! [`Subscription::try_recv`] in a loop, `event` blocks in
//! [`Subscription::recv_timeout`] — what a user of `connect` gets; `connect` has no
//! wait strategy of its own to choose.
//!
//! The structure of each leg is made before the timer starts (by the measuring process
//! just before, timed apart as the producer's write; by the peer while it waits): a
//! `RobotState`, or a 640×480 RGB `Image` whose pixels are written once into a fresh
//! buffer, as a camera renders a frame. For images, as in [`super::ipc_esgm_echo`], two
//! more trajectories keep the peer's 921,600-byte writes out of the hops: the peer says
//! on `ready` that its reply frame is made and it is waiting, and the measuring process
//! says on `done` that it has read the reply and stopped its timer, before the peer
//! makes its next frame. A *paced* small row (`connect-small-paced`) runs the same
//! exchange with a `RobotState`, so that the image's hop is compared with a small hop
//! that comes after the same steps, as a camera's do, rather than back to back.
//!
//! The sequence number travels as the structure's valid time (the trajectories are
//! unconstrained but for a cache of [`CACHE`] samples, so any valid time is admitted); a
//! reply with another number is skipped. Start-up: the measuring process adds pings with
//! sequence 0, ever less often, until one is answered, because a structure added before
//! the peer's replica is connected never reaches it, then lets the peer answer those
//! still queued and forgets the answers. Stop: a ping with sequence −1. Every wait gives up when the
//! peer exits or after [`crate::patience::PEER_TIMEOUT`].

use std::hint::black_box;
use std::time::{Duration, Instant};

use crate::domain_end::DomainEnd;
use anyhow::{Context as _, bail};
use esgm_core::library::Image;
use esgm_core::store::RecvError;
use esgm_core::{
    AddOutcome, CacheConstraint, Entity, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InProcessTrajectory, Sample, SubscribeOptions, Subscription,
    TrajectorySpec, TypeRegistry,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

use super::ipc_payload::protocol::{DONE, HELLO, PING, PONG, READY, STOP};
use super::ipc_payload::{
    IMAGE_FORMAT, IMAGE_HEIGHT, IMAGE_NAME, IMAGE_WIDTH, Kind, pattern, read_value,
};
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::scenario::Context;
use crate::wait_mode::WaitMode;

/// How long the measuring process waits for an answer to its first start-up ping; the
/// wait doubles with each ping after it, up to [`HELLO_EVERY_MAX`].
const HELLO_EVERY: Duration = Duration::from_millis(5);
/// The longest wait between two start-up pings. Pings must not come faster than the
/// writer's location thread publishes them (an image takes milliseconds in a debug
/// build): it publishes all that are queued before it reads the answers.
const HELLO_EVERY_MAX: Duration = Duration::from_millis(200);
/// Time for the peer to answer the start-up pings still queued once it answered one.
const HELLO_SETTLE: Duration = Duration::from_millis(50);
/// Samples each trajectory keeps: a controller's few latest, and few enough images
/// that every one a replica keeps stays borrowed in shared memory, not copied.
pub const CACHE: usize = 4;

/// What one ping-pong measured.
#[derive(Debug)]
pub struct ConnectRun {
    /// One-way latency (half round trips).
    pub one_way: Latency,
    /// Time the measuring process took to make each structure before its hop (for an
    /// image: write every pixel into a fresh buffer).
    pub write: Latency,
    /// Replies measured.
    pub replies: u64,
    /// Replies whose pixels the measuring process read in shared memory (held, not
    /// copied onto its heap).
    pub held: u64,
    /// Measured pings whose writer skipped the iceoryx2 notify: the peer's connection
    /// was covered by its thread asleep on the word (`esgm_shm::wake_word`).
    pub notifies_spared: u64,
    /// What the peer reported.
    pub peer_notes: Vec<String>,
}

/// Runs the measuring side of scenario `scenario` with `mode` in both processes;
/// `paced`: each hop waits for the `ready`/`done` exchange of the module docs, as a
/// camera's frames do (every image row is paced).
pub fn ping_pong(
    ctx: &Context,
    scenario: &str,
    (kind, history): (Kind, History),
    paced: bool,
    mode: WaitMode,
) -> anyhow::Result<ConnectRun> {
    let (full, quick) = kind.samples();
    let samples = ctx.samples(full, quick);
    let warmup = ctx.warmup(samples);

    // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let domain = unique_domain("esgm-bench-connect");
    // Dropped after every process of the domain: removes its futex words, which a
    // peer killed on a failure would leave in /dev/shm.
    let _end = DomainEnd::new(&domain);
    // Dropped last (declared first): it stops when the measurement is over or failed.
    let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
        .with_context(|| format!("could not start a coordinator for {domain}"))?;
    let esgm = connect(coordinator.domain(), "bench-measuring")?;
    let ping = create_as(&esgm, PING, kind, history)?;
    // Images only (see the module docs).
    let done = if paced { Some(create_as(&esgm, DONE, Kind::Small, history)?) } else { None };
    let mut peer = ctx.spawn_peer_process(scenario, mode, &domain)?;
    let mut patience = Patience::for_peer(&mut peer);
    // The peer subscribes to ours before it creates its own: once its trajectories
    // exist, its subscriptions do too.
    let pong = subscribe_when_created(&esgm, PONG, &mut patience)?;
    let ready =
        if paced { Some(subscribe_when_created(&esgm, READY, &mut patience)?) } else { None };

    // Made once: start-up pings share its pixels.
    let hello = kind.make(0);
    let started = Instant::now();
    let mut every = HELLO_EVERY;
    loop {
        add(&ping, stamped(hello.clone(), HELLO))?;
        if received(&pong, every)?.is_some() {
            break;
        }
        patience.check("answer to the first ping", started)?;
        every = (every * 2).min(HELLO_EVERY_MAX);
    }
    // Let the peer answer the start-up pings still queued, and forget the answers, so
    // that the first measured ping finds it idle.
    std::thread::sleep(HELLO_SETTLE);
    drop(pong.drain());
    // The latest ping the peer said it is ready after (images only).
    let mut ready_after = HELLO - 1;
    if let Some(ready) = &ready {
        for s in ready.drain() {
            ready_after = ready_after.max(s.valid_time());
        }
    }

    let mut run = ConnectRun {
        one_way: Latency::new()?,
        write: Latency::new()?,
        replies: 0,
        held: 0,
        notifies_spared: 0,
        peer_notes: Vec::new(),
    };
    let mut spared_before = 0;
    let mut dones_spared = 0;
    for i in 1..=warmup + samples {
        let seq = i as i64;
        if let Some(ready) = &ready {
            // Ready after answering the previous ping (or the start-up ones).
            while ready_after < seq - 1 {
                let signal = next(ready, mode, &mut patience, "peer ready")?;
                ready_after = ready_after.max(signal.valid_time());
            }
        }
        let making = Instant::now();
        let structure = stamped(make_for(&ping, kind, i), seq);
        let made = making.elapsed();

        if i == warmup + 1 {
            spared_before = esgm_shm::unstable::notifies_spared_here();
        }
        ctx.before_hop(mode.wait());
        let start = Instant::now();
        add(&ping, structure)?;
        let back = reply(&pong, mode, &mut patience, seq)?;
        let (value, held) = read_value(kind, &back.structure).context("reading the pong")?;
        black_box(value);
        let round_trip = start.elapsed();
        if let Some(done) = &done {
            let before = esgm_shm::unstable::notifies_spared_here();
            add(done, stamped(Kind::Small.make(i), seq))?;
            // Counted out below: the row counts the measured pings' notifies.
            if i > warmup {
                dones_spared += esgm_shm::unstable::notifies_spared_here() - before;
            }
        }

        if i > warmup {
            run.one_way.record_half(round_trip);
            run.write.record(made);
            run.replies += 1;
            run.held += u64::from(held);
        }
    }
    // Every publisher of this process is the measuring connection's: its pings, and a
    // paced row's `done` signals.
    run.notifies_spared = esgm_shm::unstable::notifies_spared_here() - spared_before - dones_spared;
    add(&ping, stamped(hello, STOP))?;
    run.peer_notes = peer.finish(FINISH_TIMEOUT)?;
    // The connection goes before its coordinator.
    drop(esgm);
    drop(coordinator);
    Ok(run)
}

/// The peer side: echoes every ping until the stop (`paced` as the measuring side's).
pub fn echo(
    role: &PeerRole,
    (kind, history): (Kind, History),
    paced: bool,
) -> anyhow::Result<Vec<String>> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let esgm = connect(&role.domain, "bench-peer")?;
    // Subscribed before ours are created: see `ping_pong`.
    let ping = subscribe(&esgm, PING)?;
    let done = if paced { Some(subscribe(&esgm, DONE)?) } else { None };
    let pong = create_as(&esgm, PONG, kind, history)?;
    let ready = if paced { Some(create_as(&esgm, READY, Kind::Small, history)?) } else { None };

    let mut patience = Patience::alone();
    let (mut pings, mut early, mut held, mut last) = (0u64, 0u64, 0u64, HELLO);
    let mut reply_frame = kind.make(0);
    loop {
        // A ping already here came while the reply was being made.
        let early_ping = ping.try_recv();
        if let Some(ready) = &ready {
            add(ready, stamped(Kind::Small.make(pings), last))?;
        }
        let (sample, waiting) = match early_ping {
            Some(sample) => (sample, true),
            None => (next(&ping, role.wait, &mut patience, "ping")?, false),
        };
        let seq = sample.valid_time();
        if seq == STOP {
            break;
        }
        let (value, in_place) = read_value(kind, &sample.structure).context("reading a ping")?;
        black_box(value);
        drop(sample);
        // A clone shares the pixels: start-up answers reuse the first frame.
        add(&pong, stamped(reply_frame.clone(), seq))?;
        last = seq;
        if seq == HELLO {
            continue;
        }
        if let Some(done) = &done {
            // Make the next frame only once the reply has been read.
            let mut read_up_to = HELLO;
            while read_up_to < seq {
                let signal = next(done, role.wait, &mut patience, "done")
                    .context("waiting for the reply to be read")?;
                read_up_to = read_up_to.max(signal.valid_time());
            }
        }
        pings += 1;
        early += u64::from(waiting);
        held += u64::from(in_place);
        reply_frame = make_for(&pong, kind, pings);
    }

    let mut notes = Vec::new();
    if early > 0 {
        notes.push(format!(
            "{early} of {pings} pings (warm-up included) reached the peer before its reply was \
             made (those hops include part of the peer's preparation)"
        ));
    }
    if kind == Kind::Image {
        notes.push(format!(
            "the peer read {held} of {pings} pings' pixels (warm-up included) in place in \
             shared memory (held), {} copied onto its heap",
            pings - held
        ));
    }
    Ok(notes)
}

/// Connects to the coordinator of `domain` as `host`.
pub fn connect(domain: &str, host: &str) -> anyhow::Result<ShmEsgm> {
    ShmEsgm::builder()
        .domain(domain)
        .host(host)
        .connect()
        .with_context(|| format!("{host}: could not connect to the coordinator of {domain}"))
}

/// Whether a row's primitive trajectories keep what they acknowledged beyond their
/// writer (the default, SPEC D1) or are volatile: the two rows of a scenario say what
/// keeping costs a hop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum History {
    /// Kept (the default).
    Kept,
    /// [`TrajectorySpec::volatile`].
    Volatile,
}

/// Creates primitive trajectory `name` of `kind`, written by this process, its history
/// kept.
pub fn create(esgm: &ShmEsgm, name: &str, kind: Kind) -> anyhow::Result<InProcessTrajectory> {
    create_as(esgm, name, kind, History::Kept)
}

/// [`create`], its history kept or volatile.
pub fn create_as(
    esgm: &ShmEsgm,
    name: &str,
    kind: Kind,
    history: History,
) -> anyhow::Result<InProcessTrajectory> {
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(CACHE));
    let mut spec = TrajectorySpec::primitive(name, kind.type_name()).policy(policy);
    if history == History::Volatile {
        spec = spec.volatile();
    }
    esgm.create_trajectory(spec).with_context(|| format!("could not create trajectory {name}"))
}

/// Subscribes to trajectory `name`, which exists.
pub fn subscribe(esgm: &ShmEsgm, name: &str) -> anyhow::Result<Subscription<Sample>> {
    esgm.get_entity_trajectory_structure(name)
        .with_context(|| format!("no trajectory {name}"))?
        .subscribe(SubscribeOptions::default())
        .with_context(|| format!("could not subscribe to {name}"))
}

/// Subscribes to trajectory `name` once the peer has created it.
fn subscribe_when_created(
    esgm: &ShmEsgm,
    name: &str,
    patience: &mut Patience<'_>,
) -> anyhow::Result<Subscription<Sample>> {
    let started = Instant::now();
    loop {
        if let Ok(trajectory) = esgm.get_entity_trajectory_structure(name) {
            return trajectory
                .subscribe(SubscribeOptions::default())
                .with_context(|| format!("could not subscribe to {name}"));
        }
        patience.check(&format!("trajectory {name} from the peer"), started)?;
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The `i`-th structure for `trajectory`, as its producer makes it: an image's pixels
/// are written once, into the trajectory's own buffer (a loan of its shared memory,
/// [`InProcessTrajectory::image_buffer`]), as a camera renders a frame.
pub fn make_for(trajectory: &InProcessTrajectory, kind: Kind, i: u64) -> EntityStructure {
    let Kind::Image = kind else { return kind.make(i) };
    let Some(mut buffer) = trajectory.image_buffer(IMAGE_WIDTH, IMAGE_HEIGHT, IMAGE_FORMAT) else {
        return kind.make(i);
    };
    let seed = i as u8;
    for (k, p) in buffer.pixels_mut().iter_mut().enumerate() {
        *p = pattern(k, seed);
    }
    Image {
        width: IMAGE_WIDTH,
        height: IMAGE_HEIGHT,
        format: IMAGE_FORMAT,
        image_data: buffer.into_octets(),
    }
    .to_structure(IMAGE_NAME, 0, 0)
}

/// `es` with sequence `seq` as its valid and create time.
pub fn stamped(mut es: EntityStructure, seq: i64) -> EntityStructure {
    es.valid_time = seq;
    es.create_time = seq;
    es
}

/// Adds `es` to `trajectory`, which this process writes: it must be admitted.
pub fn add(trajectory: &InProcessTrajectory, es: EntityStructure) -> anyhow::Result<()> {
    let seq = es.valid_time;
    match trajectory.add(es) {
        Ok(AddOutcome::Added) => Ok(()),
        Ok(other) => bail!("{}: structure {seq} was not admitted: {other:?}", trajectory.name()),
        Err(e) => Err(e).with_context(|| format!("{}: could not add {seq}", trajectory.name())),
    }
}

/// The next sample within `slice`, if one comes.
pub fn received(sub: &Subscription<Sample>, slice: Duration) -> anyhow::Result<Option<Sample>> {
    match sub.recv_timeout(slice) {
        Ok(sample) => Ok(Some(sample)),
        Err(RecvError::Timeout) => Ok(None),
        Err(e) => Err(e).context("the subscription ended"),
    }
}

/// The next sample, waiting as `mode` says.
pub fn next(
    sub: &Subscription<Sample>,
    mode: WaitMode,
    patience: &mut Patience<'_>,
    what: &str,
) -> anyhow::Result<Sample> {
    match mode {
        WaitMode::Spin => patience.spin(what, || Ok(sub.try_recv())),
        WaitMode::Block | WaitMode::SpinThenBlock => {
            patience.block(what, |slice| received(sub, slice))
        }
    }
}

/// The reply with sequence `seq`; earlier replies are dropped.
fn reply(
    pong: &Subscription<Sample>,
    mode: WaitMode,
    patience: &mut Patience<'_>,
    seq: i64,
) -> anyhow::Result<Sample> {
    match mode {
        WaitMode::Spin => {
            patience.spin("pong", || Ok(pong.try_recv().filter(|s| s.valid_time() == seq)))
        }
        WaitMode::Block | WaitMode::SpinThenBlock => patience
            .block("pong", |slice| Ok(received(pong, slice)?.filter(|s| s.valid_time() == seq))),
    }
}
