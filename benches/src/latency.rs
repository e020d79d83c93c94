//! Latency recording: an HDR histogram of nanoseconds, read out as a [`Measurement`].

use std::time::Duration;

use anyhow::Context as _;
use hdrhistogram::Histogram;

use crate::report::{Measurement, Method, Wait};

/// The largest value recorded exactly enough; anything slower is clamped to it (and
/// would be a broken run anyway).
const HIGHEST_NS: u64 = 60_000_000_000;

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
            notes: Vec::new(),
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
    fn empty_reads_as_zero() {
        let m = Latency::new().unwrap().measurement("x", Wait::Event);
        assert_eq!((m.n, m.p50_ns, m.max_ns), (0, 0, 0));
    }
}
