//! A structure encoded into shared memory and not yet sent: prepare now, send later.
//!
//! [`TrajectoryPublisher::publish`] encodes and sends in one call. A producer that
//! knows its structure before the moment it must go — a reply prepared while waiting
//! for the request, a state published on a control tick — can take the encoding off
//! that moment: [`TrajectoryPublisher::loan_structure`] encodes into a loaned slice at
//! once, and [`StructureLoan::send`] later only stamps the header and sends. If the
//! times are known only at sending, [`StructureLoan::set_times`] rewrites them in the
//! archive in place (two 8-byte writes, [`esgm_core::codec::restamp`]).
//!
//! An image written in place ([`crate::ImageLoan::into_structure`]) becomes a
//! structure loan too.
//!
//! Dropping a loan without sending it returns the shared memory to the publisher;
//! nothing is sent. `publish` is exactly `loan_structure` followed by `send`.

use esgm_core::Time;
use esgm_core::codec;

use crate::data_plane::publisher::{LoanedSample, PublishError, Published, TrajectoryPublisher};

/// An entity structure archived in a loaned shared-memory slice, ready to send; see
/// the module docs.
pub struct StructureLoan<'p> {
    publisher: &'p TrajectoryPublisher,
    sample: LoanedSample,
    archive_len: usize,
    valid_time: Time,
    create_time: Time,
    flags: u32,
}

impl std::fmt::Debug for StructureLoan<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StructureLoan")
            .field("trajectory", &self.publisher.trajectory())
            .field("archive_len", &self.archive_len)
            .field("times", &(self.valid_time, self.create_time))
            .finish_non_exhaustive()
    }
}

impl<'p> StructureLoan<'p> {
    /// A loan whose first `archive_len` payload bytes hold the archive of a structure
    /// with these times, and whose other bytes are zeroed; `flags` go into the header
    /// ([`crate::SampleHeader::FLAG_IMAGE_IN_PLACE`]).
    pub(crate) fn new(
        publisher: &'p TrajectoryPublisher,
        sample: LoanedSample,
        archive_len: usize,
        (valid_time, create_time): (Time, Time),
        flags: u32,
    ) -> Self {
        Self { publisher, sample, archive_len, valid_time, create_time, flags }
    }

    /// The slice's length in blocks: what the writer's next loan is made ahead at.
    pub(crate) fn blocks(&self) -> usize {
        self.sample.payload().len()
    }

    /// True if the structure is an image whose pixels were written in place
    /// ([`crate::ImageLoan`]).
    pub fn is_image_in_place(&self) -> bool {
        self.flags & crate::SampleHeader::FLAG_IMAGE_IN_PLACE != 0
    }

    /// Bytes of the archive (codec envelope included), as the header will say.
    pub fn archive_len(&self) -> usize {
        self.archive_len
    }

    /// The valid time the structure will be sent with.
    pub fn valid_time(&self) -> Time {
        self.valid_time
    }

    /// The create time the structure will be sent with.
    pub fn create_time(&self) -> Time {
        self.create_time
    }

    /// Gives the structure new valid and create times, in the archive and in the
    /// header it will be sent with; nothing is encoded again.
    pub fn set_times(&mut self, valid_time: Time, create_time: Time) -> Result<(), PublishError> {
        let payload: &mut [u8] = bytemuck::cast_slice_mut(self.sample.payload_mut());
        let bytes = &mut payload[..self.archive_len];
        codec::restamp(bytes, valid_time, create_time).map_err(PublishError::Encode)?;
        self.valid_time = valid_time;
        self.create_time = create_time;
        Ok(())
    }

    /// Sends the structure to every subscriber and wakes sleeping readers; its add time
    /// is the time of sending.
    pub fn send(self) -> Result<Published, PublishError> {
        self.send_added_at(None)
    }

    /// [`Self::send`] with the add time a runtime's gate gave the structure.
    pub fn send_added(self, add_time: Time) -> Result<Published, PublishError> {
        self.send_added_at(Some(add_time))
    }

    /// [`Self::send_added`] for a structure kept at index `kept` of its trajectory's
    /// kept history ([`crate::SampleHeader::kept`]).
    pub fn send_kept(self, add_time: Time, kept: u64) -> Result<Published, PublishError> {
        self.send_with(Some(add_time), Some(kept))
    }

    fn send_added_at(self, add_time: Option<Time>) -> Result<Published, PublishError> {
        self.send_with(add_time, None)
    }

    fn send_with(
        self,
        add_time: Option<Time>,
        kept: Option<u64>,
    ) -> Result<Published, PublishError> {
        self.publisher.send(
            self.sample,
            self.archive_len,
            (self.valid_time, self.create_time),
            self.flags,
            add_time,
            kept,
        )
    }
}
