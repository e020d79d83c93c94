//! Targets: ratios between two rows of the same run that an issue sets as goals.
//!
//! A scenario declares them ([`crate::Scenario::targets`]); the table prints each one
//! with the ratio measured and whether it was met. They are shown, never asserted: a
//! missed target is a finding to report, not a failed run. The ratio is taken at the
//! median (p50), the figure the issues state their targets in; the p99 ratio is
//! printed beside it.

use crate::report::{Measurement, Report, Wait};

/// Which way a ratio must go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// `row / baseline ≤ x`.
    AtMost(f64),
    /// `row / baseline ≥ x`.
    AtLeast(f64),
}

/// A goal for `row / baseline` (p50, both rows with the same wait).
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The row measured (a scenario's row name, e.g. `esgm-small-default`).
    pub row: String,
    /// The row it is compared with.
    pub baseline: String,
    /// The wait of both rows.
    pub wait: Wait,
    /// The goal.
    pub bound: Bound,
}

/// A target evaluated on a report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// `row.p50 / baseline.p50`.
    pub p50_ratio: f64,
    /// `row.p99 / baseline.p99`.
    pub p99_ratio: f64,
    /// Whether the p50 ratio meets the bound.
    pub met: bool,
}

impl Target {
    /// `row / baseline ≤ ratio` with both rows at `wait`.
    pub fn at_most(row: &str, baseline: &str, wait: Wait, ratio: f64) -> Self {
        Self { row: row.into(), baseline: baseline.into(), wait, bound: Bound::AtMost(ratio) }
    }

    /// `row / baseline ≥ ratio` with both rows at `wait`.
    pub fn at_least(row: &str, baseline: &str, wait: Wait, ratio: f64) -> Self {
        Self { row: row.into(), baseline: baseline.into(), wait, bound: Bound::AtLeast(ratio) }
    }

    /// The ratio in `report`, or the names of the rows that did not run.
    pub fn evaluate(&self, report: &Report) -> Result<Outcome, Vec<&str>> {
        let find = |name: &str| -> Option<&Measurement> {
            report.scenarios.iter().find(|m| m.name == name && m.wait == self.wait)
        };
        match (find(&self.row), find(&self.baseline)) {
            (Some(row), Some(base)) => {
                let ratio = |a: u64, b: u64| a as f64 / (b as f64).max(1.0);
                let p50_ratio = ratio(row.p50_ns, base.p50_ns);
                let met = match self.bound {
                    Bound::AtMost(x) => p50_ratio <= x,
                    Bound::AtLeast(x) => p50_ratio >= x,
                };
                Ok(Outcome { p50_ratio, p99_ratio: ratio(row.p99_ns, base.p99_ns), met })
            }
            (row, base) => {
                let mut missing = Vec::new();
                if row.is_none() {
                    missing.push(self.row.as_str());
                }
                if base.is_none() {
                    missing.push(self.baseline.as_str());
                }
                Err(missing)
            }
        }
    }

    /// `≤ ×1.50` / `≥ ×10`.
    pub fn bound_label(&self) -> String {
        match self.bound {
            Bound::AtMost(x) => format!("≤ ×{}", ratio_label(x)),
            Bound::AtLeast(x) => format!("≥ ×{}", ratio_label(x)),
        }
    }
}

/// A ratio with three significant digits: `×0.853`, `×1.32`, `×45.1`, `×312`.
pub fn ratio_label(x: f64) -> String {
    if x >= 100.0 {
        format!("{x:.0}")
    } else if x >= 10.0 {
        format!("{x:.1}")
    } else if x >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latency::Latency;

    fn row(name: &str, wait: Wait, ns: u64) -> Measurement {
        let mut l = Latency::new().unwrap();
        l.record_ns(ns);
        l.measurement(name, wait)
    }

    #[test]
    fn targets_compare_same_wait_rows_at_the_median() {
        let report = Report {
            scenarios: vec![
                row("floor", Wait::Spin, 1000),
                row("small", Wait::Spin, 1400),
                row("small", Wait::Event, 90_000),
            ],
            ..Report::default()
        };
        let ok = Target::at_most("small", "floor", Wait::Spin, 1.5).evaluate(&report).unwrap();
        assert!(ok.met && (ok.p50_ratio - 1.4).abs() < 0.01, "{ok:?}");
        let far = Target::at_least("small", "floor", Wait::Spin, 10.0).evaluate(&report).unwrap();
        assert!(!far.met);
        let event = Target::at_most("small", "floor", Wait::Event, 1.5);
        assert_eq!(event.evaluate(&report), Err(vec!["floor"]));
        assert_eq!(Target::at_least("a", "b", Wait::Spin, 10.0).bound_label(), "≥ ×10.0");
    }
}
