//! What a bridge counts per trajectory, reported as JSON lines (`--report-every`) and
//! logged when something is lost.

use std::collections::BTreeMap;
use std::sync::Arc;

use parking_lot::Mutex;
use serde::Serialize;

/// Why samples the writer admitted did not reach the importing domain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LossCause {
    /// A gap in the writer's sequence numbers within one run of the exporter: Zenoh
    /// dropped them (congestion), or the exporter fell behind the writer.
    SequenceGap,
    /// The gap spans a restart of the exporting bridge (or a reconnect) and its history
    /// did not reach back far enough.
    ExporterRestarted,
}

/// One trajectory's counters.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TrajectoryCounters {
    /// `export` or `import`.
    pub role: &'static str,
    /// The domain the trajectory comes from.
    pub domain: String,
    /// Its name.
    pub trajectory: String,
    /// Exporter: samples sent. Importer: samples received (history included).
    pub messages: u64,
    /// Importer: samples added to the local trajectory.
    pub added: u64,
    /// Importer: samples already received (history overlapping the stream).
    pub duplicates: u64,
    /// Samples lost, per cause (importer).
    pub lost: BTreeMap<LossCause, u64>,
    /// Samples deliberately not sent (`--latest-only`, `--max-rate`).
    pub skipped: u64,
    /// Importer: messages rejected as malformed (header or archive).
    pub malformed: u64,
    /// Exporter: samples and resets not sent because they came from a publisher port
    /// that is not the one the registry names as the writer's (they bypassed its gate).
    pub not_writer: u64,
    /// Importer: structures the local trajectory's gate dropped (type or policy).
    pub dropped: u64,
    /// Importer: messages refused because the type conflicts with a local one.
    pub refused: u64,
    /// The last error, if any.
    pub error: Option<String>,
}

impl TrajectoryCounters {
    /// Sum of `lost`.
    pub fn lost_total(&self) -> u64 {
        self.lost.values().fold(0, |a, &n| a.saturating_add(n))
    }
}

/// Counters by role (`export`, `import`), domain and trajectory.
type ByTrajectory = BTreeMap<(&'static str, String, String), TrajectoryCounters>;

/// Every trajectory's counters, shared by the bridge's threads.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    inner: Arc<Mutex<ByTrajectory>>,
}

impl Stats {
    /// Runs `f` on the counters of `role`/`domain`/`trajectory`.
    pub fn with<R>(
        &self,
        role: &'static str,
        domain: &str,
        trajectory: &str,
        f: impl FnOnce(&mut TrajectoryCounters) -> R,
    ) -> R {
        let mut map = self.inner.lock();
        let c = map.entry((role, domain.to_owned(), trajectory.to_owned())).or_insert_with(|| {
            TrajectoryCounters {
                role,
                domain: domain.to_owned(),
                trajectory: trajectory.to_owned(),
                ..TrajectoryCounters::default()
            }
        });
        f(c)
    }

    /// A copy of every trajectory's counters.
    pub fn snapshot(&self) -> Vec<TrajectoryCounters> {
        self.inner.lock().values().cloned().collect()
    }
}
