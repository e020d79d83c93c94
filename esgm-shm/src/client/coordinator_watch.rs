//! Whether a process's coordinator is gone: what a long-running program that serves a
//! domain (a worker, `esgm-bridge`, `esgm-ros2`) asks in its main loop, so that it
//! leaves with its system instead of outliving it. One implementation for all of them.

use std::time::{Duration, Instant};

use esgm_core::Esgm as _;

use super::ShmEsgm;

/// Pings the coordinator at most every [`CoordinatorWatch::every`] and says it is gone
/// once it has not answered for the patience given: a coordinator restarting (a
/// supervised `esgm up`) answers again within it.
#[derive(Debug, Clone)]
pub struct CoordinatorWatch {
    patience: Duration,
    every: Duration,
    pinged: Option<Instant>,
    gone_since: Option<Instant>,
    /// The last answer, given again between pings.
    gone: bool,
}

impl CoordinatorWatch {
    /// A watch that says "gone" after `patience` without an answer, pinging at most
    /// every 500 ms.
    pub fn new(patience: Duration) -> Self {
        Self {
            patience,
            every: Duration::from_millis(500),
            pinged: None,
            gone_since: None,
            gone: false,
        }
    }

    /// Pings at most this often (a loop that sleeps longer pings every round).
    #[must_use]
    pub fn every(mut self, every: Duration) -> Self {
        self.every = every;
        self
    }

    /// Pings `esgm`'s coordinator if it is time to; true once it has not answered for
    /// the patience. Between pings, the last answer. Cheap to call every round of a
    /// loop.
    pub fn gone(&mut self, esgm: &ShmEsgm) -> bool {
        if self.pinged.is_some_and(|p| p.elapsed() < self.every) {
            return self.gone;
        }
        self.pinged = Some(Instant::now());
        self.gone = if esgm.ping() {
            self.gone_since = None;
            false
        } else {
            self.gone_since.get_or_insert_with(Instant::now).elapsed() >= self.patience
        };
        self.gone
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::control::{Coordinator, Registry};

    #[test]
    fn a_coordinator_that_answers_is_not_gone_and_one_that_stopped_is_after_the_patience() {
        let domain = crate::unique_domain("watch");
        let coordinator =
            Coordinator::spawn(&domain, Registry::new(esgm_core::TypeRegistry::with_library()))
                .unwrap();
        let esgm = ShmEsgm::builder().domain(&domain).connect().unwrap();
        let mut watch = CoordinatorWatch::new(Duration::from_millis(300)).every(Duration::ZERO);
        assert!(!watch.gone(&esgm));
        drop(coordinator);
        let stopped = Instant::now();
        let deadline = stopped + Duration::from_secs(10);
        while !watch.gone(&esgm) {
            assert!(Instant::now() < deadline, "not gone after 10 s");
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(stopped.elapsed() >= Duration::from_millis(300), "not before the patience");
        // Pinged at most every `every`: between pings it says what it last knew.
        let mut slow = CoordinatorWatch::new(Duration::ZERO).every(Duration::from_secs(60));
        assert!(slow.gone(&esgm));
        assert!(slow.gone(&esgm), "the last answer, without a ping within `every`");
    }
}
