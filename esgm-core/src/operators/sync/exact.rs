//! The exact sync policy: one item per input, all with the same valid time.
//!
//! Behaves like ROS message_filters' ExactTime policy, with two choices of its own:
//! - The queue bound is per input (at most `queue_size` unmatched items held for each
//!   input), so one chatty input cannot push out another input's items.
//! - Output is strictly in valid-time order: when a set is emitted at time `t`, items
//!   older than `t` can never be emitted any more and are dropped, and an item arriving
//!   later with a valid time `<= t` is dropped at once. ExactTime drops the former too;
//!   the latter it would keep until the next set.
//!
//! Every item that leaves without being emitted is counted in [`ExactSync::dropped`].

use std::collections::BTreeMap;

use super::drops::DropTally;
use super::{InputDrops, Stamped, SyncDropReason, SyncError, Synchronizer};
use crate::Time;

/// Settings of [`ExactSync`].
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct ExactConfig {
    /// At most this many unmatched items are held per input; when an input has more, its
    /// oldest unmatched item is dropped. At least 1.
    pub queue_size: usize,
}

impl Default for ExactConfig {
    /// Ten items per input: message_filters' customary queue size.
    fn default() -> Self {
        Self { queue_size: 10 }
    }
}

impl ExactConfig {
    /// Sets [`ExactConfig::queue_size`].
    #[must_use]
    pub fn queue_size(mut self, queue_size: usize) -> Self {
        self.queue_size = queue_size;
        self
    }
}

/// sync(s1..sn) with the exact policy: emits a set when every input has an item with the
/// same valid time.
#[derive(Debug, Clone)]
pub struct ExactSync<T> {
    inputs: usize,
    queue_size: usize,
    /// Unmatched items by valid time, one slot per input.
    pending: BTreeMap<Time, Vec<Option<T>>>,
    /// How many items `pending` holds for each input (what the queue bound limits).
    held: Vec<usize>,
    /// The valid time of the last emitted set: nothing at or before it can be emitted.
    last_emitted: Option<Time>,
    drops: DropTally,
}

impl<T: Stamped> ExactSync<T> {
    /// A synchronizer over `inputs` inputs.
    ///
    /// # Errors
    /// [`SyncError::NoInputs`] if `inputs` is 0, [`SyncError::ZeroQueueSize`] if the
    /// queue size is 0.
    pub fn new(inputs: usize, config: ExactConfig) -> Result<Self, SyncError> {
        if inputs == 0 {
            return Err(SyncError::NoInputs);
        }
        if config.queue_size == 0 {
            return Err(SyncError::ZeroQueueSize);
        }
        Ok(Self {
            inputs,
            queue_size: config.queue_size,
            pending: BTreeMap::new(),
            held: vec![0; inputs],
            last_emitted: None,
            drops: DropTally::new(inputs),
        })
    }

    /// How many inputs the synchronizer matches.
    pub fn inputs(&self) -> usize {
        self.inputs
    }

    /// Feeds one item arriving on input `input`; returns the set it completed, if any
    /// (at most one: a set is completed by its last item).
    ///
    /// An item with the same valid time as one already held for the same input replaces
    /// it (the newer estimate wins); the replaced one is counted as dropped.
    ///
    /// # Errors
    /// [`SyncError::NoSuchInput`] if `input >= self.inputs()`.
    pub fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError> {
        if input >= self.inputs {
            return Err(SyncError::NoSuchInput { input, inputs: self.inputs });
        }
        let stamp = item.stamp();
        if self.last_emitted.is_some_and(|last| stamp <= last) {
            // Its set could only come out after a later one, breaking valid-time order.
            self.drops.count(input, SyncDropReason::Late, stamp);
            return Ok(Vec::new());
        }
        let inputs = self.inputs;
        let slots =
            self.pending.entry(stamp).or_insert_with(|| (0..inputs).map(|_| None).collect());
        let Some(slot) = slots.get_mut(input) else {
            return Ok(Vec::new());
        };
        if slot.replace(item).is_some() {
            self.drops.count(input, SyncDropReason::Replaced, stamp);
        } else {
            self.held[input] += 1;
        }

        if slots.iter().all(Option::is_some) {
            return Ok(self.emit(stamp).into_iter().collect());
        }
        self.bound_queue(input);
        Ok(Vec::new())
    }

    /// Items discarded without being part of an emitted set: unmatched items pushed out by
    /// the queue bound, passed over by a later set, or arriving too late.
    pub fn dropped(&self) -> u64 {
        self.drops.total()
    }

    /// Each input's discarded items, by reason (they sum to [`Self::dropped`]).
    pub fn drops(&self) -> &[InputDrops] {
        self.drops.per_input()
    }

    /// Items held, waiting for the rest of their set.
    pub fn queued(&self) -> usize {
        self.held.iter().sum()
    }

    /// Takes out the complete set at `stamp` and drops everything older.
    fn emit(&mut self, stamp: Time) -> Option<Vec<T>> {
        let set = self.pending.remove(&stamp)?;
        for (input, held) in self.held.iter_mut().enumerate() {
            if set.get(input).is_some_and(Option::is_some) {
                *held = held.saturating_sub(1);
            }
        }
        let newer = self.pending.split_off(&stamp);
        for (older, slots) in std::mem::replace(&mut self.pending, newer) {
            for (input, slot) in slots.iter().enumerate() {
                if slot.is_some() {
                    self.drops.count(input, SyncDropReason::PassedOver, older);
                    if let Some(held) = self.held.get_mut(input) {
                        *held = held.saturating_sub(1);
                    }
                }
            }
        }
        self.last_emitted = Some(stamp);
        set.into_iter().collect()
    }

    /// Drops the oldest unmatched items of `input` until it holds at most `queue_size`.
    fn bound_queue(&mut self, input: usize) {
        while self.held[input] > self.queue_size {
            let Some((&stamp, slots)) = self
                .pending
                .iter_mut()
                .find(|(_, slots)| slots.get(input).is_some_and(Option::is_some))
            else {
                return;
            };
            if let Some(slot) = slots.get_mut(input) {
                *slot = None;
            }
            let now_empty = slots.iter().all(Option::is_none);
            if now_empty {
                self.pending.remove(&stamp);
            }
            self.held[input] -= 1;
            self.drops.count(input, SyncDropReason::QueueFull, stamp);
        }
    }
}

impl<T: Stamped> Synchronizer<T> for ExactSync<T> {
    fn inputs(&self) -> usize {
        ExactSync::inputs(self)
    }
    fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError> {
        ExactSync::push(self, input, item)
    }
    fn dropped(&self) -> u64 {
        ExactSync::dropped(self)
    }
    fn drops(&self) -> &[InputDrops] {
        ExactSync::drops(self)
    }
    fn queued_on(&self, input: usize) -> usize {
        self.held.get(input).copied().unwrap_or(0)
    }
    fn queued(&self) -> usize {
        ExactSync::queued(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exact(inputs: usize, queue_size: usize) -> Result<ExactSync<Time>, SyncError> {
        ExactSync::new(inputs, ExactConfig::default().queue_size(queue_size))
    }

    /// Feeds `(input, stamp)` pairs; returns the stamps of the sets emitted after each push.
    fn feed(
        sync: &mut ExactSync<Time>,
        pushes: &[(usize, Time)],
    ) -> Result<Vec<Vec<Vec<Time>>>, SyncError> {
        pushes.iter().map(|&(input, stamp)| sync.push(input, stamp)).collect()
    }

    #[test]
    fn equal_stamps_make_a_set_when_the_last_input_arrives() -> Result<(), SyncError> {
        let mut sync = exact(3, 10)?;
        let out = feed(&mut sync, &[(0, 5), (2, 5), (1, 5)])?;
        assert_eq!(out, vec![vec![], vec![], vec![vec![5, 5, 5]]]);
        assert_eq!((sync.queued(), sync.dropped()), (0, 0));
        Ok(())
    }

    #[test]
    fn a_missing_input_holds_the_set_back() -> Result<(), SyncError> {
        let mut sync = exact(3, 10)?;
        let out = feed(&mut sync, &[(0, 5), (1, 5), (0, 6), (1, 6)])?;
        assert!(out.iter().all(Vec::is_empty));
        assert_eq!((sync.queued(), sync.dropped()), (4, 0));
        // Input 2 catches up with the later stamp: the older incomplete set is passed over.
        assert_eq!(sync.push(2, 6)?, vec![vec![6, 6, 6]]);
        assert_eq!((sync.queued(), sync.dropped()), (0, 2));
        Ok(())
    }

    #[test]
    fn sets_come_out_in_valid_time_order_and_late_items_are_dropped() -> Result<(), SyncError> {
        let mut sync = exact(2, 10)?;
        let out = feed(&mut sync, &[(0, 1), (0, 2), (1, 2), (1, 1), (0, 3), (1, 3)])?;
        assert_eq!(out.concat(), vec![vec![2, 2], vec![3, 3]]);
        // (0, 1) is passed over by the set at 2, (1, 1) arrives after it.
        assert_eq!((sync.queued(), sync.dropped()), (0, 2));
        let drops = sync.drops();
        assert_eq!(
            (drops[0].passed_over, drops[0].last),
            (1, Some((1, SyncDropReason::PassedOver)))
        );
        assert_eq!((drops[1].late, drops[1].last), (1, Some((1, SyncDropReason::Late))));
        assert_eq!(drops[0].total() + drops[1].total(), 2);
        Ok(())
    }

    #[test]
    fn a_repeated_stamp_on_one_input_replaces_the_held_item() -> Result<(), SyncError> {
        let mut sync = exact(2, 10)?;
        assert!(feed(&mut sync, &[(0, 4), (0, 4)])?.concat().is_empty());
        assert_eq!((sync.queued(), sync.dropped()), (1, 1));
        assert_eq!(sync.drops()[0].replaced, 1);
        assert_eq!(sync.push(1, 4)?, vec![vec![4, 4]]);
        Ok(())
    }

    #[test]
    fn the_queue_bound_drops_the_oldest_unmatched_items_and_counts_them() -> Result<(), SyncError> {
        let mut sync = exact(2, 2)?;
        assert!(feed(&mut sync, &[(0, 1), (0, 2), (0, 3), (0, 4)])?.concat().is_empty());
        assert_eq!((sync.queued(), sync.dropped()), (2, 2));
        assert_eq!(
            (sync.drops()[0].queue_full, sync.drops()[0].last),
            (2, Some((2, SyncDropReason::QueueFull)))
        );
        // 1 and 2 are gone, 3 still matches; input 1's own bound is untouched.
        assert!(sync.push(1, 1)?.is_empty());
        assert_eq!(sync.push(1, 3)?, vec![vec![3, 3]]);
        assert_eq!((sync.queued(), sync.dropped()), (1, 3));
        Ok(())
    }

    // Upstream: message_filters test/test_exact_time_policy.cpp, ExactTime.multipleTimes.
    #[test]
    fn upstream_multiple_times() -> Result<(), SyncError> {
        let mut sync = exact(3, 2)?;
        let out = feed(&mut sync, &[(0, 0), (1, 100_000_000), (0, 100_000_000)])?;
        assert!(out.concat().is_empty());
        let set = sync.push(2, 100_000_000)?;
        assert_eq!(set, vec![vec![100_000_000; 3]]);
        Ok(())
    }

    // Upstream: message_filters test/test_exact_time_policy.cpp, ExactTime.queueSize.
    #[test]
    fn upstream_queue_size() -> Result<(), SyncError> {
        let mut sync = exact(3, 1)?;
        let out = feed(&mut sync, &[(0, 0), (1, 0), (1, 100_000_000), (1, 0), (2, 0)])?;
        assert!(out.concat().is_empty());
        Ok(())
    }

    // Upstream: message_filters test/test_exact_time_policy.cpp, ExactTime.dropCallback.
    #[test]
    fn upstream_drop_callback() -> Result<(), SyncError> {
        let mut sync = exact(2, 1)?;
        assert!(sync.push(0, 0)?.is_empty());
        assert_eq!(sync.dropped(), 0);
        assert!(sync.push(0, 100_000_000)?.is_empty());
        assert_eq!(sync.dropped(), 1);
        Ok(())
    }

    #[test]
    fn an_unknown_input_is_refused_without_change() -> Result<(), SyncError> {
        let mut sync = exact(2, 10)?;
        assert_eq!(sync.push(2, 1), Err(SyncError::NoSuchInput { input: 2, inputs: 2 }));
        assert_eq!((sync.queued(), sync.dropped()), (0, 0));
        Ok(())
    }
}
