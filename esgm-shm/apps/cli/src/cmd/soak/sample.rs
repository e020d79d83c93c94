//! One second of a soak run as it is recorded (`soak.json`), and the rule that says
//! which losses are explained.
//!
//! # Explained and unexplained losses
//! A loss is a structure a trajectory's writer made (or was offered) that some process
//! does not have. Every loss esgm knows of is counted under a cause; the soak sorts the
//! causes into two kinds, for a system that runs the tutorial and nothing else:
//!
//! - **Explained**: a loss the design chooses under load, counted where it happens:
//!   - [`DropCause::Violation`]: the trajectory's own policy refused the structure
//!     (robot_state's `delay = "50ms"` when the robot is descheduled that long);
//!   - [`DropCause::Lost`]: a reader fell behind and its queue was overwritten. Every
//!     trajectory `connect` makes is latest-wins (the writer never waits for a
//!     reader), so this is the documented price of a slow reader, not a broken promise;
//!   - a unit's `input_overflow` (it fell behind its inputs; the oldest went first), a
//!     sampler's `missed_periods` (it woke a period or more late) and a store's
//!     `subscriber_overflow` (an in-process subscriber's buffer overflowed).
//! - **Unexplained**: everything else, which in this system is a bug:
//!   [`DropCause::Rejected`] (no process of the soak writes anything but valid samples
//!   from the registered writer), [`DropCause::InvalidType`] (the built-in units and
//!   sensors write their declared types), [`DropCause::Bridge`] (the soak runs no
//!   bridge to another middleware), [`DropCause::Reset`] (the soak resets
//!   nothing), a worker's `failures` and `panics`, and any cause this version does not
//!   know.

use std::collections::BTreeMap;

use esgm_core::DropCause;
use esgm_core::esgm::TrajectoryReport;

use super::probe::ShmUse;

/// Everything measured at one instant of the run.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    /// Seconds since sampling began (the system was up and applied at 0).
    pub t: f64,
    /// The host's 1, 5 and 15 minute load averages.
    pub load: [f64; 3],
    /// Per process of the system (the coordinator and every supervised worker).
    pub processes: BTreeMap<String, ProcessSample>,
    /// The domain's shared memory: the `/dev/shm` files its processes map (zero, and
    /// `shm_failed`, when it could not be measured).
    pub shm: ShmUse,
    /// The shared memory could not be measured this second (see `gaps`): the verdict
    /// takes no zero for a figure, and counts the failure as a missed check.
    #[serde(default)]
    pub shm_failed: bool,
    /// Every iceoryx2 file on the host, other domains' and tests' included (context).
    pub host_iceoryx2: ShmUse,
    /// Per trajectory, its counters as the domain reports them (empty when the
    /// processes did not answer this second; see `gaps`).
    pub trajectories: BTreeMap<String, Counts>,
    /// What could not be measured this second, and why.
    pub gaps: Vec<String>,
}

/// One process at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ProcessSample {
    /// Its pid (a restarted worker has a new one).
    pub pid: u32,
    /// Resident memory (`VmRSS`), bytes.
    pub rss: u64,
    /// Private resident memory (`RssAnon`), bytes.
    pub anon: u64,
    /// Restarts the supervisor counted (0 for the coordinator).
    pub restarts: u32,
}

/// A trajectory's counters at one instant.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Counts {
    /// Structures its writer added.
    pub added: u64,
    /// Samples its writer's cache holds (what its cache constraint retains).
    pub stored: usize,
    /// Adds per second over its last 128 adds.
    pub rate_hz: f64,
    /// Its losses by cause (only causes with a count).
    pub losses: Vec<Loss>,
}

/// Losses of one trajectory under one cause.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Loss {
    /// The cause as `esgm stats` names it (`lost`, `delay`, `input_overflow`, …).
    pub cause: String,
    /// How many.
    pub count: u64,
    /// Whether the cause is one the design chooses under load (module docs).
    pub explained: bool,
}

impl Counts {
    /// The counters of a trajectory's report from the domain.
    pub fn of(report: &TrajectoryReport) -> Self {
        let (s, w) = (&report.stats, &report.worker);
        let store = s.dropped.iter().map(|(cause, n)| (cause.to_string(), *n, explained(*cause)));
        let counted = [
            ("input_overflow", w.input_overflow, true),
            ("missed_periods", w.missed_periods, true),
            ("subscriber_overflow", s.subscriber_overflow, true),
            ("worker_failures", w.failures, false),
            ("worker_panics", w.panics, false),
        ];
        let losses = store
            .chain(counted.into_iter().map(|(c, n, e)| (c.to_owned(), n, e)))
            .filter(|(_, n, _)| *n > 0)
            .map(|(cause, count, explained)| Loss { cause, count, explained })
            .collect();
        Counts { added: s.added, stored: s.stored, rate_hz: s.rate_hz, losses }
    }
}

/// Whether a store's drop cause is explained (module docs).
pub fn explained(cause: DropCause) -> bool {
    match cause {
        DropCause::Violation(_) | DropCause::Lost => true,
        DropCause::InvalidType
        | DropCause::Reset
        | DropCause::Rejected(_)
        | DropCause::Unpublished
        | DropCause::Bridge(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use esgm_core::{Constraint, Rejection};

    use super::*;

    #[test]
    fn only_load_explains_a_loss() {
        assert!(explained(DropCause::Violation(Constraint::Delay)));
        assert!(explained(DropCause::Lost));
        for bug in [
            DropCause::InvalidType,
            DropCause::Reset,
            DropCause::Rejected(Rejection::Malformed),
            DropCause::Rejected(Rejection::WrongType),
        ] {
            assert!(!explained(bug), "{bug} counted as explained");
        }
    }

    #[test]
    fn counts_list_every_cause_with_a_count() {
        let mut report = TrajectoryReport {
            info: esgm_core::esgm::TrajectoryInfo::new(
                "images",
                esgm_core::esgm::TrajectoryKind::Sampled,
                "Image",
            ),
            stats: esgm_core::TrajectoryStats {
                added: 90,
                dropped: vec![(DropCause::Lost, 3), (DropCause::Reset, 0)],
                dropped_total: 3,
                violations: 0,
                evicted: 85,
                stored: 5,
                held: 0,
                subscribers: 1,
                subscriber_overflow: 0,
                missed_sample_points: 0,
                rate_hz: 30.0,
                add_delay_p50: None,
                add_delay_p90: None,
                add_delay_p99: None,
                add_delay_max: None,
            },
            worker: esgm_core::esgm::WorkerStats::default(),
        };
        report.worker.panics = 1;
        let c = Counts::of(&report);
        assert_eq!((c.added, c.stored), (90, 5));
        assert_eq!(
            c.losses,
            [
                Loss { cause: "lost".into(), count: 3, explained: true },
                Loss { cause: "worker_panics".into(), count: 1, explained: false },
            ]
        );
    }
}
