//! Samples kept borrowed because values elsewhere in the process read their bytes in
//! place: how an image received from another process reaches a replica's cache, its
//! units, its subscribers and query answers without being copied.
//!
//! A received sample is decoded with [`codec::decode_holding`]: its small fields are
//! copied (they cost less than bookkeeping), its octet sequences become
//! [`Octets::held`](esgm_core::value::Octets::held) values pointing into the
//! shared-memory chunk. The chunk stays borrowed — the publisher cannot reuse it —
//! until the last such value anywhere in the process is dropped. The iceoryx2 sample
//! itself cannot leave the thread that owns the subscriber, so it stays here, in
//! `Holdings`, and the values carry a `SharedChunk` whose drop sends the sample's
//! key back; `Holdings::collect` then returns the sample to its publisher.
//!
//! Values may outlive the connection that received them (a user keeps an image after
//! dropping its `ShmEsgm`). Their samples are then never returned, and the location
//! keeps their subscribers and its node rather than dropping them — iceoryx2 gives a
//! publisher back every chunk a subscriber held once that subscriber's port or node is
//! gone — until the process exits; the coordinator's dead-node cleanup reclaims them
//! after that.
//!
//! A subscriber may borrow only so many samples at once
//! ([`crate::TrajectoryQos::max_borrowed_samples`]): an owner past its budget, or a
//! sample too small to be worth holding, is copied instead, and the copy is counted.

use std::collections::HashMap;
use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};
use esgm_core::EntityStructure;
use esgm_core::codec::{self, CodecError};
use esgm_core::value::OctetsHolder;

use crate::received::ReceivedSample;

/// Archives smaller than this are copied, never held: holding costs a borrowed chunk
/// (of a limited budget) and a message back at release, which only pays off for large
/// octet sequences such as images.
pub(crate) const HOLD_MIN_BYTES: usize = 16 * 1024;

/// Which subscriber a held sample counts against (each has its own borrow budget).
pub(crate) type OwnerId = u64;

/// What a process holds in shared memory on behalf of its values, and what it had to
/// copy: how to check that images from other processes reach this one without a copy.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HoldingStats {
    /// Received samples borrowed now, because values in this process read their
    /// octets (images) in place.
    pub held_now: usize,
    /// Received samples whose octets were kept in shared memory, since the start.
    pub held_total: u64,
    /// Received samples with large octets that were copied instead, because their
    /// subscriber's borrow budget was spent (values kept too many older ones).
    pub copied_over_budget: u64,
}

/// Samples borrowed on behalf of values elsewhere in the process (see the module docs).
/// Lives on the thread that owns the subscribers.
pub(crate) struct Holdings {
    held: HashMap<u64, (OwnerId, ReceivedSample)>,
    per_owner: HashMap<OwnerId, usize>,
    next_key: u64,
    next_owner: OwnerId,
    release: Sender<u64>,
    released: Receiver<u64>,
    held_total: u64,
    copied_over_budget: u64,
}

impl std::fmt::Debug for Holdings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Holdings")
            .field("held", &self.held.len())
            .field("copied_over_budget", &self.copied_over_budget)
            .finish_non_exhaustive()
    }
}

impl Default for Holdings {
    fn default() -> Self {
        let (release, released) = crossbeam_channel::unbounded();
        Self {
            held: HashMap::new(),
            per_owner: HashMap::new(),
            next_key: 0,
            next_owner: 0,
            release,
            released,
            held_total: 0,
            copied_over_budget: 0,
        }
    }
}

impl Holdings {
    /// A new owner id, for a subscriber about to hold samples.
    pub fn new_owner(&mut self) -> OwnerId {
        self.next_owner += 1;
        self.next_owner
    }

    /// Samples `owner` holds now.
    pub fn held_by(&self, owner: OwnerId) -> usize {
        self.per_owner.get(&owner).copied().unwrap_or(0)
    }

    /// What is held now and what was copied.
    pub fn stats(&self) -> HoldingStats {
        HoldingStats {
            held_now: self.held.len(),
            held_total: self.held_total,
            copied_over_budget: self.copied_over_budget,
        }
    }

    /// Returns to their publishers the samples no value points into any more; returns
    /// how many.
    /// Where released keys arrive: a thread that sleeps until something happens waits on
    /// it too, so that a chunk goes back as soon as its last value is dropped.
    pub fn releases(&self) -> &Receiver<u64> {
        &self.released
    }

    pub fn collect(&mut self) -> usize {
        let mut n = 0;
        while let Ok(key) = self.released.try_recv() {
            if let Some((owner, sample)) = self.held.remove(&key) {
                drop(sample);
                n += 1;
                if let Some(count) = self.per_owner.get_mut(&owner) {
                    *count = count.saturating_sub(1);
                }
            }
        }
        n
    }

    /// Decodes `sample` for `owner`, whose subscriber may borrow `budget` samples
    /// besides the one it receives into. Large octet sequences stay in shared memory
    /// while the owner has budget; otherwise everything is copied and the sample
    /// returned at once.
    pub fn decode(
        &mut self,
        owner: OwnerId,
        budget: usize,
        sample: ReceivedSample,
    ) -> Result<EntityStructure, CodecError> {
        let archived = sample.structure()?;
        if sample.archive_bytes().len() < HOLD_MIN_BYTES {
            return codec::decode(archived);
        }
        if self.held_by(owner) >= budget {
            self.collect();
        }
        if self.held_by(owner) >= budget {
            self.copied_over_budget += 1;
            if self.copied_over_budget == 1 {
                tracing::warn!(
                    budget,
                    "every shared-memory sample this subscriber may borrow is held by \
                     values in this process; copying images instead (raise the cache \
                     bound's slack, or drop old samples sooner)"
                );
            }
            return codec::decode(archived);
        }
        self.next_key += 1;
        let key = self.next_key;
        let bytes = sample.archive_bytes();
        let holder: Arc<dyn OctetsHolder> = Arc::new(SharedChunk {
            bytes: bytes.as_ptr(),
            len: bytes.len(),
            key,
            release: self.release.clone(),
        });
        let structure = codec::decode_holding(archived, &holder)?;
        if Arc::strong_count(&holder) == 1 {
            // No octets in it after all: nothing points into the sample.
            return Ok(structure);
        }
        drop(holder);
        self.held.insert(key, (owner, sample));
        *self.per_owner.entry(owner).or_default() += 1;
        self.held_total += 1;
        Ok(structure)
    }
}

impl Drop for Holdings {
    fn drop(&mut self) {
        self.collect();
        // Values still point into these samples (a user kept an image past the
        // connection): returning the samples would let the publisher overwrite, and
        // dropping the subscriber unmap, bytes they read. Keep them borrowed and mapped
        // until the process exits (the location keeps their subscribers and node too,
        // see the module docs); the coordinator's dead-node cleanup reclaims them.
        let still_held = self.held.len();
        if still_held > 0 {
            tracing::debug!(still_held, "shared-memory samples still read by values; kept");
        }
        for (_, (_, sample)) in self.held.drain() {
            std::mem::forget(sample);
        }
    }
}

/// The bytes of one borrowed sample, as [`esgm_core::value::Octets`] read them; its drop
/// tells [`Holdings`] the sample may go back.
struct SharedChunk {
    bytes: *const u8,
    len: usize,
    key: u64,
    release: Sender<u64>,
}

// SAFETY: `bytes..bytes+len` is the payload of a sample that `Holdings` keeps borrowed
// (so the publisher does not reuse the chunk, and the subscriber keeps the segment
// mapped) until this value's drop has sent `key` and `Holdings::collect` has received
// it — or, if `Holdings` goes first, forever. The bytes are only ever read through
// `&[u8]`, from any thread.
unsafe impl Send for SharedChunk {}
// SAFETY: as above; `&SharedChunk` gives only shared reads.
unsafe impl Sync for SharedChunk {}

impl OctetsHolder for SharedChunk {
    fn bytes(&self) -> &[u8] {
        // SAFETY: see the `Send` impl: the range stays mapped and unchanged by esgm's
        // publishers for this value's whole life.
        unsafe { std::slice::from_raw_parts(self.bytes, self.len) }
    }
}

impl Drop for SharedChunk {
    fn drop(&mut self) {
        // Nobody listens once the holdings are gone; the sample then stays borrowed.
        let _ = self.release.send(self.key);
    }
}
