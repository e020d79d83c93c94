//! The run's report: cases, cases per second and findings per target, by kind.

use std::fmt;

use crate::event::{Finding, Kind};
use crate::runner::SAVED_ALIKE;
use crate::supervise::{Plan, TargetReport};
use crate::target::RESET_EVERY;

/// Everything a run found, printed as a table and a list of findings.
#[derive(Debug, Clone)]
pub struct Report {
    /// What was run.
    pub plan: Plan,
    /// Per target.
    pub targets: Vec<TargetReport>,
}

impl Report {
    /// Findings of every target.
    pub fn findings(&self) -> usize {
        self.targets.iter().map(|t| t.findings.len()).sum()
    }

    /// Cases of every target.
    pub fn cases(&self) -> u64 {
        self.targets.iter().map(|t| t.cases).sum()
    }
}

/// Findings listed per target; the rest are counted.
const SHOWN: usize = 20;

/// The columns of findings, in the header's order.
const KINDS: [Kind; 4] = [Kind::Panic, Kind::Hang, Kind::Abort, Kind::Broken];

fn rate(cases: u64, seconds: f64) -> f64 {
    if seconds > 0.0 { cases as f64 / seconds } else { 0.0 }
}

fn row(
    f: &mut fmt::Formatter<'_>,
    name: &str,
    cases: u64,
    seconds: f64,
    findings: &[&Finding],
) -> fmt::Result {
    write!(f, "{name:<10} {cases:>12} {seconds:>9.1} {:>10.0}", rate(cases, seconds))?;
    for kind in KINDS {
        write!(f, " {:>7}", findings.iter().filter(|x| x.kind == kind).count())?;
    }
    writeln!(f)
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = &self.plan;
        writeln!(
            f,
            "esgm-fuzz: seed {}, {} s over {} target(s), hang limit {} ms",
            p.seed,
            p.seconds,
            self.targets.len(),
            p.hang.as_millis()
        )?;
        write!(f, "{:<10} {:>12} {:>9} {:>10}", "target", "cases", "seconds", "cases/s")?;
        writeln!(f, " {:>7} {:>7} {:>7} {:>7}", "panics", "hangs", "aborts", "broken")?;
        for t in &self.targets {
            row(f, &t.name, t.cases, t.seconds, &t.findings.iter().collect::<Vec<_>>())?;
        }
        let all: Vec<&Finding> = self.targets.iter().flat_map(|t| &t.findings).collect();
        let seconds = self.targets.iter().map(|t| t.seconds).sum();
        row(f, "total", self.cases(), seconds, &all)?;
        for t in &self.targets {
            for x in t.findings.iter().take(SHOWN) {
                let file = match x.file.to_str() {
                    Some("") => "no input saved".to_owned(),
                    _ => x.file.display().to_string(),
                };
                writeln!(
                    f,
                    "FINDING {} {} case {}: {} ({file})",
                    t.name, x.kind, x.index, x.message
                )?;
                // From the last reset on: a case may depend on the state earlier cases
                // left (the request target's registry).
                let from = x.index - x.index % RESET_EVERY;
                writeln!(
                    f,
                    "  again: esgm-fuzz --target {} --seed {} --from {from} --max-cases {}",
                    t.name,
                    p.seed,
                    x.index - from + 1
                )?;
            }
            let more = t.findings.len().saturating_sub(SHOWN);
            if more > 0 {
                writeln!(
                    f,
                    "  {more} more {} finding(s) (inputs saved for {SAVED_ALIKE} alike)",
                    t.name
                )?;
            }
        }
        Ok(())
    }
}
