//! Latency recording: an HDR histogram of nanoseconds, read out as a [`Measurement`].

use std::time::Duration;

use anyhow::Context as _;
use hdrhistogram::Histogram;

use crate::report::{Measurement, Method, Wait};

/// The largest value recorded exactly enough; anything slower is clamped to it (and
/// would be a broken run anyway).
const HIGHEST_NS: u64 = 60_000_000_000;

/// The quantiles kept for CDF plots: every percent, then the tail.
const CDF_POINTS: [f64; 106] = {
    let mut q = [0.0; 106];
    let mut i = 0;
    while i < 100 {
        q[i] = i as f64 / 100.0;
        i += 1;
    }
    q[100] = 0.995;
    q[101] = 0.999;
    q[102] = 0.9995;
    q[103] = 0.9999;
    q[104] = 0.99999;
    q[105] = 1.0;
    q
};

/// Latency samples in nanoseconds, to three significant digits.
#[derive(Debug, Clone)]
pub struct Latency {
    histogram: Histogram<u64>,
}

impl Latency {
    /// An empty recorder for values from 1 ns to 60 s.
    pub fn new() -> anyhow::Result<Self> {
        let histogram = Histogram::new_with_bounds(1, HIGHEST_NS, 3)
            .context("could not create the latency histogram")?;
        Ok(Self { histogram })
    }

    /// Records one value in nanoseconds (0 counts as 1 ns, the histogram's floor).
    pub fn record_ns(&mut self, ns: u64) {
        self.histogram.saturating_record(ns.max(1));
    }

    /// Records a duration.
    pub fn record(&mut self, d: Duration) {
        self.record_ns(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    }

    /// Records half of a round trip: the one-way estimate.
    pub fn record_half(&mut self, round_trip: Duration) {
        self.record_ns(u64::try_from(round_trip.as_nanos() / 2).unwrap_or(u64::MAX));
    }

    /// Records `count` samples of `ns` nanoseconds (merging another recorder's
    /// buckets, e.g. sent by a peer process as [`Latency::buckets`]).
    pub fn record_count(&mut self, ns: u64, count: u64) {
        let _ = self.histogram.record_n(ns.clamp(1, HIGHEST_NS), count);
    }

    /// The recorded values as (value, count) pairs, one per non-empty bucket: enough to
    /// rebuild the percentiles elsewhere ([`Latency::record_count`]).
    pub fn buckets(&self) -> Vec<(u64, u64)> {
        self.histogram
            .iter_recorded()
            .map(|v| (v.value_iterated_to(), v.count_at_value()))
            .collect()
    }

    /// The value at each of `points` quantiles, for a CDF plot (none when empty).
    pub fn cdf(&self, points: &[f64]) -> Vec<(f64, u64)> {
        if self.is_empty() {
            return Vec::new();
        }
        points.iter().map(|&q| (q, self.quantile(q))).collect()
    }

    /// Samples recorded.
    pub fn len(&self) -> u64 {
        self.histogram.len()
    }

    /// True if nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.histogram.is_empty()
    }

    /// The value at quantile `q` (0 when empty).
    pub fn quantile(&self, q: f64) -> u64 {
        if self.histogram.is_empty() { 0 } else { self.histogram.value_at_quantile(q) }
    }

    /// A row for scenario `name` with this recorder's percentiles. The caller sets
    /// payload size, method and baseline with the builder methods of [`Measurement`].
    pub fn measurement(&self, name: &str, wait: Wait) -> Measurement {
        Measurement {
            name: name.to_owned(),
            payload_bytes: 0,
            wait,
            wait_strategy: None,
            n: self.len(),
            p50_ns: self.quantile(0.5),
            p99_ns: self.quantile(0.99),
            p999_ns: self.quantile(0.999),
            max_ns: if self.is_empty() { 0 } else { self.histogram.max() },
            method: Method::HalfRoundTrip,
            baseline: None,
            producer_write_p50_ns: None,
            msgs_per_s: None,
            lost: None,
            notes: Vec::new(),
            cdf: self.cdf(&CDF_POINTS),
            if_empty: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_and_halving() {
        let mut l = Latency::new().unwrap();
        for ns in 1..=1000 {
            l.record_half(Duration::from_nanos(2 * ns));
        }
        let m = l.measurement("x", Wait::Spin);
        assert_eq!(m.n, 1000);
        assert_eq!(m.p50_ns, 500);
        assert_eq!(m.p99_ns, 990);
        assert_eq!(m.max_ns, 1000);
    }

    #[test]
    fn buckets_rebuild_the_percentiles() {
        let mut l = Latency::new().unwrap();
        for ns in [100, 100, 2_000, 50_000] {
            l.record_ns(ns);
        }
        let mut m = Latency::new().unwrap();
        for (v, c) in l.buckets() {
            m.record_count(v, c);
        }
        assert_eq!(m.len(), 4);
        assert_eq!(m.quantile(0.5), l.quantile(0.5));
        assert_eq!(m.quantile(1.0), l.quantile(1.0));
    }

    #[test]
    fn empty_reads_as_zero() {
        let m = Latency::new().unwrap().measurement("x", Wait::Event);
        assert_eq!((m.n, m.p50_ns, m.max_ns), (0, 0, 0));
    }
}
