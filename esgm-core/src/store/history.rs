//! The samples a trajectory holds, indexed both by add order and by valid time.
//!
//! Streams are ordered by add time (Definition 3.3.9), but queries are by valid time.
//! In the common case (a monotone stream) the two orders agree and one `VecDeque` in
//! add order answers both: time lookups binary-search it, so they are O(log n) with a
//! million samples and eviction is O(1). Only when a sample arrives out of valid-time
//! order (possible under `OrderConstraint::Any`) is a `BTreeMap` index on
//! (valid time, add sequence) built, once, and kept from then on.

use std::collections::{BTreeMap, VecDeque};
use std::ops::Bound;
use std::sync::Arc;

use crate::structure::SharedStructure;
use crate::time::Time;

/// One stored sample: the shared structure, when it entered, and its add sequence
/// number (strictly increasing; ties in valid time are broken by it).
#[derive(Debug, Clone)]
pub(crate) struct Entry {
    /// The structure's valid time, kept inline: binary searches read it for every
    /// probe, and reading it through the `Arc` costs a cache miss each on a large
    /// history.
    pub vt: Time,
    pub es: SharedStructure,
    pub add_time: Time,
    pub seq: u64,
    /// The inputs it was made from (a produced structure's; see [`crate::lineage`]).
    pub lineage: Option<Arc<crate::lineage::Lineage>>,
}

impl Entry {
    fn key(&self) -> (Time, u64) {
        (self.vt, self.seq)
    }
}

#[derive(Debug, Default)]
pub(crate) struct History {
    /// Add order; `seq` strictly increasing front to back.
    entries: VecDeque<Entry>,
    /// Present once the add order stopped being valid-time order.
    index: Option<BTreeMap<(Time, u64), Entry>>,
}

impl History {
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn clear(&mut self) {
        self.entries.clear();
        self.index = None;
    }

    pub fn push(&mut self, e: Entry) {
        if let Some(index) = &mut self.index {
            index.insert(e.key(), e.clone());
        } else if self.entries.back().is_some_and(|b| b.vt > e.vt) {
            let mut index: BTreeMap<_, _> =
                self.entries.iter().map(|x| (x.key(), x.clone())).collect();
            index.insert(e.key(), e.clone());
            self.index = Some(index);
        }
        self.entries.push_back(e);
    }

    /// Removes the oldest sample in add order.
    pub fn pop_oldest(&mut self) -> Option<Entry> {
        let e = self.entries.pop_front()?;
        if let Some(index) = &mut self.index {
            index.remove(&e.key());
        }
        self.maybe_drop_index();
        Some(e)
    }

    /// Removes every sample whose valid time is before `min_valid_time`, smallest valid
    /// time first; returns how many went.
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
                while let Some(entry) = index.first_entry() {
                    if entry.key().0 >= min_valid_time {
                        break;
                    }
                    let seq = entry.key().1;
                    entry.remove();
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

    fn maybe_drop_index(&mut self) {
        if self.entries.is_empty() {
            self.index = None;
        }
    }

    /// The `n`-th latest sample in add order (0 = latest).
    pub fn nth_latest(&self, n: usize) -> Option<&Entry> {
        let len = self.entries.len();
        if n >= len { None } else { self.entries.get(len - 1 - n) }
    }

    /// The last `n` samples in add order, oldest first.
    pub fn last_n(&self, n: usize) -> impl Iterator<Item = &Entry> {
        self.entries.iter().skip(self.entries.len().saturating_sub(n))
    }

    /// All samples in add order.
    pub fn iter(&self) -> impl Iterator<Item = &Entry> {
        self.entries.iter()
    }

    /// Smallest valid time held.
    pub fn min_valid_time(&self) -> Option<Time> {
        match &self.index {
            None => self.entries.front().map(|e| e.vt),
            Some(index) => index.keys().next().map(|k| k.0),
        }
    }

    /// Largest valid time held.
    pub fn max_valid_time(&self) -> Option<Time> {
        match &self.index {
            None => self.entries.back().map(|e| e.vt),
            Some(index) => index.keys().next_back().map(|k| k.0),
        }
    }

    /// Samples with valid time in `[from, to]`, in (valid time, add order) order.
    pub fn between(&self, from: Time, to: Time) -> Vec<&Entry> {
        if from > to {
            return Vec::new();
        }
        match &self.index {
            None => {
                let lo = self.entries.partition_point(|e| e.vt < from);
                let hi = self.entries.partition_point(|e| e.vt <= to);
                self.entries.range(lo..hi).collect()
            }
            Some(index) => index.range((from, 0)..=(to, u64::MAX)).map(|(_, e)| e).collect(),
        }
    }

    /// The sample with the largest valid time ≤ `t` (the latest added among equals).
    pub fn at_or_before(&self, t: Time) -> Option<&Entry> {
        match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt <= t);
                i.checked_sub(1).and_then(|i| self.entries.get(i))
            }
            Some(index) => index.range(..=(t, u64::MAX)).next_back().map(|(_, e)| e),
        }
    }

    /// The sample with the largest valid time < `t`.
    pub fn before(&self, t: Time) -> Option<&Entry> {
        match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt < t);
                i.checked_sub(1).and_then(|i| self.entries.get(i))
            }
            Some(index) => {
                index.range((Bound::Unbounded, Bound::Excluded((t, 0)))).next_back().map(|(_, e)| e)
            }
        }
    }

    /// The sample with the smallest valid time > `t` (the latest added among equals).
    pub fn after(&self, t: Time) -> Option<&Entry> {
        let first = match &self.index {
            None => {
                let i = self.entries.partition_point(|e| e.vt <= t);
                self.entries.get(i)?.vt
            }
            Some(index) => index.range((t, u64::MAX)..).find(|(k, _)| k.0 > t)?.0.0,
        };
        self.at_or_before(first)
    }

    /// Every sample with valid time exactly `t`, in add order.
    pub fn exactly_at(&self, t: Time) -> Vec<&Entry> {
        self.between(t, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(vt: Time, seq: u64) -> Entry {
        Entry {
            vt,
            es: crate::value::frame::EntityStructure::new("e", vt, vt).into(),
            add_time: seq as Time,
            seq,
            lineage: None,
        }
    }

    fn vts(v: &[&Entry]) -> Vec<(Time, u64)> {
        v.iter().map(|e| (e.vt, e.seq)).collect()
    }

    /// Runs the same assertions in sorted mode and in index mode.
    fn both_modes(f: impl Fn(&History)) {
        let mut sorted = History::default();
        for (i, vt) in [10, 20, 20, 30, 40].into_iter().enumerate() {
            sorted.push(entry(vt, i as u64));
        }
        assert!(sorted.index.is_none());
        f(&sorted);
        // Same content arriving out of order forces the index.
        let mut indexed = History::default();
        for (vt, seq) in [(20, 1), (10, 0), (30, 3), (20, 2), (40, 4)] {
            indexed.push(entry(vt, seq));
        }
        assert!(indexed.index.is_some());
        f(&indexed);
    }

    #[test]
    fn time_lookups_agree_in_both_modes() {
        both_modes(|h| {
            assert_eq!(h.at_or_before(20).map(|e| e.seq), Some(2));
            assert_eq!(h.at_or_before(25).map(|e| e.seq), Some(2));
            assert_eq!(h.at_or_before(9).map(|e| e.seq), None);
            assert_eq!(h.before(20).map(|e| e.seq), Some(0));
            assert_eq!(h.after(20).map(|e| e.seq), Some(3));
            assert_eq!(h.after(40).map(|e| e.seq), None);
            assert_eq!(vts(&h.between(15, 30)), vec![(20, 1), (20, 2), (30, 3)]);
            assert_eq!(vts(&h.between(30, 15)), vec![]);
            assert_eq!(vts(&h.exactly_at(20)), vec![(20, 1), (20, 2)]);
            assert_eq!(h.min_valid_time(), Some(10));
            assert_eq!(h.max_valid_time(), Some(40));
        });
    }

    #[test]
    fn eviction_keeps_both_orders_consistent() {
        let mut h = History::default();
        for (vt, seq) in [(20, 0), (10, 1), (30, 2), (25, 3)] {
            h.push(entry(vt, seq));
        }
        assert_eq!(h.remove_older_than(21), 2);
        assert_eq!(h.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![2, 3]);
        assert_eq!(h.min_valid_time(), Some(25));
        assert_eq!(h.pop_oldest().map(|e| e.seq), Some(2));
        assert_eq!(h.nth_latest(0).map(|e| e.seq), Some(3));
        assert_eq!(h.pop_oldest().map(|e| e.seq), Some(3));
        assert!(h.is_empty() && h.index.is_none());
    }
}
