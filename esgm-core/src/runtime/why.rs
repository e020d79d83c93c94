//! `why` in the in-process runtime: what this process knows of one of its
//! trajectories, read from its store, its worker's counters and recent calls, and its
//! inputs' stores ([`crate::esgm::Why`]).

use std::sync::Arc;

use crate::esgm::{
    DropSummary, InputHealth, LookupError, SyncInputDrops, SyncWait, TrajectoryKind, Why,
};
use crate::operators::sync::SyncPolicy;
use crate::time::Time;

use super::InProcessEsgm;
use super::cell::TrajectoryCell;

impl InProcessEsgm {
    /// The evidence of why `name` has (or has not) produced since `since`, as this
    /// process knows it: from the trajectory's store here, its worker if it runs here,
    /// and its inputs as this process holds them. The reasons are left empty, and the
    /// writer's process (alive, changed) unknown: across processes the runtime that
    /// knows those fills them in, then calls [`Why::explain`] once.
    /// [`crate::Esgm::why`] is this, explained.
    pub fn why_evidence(&self, name: &str, since: Time) -> Result<Why, LookupError> {
        let cell = self
            .descriptor(name)
            .and_then(|d| d.get())
            .ok_or_else(|| self.inner.catalog.read().no_such_trajectory(name))?;
        let now = self.inner.clock.now();
        let (last_added, added_since, drops) = {
            let store = cell.store.lock();
            let (last, n) = store.adds_since(since);
            (last, n, drop_summaries(&store, since))
        };
        let inputs: Vec<InputHealth> =
            cell.info.inputs.iter().map(|input| self.input_health(input, now)).collect();
        let kind = cell.info.kind;
        let has_worker = !matches!(kind, TrajectoryKind::Primitive);
        // The calls before the counters: a worker bumps its counter, then records the
        // call, so the counters read after include every call listed.
        let recent_calls = cell.counters.recent_calls.lock().iter().cloned().collect();
        let missed = cell.counters.recent_misses.lock().iter().cloned().collect();
        let worker = has_worker.then(|| cell.counters.snapshot());
        let sync = (kind == TrajectoryKind::Sync).then(|| sync_wait(&cell, &inputs));
        Ok(Why {
            trajectory: name.to_owned(),
            kind,
            since,
            now,
            last_added,
            added_since,
            inputs,
            worker,
            recent_calls,
            sync,
            missed,
            drops,
            writer_alive: None,
            writer_changed: None,
            reasons: Vec::new(),
        })
    }

    fn input_health(&self, name: &str, now: Time) -> InputHealth {
        let cell = self.descriptor(name).and_then(|d| d.get());
        let latest = cell.as_ref().and_then(|c| c.store.lock().get_latest().ok());
        InputHealth {
            trajectory: name.to_owned(),
            exists: cell.is_some(),
            latest_valid_time: latest.as_ref().map(|s| s.valid_time()),
            latest_add_time: latest.as_ref().map(|s| s.add_time),
            age: latest.as_ref().map(|s| now.saturating_sub(s.add_time)),
            writer_alive: None,
        }
    }
}

/// The store's drops per cause: how many of those remembered are since `since`, how
/// many in all, and the last one.
fn drop_summaries(store: &crate::store::TrajectoryStore, since: Time) -> Vec<DropSummary> {
    let recent = store.recent_drops();
    store
        .stats()
        .dropped
        .into_iter()
        .map(|(cause, total)| {
            let of_cause: Vec<_> = recent.iter().filter(|d| d.cause == cause).collect();
            DropSummary {
                cause,
                since: of_cause.iter().filter(|d| d.at >= since).count() as u64,
                total,
                last: of_cause.last().map(|d| (*d).clone()),
            }
        })
        .collect()
}

/// What a sync waits for: the input whose latest valid time is the oldest (or that
/// holds nothing), how far behind the newest it is, and the policy's tolerance.
fn sync_wait(cell: &Arc<TrajectoryCell>, inputs: &[InputHealth]) -> SyncWait {
    let newest = inputs.iter().filter_map(|i| i.latest_valid_time).max();
    let lagging = inputs.iter().min_by_key(|i| i.latest_valid_time.unwrap_or(Time::MIN));
    let tolerance = match &*cell.counters.sync.lock() {
        Some(SyncPolicy::Approximate(c)) => c.tolerance,
        Some(SyncPolicy::Epsilon(c)) => Some(c.tolerance),
        Some(SyncPolicy::Exact(_)) => Some(0),
        None => None,
    };
    SyncWait {
        waits_for: lagging.map(|i| i.trajectory.clone()),
        gap: match (newest, lagging.and_then(|i| i.latest_valid_time)) {
            (Some(n), Some(l)) => Some(n.saturating_sub(l)),
            _ => None,
        },
        tolerance,
        discarded: cell.counters.discarded.load(std::sync::atomic::Ordering::Relaxed),
        dropped: inputs
            .iter()
            .zip(cell.counters.sync_drops.lock().iter())
            .map(|(i, drops)| SyncInputDrops { input: i.trajectory.clone(), drops: drops.clone() })
            .collect(),
    }
}
