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

/// A goal for `row / baseline` (p50, both rows with the same wait), or for `row` against
/// a budget: `baseline` plus multiples of other rows ([`Target::plus`]).
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
    /// Terms added to the baseline, each a row (at its own wait) and its multiple: "the
    /// in-process hot path plus five wake-ups plus the work".
    pub plus: Vec<Term>,
}

/// A multiple of a row, added to a target's baseline.
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    /// The row.
    pub row: String,
    /// Its wait.
    pub wait: Wait,
    /// How many times it counts.
    pub times: f64,
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
        Self {
            row: row.into(),
            baseline: baseline.into(),
            wait,
            bound: Bound::AtMost(ratio),
            plus: Vec::new(),
        }
    }

    /// `row / baseline ≥ ratio` with both rows at `wait`.
    pub fn at_least(row: &str, baseline: &str, wait: Wait, ratio: f64) -> Self {
        Self {
            row: row.into(),
            baseline: baseline.into(),
            wait,
            bound: Bound::AtLeast(ratio),
            plus: Vec::new(),
        }
    }

    /// Adds `times` × `row` (at `wait`) to the baseline: the target becomes
    /// `row / (baseline + Σ times × term)`, at p50 and at p99 alike.
    #[must_use]
    pub fn plus(mut self, row: &str, wait: Wait, times: f64) -> Self {
        self.plus.push(Term { row: row.into(), wait, times });
        self
    }

    /// Every row the target reads: its row, its baseline and its terms'.
    pub fn rows(&self) -> impl Iterator<Item = &str> {
        [self.row.as_str(), self.baseline.as_str()]
            .into_iter()
            .chain(self.plus.iter().map(|t| t.row.as_str()))
    }

    /// What is compared: `row / baseline`, or `row / baseline + 5×term`.
    pub fn label(&self) -> String {
        let mut out = format!("{} / {}", self.row, self.baseline);
        for t in &self.plus {
            out.push_str(&format!(" + {}×{}", t.times, t.row));
        }
        out
    }

    /// The ratio in `report`, or the names of the rows that did not run.
    pub fn evaluate(&self, report: &Report) -> Result<Outcome, Vec<&str>> {
        let find = |name: &str, wait: Wait| -> Option<&Measurement> {
            report.scenarios.iter().find(|m| m.name == name && m.wait == wait)
        };
        let mut missing = Vec::new();
        let row = find(&self.row, self.wait);
        let base = find(&self.baseline, self.wait);
        if row.is_none() {
            missing.push(self.row.as_str());
        }
        if base.is_none() {
            missing.push(self.baseline.as_str());
        }
        let (mut budget50, mut budget99) =
            base.map_or((0.0, 0.0), |b| (b.p50_ns as f64, b.p99_ns as f64));
        for t in &self.plus {
            match find(&t.row, t.wait) {
                Some(m) => {
                    budget50 += t.times * m.p50_ns as f64;
                    budget99 += t.times * m.p99_ns as f64;
                }
                None => missing.push(t.row.as_str()),
            }
        }
        let Some(row) = row.filter(|_| missing.is_empty()) else {
            return Err(missing);
        };
        let p50_ratio = row.p50_ns as f64 / budget50.max(1.0);
        let met = match self.bound {
            Bound::AtMost(x) => p50_ratio <= x,
            Bound::AtLeast(x) => p50_ratio >= x,
        };
        Ok(Outcome { p50_ratio, p99_ratio: row.p99_ns as f64 / budget99.max(1.0), met })
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

    #[test]
    fn a_budget_adds_multiples_of_other_rows_to_the_baseline() {
        let report = Report {
            scenarios: vec![
                row("inproc", Wait::Event, 1000),
                row("wake", Wait::Event, 100),
                row("work", Wait::Spin, 50),
                row("procs", Wait::Event, 1800),
            ],
            ..Report::default()
        };
        let t = Target::at_most("procs", "inproc", Wait::Event, 1.0)
            .plus("wake", Wait::Event, 5.0)
            .plus("work", Wait::Spin, 2.0);
        let o = t.evaluate(&report).unwrap();
        // 1800 / (1000 + 500 + 100)
        assert!(!o.met && (o.p50_ratio - 1.125).abs() < 1e-9, "{o:?}");
        assert_eq!(t.label(), "procs / inproc + 5×wake + 2×work");
        let gone = Target::at_most("procs", "inproc", Wait::Event, 1.0).plus("x", Wait::Event, 1.0);
        assert_eq!(gone.evaluate(&report), Err(vec!["x"]));
    }
}
