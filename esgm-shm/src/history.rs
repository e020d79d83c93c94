//! A trajectory's history as a reader keeps it: samples still in shared memory,
//! indexed by the times in their headers, evicted by the policy's cache constraint.
//!
//! # How many samples
//! The cache constraint (C2) decides what a trajectory keeps, and iceoryx2 needs a
//! number up front (its history size and the samples a subscriber may hold). So one
//! bound serves every process of the trajectory ([`history_bound`]):
//! - `Elements(n)` keeps `n`: the publisher's history is `n`, a late reader gets the
//!   last `n`, exactly what an in-process store would hold;
//! - `All` and `Duration(t)` keep at most a configured maximum
//!   ([`DEFAULT_MAX_HISTORY`] = 1024 unless set): shared memory is allocated up front,
//!   so "everything" must have a number. Beyond it the oldest sample in add order goes
//!   first, counted apart from policy evictions so a too small maximum shows.
//!
//! [`history_qos`] turns the bound into the service settings; writer and readers derive
//! them from the same policy and maximum, so whoever comes first creates a service the
//! others can open.
//!
//! Memory, measured: a writer of small structures with an `All` cache and the defaults
//! (bound 1024, 8 readers, 4 KiB samples) maps a 73 MB segment in `/dev/shm` but
//! commits 0.1 MB at start; with one reader holding 1024 samples, 9 MB (the samples and
//! that reader's 1024-deep queue). Image trajectories want an `Elements(n)` cache and
//! fewer `max_subscribers`; through `connect`, a trajectory of octets without an
//! element cache keeps only the last 16 for other processes (with a warning), since
//! 1024 camera frames would reserve gigabytes.
//!
//! # Lookups by header times
//! Queries are by valid time, but the history is in add order. When the two agree (any
//! monotone stream) one deque answers both, with binary searches over the valid times
//! copied from the headers; only a sample arriving out of valid-time order builds an
//! ordered index, once. This is the in-process store's history
//! (`esgm_core::store`), rebuilt over items that cannot be cloned: the index holds keys
//! and finds its entry by a binary search on the arrival number.

use std::collections::{BTreeSet, VecDeque};
use std::ops::Bound;

use esgm_core::{CacheConstraint, Time};

use crate::qos::TrajectoryQos;

/// The history kept for `CacheConstraint::All` and `CacheConstraint::Duration` when no
/// other maximum is configured.
pub const DEFAULT_MAX_HISTORY: usize = 1024;

/// How many samples the history of a trajectory whose cache constraint is `cache` may
/// hold: `n` for `Elements(n)`, `max_history` for every other constraint (including
/// `Elements(0)`, which means all). At least 1.
pub fn history_bound(cache: CacheConstraint, max_history: usize) -> usize {
    match cache {
        CacheConstraint::Elements(n) if n > 0 => n,
        _ => max_history.max(1),
    }
}

/// The service settings of a trajectory whose history keeps `bound` samples
/// ([`history_bound`]), starting from `base` for everything else.
///
/// The publisher keeps `bound` samples for late readers; each reader may hold `bound`
/// samples plus the one it is receiving; a reader's queue holds at least `bound` so
/// that the whole history fits when it connects. Queue and held samples only grow from
/// `base`, so a plain [`crate::TrajectorySubscriber`] with `base` settings (e.g. a unit
/// that needs no history) can still open the service.
pub fn history_qos(bound: usize, base: TrajectoryQos) -> TrajectoryQos {
    TrajectoryQos {
        history_size: bound,
        subscriber_buffer_size: base.subscriber_buffer_size.max(bound),
        max_borrowed_samples: base.max_borrowed_samples.max(bound + 1),
        ..base
    }
}

/// One stored item with the keys lookups need.
#[derive(Debug)]
pub(crate) struct Entry<T> {
    /// Valid time, from the header.
    pub vt: Time,
    /// Arrival number, strictly increasing; breaks ties in valid time.
    pub seq: u64,
    pub item: T,
}

/// Items in arrival (add) order, searchable by valid time.
#[derive(Debug)]
pub(crate) struct History<T> {
    entries: VecDeque<Entry<T>>,
    /// (valid time, arrival number) of every entry, present once the arrival order
    /// stopped being valid-time order.
    index: Option<BTreeSet<(Time, u64)>>,
    next_seq: u64,
}

impl<T> Default for History<T> {
    fn default() -> Self {
        Self { entries: VecDeque::new(), index: None, next_seq: 0 }
    }
}

/// What one eviction pass removed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Evicted {
    /// By the cache constraint itself.
    pub by_policy: usize,
    /// Beyond the bound of an `All` or `Duration` cache.
    pub by_bound: usize,
}

impl<T> History<T> {
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Appends `item`, valid at `vt`, as the latest in add order.
    pub fn push(&mut self, vt: Time, item: T) {
        let seq = self.next_seq;
        self.next_seq += 1;
        if let Some(index) = &mut self.index {
            index.insert((vt, seq));
        } else if self.entries.back().is_some_and(|b| b.vt > vt) {
            let mut index: BTreeSet<_> = self.entries.iter().map(|e| (e.vt, e.seq)).collect();
            index.insert((vt, seq));
            self.index = Some(index);
        }
        self.entries.push_back(Entry { vt, seq, item });
    }

    /// Removes the oldest item in add order.
    pub fn pop_oldest(&mut self) -> Option<T> {
        let e = self.entries.pop_front()?;
        if let Some(index) = &mut self.index {
            index.remove(&(e.vt, e.seq));
        }
        self.maybe_drop_index();
        Some(e.item)
    }

    /// Removes every item valid before `min_valid_time`; returns how many went.
    pub fn remove_older_than(&mut self, min_valid_time: Time) -> usize {
        let mut n = 0;
        match &mut self.index {
            None => {
                while self.entries.front().is_some_and(|e| e.vt < min_valid_time) {
                    self.entries.pop_front();
                    n += 1;
                }
            }
            Some(index) => {
                while let Some(&(vt, seq)) = index.first() {
                    if vt >= min_valid_time {
                        break;
                    }
                    index.pop_first();
                    if let Ok(pos) = self.entries.binary_search_by_key(&seq, |e| e.seq) {
                        self.entries.remove(pos);
                    }
                    n += 1;
                }
            }
        }
        self.maybe_drop_index();
        n
    }

    /// Applies the cache constraint `cache` and then `bound` (see the module docs).
    pub fn evict(&mut self, cache: CacheConstraint, bound: usize) -> Evicted {
        let mut evicted = Evicted::default();
        match cache {
            CacheConstraint::All | CacheConstraint::Elements(0) => {}
            CacheConstraint::Elements(n) => {
                while self.len() > n && self.pop_oldest().is_some() {
                    evicted.by_policy += 1;
                }
            }
            // The same window as the in-process store: valid times less than `t`
            // before the newest stay.
            CacheConstraint::Duration(t) => {
                if let Some(newest) = self.max_valid_time() {
                    evicted.by_policy = self.remove_older_than(newest.saturating_sub(t) + 1);
                }
            }
        }
        while self.len() > bound && self.pop_oldest().is_some() {
            evicted.by_bound += 1;
        }
        evicted
    }

    fn maybe_drop_index(&mut self) {
        if self.entries.is_empty() {
            self.index = None;
        }
    }

    fn by_seq(&self, seq: u64) -> Option<&Entry<T>> {
        let pos = self.entries.binary_search_by_key(&seq, |e| e.seq).ok()?;
        self.entries.get(pos)
    }

    /// The `n`-th latest item in add order (0 = latest).
    pub fn nth_latest(&self, n: usize) -> Option<&Entry<T>> {
        let len = self.entries.len();
        if n >= len { None } else { self.entries.get(len - 1 - n) }
    }

    /// All items in add order.
    pub fn iter(&self) -> impl DoubleEndedIterator<Item = &Entry<T>> {
        self.entries.iter()
    }

    /// Smallest valid time held.
    pub fn min_valid_time(&self) -> Option<Time> {
        match &self.index {
            None => self.entries.front().map(|e| e.vt),
            Some(index) => index.first().map(|k| k.0),
        }
    }

    /// Largest valid time held.
    pub fn max_valid_time(&self) -> Option<Time> {
        match &self.index {
            None => self.entries.back().map(|e| e.vt),
            Some(index) => index.last().map(|k| k.0),
        }
    }

    /// Items valid in `[from, to]`, by (valid time, add order).
    pub fn between(&self, from: Time, to: Time) -> Vec<&Entry<T>> {
        if from > to {
            return Vec::new();
        }
        match &self.index {
            None => {
                let lo = self.entries.partition_point(|e| e.vt < from);
                let hi = self.entries.partition_point(|e| e.vt <= to);
                self.entries.range(lo..hi).collect()
            }
            Some(index) => {
                index.range((from, 0)..=(to, u64::MAX)).filter_map(|k| self.by_seq(k.1)).collect()
            }
        }
    }

    /// The item with the largest valid time ≤ `t` (the latest added among equals).
    pub fn at_or_before(&self, t: Time) -> Option<&Entry<T>> {
        match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt <= t);
                i.checked_sub(1).and_then(|i| self.entries.get(i))
            }
            Some(index) => index.range(..=(t, u64::MAX)).next_back().and_then(|k| self.by_seq(k.1)),
        }
    }

    /// The item with the largest valid time < `t` (the latest added among equals).
    pub fn before(&self, t: Time) -> Option<&Entry<T>> {
        match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt < t);
                i.checked_sub(1).and_then(|i| self.entries.get(i))
            }
            Some(index) => index
                .range((Bound::Unbounded, Bound::Excluded((t, 0))))
                .next_back()
                .and_then(|k| self.by_seq(k.1)),
        }
    }

    /// The item with the smallest valid time > `t` (the latest added among equals).
    pub fn after(&self, t: Time) -> Option<&Entry<T>> {
        let first = match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt <= t);
                self.entries.get(i)?.vt
            }
            Some(index) => index.range((t, u64::MAX)..).find(|k| k.0 > t)?.0,
        };
        self.at_or_before(first)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seqs(v: &[&Entry<u32>]) -> Vec<u32> {
        v.iter().map(|e| e.item).collect()
    }

    fn item(e: Option<&Entry<u32>>) -> Option<u32> {
        e.map(|e| e.item)
    }

    /// The same assertions on a history in valid-time order and on one whose items
    /// arrived out of order (which builds the index). Items are named by add order.
    fn both_modes(f: impl Fn(&History<u32>)) {
        let mut sorted = History::default();
        for (i, vt) in [10, 20, 20, 30, 40].into_iter().enumerate() {
            sorted.push(vt, i as u32);
        }
        assert!(sorted.index.is_none());
        f(&sorted);
        // Same (valid time, add order) pairs, but arriving out of valid-time order.
        let mut indexed = History::default();
        for (vt, name) in [(20, 1), (10, 0), (20, 2), (30, 3), (40, 4)] {
            indexed.push(vt, name);
        }
        assert!(indexed.index.is_some());
        f(&indexed);
    }

    #[test]
    fn time_lookups_agree_in_both_modes() {
        both_modes(|h| {
            assert_eq!(item(h.at_or_before(20)), Some(2));
            assert_eq!(item(h.at_or_before(25)), Some(2));
            assert_eq!(item(h.at_or_before(9)), None);
            assert_eq!(item(h.before(20)), Some(0));
            assert_eq!(item(h.after(20)), Some(3));
            assert_eq!(item(h.after(40)), None);
            assert_eq!(seqs(&h.between(15, 30)), vec![1, 2, 3]);
            assert!(h.between(30, 15).is_empty());
            assert_eq!(h.min_valid_time(), Some(10));
            assert_eq!(h.max_valid_time(), Some(40));
        });
    }

    #[test]
    fn cache_constraints_evict_like_the_store() {
        let mut h = History::default();
        for (i, vt) in [10, 20, 30, 40, 50].into_iter().enumerate() {
            h.push(vt, i as u32);
        }
        assert_eq!(h.evict(CacheConstraint::Elements(3), 100).by_policy, 2);
        assert_eq!(h.iter().map(|e| e.item).collect::<Vec<_>>(), vec![2, 3, 4]);
        // Window of 20 below the newest (50): 30 is exactly 20 before, so it goes.
        assert_eq!(h.evict(CacheConstraint::Duration(20), 100).by_policy, 1);
        assert_eq!(h.min_valid_time(), Some(40));
        let e = h.evict(CacheConstraint::All, 1);
        assert_eq!(e, Evicted { by_policy: 0, by_bound: 1 });
        assert_eq!(item(h.nth_latest(0)), Some(4));
    }

    #[test]
    fn eviction_keeps_both_orders_consistent() {
        let mut h = History::default();
        for (vt, name) in [(20, 0), (10, 1), (30, 2), (25, 3)] {
            h.push(vt, name);
        }
        assert_eq!(h.remove_older_than(21), 2);
        assert_eq!(h.iter().map(|e| e.item).collect::<Vec<_>>(), vec![2, 3]);
        assert_eq!(h.min_valid_time(), Some(25));
        assert_eq!(item(h.at_or_before(29)), Some(3));
        assert_eq!(h.pop_oldest(), Some(2));
        assert_eq!(item(h.nth_latest(0)), Some(3));
        assert_eq!(h.pop_oldest(), Some(3));
        assert!(h.is_empty() && h.index.is_none());
    }

    #[test]
    fn bounds_and_settings() {
        assert_eq!(history_bound(CacheConstraint::Elements(4), 1024), 4);
        assert_eq!(history_bound(CacheConstraint::Elements(0), 16), 16);
        assert_eq!(history_bound(CacheConstraint::All, 0), 1);
        assert_eq!(history_bound(CacheConstraint::Duration(5), 32), 32);
        let base = TrajectoryQos::default();
        let q = history_qos(20, base);
        assert_eq!(
            (q.history_size, q.subscriber_buffer_size, q.max_borrowed_samples),
            (20, 20, 21)
        );
        assert_eq!(q.max_subscribers, base.max_subscribers);
        // Never below the base: plain subscribers with the base settings still fit.
        let q = history_qos(1, base);
        assert_eq!((q.subscriber_buffer_size, q.max_borrowed_samples), (8, 4));
    }
}
