//! Counting lost samples per publisher.
//!
//! Every publisher numbers its samples 0, 1, 2, …; a reader that sees a number jump
//! knows how many of that publisher's samples it missed (overwritten in its queue while
//! it was not reading). A trajectory may have several publishers — two raw
//! [`crate::TrajectoryPublisher`]s, or a writer that restarted — whose numbers
//! interleave, so the next expected number is kept per publisher, keyed by iceoryx2's
//! id of the publishing port. A number smaller than expected is a restarted numbering,
//! not a loss.

use std::collections::HashMap;

use iceoryx2::identifiers::UniquePublisherId;

/// Publishers remembered at most; past this the memory starts afresh (a trajectory
/// with that many publishers over its life loses one round of gap detection, nothing
/// else).
const MAX_PUBLISHERS: usize = 1024;

/// The next expected sequence number of every publisher seen; see the module docs.
#[derive(Debug, Default)]
pub(crate) struct SequenceGaps {
    next: HashMap<UniquePublisherId, u64>,
}

impl SequenceGaps {
    /// Notes sample `sequence` of `publisher`; returns how many of its samples were
    /// skipped since the previous one seen.
    pub(crate) fn observe(&mut self, publisher: UniquePublisherId, sequence: u64) -> u64 {
        let lost =
            self.next.get(&publisher).map_or(0, |&expected| sequence.saturating_sub(expected));
        self.expect_after(publisher, sequence);
        lost
    }

    /// The next sample of `publisher` should follow `sequence` (e.g. a reset marker
    /// took that number).
    pub(crate) fn expect_after(&mut self, publisher: UniquePublisherId, sequence: u64) {
        if self.next.len() >= MAX_PUBLISHERS && !self.next.contains_key(&publisher) {
            self.next.clear();
        }
        self.next.insert(publisher, sequence.wrapping_add(1));
    }
}
