//! Per-trajectory statistics (E7): what was added, what was dropped and why, how fast
//! and how late samples arrive.

use std::cell::Cell;
use std::collections::{BTreeMap, VecDeque};

use hdrhistogram::Histogram;

use crate::store::violation::DropCause;
use crate::time::{TIMEUNITS_PER_SECOND, Time};

/// How many recent add times the rate is computed over (like `ros2 topic hz`'s window).
const RATE_WINDOW: usize = 128;

#[derive(Debug)]
pub(crate) struct StatsRecorder {
    added: u64,
    dropped: BTreeMap<DropCause, u64>,
    evicted: u64,
    subscriber_overflow: u64,
    missed_sample_points: u64,
    recent_adds: VecDeque<Time>,
    /// add time − valid time in ns, clamped to ≥ 0 (a predicted value has no delay).
    /// Made at the first add: an idle trajectory pays nothing for it.
    add_delay: Option<Histogram<u32>>,
    /// The delay's p50, p90 and p99 as last computed, with the count they were computed
    /// at. Each walks the histogram's buckets up to it (tens of µs), and `esgm stats`
    /// asks every trajectory of the domain at once: 1,000 trajectories cost 75 ms of
    /// the writer's time per question, now only those that changed since.
    percentiles: Cell<Option<(u64, [Option<Time>; 3])>>,
}

impl Default for StatsRecorder {
    fn default() -> Self {
        Self {
            added: 0,
            dropped: BTreeMap::new(),
            evicted: 0,
            subscriber_overflow: 0,
            missed_sample_points: 0,
            recent_adds: VecDeque::with_capacity(RATE_WINDOW),
            add_delay: None,
            percentiles: Cell::new(None),
        }
    }
}

/// Two significant digits (a percentile within 1 %) from a nanosecond up to an hour of
/// delay, with 32-bit counts (a bucket saturates at 4·10⁹ samples): about 17 KiB, paid
/// by a trajectory once something is added. Three digits took 135 KiB, 135 MB in a
/// process writing 1,000 trajectories, and made every percentile walk eight times as
/// many buckets. If creation fails the percentiles are simply absent.
fn delay_histogram() -> Option<Histogram<u32>> {
    Histogram::new_with_bounds(1, 3_600 * TIMEUNITS_PER_SECOND as u64, 2).ok()
}

impl StatsRecorder {
    pub fn record_added(&mut self, add_time: Time, valid_time: Time) {
        self.added += 1;
        if self.recent_adds.len() == RATE_WINDOW {
            self.recent_adds.pop_front();
        }
        self.recent_adds.push_back(add_time);
        if self.add_delay.is_none() {
            self.add_delay = delay_histogram();
        }
        if let Some(h) = &mut self.add_delay {
            h.saturating_record(
                u64::try_from(add_time.saturating_sub(valid_time)).unwrap_or(0).max(1),
            );
        }
    }

    /// The last add time, and how many of the remembered adds are at or after `since`.
    pub fn adds_since(&self, since: Time) -> (Option<Time>, u64) {
        let n = self.recent_adds.iter().rev().take_while(|t| **t >= since).count();
        (self.recent_adds.back().copied(), n as u64)
    }

    pub fn record_dropped(&mut self, cause: DropCause) {
        self.record_dropped_n(cause, 1);
    }

    /// `n` drops for one cause at once. Counts can come from another process (a gap
    /// in its sequence numbers): they saturate, never wrap, and cost O(1) whatever `n`.
    pub fn record_dropped_n(&mut self, cause: DropCause, n: u64) {
        if n > 0 {
            let count = self.dropped.entry(cause).or_default();
            *count = count.saturating_add(n);
        }
    }

    pub fn record_evicted(&mut self, n: usize) {
        self.evicted += n as u64;
    }

    pub fn record_overflow(&mut self, n: u64) {
        self.subscriber_overflow += n;
    }

    pub fn record_missed_sample_points(&mut self, n: u64) {
        self.missed_sample_points += n;
    }

    pub fn dropped_total(&self) -> u64 {
        self.dropped.values().fold(0, |a, &n| a.saturating_add(n))
    }

    /// p50, p90 and p99 of the add delay; none before the first add.
    fn percentiles(&self) -> [Option<Time>; 3] {
        let Some(h) = self.add_delay.as_ref().filter(|h| !h.is_empty()) else {
            return [None; 3];
        };
        match self.percentiles.get() {
            Some((count, known)) if count == h.len() => known,
            _ => {
                let known = [0.5, 0.9, 0.99].map(|q| Some(h.value_at_quantile(q) as Time));
                self.percentiles.set(Some((h.len(), known)));
                known
            }
        }
    }

    pub fn snapshot(&self, stored: usize, held: usize, subscribers: usize) -> TrajectoryStats {
        let rate_hz = match (self.recent_adds.front(), self.recent_adds.back()) {
            (Some(first), Some(last)) if last > first => {
                (self.recent_adds.len() - 1) as f64 * TIMEUNITS_PER_SECOND as f64
                    / (*last as f64 - *first as f64)
            }
            _ => 0.0,
        };
        let [p50, p90, p99] = self.percentiles();
        TrajectoryStats {
            added: self.added,
            dropped: self.dropped.iter().map(|(c, n)| (*c, *n)).collect(),
            dropped_total: self.dropped_total(),
            violations: self
                .dropped
                .iter()
                .filter(|(c, _)| matches!(c, DropCause::Violation(_)))
                .fold(0, |a, (_, &n)| a.saturating_add(n)),
            evicted: self.evicted,
            stored,
            held,
            subscribers,
            subscriber_overflow: self.subscriber_overflow,
            missed_sample_points: self.missed_sample_points,
            rate_hz,
            add_delay_p50: p50,
            add_delay_p90: p90,
            add_delay_p99: p99,
            add_delay_max: self
                .add_delay
                .as_ref()
                .filter(|h| !h.is_empty())
                .map(|h| h.max() as Time),
        }
    }
}

/// A snapshot of one trajectory's statistics.
///
/// Every structure ever offered is accounted for: `added + dropped_total + held`
/// equals the number offered; `evicted` counts samples that left the cache normally.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajectoryStats {
    /// Structures that entered the stream.
    pub added: u64,
    /// Structures dropped, per cause.
    pub dropped: Vec<(DropCause, u64)>,
    /// Sum of `dropped`.
    pub dropped_total: u64,
    /// Drops caused by a policy constraint (a subset of `dropped_total`).
    pub violations: u64,
    /// Samples that left the cache because of the cache constraint.
    pub evicted: u64,
    /// Samples stored now.
    pub stored: usize,
    /// Samples held for reordering now.
    pub held: usize,
    /// Live subscribers.
    pub subscribers: usize,
    /// Samples (and violation reports) discarded from slow subscribers' buffers,
    /// replays longer than a new subscriber's buffer included.
    pub subscriber_overflow: u64,
    /// Sample points skipped by a sampled stream (gaps of two periods or more).
    pub missed_sample_points: u64,
    /// Adds per second over the last 128 adds.
    pub rate_hz: f64,
    /// Median add delay (add time − valid time), ns.
    pub add_delay_p50: Option<Time>,
    /// 90th percentile add delay, ns.
    pub add_delay_p90: Option<Time>,
    /// 99th percentile add delay, ns.
    pub add_delay_p99: Option<Time>,
    /// Largest add delay, ns.
    pub add_delay_max: Option<Time>,
}

impl TrajectoryStats {
    /// Drops counted under `cause`.
    pub fn dropped_for(&self, cause: DropCause) -> u64 {
        self.dropped.iter().find(|(c, _)| *c == cause).map_or(0, |(_, n)| *n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The percentiles as hdrhistogram gives them, whether remembered or computed anew.
    #[test]
    fn remembered_percentiles_follow_every_add() {
        let mut r = StatsRecorder::default();
        assert_eq!(r.snapshot(0, 0, 0).add_delay_p50, None, "none before the first add");
        for delay in [1_000, 2_000, 3_000] {
            r.record_added(10_000 + delay, 10_000);
        }
        let first = r.snapshot(3, 0, 0);
        let h = r.add_delay.as_ref().unwrap();
        assert!(h.distinct_values() <= 256 * 32, "two significant digits: {}", h.distinct_values());
        assert_eq!(r.snapshot(3, 0, 0), first, "asked again, unchanged");
        let near =
            |got: Option<Time>, want: Time| got.is_some_and(|g| (g - want).abs() <= want / 100);
        assert!(near(first.add_delay_p50, 2_000), "{first:?}");
        assert!(near(first.add_delay_p99, 3_000), "{first:?}");
        for _ in 0..10 {
            r.record_added(1_000_000, 0);
        }
        let after = r.snapshot(13, 0, 0);
        assert!(near(after.add_delay_p50, 1_000_000), "recomputed after adds: {after:?}");
        assert!(near(after.add_delay_p90, 1_000_000), "{after:?}");
    }
}
