//! When the topology runs: sensors and the planner's timer produce only inside a
//! window, set once every process of a system is ready (`go START UNTIL`, see
//! [`super::processes`]); what is in flight at UNTIL is let through for
//! [`DRAIN`] before the nodes report.

use std::sync::atomic::{AtomicI64, Ordering::SeqCst};
use std::time::Duration;

use esgm_shm::prelude::Time;

/// How long after UNTIL messages in flight are let through before reporting.
pub const DRAIN: Duration = Duration::from_millis(500);

/// The window of a run, shared by the sensors and units one process serves.
#[derive(Debug, Default)]
pub struct Window {
    start: AtomicI64,
    until: AtomicI64,
}

impl Window {
    /// Opens the window from `start` to `until` (ns on the system clock).
    pub fn set(&self, start: Time, until: Time) {
        self.until.store(until, SeqCst);
        self.start.store(start, SeqCst);
    }

    /// Opens it for good: a system run by hand (`esgm up --config`), not measured.
    pub fn open_for_good(&self) {
        self.set(1, Time::MAX);
    }

    /// Whether `t` is inside it.
    pub fn open(&self, t: Time) -> bool {
        let start = self.start.load(SeqCst);
        start > 0 && t >= start && t < self.until.load(SeqCst)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_is_closed_until_set_and_ends_at_until() {
        let w = Window::default();
        assert!(!w.open(5));
        w.set(10, 20);
        assert!(!w.open(9) && w.open(10) && w.open(19) && !w.open(20));
        w.open_for_good();
        assert!(w.open(1) && w.open(Time::MAX - 1));
    }
}
