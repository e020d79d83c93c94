//! Recording a running system: subscriptions into a [`RecordingWriter`].
//!
//! Each recorded trajectory gets a subscription with a large buffer and a thread that
//! drains it into the writer. The system's writers never wait for the recorder: a
//! subscription that is full drops its oldest structure and counts it
//! ([`Subscription::overflowed`](esgm_core::Subscription::overflowed)),
//! and the recorder writes each such loss into the file's events channel, with the
//! cause `recorder_overflow`. Structures lost before they reached this process (a
//! replica's `lost` drops) are written as losses with the cause `lost`, and policy
//! violations as violations. Nothing the recorder misses is silent: it is in the
//! file, in [`RecorderStats`], and printed by `esgm record`.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use esgm_core::clock::{Clock, SystemClock};
use esgm_core::{
    DropCause, EntityStructureType, EntityTrajectoryStructure, Esgm, PolicyViolation, QueryError,
    RecvError, Sample, SubscribeOptions, Subscription,
};
use parking_lot::Mutex;

use crate::layout::{EventKind, RecordedEvent, TypeSchema};
use crate::writer::{RecordError, RecordingWriter, TrajectoryId, WriteSummary};

/// Structures a recorded trajectory's subscription buffers before the oldest is
/// dropped (and counted): a second of a 65 kHz stream.
pub const DEFAULT_BUFFER: usize = 1 << 16;
/// Structures a recording thread takes from its subscription and writes under one
/// lock of the writer, at most (what is queued, never waiting for more).
const WRITE_BATCH: usize = 64;
/// How often quiet trajectories are checked for losses and the file is flushed.
const TICK: Duration = Duration::from_millis(100);

/// Starting or stopping a recorder failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecorderError {
    /// The system could not list its trajectories (across processes: the coordinator
    /// did not answer).
    #[error(transparent)]
    System(#[from] esgm_core::SystemError),
    /// A trajectory to record does not exist.
    #[error("no trajectory `{0}` to record")]
    NoSuchTrajectory(String),
    /// A trajectory's type is not registered.
    #[error("the type `{type_name}` of `{trajectory}` is not registered")]
    NoSuchType {
        /// The trajectory.
        trajectory: String,
        /// Its type.
        type_name: String,
    },
    /// Subscribing failed.
    #[error("cannot subscribe to `{trajectory}`: {source}")]
    Subscribe {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: QueryError,
    },
    /// Writing the file failed; recording stopped.
    #[error(transparent)]
    Write(#[from] RecordError),
    /// A recording thread could not be started or panicked.
    #[error("recording thread for `{0}` failed")]
    Thread(String),
}

/// What a recorder did, per trajectory.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecorderStats {
    /// Per trajectory name.
    pub trajectories: BTreeMap<String, TrajectoryCounts>,
}

/// What was recorded and missed of one trajectory.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct TrajectoryCounts {
    /// Structures written.
    pub recorded: u64,
    /// Structures dropped because the recorder fell behind.
    pub recorder_overflow: u64,
    /// Structures lost before they reached the recorder's process.
    pub lost: u64,
    /// Policy violations seen.
    pub violations: u64,
    /// The trajectory was destroyed while it was recorded: its recording ended there
    /// (what it held until then is in the file).
    pub ended: bool,
}

impl RecorderStats {
    /// Everything missed, over all trajectories.
    pub fn missed(&self) -> u64 {
        self.trajectories.values().map(|c| c.recorder_overflow + c.lost).sum()
    }
    /// Everything recorded.
    pub fn recorded(&self) -> u64 {
        self.trajectories.values().map(|c| c.recorded).sum()
    }
}

/// One trajectory ready to record: name, writer id, handle, samples, violations.
type Planned<T> = (String, TrajectoryId, T, Subscription<Sample>, Subscription<PolicyViolation>);

/// State the recording threads share.
struct Shared {
    writer: Mutex<Option<RecordingWriter>>,
    stats: Mutex<RecorderStats>,
    error: Mutex<Option<RecordError>>,
    stop: AtomicBool,
}

impl Shared {
    /// Runs `f` on the writer; the first error stops the recording and is kept.
    fn with_writer(&self, f: impl FnOnce(&mut RecordingWriter) -> Result<(), RecordError>) {
        let mut w = self.writer.lock();
        let Some(writer) = w.as_mut() else { return };
        if let Err(e) = f(writer) {
            tracing::error!("recording stopped: {e}");
            self.error.lock().get_or_insert(e);
            self.stop.store(true, Ordering::Release);
        }
    }

    fn count(&self, name: &str, f: impl FnOnce(&mut TrajectoryCounts)) {
        f(self.stats.lock().trajectories.entry(name.to_owned()).or_default());
    }
}

/// Records trajectories of a running system until stopped: see the [module docs](self).
pub struct Recorder {
    shared: Arc<Shared>,
    threads: Vec<(String, JoinHandle<()>)>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("trajectories", &self.threads.len())
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Starts recording `names` of `esgm` into `writer`, each from now on, with
    /// subscription buffers of `buffer` structures.
    pub fn start<E>(
        esgm: &E,
        names: &[String],
        writer: RecordingWriter,
        buffer: usize,
    ) -> Result<Self, RecorderError>
    where
        E: Esgm,
        E::Trajectory: Send + 'static,
    {
        Self::start_from(esgm, names, writer, buffer, 0)
    }

    /// Starts recording `names` of `esgm` into `writer` with what each trajectory
    /// holds already (up to `buffer` of its newest structures), then from now on.
    ///
    /// For a recorder that waited for its trajectories to appear (a replay, a system
    /// starting up): a structure written between a trajectory's creation and the
    /// recorder's subscription is in the trajectory's cache, and would be missed
    /// otherwise. A structure already held and arriving meanwhile is recorded once.
    pub fn start_with_held<E>(
        esgm: &E,
        names: &[String],
        writer: RecordingWriter,
        buffer: usize,
    ) -> Result<Self, RecorderError>
    where
        E: Esgm,
        E::Trajectory: Send + 'static,
    {
        Self::start_from(esgm, names, writer, buffer, buffer)
    }

    /// [`Recorder::start`], with each subscription replaying the last `held` stored
    /// structures first.
    fn start_from<E>(
        esgm: &E,
        names: &[String],
        mut writer: RecordingWriter,
        buffer: usize,
        held: usize,
    ) -> Result<Self, RecorderError>
    where
        E: Esgm,
        E::Trajectory: Send + 'static,
    {
        let infos = esgm.trajectories()?;
        let mut plan: Vec<Planned<E::Trajectory>> = Vec::new();
        for name in names {
            let info = infos
                .iter()
                .find(|i| &i.name == name)
                .cloned()
                .ok_or_else(|| RecorderError::NoSuchTrajectory(name.clone()))?;
            let root = esgm.get_entity_structure_type(&info.type_name).map_err(|_| {
                RecorderError::NoSuchType {
                    trajectory: name.clone(),
                    type_name: info.type_name.clone(),
                }
            })?;
            // A nested type the registry cannot give is left out of the schema, with a warning.
            let lookup = |n: &str| -> Option<EntityStructureType> {
                esgm.get_entity_structure_type(n)
                    .inspect_err(|e| {
                        tracing::warn!(type_name = n, error = %e,
                            "a nested type is left out of the schema")
                    })
                    .ok()
            };
            let types = TypeSchema::collect(root, &lookup);
            let trajectory = esgm
                .get_entity_trajectory_structure(name)
                .map_err(|_| RecorderError::NoSuchTrajectory(name.clone()))?;
            let subscribe_err =
                |source| RecorderError::Subscribe { trajectory: name.clone(), source };
            let samples = trajectory
                .subscribe(SubscribeOptions::default().capacity(buffer).last(held))
                .map_err(subscribe_err)?;
            let violations = trajectory.subscribe_violations(buffer).map_err(subscribe_err)?;
            let id = writer.add_trajectory(info, types)?;
            plan.push((name.clone(), id, trajectory, samples, violations));
        }
        let shared = Arc::new(Shared {
            writer: Mutex::new(Some(writer)),
            stats: Mutex::new(RecorderStats::default()),
            error: Mutex::new(None),
            stop: AtomicBool::new(false),
        });
        let mut threads: Vec<(String, JoinHandle<()>)> = Vec::new();
        for (name, id, trajectory, samples, violations) in plan {
            shared.count(&name, |_| {});
            let s = Arc::clone(&shared);
            let thread_name = name.clone();
            let handle = std::thread::Builder::new()
                .name(format!("record-{name}"))
                .spawn(move || record_one(&s, &thread_name, id, &trajectory, &samples, &violations))
                .map_err(|_| RecorderError::Thread(name.clone()))?;
            threads.push((name, handle));
        }
        let s = Arc::clone(&shared);
        let flusher = std::thread::Builder::new()
            .name("record-flush".into())
            .spawn(move || {
                while !s.stop.load(Ordering::Acquire) {
                    std::thread::sleep(TICK);
                    s.with_writer(RecordingWriter::flush_if_due);
                }
            })
            .map_err(|_| RecorderError::Thread("flush".into()))?;
        threads.push(("flush".into(), flusher));
        Ok(Self { shared, threads })
    }

    /// What was recorded and missed so far.
    pub fn stats(&self) -> RecorderStats {
        self.shared.stats.lock().clone()
    }

    /// True once writing failed (see [`Recorder::stop`] for the error).
    pub fn failed(&self) -> bool {
        self.shared.error.lock().is_some()
    }

    /// Stops: drains what the subscriptions hold, writes the summary, closes the file.
    pub fn stop(mut self) -> Result<(WriteSummary, RecorderStats), RecorderError> {
        self.shared.stop.store(true, Ordering::Release);
        let mut panicked = None;
        for (name, t) in self.threads.drain(..) {
            if t.join().is_err() {
                panicked.get_or_insert(name);
            }
        }
        if let Some(e) = self.shared.error.lock().take() {
            return Err(e.into());
        }
        if let Some(name) = panicked {
            return Err(RecorderError::Thread(name));
        }
        let writer = self.shared.writer.lock().take();
        let summary = match writer {
            Some(w) => w.finish()?,
            None => WriteSummary::default(),
        };
        Ok((summary, self.stats()))
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        for (_, t) in self.threads.drain(..) {
            if t.join().is_err() {
                tracing::error!("a recording thread panicked");
            }
        }
    }
}

/// The loop of one trajectory's thread.
fn record_one<T: EntityTrajectoryStructure>(
    shared: &Shared,
    name: &str,
    id: TrajectoryId,
    trajectory: &T,
    samples: &Subscription<Sample>,
    violations: &Subscription<PolicyViolation>,
) {
    let clock = SystemClock;
    let mut overflow_seen = 0;
    let mut lost_seen = trajectory.stats().map(|s| s.dropped_for(DropCause::Lost)).unwrap_or(0);
    let mut last_check = Instant::now();
    let mut batch: Vec<(Sample, i64)> = Vec::with_capacity(WRITE_BATCH);
    loop {
        let stopping = shared.stop.load(Ordering::Acquire);
        // Timeout: nothing yet. Closed: the trajectory was destroyed (its subscription
        // ended, and everything it held was taken): its recording ends below.
        let (sample, closed) = if stopping {
            (samples.try_recv(), false)
        } else {
            match samples.recv_timeout(TICK) {
                Ok(sample) => (Some(sample), false),
                Err(RecvError::Timeout) => (None, false),
                // Closed, or whatever else ends a subscription.
                Err(_) => (None, true),
            }
        };
        let got = sample.is_some();
        if let Some(sample) = sample {
            // What else is queued goes under the same lock of the writer and of the
            // counts: a burst costs two locks, not two per structure.
            batch.push((sample, clock.now()));
            while batch.len() < WRITE_BATCH {
                let Some(next) = samples.try_recv() else { break };
                batch.push((next, clock.now()));
            }
            let mut written = 0;
            shared.with_writer(|w| {
                for (s, recorded) in &batch {
                    w.write_sample(id, s, *recorded)?;
                    written += 1;
                }
                Ok(())
            });
            batch.clear();
            shared.count(name, |c| c.recorded += written);
        }
        // Keep draining while there is more: losses are checked between bursts.
        if got && last_check.elapsed() < TICK {
            continue;
        }
        last_check = Instant::now();
        while let Some(v) = violations.try_recv() {
            let event = RecordedEvent {
                trajectory: name.to_owned(),
                kind: EventKind::Violation,
                cause: v.constraint.to_string(),
                count: 1,
                valid_time: Some(v.valid_time),
                time: v.add_time,
                detail: v.detail.clone(),
            };
            shared.with_writer(|w| w.write_event(&event));
            shared.count(name, |c| c.violations += 1);
        }
        let overflow = samples.overflowed();
        if overflow > overflow_seen {
            let n = overflow - overflow_seen;
            overflow_seen = overflow;
            write_loss(
                shared,
                name,
                "recorder_overflow",
                n,
                "the recorder fell behind its subscription buffer",
            );
            shared.count(name, |c| c.recorder_overflow += n);
        }
        if closed {
            // A destroyed trajectory has no statistics left to read.
            tracing::info!(trajectory = name, "the trajectory was destroyed; its recording ends");
            shared.count(name, |c| c.ended = true);
            return;
        }
        match trajectory.stats() {
            Ok(stats) => {
                let lost = stats.dropped_for(DropCause::Lost);
                if lost > lost_seen {
                    let n = lost - lost_seen;
                    lost_seen = lost;
                    write_loss(
                        shared,
                        name,
                        "lost",
                        n,
                        "lost before reaching the recorder's process",
                    );
                    shared.count(name, |c| c.lost += n);
                }
            }
            Err(e) => tracing::warn!("cannot read the statistics of `{name}`: {e}"),
        }
        if stopping && !got {
            return;
        }
    }
}

fn write_loss(shared: &Shared, name: &str, cause: &str, count: u64, detail: &str) {
    let event = RecordedEvent {
        trajectory: name.to_owned(),
        kind: EventKind::Loss,
        cause: cause.to_owned(),
        count,
        valid_time: None,
        time: SystemClock.now(),
        detail: detail.to_owned(),
    };
    shared.with_writer(|w| w.write_event(&event));
}
