//! The run's report: cases, cases per second and findings per target.

use std::fmt;

use crate::runner::SAVED_ALIKE;
use crate::supervise::{Plan, TargetReport};

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

/// Findings with a saved input listed per target; the rest are counted.
const SHOWN: usize = 20;

fn shown_count(t: &TargetReport) -> usize {
    t.findings.iter().filter(|x| !x.file.as_os_str().is_empty()).take(SHOWN).count()
}

fn rate(cases: u64, seconds: f64) -> f64 {
    if seconds > 0.0 { cases as f64 / seconds } else { 0.0 }
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
        writeln!(
            f,
            "{:<10} {:>12} {:>9} {:>10} {:>9}",
            "target", "cases", "seconds", "cases/s", "findings"
        )?;
        let mut seconds = 0.0;
        for t in &self.targets {
            seconds += t.seconds;
            writeln!(
                f,
                "{:<10} {:>12} {:>9.1} {:>10.0} {:>9}",
                t.name,
                t.cases,
                t.seconds,
                rate(t.cases, t.seconds),
                t.findings.len()
            )?;
        }
        writeln!(
            f,
            "{:<10} {:>12} {:>9.1} {:>10.0} {:>9}",
            "total",
            self.cases(),
            seconds,
            rate(self.cases(), seconds),
            self.findings()
        )?;
        for t in &self.targets {
            let unsaved = t.findings.iter().filter(|x| x.file.as_os_str().is_empty()).count();
            let shown = t.findings.iter().filter(|x| !x.file.as_os_str().is_empty()).take(SHOWN);
            for x in shown {
                let file = x.file.display();
                writeln!(
                    f,
                    "FINDING {} {} case {}: {} ({file})",
                    t.name, x.kind, x.index, x.message
                )?;
                writeln!(
                    f,
                    "  again: esgm-fuzz --target {} --seed {} --from {} --max-cases 1",
                    t.name, p.seed, x.index
                )?;
            }
            let hidden = t.findings.len() - unsaved - shown_count(t);
            if unsaved + hidden > 0 {
                writeln!(
                    f,
                    "  {} more {} finding(s) like those above (inputs saved for {SAVED_ALIKE} of each kind)",
                    unsaved + hidden,
                    t.name
                )?;
            }
        }
        Ok(())
    }
}
