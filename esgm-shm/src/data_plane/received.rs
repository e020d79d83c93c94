//! A sample a subscriber took from shared memory, read in place.

use crate::data_plane::service::ShmService;
use std::cell::Cell;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::EntityStructure;
use esgm_core::codec::{self, ArchivedEntityStructure, CodecError};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::sample::Sample;

use crate::data_plane::kept::{KeptHold, Taken};
use crate::data_plane::payload::{Block16, SampleHeader, as_bytes};
use crate::data_plane::sample_check::validate;
use iceoryx2::identifiers::UniquePublisherId;

/// The iceoryx2 sample type of a trajectory.
pub(crate) type RawSample = Sample<ShmService, [Block16], SampleHeader>;

/// The iceoryx2 subscriber port of a trajectory.
pub(crate) type SubscriberPort = Subscriber<ShmService, [Block16], SampleHeader>;

/// Counters shared by a subscriber and, when validation is deferred, its samples.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub(crate) received: AtomicU64,
    pub(crate) malformed: AtomicU64,
    pub(crate) type_mismatch: AtomicU64,
}

impl Counters {
    /// Counts a malformed sample; true for the first one (which is worth a warning).
    pub(crate) fn count_malformed(&self) -> bool {
        self.malformed.fetch_add(1, Ordering::Relaxed) == 0
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Checked {
    /// Not validated yet (deferred validation).
    No,
    /// Passed [`codec::access`] and the header cross-check.
    Valid,
    /// Failed validation (already counted).
    Invalid,
}

/// A sample taken from a trajectory, read in place: the iceoryx2 sample itself (its
/// payload stays in shared memory, where the producer wrote it), or the entry of the
/// trajectory's kept history it names, held in the file; and what the subscriber
/// checked.
///
/// Holding it keeps the memory borrowed: the publisher cannot reuse the chunk (a
/// subscriber may hold only `max_borrowed_samples` at once, [`crate::TrajectoryQos`]),
/// and the kept history's writer does not write over the entry. Drop samples you are
/// done with.
///
/// A sample owns what keeps its bytes valid: the chunk, and a share of the subscriber
/// port it came through (iceoryx2 hands a publisher back every chunk of a port that is
/// gone), which keeps the port's node and segment mapped too; or the kept entry's hold
/// and the file's mapping. So a sample stays valid and unchanged after its subscriber
/// is dropped, on any thread, whatever ended the subscriber (a destroyed trajectory, a
/// closed connection, a panic): no path has to remember to keep anything alive.
#[derive(Debug)]
pub struct ReceivedSample {
    body: Body,
    header: SampleHeader,
    publisher: UniquePublisherId,
    archive_len: usize,
    checked: Cell<Checked>,
    /// Present only when validation is deferred, to count failures found later.
    counters: Option<Arc<Counters>>,
}

/// Where a received sample's bytes are.
#[derive(Debug)]
enum Body {
    /// In the iceoryx2 chunk. Dropped in this order: the chunk goes back through the
    /// port before the port goes.
    Chunk { sample: RawSample, _port: Arc<SubscriberPort> },
    /// In the trajectory's kept history, held.
    Kept(KeptHold),
    /// Copied out of the kept history (no holder slot was free).
    Copied(esgm_core::codec::ArchiveBuffer),
}

impl ReceivedSample {
    pub(crate) fn new(
        sample: RawSample,
        port: &Arc<SubscriberPort>,
        archive_len: usize,
        checked: Checked,
        counters: Option<Arc<Counters>>,
    ) -> Self {
        let header = *sample.user_header();
        let publisher = sample.header().publisher_id();
        Self {
            body: Body::Chunk { sample, _port: Arc::clone(port) },
            header,
            publisher,
            archive_len,
            checked: Cell::new(checked),
            counters,
        }
    }

    /// A structure of the kept history the sample `header` named, taken from the file
    /// and checked there (`Malformed` if its bytes do not check).
    pub(crate) fn kept(
        taken: Taken,
        header: SampleHeader,
        publisher: UniquePublisherId,
    ) -> Result<Self, CodecError> {
        let body = match taken {
            Taken::Held(hold) => Body::Kept(hold),
            Taken::Copied(bytes) => Body::Copied(bytes),
        };
        let mut sample = Self {
            body,
            header,
            publisher,
            archive_len: 0,
            checked: Cell::new(Checked::No),
            counters: None,
        };
        let held = sample.bytes().len();
        sample.archive_len = usize::try_from(header.archive_len).unwrap_or(usize::MAX);
        if sample.archive_len > held {
            return Err(CodecError::Malformed {
                len: held,
                reason: format!(
                    "the kept entry has {held} bytes, the sample says {}",
                    header.archive_len
                ),
            });
        }
        validate(sample.archive_bytes(), &sample.header)?;
        sample.checked.set(Checked::Valid);
        Ok(sample)
    }

    /// Every byte of the body.
    fn bytes(&self) -> &[u8] {
        match &self.body {
            Body::Chunk { sample, .. } => as_bytes(sample.payload()),
            Body::Kept(hold) => hold.all_bytes(),
            Body::Copied(bytes) => bytes,
        }
    }

    /// The header: times, type id, sequence, archive length. Reading it never touches
    /// the payload.
    pub fn header(&self) -> &SampleHeader {
        &self.header
    }

    /// The iceoryx2 publisher port that sent the sample: sequence numbers
    /// ([`SampleHeader::sequence`]) count per publisher.
    pub fn publisher_id(&self) -> UniquePublisherId {
        self.publisher
    }

    /// The codec bytes (envelope + archive) in shared memory.
    pub fn archive_bytes(&self) -> &[u8] {
        // The subscriber checked `archive_len <= payload length` before building us.
        let bytes = self.bytes();
        bytes.get(..self.archive_len).unwrap_or(bytes)
    }

    /// True if the structure was read from the trajectory's kept history.
    pub fn is_kept(&self) -> bool {
        !matches!(self.body, Body::Chunk { .. })
    }

    /// The lineage the writer sent with the structure ([`esgm_core::lineage`]), read
    /// from the payload after the archive; `None` for a structure without one (pushed
    /// or sampled). Bytes another process wrote that do not make a lineage are an
    /// error that says what is wrong.
    pub fn lineage(&self) -> Result<Option<esgm_core::Lineage>, CodecError> {
        if !self.header().has_flag(SampleHeader::FLAG_LINEAGE) {
            return Ok(None);
        }
        let payload = self.bytes();
        let bytes = crate::data_plane::payload::lineage_trailer(payload, self.archive_len)
            .map_err(|reason| CodecError::Malformed { len: payload.len(), reason })?;
        codec::decode_lineage(bytes).map(Some)
    }

    /// True if the producer wrote an image's pixels straight into shared memory.
    pub fn is_image_in_place(&self) -> bool {
        self.header().has_flag(SampleHeader::FLAG_IMAGE_IN_PLACE)
    }

    /// The archived entity structure, read in place and validated.
    ///
    /// With the default [`crate::Validation::InPlace`] the subscriber validated the bytes
    /// when it received them and this is free. With [`crate::Validation::OnAccess`] the
    /// first call validates (and counts a failure in the subscriber's stats); later
    /// calls reuse the verdict.
    pub fn structure(&self) -> Result<&ArchivedEntityStructure, CodecError> {
        let bytes = self.archive_bytes();
        match self.checked.get() {
            Checked::Valid => {
                // SAFETY: these exact bytes passed `codec::access` (full validation) in
                // this sample's lifetime. Shared memory stays writable by its publisher:
                // validation guards against corrupt or foreign-version writers, not
                // against a publisher that changes a chunk after sending it (a peer that
                // hostile must not share memory with this process; see the crate docs).
                unsafe { codec::access_unchecked(bytes) }
            }
            Checked::No | Checked::Invalid => match validate(bytes, self.header()) {
                Ok(archived) => {
                    self.checked.set(Checked::Valid);
                    Ok(archived)
                }
                Err(e) => {
                    if self.checked.replace(Checked::Invalid) == Checked::No {
                        if let Some(c) = &self.counters {
                            c.count_malformed();
                        }
                    }
                    Err(e)
                }
            },
        }
    }

    /// The archived entity structure without validating the archive (only the
    /// envelope: magic, version, length).
    ///
    /// # Safety
    /// The bytes come from another process. Call this only when every process that
    /// can publish on this trajectory is trusted to run esgm's own, unmodified
    /// publisher of the same format version: a malformed archive read unchecked is
    /// undefined behaviour (out-of-bounds reads through corrupt relative pointers).
    /// It saves the validation (≈40 ns for a small structure); measure before using it.
    pub unsafe fn structure_unchecked(&self) -> Result<&ArchivedEntityStructure, CodecError> {
        // SAFETY: forwarded to the caller, see above.
        unsafe { codec::access_unchecked(self.archive_bytes()) }
    }

    /// An owned copy of the structure (decodes every field, image bytes included: use
    /// it where an owned copy is really needed, e.g. to hand it to an in-process store).
    pub fn to_owned(&self) -> Result<EntityStructure, CodecError> {
        codec::decode(self.structure()?)
    }
}
