//! Samples kept borrowed because values elsewhere in the process read them in place:
//! how a structure received from another process reaches a replica's cache, its
//! units, its subscribers and query answers without being decoded or copied (P7).
//!
//! A received sample, checked once by its subscriber, becomes an archived
//! [`SharedStructure`] read where it arrived: every field, and every
//! [`Octets`](esgm_core::value::Octets) taken from it, reads the shared-memory chunk.
//! They share one `SharedChunk`, which *owns* the received sample — and through it a
//! share of the subscriber port and node that keep the chunk borrowed and mapped (see
//! [`ReceivedSample`]). The chunk goes back to its publisher when the last value
//! reading it is dropped, on whatever thread that happens, and never before:
//! destroying the trajectory, dropping the connection or a panic of any esgm thread
//! drops only *other* shares. Nothing has to remember to keep a sample alive; the
//! value that reads it does.
//!
//! A subscriber may borrow only so many samples at once
//! ([`crate::TrajectoryQos::max_borrowed_samples`]): past its budget, the archive's
//! bytes are copied onto this process's heap (still archived, never decoded), the chunk
//! goes back at once, and the copy is counted.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use esgm_core::SharedStructure;
use esgm_core::codec::CodecError;
use esgm_core::value::OctetsHolder;

use crate::data_plane::received::ReceivedSample;

/// Structures with octet sequences at least this long count as images: sent from a
/// loan or copied ([`HoldingOwner::count_sent`]), and their copies past a reader's
/// budget are worth a warning.
pub(crate) const HOLD_MIN_BYTES: usize = 16 * 1024;

pub use crate::control::holding_stats::HoldingStats;

/// The process-wide counters behind [`HoldingStats`], shared by every owner.
#[derive(Debug, Default)]
pub(crate) struct Holdings {
    held_now: AtomicUsize,
    held_total: AtomicU64,
    copied_over_budget: AtomicU64,
    copied_small: AtomicU64,
    sent_in_place: AtomicU64,
    sent_copied: AtomicU64,
}

impl Holdings {
    /// What is held now and what was copied.
    pub fn stats(&self) -> HoldingStats {
        HoldingStats {
            held_now: self.held_now.load(Ordering::Relaxed),
            held_total: self.held_total.load(Ordering::Relaxed),
            copied_over_budget: self.copied_over_budget.load(Ordering::Relaxed),
            copied_small: self.copied_small.load(Ordering::Relaxed),
            sent_in_place: self.sent_in_place.load(Ordering::Relaxed),
            sent_copied: self.sent_copied.load(Ordering::Relaxed),
        }
    }

    /// A new owner: a subscriber that may borrow `budget` samples for values besides
    /// the one it receives into.
    pub fn owner(self: &Arc<Self>, budget: usize) -> HoldingOwner {
        HoldingOwner { held: Arc::default(), budget, process: Arc::clone(self) }
    }
}

/// One subscriber's share of the holdings: its own budget, the process's counters.
#[derive(Debug)]
pub(crate) struct HoldingOwner {
    held: Arc<AtomicUsize>,
    budget: usize,
    process: Arc<Holdings>,
}

impl HoldingOwner {
    /// Counts an image this process published: from a loan (`in_place`) or encoded
    /// from the heap (a copy).
    pub fn count_sent(&self, in_place: bool) {
        let counter = match in_place {
            true => &self.process.sent_in_place,
            false => &self.process.sent_copied,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// The structure `sample` carries, read in place where it arrived (the chunk held
    /// for as long as any value reads it), or, past the owner's budget, from a copy of
    /// its archive on the heap (counted). Nothing is decoded.
    pub fn hold(&self, sample: ReceivedSample) -> Result<SharedStructure, CodecError> {
        let root = std::ptr::from_ref(sample.structure()?);
        // A kept-history entry counts too, though its chunk went back already: each
        // one held pins its place in the writer's file, which moves to a new file
        // rather than write over it, so one subscriber that keeps every image would
        // cost the writer a file per ring's turn.
        if self.held.load(Ordering::Relaxed) >= self.budget {
            let bytes = sample.archive_bytes();
            if bytes.len() < HOLD_MIN_BYTES {
                self.process.copied_small.fetch_add(1, Ordering::Relaxed);
                return SharedStructure::archived_copy(bytes);
            }
            let copied = self.process.copied_over_budget.fetch_add(1, Ordering::Relaxed);
            if copied == 0 {
                tracing::warn!(
                    budget = self.budget,
                    "every shared-memory sample this subscriber may borrow is held by \
                     values in this process; copying images instead (raise the cache \
                     bound's slack, or drop old samples sooner)"
                );
            }
            return SharedStructure::archived_copy(bytes);
        }
        let bytes = sample.archive_bytes();
        let (ptr, len) = (bytes.as_ptr(), bytes.len());
        self.held.fetch_add(1, Ordering::Relaxed);
        self.process.held_now.fetch_add(1, Ordering::Relaxed);
        self.process.held_total.fetch_add(1, Ordering::Relaxed);
        let holder: Arc<dyn OctetsHolder> = Arc::new(SharedChunk {
            bytes: ptr,
            len,
            _sample: sample,
            owner: Arc::clone(&self.held),
            process: Arc::clone(&self.process),
        });
        // SAFETY: `root` is what `sample.structure()` validated above, inside the bytes
        // the holder now owns (the sample moved into it without moving its payload,
        // which lies in shared memory), borrowed and unchanged for the holder's life.
        let structure = unsafe { SharedStructure::archived_checked(holder, &*root) };
        structure.ok_or_else(|| CodecError::Malformed {
            len,
            reason: "the checked archive lies outside its sample".into(),
        })
    }
}

/// The bytes of one borrowed sample, as [`esgm_core::value::Octets`] read them. It owns
/// the sample; its drop returns the chunk (see the module docs).
struct SharedChunk {
    bytes: *const u8,
    len: usize,
    // Never read: owned so the chunk stays borrowed and mapped as long as this value.
    _sample: ReceivedSample,
    owner: Arc<AtomicUsize>,
    process: Arc<Holdings>,
}

// SAFETY: `bytes..bytes+len` is the payload of `sample`, which this value owns: the
// chunk stays borrowed (the publisher does not reuse it) and mapped (the sample owns a
// share of its port, node and segment) for this value's whole life. The sample is
// iceoryx2's thread-safe variant (`ShmService`), so it may be dropped on any thread.
// Its `Cell` of validation state is never touched through `SharedChunk`.
unsafe impl Send for SharedChunk {}
// SAFETY: as above; `&SharedChunk` gives only shared reads of the payload bytes.
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
        self.owner.fetch_sub(1, Ordering::Relaxed);
        self.process.held_now.fetch_sub(1, Ordering::Relaxed);
        // `_sample` drops after this, returning the chunk through its port.
    }
}
