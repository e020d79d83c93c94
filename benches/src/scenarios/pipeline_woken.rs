//! Where a pipeline stage's time goes, seen from the unit's own process: how long
//! after its input was added the unit's `compute` was called.
//!
//! `pipeline-<stage>` times a stage from its input's add time to its output's, both
//! stamped by the writers' gates: the input's publish and wake-up, the wait for a core,
//! the unit process's take of the sample, `compute`, and the add of the output up to
//! its gate. [`Woken`] wraps the unit in its process and notes, for every call, the
//! time from the newest input's add time to the call: the part of the stage before
//! `compute`. The worker prints one [`Woken::report`] line when it leaves, which the
//! measuring process turns into a note on the stage's row ([`note_for`]).

use std::sync::Arc;

use esgm_core::esgm::{CompUnit, ComputeError};
use esgm_core::{Clock as _, EntityStructure, Sample, SystemClock, Time};

use crate::latency::Latency;

/// What a [`Woken::report`] line begins with.
const PREFIX: &str = "woken";

/// A unit that notes when it is called (see the module docs).
pub struct Woken {
    unit: Arc<dyn CompUnit>,
    delays: std::sync::Mutex<Latency>,
}

impl std::fmt::Debug for Woken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Woken").finish_non_exhaustive()
    }
}

impl Woken {
    /// `unit`, timed.
    pub fn new(unit: Arc<dyn CompUnit>) -> anyhow::Result<Self> {
        Ok(Woken { unit, delays: std::sync::Mutex::new(Latency::new()?) })
    }

    /// One line for the measuring process: `woken <unit> <n> <p50 ns> <p99 ns>`.
    pub fn report(&self, unit: &str) -> String {
        match self.delays.lock() {
            Ok(d) => {
                format!("{PREFIX} {unit} {} {} {}", d.len(), d.quantile(0.5), d.quantile(0.99))
            }
            Err(_) => format!("{PREFIX} {unit} 0 0 0"),
        }
    }
}

impl CompUnit for Woken {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let now = SystemClock.now();
        if let Some(added) = inputs.iter().map(|s| s.add_time).max() {
            if let Ok(mut d) = self.delays.lock() {
                d.record_ns(u64::try_from(now - added).unwrap_or(0));
            }
        }
        self.unit.compute(inputs, qtime)
    }

    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        self.unit.compute_at(inputs, t)
    }
}

/// The note for the stage computed by `unit`, from the lines its worker printed.
pub fn note_for(unit: &str, lines: &[String]) -> Option<String> {
    lines.iter().find_map(|line| {
        let mut words = line.split_whitespace();
        if words.next() != Some(PREFIX) || words.next() != Some(unit) {
            return None;
        }
        let n: u64 = words.next()?.parse().ok()?;
        let p50: f64 = words.next()?.parse().ok()?;
        let p99: f64 = words.next()?.parse().ok()?;
        Some(format!(
            "of which input added -> compute called in the unit's process (publish, wake-up, \
             wait for a core, take and decode): p50 {:.1} µs, p99 {:.1} µs over {n} calls",
            p50 / 1e3,
            p99 / 1e3
        ))
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "a failure is a failed test")]
mod tests {
    use super::*;

    #[test]
    fn a_report_line_becomes_its_units_note() {
        let lines =
            vec!["something else".to_owned(), "woken BlobSelection 12 40000 90000".to_owned()];
        let note = note_for("BlobSelection", &lines).unwrap();
        assert!(note.contains("p50 40.0 µs, p99 90.0 µs over 12 calls"), "{note}");
        assert!(note_for("DrivingDirection", &lines).is_none());
    }
}
