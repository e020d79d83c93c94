//! One trajectory's figures as a process sends them on the admin channel
//! ([`super::admin`]), in a compact form.
//!
//! Why not [`TrajectoryReport`]: `esgm stats` on a domain of 1,000 trajectories
//! gathers a report per trajectory from every process, and as JSON objects they came
//! to 700 bytes each (field names, and the trajectory's whole listing, which the
//! coordinator holds anyway): 0.7 MB that the writer encoded and the asker decoded in
//! about 4.5 ms, the most of what grew with the domain. A row is a JSON array of the
//! numbers alone, about 100 bytes, and the listing joins it at the asker
//! ([`with_listing`]).
//!
//! Every field of [`TrajectoryStats`] and [`WorkerStats`] is taken apart and put
//! together by name, without `..`: a field added there does not compile here until the
//! row carries it.

use std::collections::HashMap;

use esgm_core::esgm::{EsgmStats, TrajectoryInfo, TrajectoryReport, WorkerStats};
use esgm_core::{DropCause, Time, TrajectoryStats};
use serde::{Deserialize, Serialize};

/// A trajectory's figures in one process: its name, whether this process writes it,
/// its store's statistics and its worker's counters (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct StatsRow(String, bool, Counts, Vec<(DropCause, u64)>, f64, Delays, Option<Calls>);

/// The store's counts: added, dropped_total, violations, evicted, stored, held,
/// subscribers, subscriber_overflow, missed_sample_points.
type Counts = [u64; 9];
/// The add delay's p50, p90, p99 and max.
type Delays = [Option<Time>; 4];
/// The worker's calls, outputs, no_value, failures, panics, invalid_outputs,
/// missed_periods, restarts, discarded, input_overflow; `None` when all are zero (a
/// pushed trajectory has no worker: most rows of a large domain).
type Calls = [u64; 10];

/// A count as this process sends it (a `usize` never exceeds `u64` here).
fn wide(n: usize) -> u64 {
    u64::try_from(n).unwrap_or(u64::MAX)
}

/// A count another process sent, as a `usize` (saturating: its numbers are its own).
fn narrow(n: u64) -> usize {
    usize::try_from(n).unwrap_or(usize::MAX)
}

impl StatsRow {
    /// The row of `name`'s figures here; `writes` if this process writes it.
    pub(crate) fn new(
        name: String,
        writes: bool,
        stats: TrajectoryStats,
        worker: WorkerStats,
    ) -> Self {
        let TrajectoryStats {
            added,
            dropped,
            dropped_total,
            violations,
            evicted,
            stored,
            held,
            subscribers,
            subscriber_overflow,
            missed_sample_points,
            rate_hz,
            add_delay_p50,
            add_delay_p90,
            add_delay_p99,
            add_delay_max,
        } = stats;
        let WorkerStats {
            calls,
            outputs,
            no_value,
            failures,
            panics,
            invalid_outputs,
            missed_periods,
            restarts,
            discarded,
            input_overflow,
        } = worker;
        StatsRow(
            name,
            writes,
            [
                added,
                dropped_total,
                violations,
                evicted,
                wide(stored),
                wide(held),
                wide(subscribers),
                subscriber_overflow,
                missed_sample_points,
            ],
            dropped,
            rate_hz,
            [add_delay_p50, add_delay_p90, add_delay_p99, add_delay_max],
            Some([
                calls,
                outputs,
                no_value,
                failures,
                panics,
                invalid_outputs,
                missed_periods,
                restarts,
                discarded,
                input_overflow,
            ])
            .filter(|calls| calls.iter().any(|&n| n != 0)),
        )
    }

    /// The row taken apart: name, whether its process writes it, its figures.
    pub(crate) fn into_parts(self) -> (String, bool, Figures) {
        let StatsRow(name, writes, counts, dropped, rate_hz, delays, calls) = self;
        let [
            added,
            dropped_total,
            violations,
            evicted,
            stored,
            held,
            subscribers,
            subscriber_overflow,
            missed_sample_points,
        ] = counts;
        let [add_delay_p50, add_delay_p90, add_delay_p99, add_delay_max] = delays;
        let [
            calls,
            outputs,
            no_value,
            failures,
            panics,
            invalid_outputs,
            missed_periods,
            restarts,
            discarded,
            input_overflow,
        ] = calls.unwrap_or_default();
        let stats = TrajectoryStats {
            added,
            dropped,
            dropped_total,
            violations,
            evicted,
            stored: narrow(stored),
            held: narrow(held),
            subscribers: narrow(subscribers),
            subscriber_overflow,
            missed_sample_points,
            rate_hz,
            add_delay_p50,
            add_delay_p90,
            add_delay_p99,
            add_delay_max,
        };
        let worker = WorkerStats {
            calls,
            outputs,
            no_value,
            failures,
            panics,
            invalid_outputs,
            missed_periods,
            restarts,
            discarded,
            input_overflow,
        };
        (name, writes, Figures { stats, worker })
    }
}

/// A trajectory's figures, combined from every process's rows, before its listing
/// joins them.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Figures {
    /// Its store's statistics.
    pub(crate) stats: TrajectoryStats,
    /// Its worker's counters.
    pub(crate) worker: WorkerStats,
}

/// The domain's statistics: each trajectory of `listing` that some process reported,
/// with its figures; and the listed trajectories that no process reported (a writer
/// gone, nobody reading). A row of a trajectory the listing lacks (destroyed while the
/// question went round) is left out. The listing is moved, not copied: at 1,000
/// trajectories a copy of each listing was a tenth of `esgm stats`'s time.
pub(crate) fn with_listing(
    mut figures: HashMap<String, Figures>,
    listing: impl IntoIterator<Item = TrajectoryInfo>,
) -> (EsgmStats, Vec<TrajectoryInfo>) {
    let mut unreported = Vec::new();
    let trajectories = listing
        .into_iter()
        .filter_map(|info| match figures.remove(&info.name) {
            Some(Figures { stats, worker }) => {
                Some((info.name.clone(), TrajectoryReport { info, stats, worker }))
            }
            None => {
                unreported.push(info);
                None
            }
        })
        .collect();
    (EsgmStats { trajectories }, unreported)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use esgm_core::esgm::{Esgm, TrajectorySpec};
    use esgm_core::library::RobotState;
    use esgm_core::{Entity, EntityTrajectoryStructure, InProcessEsgm};

    fn report() -> TrajectoryReport {
        let local = InProcessEsgm::default();
        let t = local.create_trajectory(TrajectorySpec::primitive("r", "RobotState")).unwrap();
        for k in 1..=3 {
            t.add(RobotState { x: 1.0, y: 0.0, dir: 0.0 }.to_structure("r", k, k)).unwrap();
        }
        let mut report = local.stats_here().trajectories.remove("r").unwrap();
        report.stats.dropped = vec![(DropCause::Lost, 2)];
        report.stats.dropped_total = 2;
        report.worker.calls = 7;
        report.worker.input_overflow = 1;
        // serde_json reads a float back to within an ulp, not always to the same bits
        // (its `float_roundtrip` parser is off): a rate measured from the clock would make
        // the comparison below flaky, so the fixture's rate is one it reads back exactly.
        report.stats.rate_hz = 4.5;
        report
    }

    #[test]
    fn a_row_reads_back_as_the_report_it_was_made_from() {
        let report = report();
        let row = StatsRow::new("r".into(), true, report.stats.clone(), report.worker);
        let wire = serde_json::to_vec(&row).unwrap();
        let back: StatsRow = serde_json::from_slice(&wire).unwrap();
        let (name, writes, figures) = back.into_parts();
        assert_eq!((name.as_str(), writes), ("r", true));
        assert_eq!(figures, Figures { stats: report.stats.clone(), worker: report.worker });
        let (stats, unreported) = with_listing([(name, figures)].into(), [report.info.clone()]);
        assert_eq!(stats.trajectories["r"], report);
        assert!(unreported.is_empty());
        // Compact: a fraction of the report as a JSON object.
        assert!(wire.len() * 3 < serde_json::to_vec(&report).unwrap().len(), "{}", wire.len());
    }

    #[test]
    fn rows_of_trajectories_the_listing_lacks_are_left_out() {
        let report = report();
        let figures = Figures { stats: report.stats.clone(), worker: report.worker };
        let (stats, unreported) =
            with_listing([("gone".to_owned(), figures)].into(), [report.info.clone()]);
        assert!(stats.trajectories.is_empty());
        assert_eq!(unreported, [report.info], "the listed trajectory nobody reported");
    }
}
