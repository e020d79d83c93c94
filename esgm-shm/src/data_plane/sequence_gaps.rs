//! Counting lost records per publisher.
//!
//! Every publisher numbers what it sends 0, 1, 2, …; a subscriber that sees a number
//! jump knows how many of that publisher's records it missed (overwritten in its queue
//! while it was not reading). A service may have several publishers — a writer that
//! restarted, or another process that opened it — whose numbers interleave, so the next expected number is kept per publisher, keyed by iceoryx2's
//! id of the publishing port. A number smaller than expected is a restarted numbering,
//! not a loss.

use std::collections::HashMap;
use std::hash::Hash;

use iceoryx2::identifiers::UniquePublisherId;

/// Publishers remembered at most; past this the memory starts afresh (a trajectory
/// with that many publishers over its life loses one round of gap detection, nothing
/// else).
const MAX_PUBLISHERS: usize = 1024;

/// The next expected sequence number of every publisher seen, keyed by `P` (iceoryx2's
/// port id); see the module docs.
#[derive(Debug)]
pub(crate) struct SequenceGaps<P = UniquePublisherId> {
    next: HashMap<P, u64>,
}

impl<P> Default for SequenceGaps<P> {
    fn default() -> Self {
        Self { next: HashMap::new() }
    }
}

impl<P: Eq + Hash> SequenceGaps<P> {
    /// Notes sample `sequence` of `publisher`; returns how many of its samples were
    /// skipped since the previous one seen.
    pub(crate) fn observe(&mut self, publisher: P, sequence: u64) -> u64 {
        let lost =
            self.next.get(&publisher).map_or(0, |&expected| sequence.saturating_sub(expected));
        self.expect_after(publisher, sequence);
        lost
    }

    /// The next sample of `publisher` should follow `sequence` (e.g. a reset marker
    /// took that number).
    pub(crate) fn expect_after(&mut self, publisher: P, sequence: u64) {
        if self.next.len() >= MAX_PUBLISHERS && !self.next.contains_key(&publisher) {
            self.next.clear();
        }
        self.next.insert(publisher, sequence.wrapping_add(1));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn losses_are_counted_per_publisher_when_two_interleave() {
        let mut gaps = SequenceGaps::<char>::default();
        // Each numbers its own records from 0: interleaved, nothing is missing.
        let interleaved = [('a', 0), ('b', 0), ('a', 1), ('b', 1), ('a', 2)];
        assert!(interleaved.iter().all(|&(p, s)| gaps.observe(p, s) == 0));
        // Then b skips two of its numbers: two lost, whatever a did meanwhile.
        assert_eq!(gaps.observe('b', 4), 2);
        assert_eq!(gaps.observe('a', 3), 0);
    }

    #[test]
    fn a_restarted_numbering_and_extreme_numbers_are_not_losses_or_panics() {
        let mut gaps = SequenceGaps::<char>::default();
        assert_eq!(gaps.observe('a', 10), 0, "the first record seen is no gap");
        assert_eq!(gaps.observe('a', 0), 0, "numbering started again");
        assert_eq!(gaps.observe('a', u64::MAX - 1), u64::MAX - 2);
        assert_eq!(gaps.observe('a', u64::MAX), 0);
        // The next expected number wrapped to 0: anything after it counts from there.
        assert_eq!(gaps.observe('a', 3), 3);
        // A reset marker takes a number: the sample after it is no gap.
        gaps.expect_after('a', 7);
        assert_eq!(gaps.observe('a', 8), 0);
    }
}
