//! What a synchronizer gave up on, per input and per reason: the answer to "why did my
//! synchronized callback not fire?" that message_filters leaves silent
//! (ros/ros_comm#1059, ros2/message_filters#82). Each policy records every item it
//! discards here, with the item's valid time; the counts sum to
//! [`super::Synchronizer::dropped`].

use crate::Time;

/// Why a synchronizer discarded an item without emitting it in a set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SyncDropReason {
    /// Pushed out by the queue bound: its input ran more than the queue size ahead of
    /// an input that had nothing (message_filters' `queue_size`).
    QueueFull,
    /// No set within the tolerance could hold it: every other input's items were too
    /// far from it in time (or, for ApproximateTime, the set it could start could not
    /// be proven best after its own input overflowed).
    NoPartner,
    /// A better-matched set was chosen, and it was older than that set's member on its
    /// input: ApproximateTime's drop when it publishes, ExactTime's unmatched items
    /// older than a complete set.
    PassedOver,
    /// It arrived after a later set was emitted: its set could no longer come out in
    /// valid-time order.
    Late,
    /// A newer item with the same valid time on the same input replaced it.
    Replaced,
    /// It was held when an input was reset (re-pointed to a new stream), and matching
    /// started afresh.
    Reset,
}

impl SyncDropReason {
    /// The reason in words, as `why` says it.
    pub fn words(self) -> &'static str {
        match self {
            SyncDropReason::QueueFull => "pushed out of its full queue",
            SyncDropReason::NoPartner => "with no partner within the tolerance",
            SyncDropReason::PassedOver => "passed over for a better-matched set",
            SyncDropReason::Late => "arrived after a later set",
            SyncDropReason::Replaced => "replaced by a newer item of the same time",
            SyncDropReason::Reset => "held when an input was reset",
        }
    }
}

/// One input's discarded items, by reason.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InputDrops {
    /// [`SyncDropReason::QueueFull`].
    pub queue_full: u64,
    /// [`SyncDropReason::NoPartner`].
    pub no_partner: u64,
    /// [`SyncDropReason::PassedOver`].
    pub passed_over: u64,
    /// [`SyncDropReason::Late`].
    pub late: u64,
    /// [`SyncDropReason::Replaced`].
    pub replaced: u64,
    /// [`SyncDropReason::Reset`].
    pub reset: u64,
    /// The last item discarded: its valid time and why (`None`: none yet).
    pub last: Option<(Time, SyncDropReason)>,
}

impl InputDrops {
    /// Counts one item discarded for `reason`, valid at `valid_time`.
    pub fn count(&mut self, reason: SyncDropReason, valid_time: Time) {
        self.add(reason, 1);
        self.last = Some((valid_time, reason));
    }

    /// How many items in all.
    pub fn total(&self) -> u64 {
        self.queue_full
            + self.no_partner
            + self.passed_over
            + self.late
            + self.replaced
            + self.reset
    }

    /// The counts by reason, the non-zero ones, largest first.
    pub fn by_reason(&self) -> Vec<(SyncDropReason, u64)> {
        let mut all = vec![
            (SyncDropReason::QueueFull, self.queue_full),
            (SyncDropReason::NoPartner, self.no_partner),
            (SyncDropReason::PassedOver, self.passed_over),
            (SyncDropReason::Late, self.late),
            (SyncDropReason::Replaced, self.replaced),
            (SyncDropReason::Reset, self.reset),
        ];
        all.retain(|(_, n)| *n > 0);
        all.sort_by_key(|(_, n)| std::cmp::Reverse(*n));
        all
    }

    /// Adds `other`'s counts to these (its last item, if it has one, is the later).
    pub fn merge(&mut self, other: &InputDrops) {
        for (reason, n) in other.by_reason() {
            self.add(reason, n);
        }
        if other.last.is_some() {
            self.last = other.last;
        }
    }

    fn add(&mut self, reason: SyncDropReason, n: u64) {
        let counter = match reason {
            SyncDropReason::QueueFull => &mut self.queue_full,
            SyncDropReason::NoPartner => &mut self.no_partner,
            SyncDropReason::PassedOver => &mut self.passed_over,
            SyncDropReason::Late => &mut self.late,
            SyncDropReason::Replaced => &mut self.replaced,
            SyncDropReason::Reset => &mut self.reset,
        };
        *counter += n;
    }
}

/// Every input's drops, kept by a synchronizer: one [`InputDrops`] per input, and their
/// sum.
#[derive(Debug, Clone)]
pub(crate) struct DropTally {
    inputs: Vec<InputDrops>,
    total: u64,
}

impl DropTally {
    /// A tally over `inputs` inputs, all zero.
    pub fn new(inputs: usize) -> Self {
        Self { inputs: vec![InputDrops::default(); inputs], total: 0 }
    }

    /// Counts one item of `input`, valid at `valid_time`, discarded for `reason`.
    pub fn count(&mut self, input: usize, reason: SyncDropReason, valid_time: Time) {
        if let Some(drops) = self.inputs.get_mut(input) {
            drops.count(reason, valid_time);
        }
        self.total += 1;
    }

    /// How many items in all.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Each input's drops, by input index.
    pub fn per_input(&self) -> &[InputDrops] {
        &self.inputs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_sum_per_input_and_in_all_and_keep_the_last() {
        let mut t = DropTally::new(2);
        t.count(0, SyncDropReason::QueueFull, 5);
        t.count(0, SyncDropReason::QueueFull, 6);
        t.count(1, SyncDropReason::PassedOver, 7);
        assert_eq!(t.total(), 3);
        assert_eq!(t.per_input()[0].by_reason(), vec![(SyncDropReason::QueueFull, 2)]);
        assert_eq!(t.per_input()[0].last, Some((6, SyncDropReason::QueueFull)));
        let mut sum = t.per_input()[0].clone();
        sum.merge(&t.per_input()[1]);
        assert_eq!(sum.total(), 3);
        assert_eq!(sum.last, Some((7, SyncDropReason::PassedOver)));
    }
}
