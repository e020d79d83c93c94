//! The writing end of a trajectory: encodes entity structures straight into loaned
//! shared memory and wakes sleeping readers.
//!
//! # One write, no heap buffer
//! [`TrajectoryPublisher::publish`] loans a slice sized by
//! `crate::data_plane::size_hint::archived_size_hint` (a walk over the structure, no encode) and
//! has the codec encode straight into the uninitialised loan
//! ([`codec::encode_into_uninit`]); the header carries the archive length, times and
//! type id. The codec initialises exactly the bytes it reports (rkyv writes padding
//! as zeros, see the codec's docs), and the publisher zeroes the rest — the hint's
//! slack and the block rounding — because a loaned slice must be fully initialised
//! before iceoryx2 treats it as bytes, and those bytes must not leak a previous
//! sample's contents to other processes. If the hint is ever short the codec names the
//! size it needs and the publisher loans again once.
//!
//! A hint that would exceed the configured maximum sample size
//! ([`TrajectoryPublisherBuilder::max_len`]) is replaced by the exact length
//! ([`codec::encoded_len`], a counting pass that allocates nothing): an over-estimate
//! must not grow the segment, or fail a [`SampleSizing::Fixed`] loan, for a structure
//! that actually fits.
//!
//! [`TrajectoryPublisher::loan_structure`] splits `publish` in two: encode into the
//! loan now, send later (`crate::data_plane::structure_loan`).
//!
//! # The next loan, made ahead
//! After each structure it sends, the publisher loans the slice for the next one (of
//! the same size) and keeps it. A loan walks iceoryx2's connections for returned
//! chunks and takes one from the segment's pool; in a pipeline paced like a camera
//! every one of those touches is a cache miss, 13–20 µs of a 50 µs stage on this
//! machine (BENCHMARKS.md, "Where a stage's time goes"). Made ahead it runs while the
//! readers wake, and the next publish starts encoding at once. The spare counts as one
//! of the publisher's loans, which iceoryx2 sizes the pool for; an image loan gives it
//! back first, and a structure it does not fit (smaller than the spare's half, or
//! larger) loans its own.
//!
//! Images written by a camera go through [`TrajectoryPublisher::loan_image`] instead,
//! which lets the camera fill the pixels in place (see `crate::data_plane::image_loan`).
//!
//! # Late joiners
//! iceoryx2 keeps the last `history_size` samples in the publisher and hands them to a
//! subscriber when the publisher next updates its connections — on its next send, or
//! when [`TrajectoryPublisher::update_connections`] is called. A producer that publishes
//! rarely should call it periodically so that new subscribers get the history at once.

use crate::data_plane::service::ShmService;
use std::cell::Cell;
use std::time::Duration;

use esgm_core::codec::{self, CodecError};
use esgm_core::{EntityStructure, Lineage, SharedClock, SharedStructure, SystemClock, Time};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::{ConnectionFailure, UpdateConnections};
use iceoryx2::port::{BackpressureAction, LoanError, SendError};
use iceoryx2::prelude::{AllocationStrategy, BackpressureStrategy};
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::port_factory::PortFactory;

use crate::data_plane::encodable::Encodable;
use crate::data_plane::image_layout::{ImageError, image_loan_len, pixel_len};
use crate::data_plane::image_loan::{ImageChunk, ImageLoan};
use crate::data_plane::kept::KeptLocation;
use crate::data_plane::payload::{
    BLOCK_LEN, Block16, SampleHeader, TRAILER_HEAD, as_uninit_bytes, blocks_for, trailer_start,
    with_trailer_len, zero_fill,
};
use crate::data_plane::qos::{Delivery, TrajectoryQos};
use crate::data_plane::service::{
    DataService, OpenError, ShmNode, WakeService, open_data_service, open_wake_service, with_room,
};
use crate::data_plane::service_name::{DEFAULT_DOMAIN, TrajectoryServiceNames};
use crate::data_plane::structure_loan::StructureLoan;
use crate::data_plane::type_id::type_id;
use crate::data_plane::wake_word::WakeWord;

/// Default initial size of a publisher's samples: small structures fit without growth.
pub const DEFAULT_INITIAL_MAX_LEN: usize = 4096;

/// Default time a [`Delivery::Lossless`] publish waits for a full subscriber.
pub const DEFAULT_LOSSLESS_TIMEOUT: Duration = Duration::from_secs(1);

/// Whether a publisher's samples may outgrow its initial maximum size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum SampleSizing {
    /// Grow the shared-memory segment (to the next power of two) when a larger sample
    /// is needed; subscribers follow transparently. Costs one reallocation per doubling.
    #[default]
    Grow,
    /// Never grow: a larger sample fails with [`PublishError::Loan`]. For real-time
    /// producers that must not allocate after start-up; size `max_len` for the largest.
    Fixed,
}

/// A structure could not be published.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PublishError {
    /// The structure could not be encoded; it is not representable (report it).
    #[error("cannot encode the structure: {0}")]
    Encode(#[source] CodecError),
    /// No shared memory could be loaned: subscribers hold too many samples, or (with
    /// [`SampleSizing::Fixed`]) the sample is larger than `max_len`. Drop held samples,
    /// or raise the limits.
    #[error("cannot loan shared memory: {0}")]
    Loan(#[source] LoanError),
    /// A [`Delivery::Lossless`] subscriber made no room within the lossless timeout;
    /// the sample reached the other subscribers only.
    #[error("a subscriber's buffer stayed full for {timeout:?}; sample not delivered to it")]
    NotDelivered {
        /// The lossless timeout that passed.
        timeout: Duration,
    },
    /// iceoryx2 could not deliver the sample (a broken connection); retry.
    #[error("cannot send the sample: {0}")]
    Send(#[source] SendError),
    /// The connections to subscribers could not be updated; retry later.
    #[error("cannot update connections: {0:?}")]
    Connections(ConnectionFailure),
    /// The image could not be loaned or laid out.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The trajectory's violations service could not be opened (at its first
    /// violation).
    #[error("cannot open the violations service: {0}")]
    Violations(#[source] Box<crate::data_plane::service::OpenError>),
}

/// What a successful publish did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Published {
    /// The sample's sequence number.
    pub sequence: u64,
    /// Subscribers the sample was delivered to.
    pub subscribers: usize,
}

/// Builds a [`TrajectoryPublisher`]; every setting has a default.
#[derive(Debug, Clone)]
pub struct TrajectoryPublisherBuilder {
    trajectory: String,
    type_name: String,
    domain: String,
    qos: TrajectoryQos,
    initial_max_len: usize,
    sizing: SampleSizing,
    lossless_timeout: Duration,
    clock: Option<SharedClock>,
}

impl TrajectoryPublisherBuilder {
    /// The domain (namespace) of the trajectory; default [`DEFAULT_DOMAIN`].
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = domain.into();
        self
    }

    /// All service settings at once (see `crate::data_plane::qos`).
    pub fn qos(mut self, qos: TrajectoryQos) -> Self {
        self.qos = qos;
        self
    }

    /// Samples kept for late subscribers; default 1.
    pub fn history_size(mut self, n: usize) -> Self {
        self.qos.history_size = n;
        self
    }

    /// Unread samples a subscriber can queue; default 8.
    pub fn subscriber_buffer_size(mut self, n: usize) -> Self {
        self.qos.subscriber_buffer_size = n;
        self
    }

    /// Overwrite the oldest unread sample, or wait for room; default
    /// [`Delivery::LatestWins`].
    pub fn delivery(mut self, delivery: Delivery) -> Self {
        self.qos.delivery = delivery;
        self
    }

    /// How long a [`Delivery::Lossless`] publish waits for a full subscriber before
    /// giving up on it; default `DEFAULT_LOSSLESS_TIMEOUT`.
    pub fn lossless_timeout(mut self, timeout: Duration) -> Self {
        self.lossless_timeout = timeout;
        self
    }

    /// Initial maximum sample size in bytes (codec envelope included); default
    /// `DEFAULT_INITIAL_MAX_LEN`. Size it for the largest sample (e.g. an image) to
    /// avoid growth after start-up.
    pub fn max_len(mut self, bytes: usize) -> Self {
        self.initial_max_len = bytes;
        self
    }

    /// Whether samples may outgrow [`Self::max_len`]; default [`SampleSizing::Grow`].
    pub fn sizing(mut self, sizing: SampleSizing) -> Self {
        self.sizing = sizing;
        self
    }

    /// The clock that stamps add times; default the system clock.
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// Has no effect: image loans no longer depend on the entity name (any name of up
    /// to [`crate::data_plane::image_layout::IMAGE_NAME_MAX`] bytes is sent in place, see
    /// `crate::data_plane::image_layout`). Kept so that existing callers compile.
    pub fn image_name(self, _name: impl Into<String>) -> Self {
        self
    }

    /// Opens (or creates) the trajectory's services and the publisher port on `node`.
    pub fn create(self, node: &ShmNode) -> Result<TrajectoryPublisher, OpenError> {
        // A crashed process's ports hold their room until someone cleans up after it.
        with_room(OpenError::lacks_room, || self.open(node))
    }

    fn open(&self, node: &ShmNode) -> Result<TrajectoryPublisher, OpenError> {
        let names = TrajectoryServiceNames::new(&self.domain, &self.trajectory)?;
        let service = open_data_service(node, &names, &self.qos)?;
        let allocation = match self.sizing {
            SampleSizing::Grow => AllocationStrategy::PowerOfTwo,
            SampleSizing::Fixed => AllocationStrategy::Static,
        };
        let max_blocks = blocks_for(self.initial_max_len).max(1);
        let mut port = service
            .publisher_builder()
            .initial_max_slice_len(max_blocks)
            .allocation_strategy(allocation);
        if self.qos.delivery == Delivery::Lossless {
            let timeout = self.lossless_timeout;
            port = port.backpressure_strategy(BackpressureStrategy::RetryUntilDelivered);
            // Bounded: a subscriber that never reads must not stall the producer forever.
            port = port.set_backpressure_handler(move |info| {
                if info.elapsed_time >= timeout {
                    BackpressureAction::DiscardDataAndFail
                } else {
                    if info.retries > 64 {
                        std::thread::yield_now();
                    }
                    BackpressureAction::Retry
                }
            });
        }
        let port = port.create().map_err(OpenError::Publisher)?;
        let wake = open_wake_service(node, &names, &self.qos)?;
        let notifier = wake.notifier_builder().create().map_err(OpenError::Notifier)?;
        // Without its word, readers that sleep on it wake only at their timeouts:
        // worth a warning, not a refusal (readers that cannot map it use the event).
        let word = WakeWord::open(names.wake().as_str())
            .inspect_err(|e| {
                tracing::warn!(trajectory = %self.trajectory, error = %e,
                    "cannot map the trajectory's wake-up word; readers sleeping on it \
                     wake only at their timeouts")
            })
            .ok();
        Ok(TrajectoryPublisher {
            type_id: type_id(&self.type_name),
            trajectory: self.trajectory.clone(),
            type_name: self.type_name.clone(),
            service,
            port,
            notifier,
            wake,
            word,
            clock: self.clock.clone().unwrap_or_else(SystemClock::shared),
            lossless_timeout: self.lossless_timeout,
            sequence: Cell::new(0),
            max_len: max_blocks * BLOCK_LEN,
            notify_failures: Cell::new(0),
            notifies_spared: Cell::new(0),
            spare: Spare::default(),
        })
    }
}

/// The writing end of one trajectory in shared memory.
#[derive(Debug)]
pub struct TrajectoryPublisher {
    trajectory: String,
    type_name: String,
    type_id: u64,
    service: DataService,
    /// The next structure's loan, made after the last send (see the module docs).
    /// Before `port`, so that it is given back before the port goes.
    spare: Spare,
    port: Publisher<ShmService, [Block16], SampleHeader>,
    notifier: Notifier<ShmService>,
    /// The notifier's service, whose listeners a ring that found every receiver
    /// covered is compared with ([`crate::data_plane::wake_word::Ring::covered`]).
    wake: WakeService,
    /// Rung before the notifier: readers sleeping on the futex word ([`WakeWord`]).
    word: Option<WakeWord>,
    clock: SharedClock,
    lossless_timeout: Duration,
    sequence: Cell<u64>,
    /// The configured maximum sample size in bytes (see the module docs).
    max_len: usize,
    notify_failures: Cell<u64>,
    /// Notifies skipped because every listener's process was covered.
    notifies_spared: Cell<u64>,
}

/// Notifies skipped by every publisher of this process ([`notifies_spared_here`]).
static SPARED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many sends of this process's publishers skipped the iceoryx2 notify, every
/// reader's connection being covered ([`TrajectoryPublisher::notifies_spared`]): for
/// diagnostics and tests, where the publisher is a connection's own.
pub fn notifies_spared_here() -> u64 {
    SPARED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Which listeners of the wake-up event a send must notify.
#[derive(Debug, Clone, Copy)]
enum Listeners {
    /// Every one: a new reader waits for its history on a listener of its own.
    All,
    /// Every one, unless every listener belongs to a connection covered by a thread
    /// asleep on the word ([`crate::data_plane::wake_word::Ring::covered`]): a notify goes to all
    /// or to none.
    Uncovered,
}

/// The spare loan of a [`TrajectoryPublisher`], if one is held.
#[derive(Default)]
struct Spare(std::cell::RefCell<Option<UninitSample>>);

impl std::fmt::Debug for Spare {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let held = self.0.try_borrow().map(|s| s.as_ref().map(|s| s.payload().len()));
        f.debug_tuple("Spare").field(&held.ok().flatten()).finish()
    }
}

/// A spare up to this many blocks (1 KiB) serves any smaller structure; a larger one
/// serves structures at least half its size.
const SPARE_SLACK_BLOCKS: usize = 64;

/// A loaned slice not yet written.
type UninitSample = iceoryx2::sample_mut_uninit::SampleMutUninit<
    ShmService,
    [std::mem::MaybeUninit<Block16>],
    SampleHeader,
>;

/// A sample whose payload is written, waiting for its header.
pub(crate) type LoanedSample = SampleMut<ShmService, [Block16], SampleHeader>;

impl TrajectoryPublisher {
    /// A builder for a publisher of `trajectory`, whose structures are of the entity
    /// structure type `type_name` (its hash goes into every header).
    pub fn builder(
        trajectory: impl Into<String>,
        type_name: impl Into<String>,
    ) -> TrajectoryPublisherBuilder {
        TrajectoryPublisherBuilder {
            trajectory: trajectory.into(),
            type_name: type_name.into(),
            domain: DEFAULT_DOMAIN.to_owned(),
            qos: TrajectoryQos::default(),
            initial_max_len: DEFAULT_INITIAL_MAX_LEN,
            sizing: SampleSizing::default(),
            lossless_timeout: DEFAULT_LOSSLESS_TIMEOUT,
            clock: None,
        }
    }

    /// The trajectory's name.
    pub fn trajectory(&self) -> &str {
        &self.trajectory
    }

    /// The entity structure type this publisher writes.
    pub fn type_name(&self) -> &str {
        &self.type_name
    }

    /// This publisher's iceoryx2 port: what every sample it sends carries
    /// ([`crate::ReceivedSample::publisher_id`]), and what a writer registers so that
    /// readers accept its samples alone.
    pub fn id(&self) -> iceoryx2::identifiers::UniquePublisherId {
        self.port.id()
    }

    /// Subscribers currently connected to the trajectory (for start-up handshakes).
    pub fn subscriber_count(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Which subscribers are connected, as one number that changes whenever the set
    /// does: a reader that came as another went (a killed one cleaned up) leaves the
    /// count alone, and would wait for its history until the next send.
    pub fn readers_fingerprint(&self) -> u128 {
        let mut fingerprint = 0u128;
        self.service.dynamic_config().list_subscribers(|details| {
            // A multiplicative mix, summed: the order of the list does not matter.
            let id = details.subscriber_id.value();
            fingerprint = fingerprint
                .wrapping_add(id.wrapping_mul(0x9e37_79b9_7f4a_7c15_f39c_c060_5ced_c835));
            iceoryx2::prelude::CallbackProgression::Continue
        });
        fingerprint
    }

    /// Wake-ups that could not be sent so far (each failure is logged once).
    pub fn notify_failures(&self) -> u64 {
        self.notify_failures.get()
    }

    /// How many sends skipped the iceoryx2 notify because every connection listening
    /// to it was counted as covered by a thread asleep on the futex word, which feeds
    /// it once woken (see [`crate::unstable::WakeWord`]): for diagnostics and tests.
    pub fn notifies_spared(&self) -> u64 {
        self.notifies_spared.get()
    }

    /// Connects subscribers that appeared since the last send and hands them the
    /// history; see the module docs.
    pub fn update_connections(&self) -> Result<(), PublishError> {
        self.port.update_connections().map_err(PublishError::Connections)
    }

    /// Hands subscribers that connected since the last send their history now, then
    /// wakes every reader: a reader that asked for its history (it rang the
    /// trajectory's join service) knows, once woken, that its queue holds it.
    pub fn welcome(&self) -> Result<(), PublishError> {
        self.update_connections()?;
        // Every listener: the reader that rang waits on its own, which nobody covers.
        self.wake(Listeners::All);
        Ok(())
    }

    /// Encodes `es` into shared memory and sends it to every subscriber.
    ///
    /// The structure is not type-checked here: the caller (the runtime) checks it
    /// against the trajectory's type before publishing.
    pub fn publish(&self, es: &EntityStructure) -> Result<Published, PublishError> {
        self.publish_inner(es.into(), None)
    }

    /// [`Self::publish`] of a structure as a trajectory holds it: an archived one is
    /// copied as it is, never decoded and encoded again.
    pub(crate) fn publish_shared(&self, es: &SharedStructure) -> Result<Published, PublishError> {
        self.publish_inner(es.into(), None)
    }

    /// [`Self::publish`] with the add time the gate gave the structure (a runtime
    /// whose store admitted it at `add_time`), instead of the time of sending.
    pub fn publish_added(
        &self,
        es: &EntityStructure,
        add_time: Time,
    ) -> Result<Published, PublishError> {
        self.publish_inner(es.into(), Some(add_time))
    }

    /// Publishes a structure its writer kept in the trajectory's kept history at `at`,
    /// valid and created at `times`, added at `add_time`: a sample that names the entry
    /// ([`SampleHeader::KIND_KEPT`]), which readers read in place in the file. The
    /// structure's bytes are not written again.
    pub fn publish_kept(
        &self,
        at: &KeptLocation,
        times: (Time, Time),
        add_time: Time,
    ) -> Result<Published, PublishError> {
        let want = blocks_for(SampleHeader::KEPT_PAYLOAD);
        let mut sample = self.loan_blocks(want).map_err(PublishError::Loan)?;
        esgm_core::probe::mark(esgm_core::probe::Step::Loaned);
        let bytes = as_uninit_bytes(sample.payload_mut());
        let bytes = zero_fill(bytes);
        bytes[..8].copy_from_slice(&at.file_id.to_ne_bytes());
        bytes[8..16].copy_from_slice(&at.start.to_ne_bytes());
        // SAFETY: `zero_fill` initialised the whole payload.
        let sample = unsafe { sample.assume_init() };
        esgm_core::probe::mark(esgm_core::probe::Step::Encoded);
        let flags = match at.lineage {
            true => SampleHeader::FLAG_LINEAGE,
            false => 0,
        };
        let kind = (flags, SampleHeader::KIND_KEPT);
        let sent = self.send_kind(sample, at.len, times, kind, Some(add_time), Some(at.index));
        self.loan_spare(want);
        sent
    }

    /// [`Self::publish_added`] for a structure
    /// made from others: `lineage` names them, and travels after the archive in the
    /// same sample ([`SampleHeader::FLAG_LINEAGE`]), so every reader's replica holds it.
    /// An archived structure (one another process wrote, passed on by a merge here) is
    /// copied as it is, never decoded and encoded again.
    pub fn publish_produced(
        &self,
        es: &SharedStructure,
        add_time: Time,
        kept: Option<u64>,
        lineage: Option<&Lineage>,
    ) -> Result<Published, PublishError> {
        let loan = self.loan_structure_traced(es.into(), lineage)?;
        let blocks = loan.blocks();
        let sent = match kept {
            Some(kept) => loan.send_kept(add_time, kept),
            None => loan.send_added(add_time),
        };
        self.loan_spare(blocks);
        sent
    }

    fn publish_inner(
        &self,
        es: Encodable<'_>,
        add_time: Option<Time>,
    ) -> Result<Published, PublishError> {
        let loan = self.loan_structure_traced(es, None)?;
        let blocks = loan.blocks();
        let sent = match add_time {
            Some(add_time) => loan.send_added(add_time),
            None => loan.send(),
        };
        self.loan_spare(blocks);
        sent
    }

    /// Loans the next structure's slice now, after a send, while its readers wake:
    /// the loan's walk over iceoryx2's chunks then costs the next publish nothing.
    /// Failing (every chunk in use) only means the next publish loans itself.
    fn loan_spare(&self, blocks: usize) {
        let mut spare = self.spare.0.borrow_mut();
        if spare.is_none() {
            *spare = self.port.loan_slice_uninit(blocks).ok();
        }
    }

    /// Gives the spare back before a loan of another kind (an image, a reset), so
    /// that the publisher has as many loans for those as it would have without it.
    fn give_back_spare(&self) {
        drop(self.spare.0.borrow_mut().take());
    }

    /// A slice of at least `blocks` blocks: the spare if it fits (large enough, and
    /// not so large that zeroing and sending its slack would cost more than a loan),
    /// or a new loan (the spare is given back first).
    fn loan_blocks(&self, blocks: usize) -> Result<UninitSample, LoanError> {
        if let Some(spare) = self.spare.0.borrow_mut().take() {
            let len = spare.payload().len();
            if (blocks..=blocks.saturating_mul(2).max(SPARE_SLACK_BLOCKS)).contains(&len) {
                return Ok(spare);
            }
        }
        self.port.loan_slice_uninit(blocks)
    }

    /// Encodes `es` into loaned shared memory now, for sending later with
    /// [`StructureLoan::send`] (see `crate::data_plane::structure_loan`): the encoding is done
    /// before the moment the structure has to go.
    pub fn loan_structure(&self, es: &EntityStructure) -> Result<StructureLoan<'_>, PublishError> {
        self.loan_structure_traced(es.into(), None)
    }

    /// [`Self::loan_structure`] with the structure's lineage after the archive.
    fn loan_structure_traced(
        &self,
        es: Encodable<'_>,
        lineage: Option<&Lineage>,
    ) -> Result<StructureLoan<'_>, PublishError> {
        let mut want = es.size_hint();
        if want > self.max_len {
            want = es.encoded_len().map_err(PublishError::Encode)?;
        }
        let lineage_len = lineage.map(codec::lineage_len);
        let mut retried = false;
        loop {
            let total = lineage_len.map_or(want, |l| with_trailer_len(want, l));
            let mut sample = self.loan_blocks(blocks_for(total)).map_err(PublishError::Loan)?;
            esgm_core::probe::mark(esgm_core::probe::Step::Loaned);
            let bytes = as_uninit_bytes(sample.payload_mut());
            match es.write_into_uninit(bytes) {
                Ok(len) => {
                    esgm_core::probe::mark(esgm_core::probe::Step::Encoded);
                    let bytes = zero_fill(&mut bytes[len..]);
                    let mut flags = 0;
                    if let (Some(lineage), Some(lineage_len)) = (lineage, lineage_len) {
                        let at = trailer_start(len) - len;
                        let Some(trailer) = bytes.get_mut(at..at + TRAILER_HEAD + lineage_len)
                        else {
                            // The archive took more than its hint: loan for what it took.
                            want = len;
                            retried = true;
                            continue;
                        };
                        trailer[..8].copy_from_slice(&(lineage_len as u64).to_le_bytes());
                        codec::encode_lineage_into(lineage, &mut trailer[TRAILER_HEAD..])
                            .map_err(PublishError::Encode)?;
                        flags |= SampleHeader::FLAG_LINEAGE;
                    }
                    // SAFETY: the encoder initialised `..len` (it promises every byte it
                    // reports) and `zero_fill` the rest of the payload.
                    let sample = unsafe { sample.assume_init() };
                    return Ok(StructureLoan::new(self, sample, len, es.times(), flags));
                }
                Err(CodecError::BufferTooSmall { needed, .. }) if !retried => {
                    tracing::debug!(trajectory = %self.trajectory, hint = want, needed,
                        "size hint too small, loaning again");
                    want = needed;
                    retried = true;
                }
                Err(e) => return Err(PublishError::Encode(e)),
            }
        }
    }

    /// Loans shared memory for an image of `width × height` pixels in `format`
    /// ([`esgm_core::library::Image`]'s formats) for the caller to fill in place; see
    /// [`ImageLoan`].
    pub fn loan_image(
        &self,
        width: i64,
        height: i64,
        format: i64,
    ) -> Result<ImageLoan<'_>, PublishError> {
        Ok(ImageLoan::new(self, self.loan_image_chunk(width, height, format)?))
    }

    /// [`Self::loan_image`] apart from the publisher: the runtime keeps the chunk while
    /// the pixels are written and completes it with [`ImageChunk::complete`].
    pub(crate) fn loan_image_chunk(
        &self,
        width: i64,
        height: i64,
        format: i64,
    ) -> Result<ImageChunk, PublishError> {
        let pixel_len = pixel_len(width, height, format)?;
        self.give_back_spare();
        let sample = self
            .port
            .loan_slice_uninit(blocks_for(image_loan_len(pixel_len)))
            .map_err(PublishError::Loan)?;
        Ok(ImageChunk::new(sample, (width, height, format), pixel_len))
    }

    /// Fills the header, sends, and wakes sleeping readers; the add time is `add_time`,
    /// or the time of sending.
    pub(crate) fn send(
        &self,
        sample: LoanedSample,
        archive_len: usize,
        times: (Time, Time),
        flags: u32,
        add_time: Option<Time>,
        kept: Option<u64>,
    ) -> Result<Published, PublishError> {
        let kind = (flags, SampleHeader::KIND_STRUCTURE);
        self.send_kind(sample, archive_len, times, kind, add_time, kept)
    }

    /// Tells every reader that the trajectory was reset (T5): a marker sample
    /// ([`SampleHeader::KIND_RESET`]) in stream order, so a reader forgets exactly the
    /// samples sent before it.
    pub fn publish_reset(&self) -> Result<Published, PublishError> {
        self.give_back_spare();
        let mut sample = self.port.loan_slice_uninit(1).map_err(PublishError::Loan)?;
        zero_fill(as_uninit_bytes(sample.payload_mut()));
        // SAFETY: `zero_fill` initialised the whole payload.
        let sample = unsafe { sample.assume_init() };
        let now = self.clock.now();
        self.send_kind(sample, 0, (now, now), (0, SampleHeader::KIND_RESET), None, None)
    }

    fn send_kind(
        &self,
        mut sample: LoanedSample,
        archive_len: usize,
        (valid_time, create_time): (Time, Time),
        (flags, kind): (u32, u32),
        add_time: Option<Time>,
        kept: Option<u64>,
    ) -> Result<Published, PublishError> {
        let sequence = self.sequence.get();
        *sample.user_header_mut() = SampleHeader {
            valid_time,
            create_time,
            add_time: add_time.unwrap_or_else(|| self.clock.now()),
            archive_len: archive_len as u64,
            type_id: self.type_id,
            sequence,
            kind,
            flags,
            kept: kept.map_or(0, |index| index + 1),
        };
        let sent = sample.send();
        esgm_core::probe::mark(esgm_core::probe::Step::Sent);
        if matches!(sent, Ok(_) | Err(SendError::UnableToDeliver)) {
            // Delivered to every reader, or to all but the ones that stayed full past
            // the timeout: either way the number is used, so a reader that missed it
            // sees a gap in the sequence and counts the sample as lost.
            self.sequence.set(sequence + 1);
            self.wake(Listeners::Uncovered);
            esgm_core::probe::mark(esgm_core::probe::Step::Rung);
        }
        let subscribers = sent.map_err(|e| match e {
            SendError::UnableToDeliver => {
                PublishError::NotDelivered { timeout: self.lossless_timeout }
            }
            e => PublishError::Send(e),
        })?;
        Ok(Published { sequence, subscribers })
    }

    /// Gives up a structure the writer admitted but could not send (no loan, no
    /// encoding, a failed send): its sequence number is used anyway, so every reader
    /// sees the gap and counts the structure as lost, instead of never knowing of it.
    pub fn forgo(&self) {
        self.sequence.set(self.sequence.get() + 1);
    }

    fn wake(&self, listeners: Listeners) {
        if let Some(word) = &self.word {
            // Read after the ring's sequentially consistent add: a listener made before
            // this send is counted.
            let ring = word.ring_counting(|| self.wake.dynamic_config().number_of_listeners());
            if ring.covered && matches!(listeners, Listeners::Uncovered) {
                self.notifies_spared.set(self.notifies_spared.get() + 1);
                SPARED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                word.notify_spared();
                return;
            }
            // A receiver's process died: its listener went, its count stays.
            if ring.listeners < ring.receivers as usize {
                word.receivers_unheard();
            }
        }
        // A failed wake-up is not a failed publish: the sample is delivered, and a
        // reader's timed wait bounds the delay. Log the first, count all.
        if let Err(e) = self.notifier.notify() {
            let n = self.notify_failures.get();
            self.notify_failures.set(n + 1);
            if n == 0 {
                tracing::warn!(trajectory = %self.trajectory, error = ?e,
                    "cannot wake readers (later failures are only counted)");
            }
        }
    }
}
