//! The reference system's own KPIs (upstream's `autoware_reference_system/README.md`),
//! computed from the nodes' reports the same way for every system:
//! - the hot path's latency, front lidar to object collision estimator (the estimator's
//!   timestamp minus the front lidar's, both read from the message's per-hop trace);
//! - the samples each transform missed on its input (sequence gaps), per node;
//! - front-lidar samples that never reached the object collision estimator;
//! - the behavior planner's jitter (each tick's distance from its period after the
//!   previous) and drift (where the last tick is against where ticks every period from
//!   the first would be).

use std::collections::BTreeSet;
use std::time::Duration;

use crate::latency::Latency;

use super::report::NodeReport;
use super::topology::{HOT_PATH_ROOT, HOT_PATH_SINK, NODES, PLANNER};

/// The KPIs of one run of one system.
#[derive(Debug)]
pub struct Kpis {
    /// Hot path latency, one value per sink output (ns).
    pub hot_path: Latency,
    /// Per transform (and each intersection connection): `(node, input, received,
    /// missed)`.
    pub transform_drops: Vec<(String, String, u64, u64)>,
    /// Front-lidar messages published.
    pub front_published: u64,
    /// Distinct front-lidar messages the hot path's sink made an output from.
    pub front_reached_sink: u64,
    /// The planner's jitter: |interval − period| per tick after the first (ns).
    pub planner_jitter: Latency,
    /// The planner's ticks.
    pub planner_ticks: u64,
    /// Its drift: last tick − (first tick + (ticks − 1) × period), ns (positive: late).
    pub planner_drift_ns: i64,
}

impl Kpis {
    /// The KPIs of `reports` (every node's), whose planner ticks every `period`.
    pub fn from_reports(reports: &[NodeReport], period: Duration) -> anyhow::Result<Self> {
        let find = |name: &str| reports.iter().find(|r| r.node == name);
        for n in &NODES {
            if find(n.name).is_none() {
                anyhow::bail!("no report of node {}", n.name);
            }
        }
        let mut hot_path = Latency::new()?;
        let mut reached = BTreeSet::new();
        if let Some(sink) = find(HOT_PATH_SINK) {
            for h in &sink.hot_path {
                hot_path.record_ns(h.sink_timestamp.saturating_sub(h.root_timestamp));
                reached.insert(h.root_sequence);
            }
        }
        let front_published = find(HOT_PATH_ROOT)
            .and_then(|r| r.published.iter().find(|(t, _)| t == HOT_PATH_ROOT))
            .map_or(0, |(_, n)| *n);
        let mut transform_drops = Vec::new();
        for n in NODES.iter().filter(|n| n.transforms()) {
            if let Some(r) = find(n.name) {
                for (input, received, missed) in &r.received {
                    transform_drops.push((n.name.to_owned(), input.clone(), *received, *missed));
                }
            }
        }
        let mut planner_jitter = Latency::new()?;
        let fired = find(PLANNER).map(|r| r.planner_fired.clone()).unwrap_or_default();
        let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
        for w in fired.windows(2) {
            let interval = w[1].saturating_sub(w[0]);
            planner_jitter.record_ns(interval.abs_diff(period_ns));
        }
        let planner_drift_ns = match (fired.first(), fired.last()) {
            (Some(first), Some(last)) if fired.len() > 1 => {
                let expected =
                    i128::from(*first) + (fired.len() as i128 - 1) * i128::from(period_ns);
                i64::try_from(i128::from(*last) - expected).unwrap_or(i64::MAX)
            }
            _ => 0,
        };
        Ok(Self {
            hot_path,
            transform_drops,
            front_published,
            front_reached_sink: reached.len() as u64,
            planner_jitter,
            planner_ticks: fired.len() as u64,
            planner_drift_ns,
        })
    }

    /// Samples the transforms missed, all together.
    pub fn transforms_missed(&self) -> u64 {
        self.transform_drops.iter().map(|(_, _, _, m)| m).sum()
    }

    /// Front-lidar messages that never reached the hot path's sink.
    pub fn front_not_reaching_sink(&self) -> u64 {
        self.front_published.saturating_sub(self.front_reached_sink)
    }
}
