//! `replay-max`: structures per second that `replay` publishes from a recording as fast
//! as the domain takes them ([`Pace::Max`]).
//!
//! A recording of 10^6 `RobotState`s (10^4 under `--quick`; `--samples N` makes it N)
//! on one primitive trajectory is written first with [`RecordingWriter`] directly
//! (zstd, views on, as `esgm record` writes; its rate is a note), then replayed with
//! [`replay`] and the default options but the pace — times shifted to now, the
//! trajectory created by the replay with its recorded policy (a cache of
//! [`CACHE`] structures) — into a fresh domain each time:
//! - `replay-max`: an in-process [`InProcessEsgm`];
//! - `replay-max-connect`: a `connect`ed [`esgm_shm::ShmEsgm`] whose coordinator runs
//!   on a thread of the measuring process (each add is published in shared memory;
//!   nobody reads it).
//!
//! One sample is one whole replay, its time over its structures (`per-item`, from the
//! call of `replay` to its return: opening the samples, reading, decoding and adding).
//! [`RUNS`] replays per row ([`QUICK_RUNS`] under `--quick`).

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context as _, bail};
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::RobotState;
use esgm_core::{
    CacheConstraint, Entity as _, Esgm, FluentStreamPolicy, InProcessEsgm, InProcessTrajectory,
};
use esgm_recording::replay::{self, Pace, ReplayOptions};
use esgm_recording::{RecordOptions, Recording, RecordingWriter, TypeSchema};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect_echo::connect;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "replay-max";
/// The recorded trajectory.
const TRAJECTORY: &str = "replay-states";
/// The cache of the recorded (and replayed) trajectory.
pub const CACHE: usize = 1_000;
/// Replays per row in a full run.
pub const RUNS: u64 = 3;
/// Replays per row under `--quick`.
pub const QUICK_RUNS: u64 = 2;

/// See the module docs.
#[derive(Debug, Clone, Copy)]
pub struct ReplayMax;

impl Scenario for ReplayMax {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "replay --max of a 10^6-RobotState recording into an in-process ESGM and a connect \
         domain: structures/s"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let structures = ctx.samples(1_000_000, 10_000);
        let runs = if ctx.is_quick() { QUICK_RUNS } else { RUNS };
        let dir = tempfile::tempdir().context("could not make a temporary folder")?;
        let path = dir.path().join("replay.mcap");
        let written = write(&path, structures)?;
        let opening = Instant::now();
        let rec = Recording::open(&path).with_context(|| format!("opening {}", path.display()))?;
        let opened = opening.elapsed();
        let file_len = rec.file_len;

        let payload = esgm_core::codec::encoded_len(&robot(0))? as u64;
        let common = format!(
            "a {structures}-structure recording ({:.1} MB, zstd) written at {written:.0} \
             structures/s by RecordingWriter, opened in {:.0} ms",
            file_len as f64 / 1e6,
            opened.as_secs_f64() * 1e3
        );
        let mut rows = Vec::new();
        let mut per = Latency::new()?;
        let mut added = 0;
        for _ in 0..runs {
            let esgm = InProcessEsgm::default();
            added = replay_once(&esgm, &rec, structures, &mut per)?;
        }
        rows.push(row(NAME, &per, payload, "an in-process InProcessEsgm", &common, added));

        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let mut per = Latency::new()?;
        for _ in 0..runs {
            let domain = unique_domain("esgm-bench-replay");
            let coordinator =
                Coordinator::spawn(&domain, Registry::new(esgm_core::TypeRegistry::with_library()))
                    .with_context(|| format!("could not start a coordinator for {domain}"))?;
            let esgm = connect(coordinator.domain(), "bench-replay")?;
            added = replay_once(&esgm, &rec, structures, &mut per)?;
            drop(esgm);
            drop(coordinator);
        }
        rows.push(row(
            "replay-max-connect",
            &per,
            payload,
            "a connect domain (coordinator on a thread of this process)",
            &common,
            added,
        ));
        drop(rec);
        dir.close().context("could not remove the temporary folder")?;
        Ok(rows)
    }
}

fn row(
    name: &str,
    per: &Latency,
    payload: u64,
    into: &str,
    common: &str,
    added: u64,
) -> Measurement {
    let p50 = per.quantile(0.5);
    per.measurement(name, Wait::Event)
        .payload_bytes(payload)
        .method(Method::PerItem)
        .wait_strategy("none (one thread replays)")
        .throughput(1e9 / p50.max(1) as f64, 0)
        .if_empty("no replay finished")
        .note(format!(
            "{:.0} structures/s at the median replay (slowest {:.0}/s) of {} replays into {into}; \
             {added} structures added by the last",
            1e9 / p50.max(1) as f64,
            1e9 / per.quantile(1.0).max(1) as f64,
            per.len()
        ))
        .note(common.to_owned())
}

/// The `i`-th recorded structure.
fn robot(i: u64) -> esgm_core::EntityStructure {
    let f = i as f64;
    RobotState { x: f, y: 0.5 * f, dir: 90.0 }.to_structure(
        "robot",
        1_000 + i as i64,
        1_000 + i as i64,
    )
}

/// Writes `n` structures, added 1 ms apart, into `path`; returns the rate written.
fn write(path: &std::path::Path, n: u64) -> anyhow::Result<f64> {
    let mut w = RecordingWriter::create(path, RecordOptions::default())
        .with_context(|| format!("could not create {}", path.display()))?;
    let info = TrajectoryInfo::new(TRAJECTORY, TrajectoryKind::Primitive, "RobotState")
        .policy(FluentStreamPolicy::default().cache(CacheConstraint::Elements(CACHE)));
    let id = w
        .add_trajectory(info, TypeSchema::collect(RobotState::entity_structure_type(), &|_| None))
        .context("declaring the trajectory")?;
    let start = Instant::now();
    for i in 0..n {
        let add_time = 1_000_000_000 + i as i64 * 1_000_000;
        w.write(id, &robot(i), add_time, add_time + 10_000).context("writing")?;
    }
    w.finish().context("finishing the recording")?;
    Ok(n as f64 / start.elapsed().as_secs_f64().max(1e-9))
}

/// Replays `rec` into `esgm` once, recording its time per structure; returns how many
/// were added.
fn replay_once<E>(esgm: &E, rec: &Recording, n: u64, per: &mut Latency) -> anyhow::Result<u64>
where
    E: Esgm<Trajectory = InProcessTrajectory>,
{
    let options = ReplayOptions { pace: Pace::Max, ..ReplayOptions::default() };
    let stop = AtomicBool::new(false);
    let start = Instant::now();
    let report = replay::replay(esgm, rec, &options, &stop).context("replay failed")?;
    let took = start.elapsed();
    let counts = report.published.get(TRAJECTORY).cloned().unwrap_or_default();
    if counts.added + counts.held != n {
        bail!(
            "replay added {} (held {}, dropped {} {:?}) of {n} structures",
            counts.added,
            counts.held,
            counts.dropped,
            counts.dropped_by
        );
    }
    per.record_ns(u64::try_from(took.as_nanos() / u128::from(n.max(1))).unwrap_or(u64::MAX));
    Ok(counts.added)
}
