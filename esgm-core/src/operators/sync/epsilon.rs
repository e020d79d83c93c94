//! The epsilon sync policy: ROS message_filters' ApproximateEpsilonTime rules.
//!
//! Each input has a queue of items in arrival order. Whenever every queue has an
//! item, the heads are looked at:
//! - the *oldest head* is the head with the earliest valid time (of equal ones, the
//!   lowest input);
//! - if every other head is at most `tolerance` after it, the heads are a set: it is
//!   emitted and every head leaves its queue;
//! - otherwise no set can include the oldest head (an input's later items are later
//!   still), so it leaves — with every head within `tolerance` of it, which could only
//!   have been matched with it — counted as dropped;
//!   and this repeats while every queue has an item.
//!
//! A set is thus emitted as soon as every input has a head within the tolerance of the
//! oldest: no waiting for a provably best set, as [`super::ApproximateSync`] does.
//! While some input has no item, an input whose queue grows beyond `queue_size` drops
//! its oldest (counted).

use std::collections::VecDeque;

use super::drops::DropTally;
use super::{InputDrops, Stamped, SyncDropReason, SyncError, Synchronizer};
use crate::Time;

/// Settings of [`EpsilonSync`].
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct EpsilonConfig {
    /// At most this many items wait per input while another input has none; beyond
    /// it the input's oldest is dropped. At least 1.
    pub queue_size: usize,
    /// The tolerance (message_filters' epsilon): every item of a set is at most this
    /// long after the set's oldest (nanoseconds, at least 0).
    pub tolerance: Time,
}

impl Default for EpsilonConfig {
    /// Ten items per input, and a tolerance of 0 (exact valid times) until one is set.
    fn default() -> Self {
        Self { queue_size: 10, tolerance: 0 }
    }
}

impl EpsilonConfig {
    /// Sets [`EpsilonConfig::queue_size`].
    #[must_use]
    pub fn queue_size(mut self, queue_size: usize) -> Self {
        self.queue_size = queue_size;
        self
    }

    /// Sets [`EpsilonConfig::tolerance`].
    #[must_use]
    pub fn tolerance(mut self, tolerance: Time) -> Self {
        self.tolerance = tolerance;
        self
    }
}

/// sync(s1..sn) with the epsilon policy (see the module docs).
#[derive(Debug, Clone)]
pub struct EpsilonSync<T> {
    queues: Vec<VecDeque<T>>,
    config: EpsilonConfig,
    drops: DropTally,
}

impl<T: Stamped> EpsilonSync<T> {
    /// A synchronizer over `inputs` inputs.
    ///
    /// # Errors
    /// [`SyncError::NoInputs`] for 0 inputs, [`SyncError::ZeroQueueSize`] for a queue
    /// size of 0, [`SyncError::NegativeDuration`] for a negative tolerance.
    pub fn new(inputs: usize, config: EpsilonConfig) -> Result<Self, SyncError> {
        if inputs == 0 {
            return Err(SyncError::NoInputs);
        }
        if config.queue_size == 0 {
            return Err(SyncError::ZeroQueueSize);
        }
        if config.tolerance < 0 {
            return Err(SyncError::NegativeDuration {
                setting: "tolerance".into(),
                value: config.tolerance,
            });
        }
        let queues = (0..inputs).map(|_| VecDeque::new()).collect();
        Ok(Self { queues, config, drops: DropTally::new(inputs) })
    }

    fn all_have_one(&self) -> bool {
        self.queues.iter().all(|q| !q.is_empty())
    }

    /// Emits or drops at the heads while every queue has one.
    fn decide(&mut self, sets: &mut Vec<Vec<T>>) {
        while self.all_have_one() {
            let heads = self.queues.iter().filter_map(|q| q.front().map(Stamped::stamp));
            let Some(oldest) = heads.min() else { return };
            let limit = oldest.saturating_add(self.config.tolerance);
            let within = |q: &VecDeque<T>| q.front().is_some_and(|h| h.stamp() <= limit);
            if self.queues.iter().all(within) {
                sets.push(self.queues.iter_mut().filter_map(VecDeque::pop_front).collect());
            } else {
                for (input, q) in self.queues.iter_mut().enumerate() {
                    if within(q) {
                        if let Some(item) = q.pop_front() {
                            self.drops.count(input, SyncDropReason::NoPartner, item.stamp());
                        }
                    }
                }
            }
        }
    }
}

impl<T: Stamped> Synchronizer<T> for EpsilonSync<T> {
    fn inputs(&self) -> usize {
        self.queues.len()
    }

    fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError> {
        let inputs = self.queues.len();
        let queue = self.queues.get_mut(input).ok_or(SyncError::NoSuchInput { input, inputs })?;
        queue.push_back(item);
        let mut sets = Vec::new();
        if self.all_have_one() {
            self.decide(&mut sets);
        } else if let Some(queue) = self.queues.get_mut(input) {
            if queue.len() > self.config.queue_size {
                if let Some(item) = queue.pop_front() {
                    self.drops.count(input, SyncDropReason::QueueFull, item.stamp());
                }
            }
        }
        Ok(sets)
    }

    fn dropped(&self) -> u64 {
        self.drops.total()
    }

    fn drops(&self) -> &[InputDrops] {
        self.drops.per_input()
    }

    fn queued_on(&self, input: usize) -> usize {
        self.queues.get(input).map_or(0, VecDeque::len)
    }

    fn queued(&self) -> usize {
        self.queues.iter().map(VecDeque::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sync(inputs: usize, tolerance: Time, queue: usize) -> EpsilonSync<Time> {
        let config = EpsilonConfig::default().tolerance(tolerance).queue_size(queue);
        EpsilonSync::new(inputs, config).unwrap()
    }

    #[test]
    fn emits_as_soon_as_every_input_has_a_head_within_the_tolerance() {
        let mut s = sync(2, 5, 10);
        assert!(s.push(0, 100).unwrap().is_empty());
        // 104 is within 5 of 100: out at once, not waiting for a closer partner.
        assert_eq!(s.push(1, 104).unwrap(), vec![vec![100, 104]]);
        // The bound is inclusive, and the oldest may be on either input.
        s.push(1, 200).unwrap();
        assert_eq!(s.push(0, 205).unwrap(), vec![vec![205, 200]]);
        assert_eq!((s.queued(), s.dropped()), (0, 0));
    }

    #[test]
    fn the_oldest_head_without_partners_goes_with_heads_near_it() {
        let mut s = sync(3, 5, 10);
        s.push(0, 100).unwrap();
        s.push(1, 103).unwrap();
        // 120 is too late for 100: 100 and 103 (within 5 of it) are dropped; 120 waits.
        assert!(s.push(2, 120).unwrap().is_empty());
        assert_eq!((s.queued(), s.dropped()), (1, 2));
        let partnerless: Vec<_> = s.drops().iter().map(|d| (d.no_partner, d.last)).collect();
        let none = SyncDropReason::NoPartner;
        assert_eq!(partnerless, [(1, Some((100, none))), (1, Some((103, none))), (0, None)]);
        s.push(0, 118).unwrap();
        assert_eq!(s.push(1, 121).unwrap(), vec![vec![118, 121, 120]]);
    }

    #[test]
    fn several_sets_can_become_decidable_at_once() {
        let mut s = sync(2, 0, 10);
        for t in [10, 20, 30] {
            s.push(0, t).unwrap();
        }
        assert_eq!(s.push(1, 10).unwrap(), vec![vec![10, 10]]);
        // 20 has no partner and goes; then 25 is the oldest head, too early for 30.
        assert_eq!(s.push(1, 25).unwrap(), Vec::<Vec<Time>>::new());
        assert_eq!(s.dropped(), 2);
        assert_eq!(s.push(1, 30).unwrap(), vec![vec![30, 30]]);
        assert_eq!((s.queued(), s.dropped()), (0, 2));
    }

    #[test]
    fn a_waiting_input_keeps_its_newest_queue_size_items() {
        let mut s = sync(2, 0, 2);
        for t in [1, 2, 3] {
            s.push(0, t).unwrap();
        }
        assert_eq!((s.queued(), s.dropped()), (2, 1));
        assert_eq!((s.drops()[0].queue_full, s.queued_on(0), s.queued_on(1)), (1, 2, 0));
        assert_eq!(s.push(1, 2).unwrap(), vec![vec![2, 2]]);
    }

    #[test]
    fn settings_are_checked() {
        let cfg = EpsilonConfig::default();
        assert_eq!(EpsilonSync::<Time>::new(0, cfg.clone()).unwrap_err(), SyncError::NoInputs);
        assert_eq!(
            EpsilonSync::<Time>::new(1, cfg.clone().queue_size(0)).unwrap_err(),
            SyncError::ZeroQueueSize
        );
        assert!(matches!(
            EpsilonSync::<Time>::new(1, cfg.tolerance(-1)),
            Err(SyncError::NegativeDuration { .. })
        ));
        assert!(sync(2, 0, 1).push(2, 5).is_err());
    }
}
