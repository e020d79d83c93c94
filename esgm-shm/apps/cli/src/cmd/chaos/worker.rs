//! One process of `esgm chaos`'s robot (`esgm chaos-worker`): the process `esgm scale`
//! runs, supervised by `esgm up` and killed at random by the harness.
//!
//! It connects (waiting out a coordinator that is being restarted), takes the
//! trajectories the profile has it write — made at its first start, taken back with
//! their kept history after a restart — and subscribes to those it reads. Then it
//! adds to each of its trajectories at its rate, numbering the structures on from the
//! trajectory's latest (its valid time is the number), and appends a line
//! `ACK <trajectory> <number>` to its acknowledgement log each time `add` returned
//! `Added`, so that the harness can check afterwards that everything acknowledged
//! is still there or was evicted by the policy. A structure added while the process
//! was killed before its line was written is not in the log: the check allows it.
//!
//! It writes `ready-<index>` (its pid) once set up, stops adding when the harness
//! makes the file `stop`, writes `stopped-<index>`, and serves until the system is
//! stopped (`esgm down`), as every worker does.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use esgm_core::esgm::{LookupError, TrajectorySpec};
use esgm_core::policy::FluentStreamPolicy;
use esgm_core::{
    AddOutcome, CacheConstraint, Clock, EntityTrajectoryStructure, Esgm, InProcessTrajectory,
    SubscribeOptions, SystemClock,
};
use esgm_shm::ShmEsgm;

use crate::cmd::scale::profile::{Class, Planned, Profile};
use crate::cmd::scale::worker::{CACHE, IMAGE_CACHE, JOINING, Pacer, make_at, wait_for_trajectory};

pub use crate::cmd::scale::worker::WorkerArgs;

/// How long a worker waits for a coordinator that is being restarted.
const CONNECT_PATIENCE: Duration = Duration::from_secs(120);

/// The process name of worker `index` (its host in the registry, stable across
/// restarts: the coordinator gives it its trajectories back).
pub fn name(index: usize) -> String {
    format!("chaos-{index}")
}

/// The file worker `index` appends its acknowledgements to.
pub fn ack_log(run: &Path, index: usize) -> PathBuf {
    run.join(format!("acks-{index}.log"))
}

/// The file worker `index` writes its pid to once set up.
pub fn ready_file(run: &Path, index: usize) -> PathBuf {
    run.join(format!("ready-{index}"))
}

/// The file worker `index` writes once it stopped adding.
pub fn stopped_file(run: &Path, index: usize) -> PathBuf {
    run.join(format!("stopped-{index}"))
}

/// The file the harness makes to stop every worker's adds.
pub fn stop_file(run: &Path) -> PathBuf {
    run.join("stop")
}

/// The cache of a trajectory of `class`: the profile `esgm scale` runs.
pub fn cache_of(class: Class) -> usize {
    if class == Class::Image { IMAGE_CACHE } else { CACHE }
}

/// Runs one worker.
pub fn run(domain: &str, a: &WorkerArgs) -> anyhow::Result<()> {
    let profile: Profile = serde_json::from_slice(
        &std::fs::read(a.run.join("profile.json")).context("cannot read the profile")?,
    )
    .context("malformed profile")?;
    let esgm = connect(domain, a.index)?;
    let mut acks = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(ack_log(&a.run, a.index))
        .context("cannot open the acknowledgement log")?;
    let mut written = Vec::new();
    for t in profile.written_by(a.index) {
        let handle = take(&esgm, t)?;
        // Numbered on from what the trajectory holds (its kept history after a restart).
        let next = handle.get_latest().map_or(0, |s| s.structure.valid_time() + 1);
        written.push((handle, t.class, t.hz, next));
    }
    let received = Arc::new(AtomicU64::new(0));
    let mut subscriptions = Vec::new();
    for t in profile.read_by(a.index) {
        let handle =
            retrying(&format!("read `{}`", t.name), || wait_for_trajectory(&esgm, &t.name))?;
        let subscription = handle
            .subscribe(SubscribeOptions::default())
            .with_context(|| format!("cannot subscribe to `{}`", t.name))?;
        let received = Arc::clone(&received);
        // A reader as a robot's is: each structure taken as it comes.
        std::thread::spawn(move || {
            while subscription.recv_timeout(Duration::from_secs(3600)).is_ok() {
                received.fetch_add(1, Ordering::Relaxed);
            }
        });
        subscriptions.push(handle);
    }
    std::fs::write(ready_file(&a.run, a.index), std::process::id().to_string())
        .context("cannot say ready")?;
    // Writing on a thread of its own, while this one serves until the system is
    // stopped (`esgm down`), as every worker does: through a coordinator's restart, and
    // not after, whether or not the harness stopped the adds first.
    let leaving = Arc::new(AtomicBool::new(false));
    let (run, index, left) = (a.run.clone(), a.index, Arc::clone(&leaving));
    let writer = std::thread::spawn(move || -> anyhow::Result<()> {
        write(&mut written, &run, &mut acks, &left)?;
        std::fs::write(stopped_file(&run, index), std::process::id().to_string())
            .context("cannot say stopped")
    });
    esgm_shm::attach::serve_while_system_lives(&esgm, None, Duration::from_millis(500));
    leaving.store(true, Ordering::Release);
    let written = writer.join().map_err(|_| anyhow::anyhow!("the writing thread panicked"))?;
    drop(subscriptions);
    written
}

/// Connects as worker `index`, waiting out a coordinator being restarted.
fn connect(domain: &str, index: usize) -> anyhow::Result<ShmEsgm> {
    retrying("connect", || {
        let builder = ShmEsgm::builder().domain(domain).host(name(index));
        builder.timeout(Duration::from_secs(10)).connect().map_err(anyhow::Error::from)
    })
}

/// `f`, tried again until it succeeds or [`CONNECT_PATIENCE`] passes: a coordinator
/// being restarted, on a machine this loaded, may not answer at once.
fn retrying<T>(what: &str, mut f: impl FnMut() -> anyhow::Result<T>) -> anyhow::Result<T> {
    let deadline = Instant::now() + CONNECT_PATIENCE;
    loop {
        match f() {
            Ok(v) => return Ok(v),
            Err(e) if Instant::now() < deadline => {
                tracing::info!(error = %e, "cannot {what} yet; trying again");
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(e) => return Err(e).with_context(|| format!("cannot {what}")),
        }
    }
}

/// The trajectory `t` this worker writes: its own again after a restart, else made.
fn take(esgm: &ShmEsgm, t: &Planned) -> anyhow::Result<InProcessTrajectory> {
    retrying(&format!("take `{}`", t.name), || {
        match esgm.get_entity_trajectory_structure(&t.name) {
            Err(LookupError::NoSuchEntityStructure { .. }) => {
                let policy = FluentStreamPolicy::default()
                    .cache(CacheConstraint::Elements(cache_of(t.class)));
                let spec = TrajectorySpec::primitive(&t.name, t.class.type_name())
                    .policy(policy)
                    .readers(t.readers.len() + JOINING);
                esgm.create_trajectory(spec).map_err(anyhow::Error::from)
            }
            other => other.map_err(anyhow::Error::from),
        }
    })
}

/// Adds to every written trajectory at its rate until the harness makes the stop
/// file (or the process is `leaving`), logging each acknowledged structure.
fn write(
    written: &mut [(InProcessTrajectory, Class, f64, i64)],
    run: &Path,
    acks: &mut std::fs::File,
    leaving: &AtomicBool,
) -> anyhow::Result<()> {
    let mut pacer = Pacer::new(written.iter().map(|(_, _, hz, _)| *hz));
    let mut last_look = Instant::now();
    let mut stopped = false;
    let mut stop = || {
        // The stop file, looked at every 100 ms at most.
        if last_look.elapsed() >= Duration::from_millis(100) {
            last_look = Instant::now();
            stopped = stop_file(run).exists();
        }
        stopped || leaving.load(Ordering::Acquire)
    };
    while let Some(i) = pacer.next(&mut stop) {
        let (handle, class, _, next) = &mut written[i];
        let es = make_at(handle, *class, *next as u64, (*next, SystemClock.now()));
        match handle.add(es) {
            Ok(AddOutcome::Added) => {
                // One write of a whole line: a kill leaves whole lines, or none.
                acks.write_all(format!("ACK {} {}\n", handle.name(), next).as_bytes())
                    .context("cannot log an acknowledgement")?;
                *next += 1;
            }
            Ok(other) => tracing::warn!(trajectory = %handle.name(), ?other, "not added here"),
            Err(e) => {
                tracing::info!(trajectory = %handle.name(), error = %e, "add refused; trying again");
            }
        }
    }
    Ok(())
}
