//! A trajectory in the in-process runtime (its store, description and worker), and the
//! descriptor that maps a name to whichever trajectory it currently denotes.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use parking_lot::{Mutex, RwLock};

use crate::esgm::{
    CallOutcome, CallRecord, MissedPoints, RECENT_CALLS, TrajectoryInfo, WorkerStats,
};
use crate::store::TrajectoryStore;

/// Counters a worker bumps; read as a [`WorkerStats`] snapshot.
#[derive(Debug, Default)]
pub(crate) struct WorkerCounters {
    pub calls: AtomicU64,
    pub outputs: AtomicU64,
    pub no_value: AtomicU64,
    pub failures: AtomicU64,
    pub panics: AtomicU64,
    pub invalid_outputs: AtomicU64,
    pub missed_periods: AtomicU64,
    pub discarded: AtomicU64,
    pub input_overflow: AtomicU64,
    /// An input-driven worker's queue, to send it flush markers (see `flush`).
    pub flush_sender: Mutex<Option<crossbeam_channel::Sender<(usize, crate::sample::Sample)>>>,
    /// Flush markers sent to the worker, and markers it reached: every input queued
    /// before a marker has been processed once the marker is reached.
    pub flush_asked: AtomicU64,
    pub flush_done: AtomicU64,
    /// The producer's most recent calls and their outcomes (for `why`).
    pub recent_calls: Mutex<std::collections::VecDeque<CallRecord>>,
    /// A sync's policy (for `why`: its tolerance).
    pub sync: Mutex<Option<crate::operators::sync::SyncPolicy>>,
    /// A sync's discarded samples, per input and reason (for `why`), since the
    /// trajectory was made: updated when a push discards.
    pub sync_drops: Mutex<Vec<crate::operators::sync::InputDrops>>,
    /// A sampler's most recent skips of sample points, with their causes (for `why`).
    pub recent_misses: Mutex<std::collections::VecDeque<MissedPoints>>,
}

impl WorkerCounters {
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// Remembers one call's outcome, forgetting the oldest past [`RECENT_CALLS`].
    pub fn called(&self, at: crate::time::Time, outcome: CallOutcome) {
        let mut calls = self.recent_calls.lock();
        if calls.len() == RECENT_CALLS {
            calls.pop_front();
        }
        calls.push_back(CallRecord { at, outcome });
    }

    /// Remembers one skip of sample points, forgetting the oldest past
    /// [`RECENT_CALLS`].
    pub fn missed(&self, points: MissedPoints) {
        let mut misses = self.recent_misses.lock();
        if misses.len() == RECENT_CALLS {
            misses.pop_front();
        }
        misses.push_back(points);
    }

    pub fn snapshot(&self) -> WorkerStats {
        let l = |c: &AtomicU64| c.load(Ordering::Relaxed);
        WorkerStats {
            calls: l(&self.calls),
            outputs: l(&self.outputs),
            no_value: l(&self.no_value),
            failures: l(&self.failures),
            panics: l(&self.panics),
            invalid_outputs: l(&self.invalid_outputs),
            missed_periods: l(&self.missed_periods),
            discarded: l(&self.discarded),
            input_overflow: l(&self.input_overflow),
            restarts: 0,
        }
    }
}

/// The thread feeding a trajectory; dropping it asks the thread to stop. The thread is
/// not joined: a unit in the middle of a long computation finishes on its own and its
/// output goes to a trajectory nobody can reach any more.
#[derive(Debug)]
pub(crate) struct Worker {
    pub stop: Arc<AtomicBool>,
    /// Dropped with the worker: a worker blocked on its inputs wakes on disconnection.
    pub _wake: Option<crossbeam_channel::Sender<()>>,
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// One trajectory: the representational structure behind a name.
#[derive(Debug)]
pub(crate) struct TrajectoryCell {
    pub store: Mutex<TrajectoryStore>,
    pub info: TrajectoryInfo,
    /// Only primitive trajectories take structures from outside.
    pub external_adds: bool,
    pub worker: Mutex<Option<Worker>>,
    pub counters: Arc<WorkerCounters>,
    /// Wakes the runtime's release thread when a sample is held (C6 releases on time).
    pub kick: crossbeam_channel::Sender<()>,
}

impl TrajectoryCell {
    /// Tells the release thread a sample was held, so it re-plans its next wake-up.
    pub fn kick_releaser(&self) {
        // Full: a kick is already pending; disconnected: the releaser has stopped.
        let _kick_pending = self.kick.try_send(());
    }
}

/// A name and the trajectory it denotes now (the seed's descriptor). Handles hold the
/// descriptor, so they follow re-pointing, and see `None` after destruction.
#[derive(Debug)]
pub(crate) struct Descriptor {
    pub name: String,
    pub current: RwLock<Option<Arc<TrajectoryCell>>>,
}

impl Descriptor {
    pub fn get(&self) -> Option<Arc<TrajectoryCell>> {
        self.current.read().clone()
    }
}
