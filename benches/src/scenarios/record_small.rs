//! `record-small`: how many small structures per second the recorder keeps up with
//! when they come from another process, and what it misses.
//!
//! The measuring process starts a coordinator on a thread of its own (in a domain
//! unique to the measurement), connects (`esgm_shm` `connect`) and creates the
//! trajectory `record-go`; the peer process connects too, subscribes to it and creates
//! the primitive trajectory `record-states` (`RobotState`, a cache of [`CACHE`]
//! structures: `connect` sizes a replica's queue by the cache, and a queue shorter than
//! a batch loses what the recorder has not taken yet). The measuring process records
//! `record-states` with [`esgm_recording::Recorder`] into a file in a temporary
//! folder, as `esgm record` does (Foxglove JSON views on), once with zstd (the
//! default) and once without compression (`record-small-none`).
//!
//! The peer adds in batches of [`BATCH`] structures, back to back, each batch when
//! the measuring process says `go` on `record-go`; the measuring process waits until
//! the recorder has written (or counted as missed) the whole batch before the next
//! `go`. A batch's time, from its `go` to its last structure written, over its
//! structures, is one sample (`per-item`): the rate the recorder sustains with the
//! publisher going as fast as it can, measured without letting a queue grow (a batch
//! is smaller than the queues). Losses
//! (`recorder_overflow`: the recorder's subscription overflowed; `lost`: lost before
//! reaching the recorder's process) are printed with their counts and causes, never
//! hidden; the goal is 200,000 structures/s with none.
//!
//! The recorder's progress is read every [`POLL`] (its statistics): each batch's time
//! is late by at most that much, a few per cent of a batch.

use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{CacheConstraint, Esgm as _, FluentStreamPolicy, TrajectorySpec};
use esgm_recording::{Compression, RecordOptions, Recorder, RecordingWriter, recorder};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect_echo::{add, connect, create, next, stamped, subscribe};
use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "record-small";
/// Structures per batch: fewer than a replica of `record-states` queues ([`CACHE`]), so
/// a batch never overflows a queue on its way to the recorder.
pub const BATCH: u64 = 1_000;
/// The cache of `record-states`, which sizes its replicas' queues.
pub const CACHE: usize = 2_048;
/// How often the measuring process reads the recorder's progress.
pub const POLL: Duration = Duration::from_micros(50);
/// A batch with no progress for this long is given up (and reported).
pub const STALL: Duration = Duration::from_secs(2);
/// The trajectory the measuring process says `go` on.
const GO: &str = "record-go";
/// The recorded trajectory, written by the peer.
const STATES: &str = "record-states";
/// `go` sequence numbers: the peer answers a hello with one structure, a stop ends it.
const HELLO: i64 = 0;
const STOP: i64 = -1;

/// See the module docs.
#[derive(Debug, Clone, Copy)]
pub struct RecordSmall;

impl Scenario for RecordSmall {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "RobotStates added back to back in another process (connect), recorded by Recorder \
         (zstd, and none): structures/s in batches, losses with their causes"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        [Compression::Zstd, Compression::None].iter().map(|&c| measure(ctx, c)).collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        publish(role)
    }
}

/// The row name and label of a compression.
fn label(c: Compression) -> (&'static str, &'static str) {
    match c {
        Compression::Zstd => (NAME, "zstd"),
        Compression::Lz4 => ("record-small-lz4", "lz4"),
        Compression::None => ("record-small-none", "none"),
    }
}

/// What the recorder has handled so far: written plus counted as missed.
pub fn handled(recorder: &Recorder) -> u64 {
    let stats = recorder.stats();
    stats.recorded() + stats.missed()
}

/// Waits until the recorder has handled `target` structures; false if it made no
/// progress for [`STALL`] (or the recording failed).
pub fn wait_handled(recorder: &Recorder, target: u64) -> bool {
    let (mut last, mut since) = (handled(recorder), Instant::now());
    while last < target {
        if recorder.failed() {
            return false;
        }
        std::thread::sleep(POLL);
        let now = handled(recorder);
        if now > last {
            (last, since) = (now, Instant::now());
        } else if since.elapsed() > STALL {
            return false;
        }
    }
    true
}

/// The recorder's losses as a note: count and cause, zero included.
pub fn losses_note(stats: &esgm_recording::RecorderStats) -> String {
    let (overflow, lost, violations) = stats
        .trajectories
        .values()
        .fold((0, 0, 0), |a, c| (a.0 + c.recorder_overflow, a.1 + c.lost, a.2 + c.violations));
    let total = overflow + lost;
    let flag = if total > 0 { "LOSSES" } else { "losses" };
    format!(
        "{flag}: {total} (recorder_overflow {overflow}: the recorder's subscription overflowed; \
         lost {lost}: lost before reaching the recorder's process); {violations} policy \
         violations"
    )
}

/// The sizes of the files a recording wrote.
pub fn file_bytes(summary: &esgm_recording::WriteSummary) -> anyhow::Result<u64> {
    let mut total = 0;
    for f in &summary.files {
        total += std::fs::metadata(f).with_context(|| format!("{}", f.display()))?.len();
    }
    Ok(total)
}

fn measure(ctx: &Context, compression: Compression) -> anyhow::Result<Measurement> {
    let (row_name, compression_label) = label(compression);
    let structures = ctx.samples(200_000, 20_000);
    let batch = structures.min(BATCH);
    let batches = structures.div_ceil(batch);
    // One untimed batch first: pages, caches, the first chunk.
    let warmup = 1;

    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let domain = unique_domain("esgm-bench-rec");
    // Dropped last (declared first): it stops when the measurement is over or failed.
    let coordinator =
        Coordinator::spawn(&domain, Registry::new(esgm_core::TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
    let esgm = connect(coordinator.domain(), "bench-recorder")?;
    let go = create(&esgm, GO, Kind::Small)?;
    let mut peer =
        ctx.spawn_peer_process_as(NAME, WaitMode::Block, &domain, Some(&batch.to_string()))?;
    let mut patience = Patience::for_peer(&mut peer);
    let started = Instant::now();
    while esgm.get_entity_trajectory_structure(STATES).is_err() {
        patience.check(&format!("trajectory {STATES} from the peer"), started)?;
        std::thread::sleep(Duration::from_millis(5));
    }

    let dir = tempfile::tempdir().context("could not make a temporary folder")?;
    let path = dir.path().join(format!("{row_name}.mcap"));
    let writer = RecordingWriter::create(&path, RecordOptions::default().compression(compression))
        .with_context(|| format!("could not create {}", path.display()))?;
    let recorder = Recorder::start(&esgm, &[STATES.to_owned()], writer, recorder::DEFAULT_BUFFER)
        .context("could not start the recorder")?;

    // Hellos until the recorder has one answer: the peer's adds reach this process
    // only once its replica is connected, and the peer must have our `go`s.
    let mut every = Duration::from_millis(5);
    let started = Instant::now();
    loop {
        add(&go, stamped(Kind::Small.make(0), HELLO))?;
        let until = Instant::now() + every;
        while handled(&recorder) == 0 && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(1));
        }
        if handled(&recorder) > 0 {
            break;
        }
        patience.check("a recorded answer to the first hello", started)?;
        every = (every * 2).min(Duration::from_millis(200));
    }
    // Answers to hellos still queued come now, before the first batch is counted.
    std::thread::sleep(Duration::from_millis(50));
    let base = handled(&recorder);

    let mut per_structure = Latency::new()?;
    let (mut timed, mut timed_structures, mut stalled) = (Duration::ZERO, 0u64, None);
    for k in 1..=warmup + batches {
        let start = Instant::now();
        add(&go, stamped(Kind::Small.make(k), k as i64))?;
        if !wait_handled(&recorder, base + k * batch) {
            patience.check("the recorder's progress", start)?;
            stalled = Some(k);
            break;
        }
        let took = start.elapsed();
        if k > warmup {
            per_structure
                .record_ns(u64::try_from(took.as_nanos() / u128::from(batch)).unwrap_or(u64::MAX));
            timed += took;
            timed_structures += batch;
        }
    }
    add(&go, stamped(Kind::Small.make(0), STOP))?;
    let peer_notes = peer.finish(FINISH_TIMEOUT)?;
    let (summary, stats) = recorder.stop().context("could not stop the recorder")?;
    let bytes = file_bytes(&summary)?;
    dir.close().context("could not remove the temporary folder")?;
    drop(esgm);
    drop(coordinator);

    let rate = timed_structures as f64 / timed.as_secs_f64().max(1e-9);
    let recorded = stats.recorded();
    let missed = stats.missed();
    let payload = esgm_core::codec::encoded_len(&Kind::Small.make(0))? as u64;
    let mut row = per_structure
        .measurement(row_name, Wait::Event)
        .payload_bytes(payload)
        .method(Method::PerItem)
        .wait_strategy("block")
        .throughput(rate, missed)
        .if_empty("no batch was recorded")
        .note(format!(
            "{rate:.0} structures/s recorded ({compression_label}) over {} timed batches of \
             {batch} (p50 {:.0}/s, p99 batch {:.0}/s); {recorded} recorded in all",
            per_structure.len(),
            1e9 / per_structure.quantile(0.5).max(1) as f64,
            1e9 / per_structure.quantile(0.99).max(1) as f64,
        ))
        .note(losses_note(&stats))
        .note(format!(
            "file: {:.1} MB, {:.1} bytes per structure ({compression_label}, JSON views on)",
            bytes as f64 / 1e6,
            bytes as f64 / recorded.max(1) as f64
        ));
    if let Some(k) = stalled {
        row = row.note(format!(
            "STALLED: batch {k} was not fully recorded within {} s of its last progress",
            STALL.as_secs()
        ));
    }
    for note in peer_notes {
        row = row.note(format!("peer: {note}"));
    }
    Ok(row)
}

/// The peer: adds a batch at each `go`, a structure at each hello, until the stop.
fn publish(role: &PeerRole) -> anyhow::Result<Vec<String>> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let batch: u64 = match role.arg.as_deref().map(str::parse) {
        Some(Ok(n)) if n > 0 => n,
        other => bail!("the record-small peer needs a batch size, got {other:?}"),
    };
    let esgm = connect(&role.domain, "bench-robot")?;
    // Subscribed before ours is created: once it exists, the `go`s reach us.
    let go = subscribe(&esgm, GO)?;
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(CACHE));
    let states = esgm
        .create_trajectory(
            TrajectorySpec::primitive(STATES, Kind::Small.type_name()).policy(policy),
        )
        .with_context(|| format!("could not create trajectory {STATES}"))?;
    let mut patience = Patience::alone();
    let mut adding = Latency::new()?;
    let (mut seq, mut batches) = (0u64, 0u64);
    loop {
        let signal = next(&go, WaitMode::Block, &mut patience, "go")?;
        let (n, timed) = match signal.valid_time() {
            STOP => break,
            HELLO => (1, false),
            _ => (batch, true),
        };
        let start = Instant::now();
        for _ in 0..n {
            seq += 1;
            add(&states, stamped(Kind::Small.make(seq), seq as i64))?;
        }
        if timed {
            adding.record_ns(
                u64::try_from(start.elapsed().as_nanos() / u128::from(n)).unwrap_or(u64::MAX),
            );
            batches += 1;
        }
    }
    Ok(vec![format!(
        "added {batches} batches (warm-up included) at p50 {:.0} structures/s within a batch",
        1e9 / adding.quantile(0.5).max(1) as f64
    )])
}
