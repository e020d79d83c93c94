//! The approximate sync policy: the sets ROS message_filters' ApproximateTime chooses.
//!
//! G2 requires the same sets as ApproximateTime on the same input, so this follows its
//! algorithm step for step (including its tie-breaks), written afresh around Rust's
//! ownership. The properties it guarantees (from the ROS wiki): every item is used at
//! most once; sets do not cross; sets are contiguous (no set could be formed from the
//! items dropped between two sets); each set has minimal size — latest minus earliest
//! valid time — among the sets contiguous to the previous one; and the output depends
//! only on the valid times, not on the order items arrive across inputs (given queues
//! large enough to wait for the slowest input).
//!
//! ## How it works
//! Each input is a lane: `waiting` items not yet looked at by the current search, and
//! `passed` items the search has stepped over (message_filters' deque and past vector).
//! While every lane has a waiting item, the heads of the lanes form a set. The first one
//! becomes the *candidate*; the lane holding its latest item is the *pivot*, and every
//! later set must contain an item at least as late as the pivot's. The search then
//! steps over the earliest head, one at a time, and keeps whichever set is smaller
//! (later sets penalised by `1 + age_penalty`). The candidate is published once it is
//! provably best: the pivot itself was stepped over, or any further set already spans
//! more than the candidate. If a lane runs dry first, per-input lower bounds on the gap
//! between items let the search assume the earliest possible next item ("virtual"
//! items) and still prove the candidate best; otherwise it waits for more input.
//!
//! ## Where it departs from message_filters, without changing the sets
//! - The candidate is not stored: it is always the oldest held item of each lane (the
//!   first `passed` item, else the first `waiting` one), so no item is cloned.
//! - Sets are returned from [`ApproximateSync::push`] instead of signalled to callbacks.
//! - Every discarded item is counted ([`ApproximateSync::dropped`]).
//! - The inter-message-bound check warns through `tracing`, once per input.
//! - With a non-zero age penalty, message_filters scales a duration in floating point
//!   (rclcpp truncates, ROS 1 rounds to the nanosecond); this truncates an `f64`
//!   product. Sets could differ only when two set sizes tie to within a nanosecond.

use std::collections::VecDeque;

use super::drops::DropTally;
use super::{InputDrops, Stamped, SyncDropReason, SyncError, Synchronizer};
use crate::Time;

/// Settings of [`ApproximateSync`], named as in message_filters.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct ApproximateConfig {
    /// At most this many items are held per input, counting those the current search
    /// stepped over; beyond it the input's oldest item is dropped (and the input cannot
    /// be the pivot of the next set, since a dropped item might have matched better).
    /// At least 1; 2 or more is recommended, and the queue must be long enough to wait
    /// for the slowest input, or sets are lost.
    pub queue_size: usize,
    /// The tolerance (message_filters' `max_interval_duration`): no emitted set spans
    /// more than this (latest minus earliest valid time, nanoseconds). `None` (the
    /// default) leaves sets unbounded, as message_filters does by default.
    #[serde(alias = "max_interval_duration")]
    pub tolerance: Option<Time>,
    /// Per input, the least gap between the valid times of two consecutive items
    /// (nanoseconds; missing entries are 0). A correct bound never changes the sets, only
    /// lets them out sooner; a wrong one is warned about once per input.
    pub inter_message_lower_bounds: Vec<Time>,
    /// When comparing set sizes, later sets are penalised by `1 + age_penalty`. Higher
    /// values output sets sooner at some cost in quality. Default 0.1, the value
    /// message_filters' code uses (its wiki says 0; the code is what G2 matches).
    pub age_penalty: f64,
}

impl Default for ApproximateConfig {
    /// message_filters' defaults: no tolerance, no lower bounds, age penalty 0.1, and the
    /// customary queue size of 10.
    fn default() -> Self {
        Self {
            queue_size: 10,
            tolerance: None,
            inter_message_lower_bounds: Vec::new(),
            age_penalty: 0.1,
        }
    }
}

impl ApproximateConfig {
    /// Sets [`ApproximateConfig::queue_size`].
    #[must_use]
    pub fn queue_size(mut self, queue_size: usize) -> Self {
        self.queue_size = queue_size;
        self
    }

    /// Sets [`ApproximateConfig::tolerance`].
    #[must_use]
    pub fn tolerance(mut self, max: Time) -> Self {
        self.tolerance = Some(max);
        self
    }

    /// Sets input `input`'s entry of [`ApproximateConfig::inter_message_lower_bounds`].
    #[must_use]
    pub fn inter_message_lower_bound(mut self, input: usize, bound: Time) -> Self {
        if self.inter_message_lower_bounds.len() <= input {
            self.inter_message_lower_bounds.resize(input + 1, 0);
        }
        self.inter_message_lower_bounds[input] = bound;
        self
    }

    /// Sets [`ApproximateConfig::age_penalty`].
    #[must_use]
    pub fn age_penalty(mut self, age_penalty: f64) -> Self {
        self.age_penalty = age_penalty;
        self
    }
}

/// sync(s1..sn) with the approximate policy: the sets ROS message_filters'
/// ApproximateTime policy chooses.
#[derive(Debug, Clone)]
pub struct ApproximateSync<T> {
    lanes: Vec<Lane<T>>,
    queue_size: usize,
    max_interval: Option<Time>,
    age_penalty: f64,
    candidate: Option<Candidate>,
    drops: DropTally,
}

/// One input's items and state.
#[derive(Debug, Clone)]
struct Lane<T> {
    /// Items the current search has not stepped over yet, oldest first.
    waiting: VecDeque<T>,
    /// Items the current search stepped over, oldest first; they go back to `waiting` when
    /// the search ends.
    passed: Vec<T>,
    /// An item was dropped by the queue bound since this lane last took part in a set
    /// without being its latest: it must not be the pivot, as the dropped item might
    /// have made a better set.
    dropped_recently: bool,
    /// The least gap between consecutive valid times, as configured.
    lower_bound: Time,
    /// The stamp of the last item pushed, to check arrival order and the lower bound.
    last_stamp: Option<Time>,
    /// Whether a broken arrival-order or lower-bound promise was already reported.
    warned: bool,
}

impl<T> Lane<T> {
    /// Puts the stepped-over items back in front of the waiting ones, in order.
    fn restore(&mut self) {
        while let Some(item) = self.passed.pop() {
            self.waiting.push_front(item);
        }
    }

    /// Restores the last `count` stepped-over items.
    fn restore_last(&mut self, count: usize) {
        for _ in 0..count {
            match self.passed.pop() {
                Some(item) => self.waiting.push_front(item),
                None => return,
            }
        }
    }

    /// Steps the search over this lane's head.
    fn step(&mut self) {
        if let Some(item) = self.waiting.pop_front() {
            self.passed.push(item);
        }
    }

    fn held(&self) -> usize {
        self.waiting.len() + self.passed.len()
    }
}

/// The best set found so far in the current search. Its items are the oldest held item
/// of each lane.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    /// Its earliest valid time.
    start: Time,
    /// Its latest valid time.
    end: Time,
    /// The lane whose item made the first candidate of this search end where it did.
    pivot: usize,
    /// That item's valid time: every set still to be considered ends at or after it.
    pivot_time: Time,
}

/// The earliest and latest of a list of times, with message_filters' tie-breaks: the
/// first lane holding the earliest time, the last lane holding the latest.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    start_lane: usize,
    start: Time,
    end: Time,
    end_lane: usize,
}

fn bounds(times: impl IntoIterator<Item = Time>) -> Option<Bounds> {
    let mut found: Option<Bounds> = None;
    for (lane, time) in times.into_iter().enumerate() {
        found = Some(match found {
            None => Bounds { start_lane: lane, start: time, end: time, end_lane: lane },
            Some(mut b) => {
                if time < b.start {
                    (b.start_lane, b.start) = (lane, time);
                }
                if time >= b.end {
                    (b.end_lane, b.end) = (lane, time);
                }
                b
            }
        });
    }
    found
}

/// `a - b` without overflow, whatever the stamps.
fn diff(a: Time, b: Time) -> i128 {
    i128::from(a) - i128::from(b)
}

impl<T: Stamped> ApproximateSync<T> {
    /// A synchronizer over `inputs` inputs.
    ///
    /// # Errors
    /// [`SyncError::NoInputs`] if `inputs` is 0; [`SyncError::ZeroQueueSize`];
    /// [`SyncError::NegativeDuration`] for a negative tolerance or lower bound;
    /// [`SyncError::NoSuchInput`] for a lower bound on an input past `inputs`;
    /// [`SyncError::InvalidAgePenalty`] for a negative or non-finite age penalty.
    pub fn new(inputs: usize, config: ApproximateConfig) -> Result<Self, SyncError> {
        if inputs == 0 {
            return Err(SyncError::NoInputs);
        }
        if config.queue_size == 0 {
            return Err(SyncError::ZeroQueueSize);
        }
        if let Some(max) = config.tolerance.filter(|&max| max < 0) {
            return Err(SyncError::NegativeDuration { setting: "tolerance".into(), value: max });
        }
        if !config.age_penalty.is_finite() || config.age_penalty < 0.0 {
            return Err(SyncError::InvalidAgePenalty(config.age_penalty));
        }
        for (input, &bound) in config.inter_message_lower_bounds.iter().enumerate() {
            if bound < 0 {
                return Err(SyncError::NegativeDuration {
                    setting: "inter_message_lower_bound".into(),
                    value: bound,
                });
            }
            if input >= inputs && bound != 0 {
                return Err(SyncError::NoSuchInput { input, inputs });
            }
        }
        let lanes = (0..inputs)
            .map(|input| Lane {
                waiting: VecDeque::new(),
                passed: Vec::new(),
                dropped_recently: false,
                lower_bound: config.inter_message_lower_bounds.get(input).copied().unwrap_or(0),
                last_stamp: None,
                warned: false,
            })
            .collect();
        Ok(Self {
            lanes,
            queue_size: config.queue_size,
            max_interval: config.tolerance,
            age_penalty: config.age_penalty,
            candidate: None,
            drops: DropTally::new(inputs),
        })
    }

    /// How many inputs the synchronizer matches.
    pub fn inputs(&self) -> usize {
        self.lanes.len()
    }

    /// Feeds one item arriving on input `input`; returns every set that became decidable,
    /// in valid-time order, each holding one item per input (indexed by input).
    ///
    /// Items on one input must arrive in valid-time order (a violation is warned about
    /// once per input, and sets may then be poor); across inputs, any order is fine.
    ///
    /// # Errors
    /// [`SyncError::NoSuchInput`] if `input >= self.inputs()`; nothing changes then.
    pub fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError> {
        let inputs = self.lanes.len();
        let Some(lane) = self.lanes.get_mut(input) else {
            return Err(SyncError::NoSuchInput { input, inputs });
        };
        check_arrival(input, lane, item.stamp());
        lane.waiting.push_back(item);
        let first_waiting = lane.waiting.len() == 1;

        let mut sets = Vec::new();
        if first_waiting {
            self.search(&mut sets);
        }
        // The search may leave this lane one item over its bound; trim after it.
        let over = self.lanes.get(input).is_some_and(|lane| lane.held() > self.queue_size);
        if over {
            // Any ongoing search is void: its steps assumed the item about to go.
            self.lanes.iter_mut().for_each(Lane::restore);
            if let Some(lane) = self.lanes.get_mut(input) {
                if let Some(item) = lane.waiting.pop_front() {
                    self.drops.count(input, SyncDropReason::QueueFull, item.stamp());
                }
                lane.dropped_recently = true;
            }
            if self.candidate.take().is_some() {
                self.search(&mut sets);
            }
        }
        Ok(sets)
    }

    /// Items discarded without being part of an emitted set: pushed out by the queue
    /// bound, part of no set within the tolerance, or passed over for a better set.
    pub fn dropped(&self) -> u64 {
        self.drops.total()
    }

    /// Each input's discarded items, by reason (they sum to [`Self::dropped`]).
    pub fn drops(&self) -> &[InputDrops] {
        self.drops.per_input()
    }

    /// Items held, waiting for a decision.
    pub fn queued(&self) -> usize {
        self.lanes.iter().map(Lane::held).sum()
    }

    /// `growth` scaled by the age penalty: how much a later set's end moved, as weighed
    /// against how much its start moved.
    fn penalized(&self, growth: i128) -> i128 {
        if self.age_penalty == 0.0 {
            growth
        } else {
            // Saturating float-to-int cast; truncates toward zero as rclcpp does.
            (growth as f64 * (1.0 + self.age_penalty)) as i128
        }
    }

    fn all_waiting(&self) -> bool {
        self.lanes.iter().all(|lane| !lane.waiting.is_empty())
    }

    /// The heads of the lanes; `None` unless every lane has a waiting item.
    fn head_bounds(&self) -> Option<Bounds> {
        let heads: Option<Vec<Time>> =
            self.lanes.iter().map(|lane| lane.waiting.front().map(Stamped::stamp)).collect();
        bounds(heads?)
    }

    /// The earliest each lane's next item can be: its head if it has one, else what the
    /// lower bound allows after its last stepped-over item, but never before the pivot.
    fn virtual_bounds(&self, candidate: &Candidate) -> Option<Bounds> {
        bounds(self.lanes.iter().map(|lane| {
            match lane.waiting.front() {
                Some(head) => head.stamp(),
                None => lane
                    .passed
                    .last()
                    .map(|last| last.stamp().saturating_add(lane.lower_bound))
                    .map_or(candidate.pivot_time, |t| t.max(candidate.pivot_time)),
            }
        }))
    }

    /// Runs the candidate search while every lane has a waiting item, publishing each
    /// candidate proven best.
    fn search(&mut self, sets: &mut Vec<Vec<T>>) {
        while let Some(heads) = self.head_bounds() {
            for (lane_index, lane) in self.lanes.iter_mut().enumerate() {
                if lane_index != heads.end_lane {
                    // A better set could not have used a dropped item of this lane.
                    lane.dropped_recently = false;
                }
            }
            let candidate = match self.candidate {
                None => {
                    let too_wide = self
                        .max_interval
                        .is_some_and(|max| diff(heads.end, heads.start) > i128::from(max));
                    let bad_pivot =
                        self.lanes.get(heads.end_lane).is_some_and(|lane| lane.dropped_recently);
                    if too_wide || bad_pivot {
                        if let Some(lane) = self.lanes.get_mut(heads.start_lane) {
                            if let Some(item) = lane.waiting.pop_front() {
                                let reason = SyncDropReason::NoPartner;
                                self.drops.count(heads.start_lane, reason, item.stamp());
                            }
                        }
                        continue;
                    }
                    self.adopt(Candidate {
                        start: heads.start,
                        end: heads.end,
                        pivot: heads.end_lane,
                        pivot_time: heads.end,
                    })
                }
                Some(current) => {
                    let smaller = self.penalized(diff(heads.end, current.end))
                        < diff(heads.start, current.start);
                    if smaller {
                        self.adopt(Candidate { start: heads.start, end: heads.end, ..current })
                    } else {
                        current
                    }
                }
            };
            if let Some(lane) = self.lanes.get_mut(heads.start_lane) {
                lane.step();
            }

            let growth = self.penalized(diff(heads.end, candidate.end));
            if heads.start_lane == candidate.pivot
                || growth >= diff(candidate.pivot_time, candidate.start)
            {
                // Either every set with this pivot was seen, or any further one contains
                // [pivot_time, heads.end], already wider than the candidate.
                self.publish(sets);
            } else if !self.all_waiting() {
                self.prove_with_lower_bounds(candidate, sets);
            }
        }
    }

    /// Makes `candidate` the current one; the items stepped over so far are older than it
    /// in their lanes and can no longer be part of any set.
    fn adopt(&mut self, candidate: Candidate) -> Candidate {
        for (index, lane) in self.lanes.iter_mut().enumerate() {
            for item in lane.passed.drain(..) {
                self.drops.count(index, SyncDropReason::PassedOver, item.stamp());
            }
        }
        self.candidate = Some(candidate);
        candidate
    }

    /// A lane ran dry: continue the search over virtual items (the earliest the lower
    /// bounds allow) and publish if even those cannot beat the candidate; otherwise undo
    /// the virtual steps and wait for input.
    fn prove_with_lower_bounds(&mut self, candidate: Candidate, sets: &mut Vec<Vec<T>>) {
        let mut steps = vec![0usize; self.lanes.len()];
        while let Some(next) = self.virtual_bounds(&candidate) {
            let growth = self.penalized(diff(next.end, candidate.end));
            if growth >= diff(candidate.pivot_time, candidate.start) {
                self.publish(sets);
                return;
            }
            let can_step =
                self.lanes.get(next.start_lane).is_some_and(|lane| !lane.waiting.is_empty());
            if growth < diff(next.start, candidate.start) || !can_step {
                // An optimistic set beats the candidate: it may be beaten by real input.
                // (`!can_step` cannot happen: an empty lane's virtual time is at least the
                // pivot time, where one of the two tests above holds.)
                break;
            }
            if let Some(lane) = self.lanes.get_mut(next.start_lane) {
                lane.step();
            }
            if let Some(count) = steps.get_mut(next.start_lane) {
                *count += 1;
            }
        }
        for (lane, count) in self.lanes.iter_mut().zip(steps) {
            lane.restore_last(count);
        }
    }

    /// Emits the candidate (the oldest held item of each lane) and ends the search.
    fn publish(&mut self, sets: &mut Vec<Vec<T>>) {
        self.candidate = None;
        let members: Vec<Option<T>> = self
            .lanes
            .iter_mut()
            .map(|lane| {
                lane.restore();
                lane.waiting.pop_front()
            })
            .collect();
        if members.iter().all(Option::is_some) {
            sets.push(members.into_iter().flatten().collect());
        } else {
            // Unreachable while every lane holds its candidate item; never lose count.
            for (index, item) in members.iter().enumerate() {
                if let Some(item) = item {
                    self.drops.count(index, SyncDropReason::NoPartner, item.stamp());
                }
            }
        }
    }
}

/// Warns, once per input, when items arrive out of order or closer than the lower bound
/// promised: the sets stay well-formed but may not be the best ones.
fn check_arrival<T>(input: usize, lane: &mut Lane<T>, stamp: Time) {
    if let Some(last) = lane.last_stamp.replace(stamp) {
        if lane.warned {
            return;
        }
        if stamp < last {
            lane.warned = true;
            tracing::warn!(
                input,
                stamp,
                previous = last,
                "sync input items arrive out of valid-time order (reported once per input)"
            );
        } else if diff(stamp, last) < i128::from(lane.lower_bound) {
            lane.warned = true;
            tracing::warn!(
                input,
                gap = stamp - last,
                lower_bound = lane.lower_bound,
                "sync input items closer than the configured lower bound (reported once per input)"
            );
        }
    }
}

impl<T: Stamped> Synchronizer<T> for ApproximateSync<T> {
    fn inputs(&self) -> usize {
        ApproximateSync::inputs(self)
    }
    fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError> {
        ApproximateSync::push(self, input, item)
    }
    fn dropped(&self) -> u64 {
        ApproximateSync::dropped(self)
    }
    fn drops(&self) -> &[InputDrops] {
        ApproximateSync::drops(self)
    }
    fn queued(&self) -> usize {
        ApproximateSync::queued(self)
    }
    fn queued_on(&self, input: usize) -> usize {
        self.lanes.get(input).map_or(0, Lane::held)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{TIMEUNITS_PER_SECOND, secs};
    use proptest::prelude::*;

    /// Per push, the sets it emitted, as stamps in seconds.
    type PerPush = Vec<Vec<Vec<i64>>>;

    /// Feeds `(input, stamp in seconds)` pairs to a fresh synchronizer; returns, per push,
    /// the stamps (in seconds) of the sets it emitted, and the synchronizer.
    fn run(
        inputs: usize,
        config: ApproximateConfig,
        pushes: &[(usize, i64)],
    ) -> Result<(PerPush, ApproximateSync<Time>), SyncError> {
        let mut sync = ApproximateSync::new(inputs, config)?;
        let mut per_push = Vec::new();
        for &(input, stamp) in pushes {
            let sets = sync.push(input, secs(stamp))?;
            per_push.push(
                sets.into_iter()
                    .map(|set| set.into_iter().map(|t| t / TIMEUNITS_PER_SECOND).collect())
                    .collect(),
            );
        }
        Ok((per_push, sync))
    }

    /// The sets emitted over the whole run, in order.
    fn sets(
        inputs: usize,
        config: ApproximateConfig,
        pushes: &[(usize, i64)],
    ) -> Result<Vec<Vec<i64>>, SyncError> {
        Ok(run(inputs, config, pushes)?.0.concat())
    }

    fn queue(queue_size: usize) -> ApproximateConfig {
        ApproximateConfig::default().queue_size(queue_size)
    }

    // In the diagrams (from upstream), each column is a second, each row an input; the
    // output rows show when each set comes out and which items it holds.

    // Upstream: message_filters test/test_approximate_time_policy.cpp, ApproxTimeSync.ExactMatch.
    //   Input A:  a..b..c     Output: a..b..c
    //   Input B:  A..B..C             A..B..C
    #[test]
    fn upstream_exact_match() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 0), (0, 3), (1, 3), (0, 6), (1, 6)];
        let (out, sync) = run(2, queue(10), &pushes)?;
        assert_eq!(out.concat(), vec![vec![0, 0], vec![3, 3], vec![6, 6]]);
        // Each set is provably best as soon as its second item arrives.
        assert_eq!(out.iter().filter(|sets| !sets.is_empty()).count(), 3);
        assert_eq!((sync.queued(), sync.dropped()), (0, 0));
        Ok(())
    }

    // Upstream: ApproxTimeSync.PerfectMatch.
    //   Input A:  a..b..c.    Output: ...a..b.
    //   Input B:  .A..B..C            ...A..B.
    #[test]
    fn upstream_perfect_match() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 1), (0, 3), (1, 4), (0, 6), (1, 7)];
        let (out, sync) = run(2, queue(10), &pushes)?;
        assert_eq!(out.concat(), vec![vec![0, 1], vec![3, 4]]);
        // Set (a, A) comes out when b arrives, (b, B) when c does; (c, C) waits.
        assert_eq!(out[2], vec![vec![0, 1]]);
        assert_eq!(out[4], vec![vec![3, 4]]);
        assert_eq!((sync.queued(), sync.dropped()), (2, 0));
        Ok(())
    }

    // Upstream: ApproxTimeSync.ImperfectMatch.
    //   Input A:  a.xb..c.    Output: ..a...c.
    //   Input B:  .A...B.C            ..A...B.
    #[test]
    fn upstream_imperfect_match() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 1), (0, 2), (0, 3), (1, 5), (0, 6), (1, 7)];
        let (out, sync) = run(2, queue(10), &pushes)?;
        assert_eq!(out.concat(), vec![vec![0, 1], vec![6, 5]]);
        // x and b were passed over for the better set (c, B); B's input lost nothing.
        let a = &sync.drops()[0];
        assert_eq!(
            (a.passed_over, a.total(), a.last),
            (2, 2, Some((secs(3), SyncDropReason::PassedOver)))
        );
        assert_eq!(sync.drops()[1].total(), 0);
        Ok(())
    }

    // Upstream: ApproxTimeSync.Acceleration.
    //   Time:     0123456789012345678
    //   Input A:  a...........b....c.    Output: ............b.....c
    //   Input B:  .......A.......B..C            ............A.....C
    #[test]
    fn upstream_acceleration() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 7), (0, 12), (1, 15), (0, 17), (1, 18)];
        assert_eq!(sets(2, queue(10), &pushes)?, vec![vec![12, 7], vec![17, 18]]);
        Ok(())
    }

    // Upstream: ApproxTimeSync.DroppedMessages, both halves.
    //   Time:     012345678901234
    //   Input A:  a...b...c.d..e.
    //   Input B:  .A.B...C...D..E
    //   Queue size 1 (too small):  Output .......b.....d.   Queue size 2:  ....a..b...c.d.
    //                                     .......B.....D.                  ....A..B...C.D.
    const DROPPED_MESSAGES: [(usize, i64); 10] =
        [(0, 0), (1, 1), (1, 3), (0, 4), (1, 7), (0, 8), (0, 10), (1, 11), (0, 13), (1, 14)];

    #[test]
    fn upstream_dropped_messages_queue_too_small() -> Result<(), SyncError> {
        let (out, sync) = run(2, queue(1), &DROPPED_MESSAGES)?;
        assert_eq!(out.concat(), vec![vec![4, 3], vec![10, 11]]);
        // Every item is emitted, held or counted as dropped.
        assert_eq!(4 + sync.queued() + sync.dropped() as usize, DROPPED_MESSAGES.len());
        assert!(sync.dropped() > 0);
        Ok(())
    }

    #[test]
    fn upstream_dropped_messages_queue_just_enough() -> Result<(), SyncError> {
        let out = sets(2, queue(2), &DROPPED_MESSAGES)?;
        assert_eq!(out, vec![vec![0, 1], vec![4, 3], vec![8, 7], vec![10, 11]]);
        Ok(())
    }

    // Upstream: ApproxTimeSync.LongQueue (queue size 5).
    //   Time:     012345678901234
    //   Input A:  abcdefghiklmnp.    Output: ..........l....
    //   Input B:  ...j......o....            ..........o....
    #[test]
    fn upstream_long_queue() -> Result<(), SyncError> {
        let mut pushes: Vec<(usize, i64)> = (0..=8).map(|t| (0, t)).collect();
        pushes.push((1, 3));
        pushes.extend((9..=12).map(|t| (0, t)));
        pushes.extend([(1, 10), (0, 13)]);
        let (out, sync) = run(2, queue(5), &pushes)?;
        assert_eq!(out.concat(), vec![vec![10, 10]]);
        assert_eq!(2 + sync.queued() + sync.dropped() as usize, pushes.len());
        Ok(())
    }

    // Upstream: ApproxTimeSync.DoublePublish.
    //   Input A:  a..b    Output: ...b + a
    //   Input B:  .A.B            ...B   A
    #[test]
    fn upstream_double_publish() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 1), (1, 3), (0, 3)];
        let (out, _) = run(2, queue(10), &pushes)?;
        // Both sets are decided by the last push, and come out in valid-time order.
        assert_eq!(out[3], vec![vec![0, 1], vec![3, 3]]);
        assert!(out[..3].iter().all(Vec::is_empty));
        Ok(())
    }

    // Upstream: ApproxTimeSync.FourTopics.
    //   Time:     012345678901234
    //   Input A:  a....e..i.m..n.    Output: ......a....e..m
    //   Input B:  .b....g..j....o            ......b....g..j
    //   Input C:  ..c...h...k....            ......c....h..k
    //   Input D:  ...d.f.....l...            ......d....f..l
    // (m, stamped 10, arrives after l, stamped 11: input A is late, not out of order.)
    #[test]
    fn upstream_four_topics() -> Result<(), SyncError> {
        let pushes = [
            (0, 0),
            (1, 1),
            (2, 2),
            (3, 3),
            (0, 5),
            (3, 5),
            (1, 6),
            (2, 6),
            (0, 8),
            (1, 9),
            (2, 10),
            (3, 11),
            (0, 10),
            (0, 13),
            (1, 14),
        ];
        let out = sets(4, queue(10), &pushes)?;
        assert_eq!(out, vec![vec![0, 1, 2, 3], vec![5, 6, 6, 5], vec![10, 9, 10, 11]]);
        Ok(())
    }

    // Upstream: ApproxTimeSync.EarlyPublish.
    //   Time:     01234567
    //   Input A:  a......e    Output: .......a (b, c, d)
    //   Input B:  .b......
    //   Input C:  ..c.....
    //   Input D:  ...d....
    #[test]
    fn upstream_early_publish() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 1), (2, 2), (3, 3), (0, 7)];
        let (out, _) = run(4, queue(10), &pushes)?;
        assert_eq!(out[4], vec![vec![0, 1, 2, 3]]);
        assert_eq!(out.concat().len(), 1);
        Ok(())
    }

    // Upstream: ApproxTimeSync.RateBound, both halves.
    //   Input A:  a..b..c.    Rate bound A 1.5 s: Output .a..b...    2 s: .a..b..c
    //   Input B:  .A..B..C                               .A..B...         .A..B..C
    const RATE_BOUND: [(usize, i64); 6] = [(0, 0), (1, 1), (0, 3), (1, 4), (0, 6), (1, 7)];

    #[test]
    fn upstream_rate_bound_too_loose_to_prove_the_last_set() -> Result<(), SyncError> {
        let config = queue(10).inter_message_lower_bound(0, secs(3) / 2);
        let (out, _) = run(2, config, &RATE_BOUND)?;
        assert_eq!(out.concat(), vec![vec![0, 1], vec![3, 4]]);
        // A next item of A 1.5 s after a could still pair with A more tightly than a
        // does, so the bound proves nothing: each set waits for the next item of A, as
        // without a bound. (The upstream diagram's output row is drawn one column early;
        // the upstream test checks only the sets.)
        assert_eq!(out[2], vec![vec![0, 1]]);
        assert_eq!(out[4], vec![vec![3, 4]]);
        Ok(())
    }

    #[test]
    fn upstream_rate_bound_proves_every_set() -> Result<(), SyncError> {
        let config = queue(10).inter_message_lower_bound(0, secs(2));
        let (out, _) = run(2, config, &RATE_BOUND)?;
        assert_eq!(out.concat(), vec![vec![0, 1], vec![3, 4], vec![6, 7]]);
        // With 2 s, every set is proven best by its own last item.
        assert_eq!(out[1], vec![vec![0, 1]]);
        assert_eq!(out[3], vec![vec![3, 4]]);
        assert_eq!(out[5], vec![vec![6, 7]]);
        Ok(())
    }

    // esgm's own: three inputs, the PerfectMatch pattern.
    //   Input A:  a...b...c..    Output: ....a...b..
    //   Input B:  .A...B...C.            ....A...B..
    //   Input C:  ..x...y...z            ....x...y..
    const THREE: [(usize, i64); 9] =
        [(0, 0), (1, 1), (2, 2), (0, 4), (1, 5), (2, 6), (0, 8), (1, 9), (2, 10)];

    #[test]
    fn three_inputs() -> Result<(), SyncError> {
        let (out, sync) = run(3, queue(10), &THREE)?;
        assert_eq!(out.concat(), vec![vec![0, 1, 2], vec![4, 5, 6]]);
        assert_eq!(out[3], vec![vec![0, 1, 2]]);
        assert_eq!(out[6], vec![vec![4, 5, 6]]);
        assert_eq!((sync.queued(), sync.dropped()), (3, 0));
        Ok(())
    }

    // esgm's own: the same with lower bounds on every input; each set is proven best by
    // its last item, including the final one.
    #[test]
    fn three_inputs_with_lower_bounds() -> Result<(), SyncError> {
        let config = (0..3).fold(queue(10), |c, input| c.inter_message_lower_bound(input, secs(4)));
        let (out, sync) = run(3, config, &THREE)?;
        assert_eq!(out.concat(), vec![vec![0, 1, 2], vec![4, 5, 6], vec![8, 9, 10]]);
        assert_eq!(out[2], vec![vec![0, 1, 2]]);
        assert_eq!(out[5], vec![vec![4, 5, 6]]);
        assert_eq!(out[8], vec![vec![8, 9, 10]]);
        assert_eq!((sync.queued(), sync.dropped()), (0, 0));
        Ok(())
    }

    // esgm's own: arrival order across inputs does not change the sets (wiki property 6).
    #[test]
    fn arrival_order_across_inputs_does_not_matter() -> Result<(), SyncError> {
        let one_input_first = [(0, 0), (0, 3), (0, 6), (1, 1), (1, 4), (1, 7)];
        assert_eq!(sets(2, queue(10), &one_input_first)?, vec![vec![0, 1], vec![3, 4]]);
        Ok(())
    }

    // esgm's own: the tolerance rejects sets wider than the tolerance.
    //   Input A:  a.........b    no tolerance: (a, A) then (b, B)
    //   Input B:  ...A......B    tolerance 1 s: (b, B) only; a and A are dropped
    #[test]
    fn tolerance_rejects_wide_sets() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 3), (0, 10), (1, 10)];
        assert_eq!(sets(2, queue(10), &pushes)?, vec![vec![0, 3], vec![10, 10]]);

        let (out, sync) = run(2, queue(10).tolerance(secs(1)), &pushes)?;
        assert_eq!(out.concat(), vec![vec![10, 10]]);
        assert_eq!((sync.queued(), sync.dropped()), (0, 2));
        Ok(())
    }

    // esgm's own: a set exactly as wide as the tolerance is kept.
    #[test]
    fn tolerance_is_inclusive() -> Result<(), SyncError> {
        let pushes = [(0, 0), (1, 1), (0, 5), (1, 6)];
        let out = sets(2, queue(10).tolerance(secs(1)), &pushes)?;
        assert_eq!(out, vec![vec![0, 1]]);
        Ok(())
    }

    // esgm's own: the age penalty (message_filters' default 0.1) prefers the earlier set
    // when a later one is only slightly smaller.
    //   Input A:  a(0 s) ....... b(19.5 s)
    //   Input B:  ........ A(10 s)
    #[test]
    fn age_penalty_prefers_earlier_sets() -> Result<(), SyncError> {
        let feed = |config: ApproximateConfig| -> Result<(Vec<Vec<Time>>, u64), SyncError> {
            let mut sync = ApproximateSync::new(2, config)?;
            let mut out = sync.push(0, 0)?;
            out.extend(sync.push(1, secs(10))?);
            out.extend(sync.push(0, secs(19) + secs(1) / 2)?);
            Ok((out, sync.dropped()))
        };
        assert_eq!(feed(queue(10))?, (vec![vec![0, secs(10)]], 0));
        assert_eq!(
            feed(queue(10).age_penalty(0.0))?,
            (vec![vec![secs(19) + secs(1) / 2, secs(10)]], 1)
        );
        Ok(())
    }

    #[test]
    fn one_input_passes_items_through() -> Result<(), SyncError> {
        let out = sets(1, queue(1), &[(0, 1), (0, 2), (0, 3)])?;
        assert_eq!(out, vec![vec![1], vec![2], vec![3]]);
        Ok(())
    }

    #[test]
    fn an_unknown_input_is_refused_without_change() -> Result<(), SyncError> {
        let mut sync = ApproximateSync::<Time>::new(2, queue(10))?;
        assert_eq!(sync.push(5, 1), Err(SyncError::NoSuchInput { input: 5, inputs: 2 }));
        assert_eq!((sync.queued(), sync.dropped()), (0, 0));
        Ok(())
    }

    /// Random streams: per input, strictly increasing stamps (in ms) with random gaps.
    fn streams(inputs: usize) -> impl Strategy<Value = Vec<Vec<i64>>> {
        prop::collection::vec(prop::collection::vec(1i64..400, 0..12), inputs).prop_map(|gaps| {
            gaps.into_iter()
                .map(|g| {
                    g.into_iter()
                        .scan(0, |t, gap| {
                            *t += gap;
                            Some(*t)
                        })
                        .collect()
                })
                .collect()
        })
    }

    /// Interleaves the streams in the order `picks` chooses, keeping each input's order.
    fn interleave(streams: &[Vec<i64>], picks: &[usize]) -> Vec<(usize, i64)> {
        let mut next = vec![0; streams.len()];
        let mut out = Vec::new();
        let mut picks = picks.iter().cycle();
        while out.len() < streams.iter().map(Vec::len).sum() {
            let pick = picks.next().copied().unwrap_or(0);
            let Some(input) = (0..streams.len())
                .map(|k| (pick + k) % streams.len())
                .find(|&i| next[i] < streams[i].len())
            else {
                break;
            };
            out.push((input, streams[input][next[input]]));
            next[input] += 1;
        }
        out
    }

    fn feed_ms(
        inputs: usize,
        config: ApproximateConfig,
        pushes: &[(usize, i64)],
    ) -> Result<(Vec<Vec<Time>>, ApproximateSync<Time>), SyncError> {
        let mut sync = ApproximateSync::new(inputs, config)?;
        let mut out = Vec::new();
        for &(input, ms) in pushes {
            out.extend(sync.push(input, crate::millis(ms))?);
        }
        Ok((out, sync))
    }

    proptest! {
        // The wiki's properties, on random input: sets are complete, do not cross, respect
        // the tolerance, every item is accounted for, and the sets do not depend on the
        // order of arrival across inputs (one run's sets are a prefix of the other's,
        // since a run may have decided more by the end).
        #[test]
        fn sets_are_well_formed_and_independent_of_arrival_order(
            data in (2usize..5).prop_flat_map(streams),
            picks_a in prop::collection::vec(0usize..5, 1..40),
            picks_b in prop::collection::vec(0usize..5, 1..40),
            tolerance in prop::option::of(0i64..300),
            age_penalty in prop::sample::select(vec![0.0, 0.1, 0.5]),
        ) {
            let inputs = data.len();
            let mut config = queue(64).age_penalty(age_penalty);
            if let Some(t) = tolerance {
                config = config.tolerance(crate::millis(t));
            }
            let total: usize = data.iter().map(Vec::len).sum();
            let run_a = feed_ms(inputs, config.clone(), &interleave(&data, &picks_a));
            let run_b = feed_ms(inputs, config, &interleave(&data, &picks_b));
            let ((a, sync_a), (b, _)) = match (run_a, run_b) {
                (Ok(a), Ok(b)) => (a, b),
                (Err(e), _) | (_, Err(e)) => return Err(TestCaseError::fail(e.to_string())),
            };
            for set in &a {
                prop_assert_eq!(set.len(), inputs);
                let span = set.iter().max().copied().unwrap_or(0) - set.iter().min().copied().unwrap_or(0);
                if let Some(t) = tolerance {
                    prop_assert!(span <= crate::millis(t));
                }
            }
            for pair in a.windows(2) {
                prop_assert!(pair[0].iter().zip(&pair[1]).all(|(x, y)| x < y), "sets cross: {:?}", pair);
            }
            prop_assert_eq!(a.len() * inputs + sync_a.queued() + sync_a.dropped() as usize, total);
            // Each drop is counted once, on its input, for one reason.
            let per_input: u64 = sync_a.drops().iter().map(InputDrops::total).sum();
            prop_assert_eq!(per_input, sync_a.dropped());
            let held: usize = (0..inputs).map(|i| Synchronizer::queued_on(&sync_a, i)).sum();
            prop_assert_eq!(held, sync_a.queued());
            let common = a.len().min(b.len());
            prop_assert_eq!(&a[..common], &b[..common]);
        }
    }
}
