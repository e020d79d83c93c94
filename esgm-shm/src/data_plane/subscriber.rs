//! The reading end of a trajectory: takes samples from shared memory, rejects and
//! counts bad ones, and waits with a [`WaitStrategy`].
//!
//! Every sample goes through [`check_sample`] (the header's type id, kind and archive
//! length, then with [`Validation::InPlace`], the default, the archive itself); see
//! `crate::data_plane::sample_check` for the order and why it is one pure function.
//!
//! A sample failing any check is returned to iceoryx2 at once and reported as a typed
//! [`ReceiveError`]; the counters in [`SubscriberStats`] say how often. Nothing a peer
//! writes can make the reader panic.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use esgm_core::codec::CodecError;
use iceoryx2::identifiers::UniquePublisherId;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::service::port_factory::PortFactory;

use crate::data_plane::kept::{KeptAt, KeptReader};
use crate::data_plane::payload::{SampleHeader, as_bytes};
use crate::data_plane::qos::TrajectoryQos;
use crate::data_plane::received::SubscriberPort;
use crate::data_plane::received::{Checked, Counters, ReceivedSample};
use crate::data_plane::sample_check::{SampleVerdict, check_sample};
use esgm_core::esgm::{Limit, LimitReached};

use crate::data_plane::service::{
    DataService, OpenError, ShmNode, open_data_service, open_wake_service, with_room,
};
use crate::data_plane::service_name::{DEFAULT_DOMAIN, TrajectoryServiceNames};
use crate::data_plane::type_id::type_id;
use crate::data_plane::wait::{Sleeper, WaitStrategy, Waiter, deadline_after};

/// When a subscriber validates archives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum Validation {
    /// Validate every sample in [`TrajectorySubscriber::receive`]: a malformed sample is
    /// never handed out. The right choice whenever bytes come from another process.
    #[default]
    InPlace,
    /// Check only the header on receive; validate on the first
    /// [`ReceivedSample::structure`] call, or skip validation with the unsafe
    /// [`ReceivedSample::structure_unchecked`] in a setup that trusts every publisher.
    /// For readers that drop most samples on header fields alone.
    OnAccess,
}

/// A sample could not be taken or was rejected.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReceiveError {
    /// The subscriber already holds `max_borrowed_samples` samples; drop some (or raise
    /// [`TrajectoryQos::max_borrowed_samples`]) and receive again.
    #[error("too many samples held; drop some before receiving more")]
    TooManyHeld,
    /// iceoryx2 could not connect to a publisher (its resources are gone or corrupt);
    /// retry later — dead publishers are cleaned up by the next node creation.
    #[error("connection to a publisher failed: {0}")]
    Connection(#[source] iceoryx2::port::ReceiveError),
    /// The sample's type id is not the subscriber's: something publishes another type
    /// on this trajectory. The sample was dropped; fix the producer's configuration.
    #[error("sample of type id {found:#018x}, expected {expected:#018x}")]
    TypeMismatch {
        /// The subscriber's type id.
        expected: u64,
        /// The sample's.
        found: u64,
    },
    /// Not a fault: the writer reset the trajectory (T5). Forget every sample received
    /// before this point, then receive again. `sequence` is the marker's number.
    #[error("the trajectory was reset (sequence {sequence})")]
    Reset {
        /// The marker's sequence number.
        sequence: u64,
        /// The publisher that sent the marker (sequence numbers are per publisher).
        publisher: UniquePublisherId,
    },
    /// The header names a payload kind this build does not know (a newer or foreign
    /// writer). The sample was dropped.
    #[error("unknown sample kind {kind}")]
    UnknownKind {
        /// The header's kind.
        kind: u32,
    },
    /// The header claims more (or fewer) bytes than an archive can have in the payload
    /// delivered. The sample was dropped.
    #[error("header says {archive_len} archive bytes, payload holds {payload_len}")]
    Truncated {
        /// The header's archive length.
        archive_len: u64,
        /// The bytes delivered.
        payload_len: usize,
    },
    /// The archive failed validation (bad envelope, corrupt archive, or header times
    /// that differ from the archive's). The sample was dropped.
    #[error("malformed sample: {0}")]
    Malformed(#[source] CodecError),
    /// The sample names an entry of the trajectory's kept history that the file no
    /// longer holds: the writer wrote over it before this reader took it (it fell
    /// behind). The sample is lost (counted by the gap it leaves).
    #[error("kept entry {index} is no longer in its file (this reader fell behind)")]
    KeptGone {
        /// The entry's index.
        index: u64,
    },
    /// The trajectory's kept history, which the sample names, cannot be opened or
    /// mapped here (another user's file, no memory): the sample is lost, counted.
    #[error("the kept history cannot be read: {0}")]
    KeptUnreadable(String),
    /// Waiting was interrupted (e.g. by a signal) or the wake-up listener failed;
    /// check for shutdown, then wait again.
    #[error("wait interrupted: {0}")]
    Wait(#[from] ListenerWaitError),
}

impl ReceiveError {
    /// Why the bytes that arrived are not a sample of the trajectory, as a store counts
    /// it ([`esgm_core::DropCause::Rejected`]); `None` if nothing was received (the port
    /// could not receive now) or the arrival is a reset marker. One mapping for every
    /// reader of another process's bytes: a replica's import and a writer's inbox.
    pub fn rejection(&self) -> Option<esgm_core::Rejection> {
        use esgm_core::Rejection;
        match self {
            ReceiveError::Malformed(_) => Some(Rejection::Malformed),
            ReceiveError::TypeMismatch { .. } => Some(Rejection::WrongType),
            ReceiveError::UnknownKind { .. } => Some(Rejection::UnknownKind),
            ReceiveError::Truncated { .. } => Some(Rejection::Truncated),
            ReceiveError::KeptUnreadable(_) => Some(Rejection::Unreadable),
            ReceiveError::TooManyHeld
            | ReceiveError::Connection(_)
            | ReceiveError::Reset { .. }
            | ReceiveError::KeptGone { .. }
            | ReceiveError::Wait(_) => None,
        }
    }
}

/// What a subscriber has seen so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SubscriberStats {
    /// Samples taken from shared memory, good or bad.
    pub received: u64,
    /// Samples rejected as malformed (unknown kind, bad length, failed validation).
    pub malformed: u64,
    /// Samples rejected because their type id was not the subscriber's.
    pub type_mismatch: u64,
}

/// Builds a [`TrajectorySubscriber`]; every setting has a default.
#[derive(Debug, Clone)]
pub struct TrajectorySubscriberBuilder {
    trajectory: String,
    type_name: String,
    domain: String,
    qos: TrajectoryQos,
    history: Option<usize>,
    wait: WaitStrategy,
    validation: Validation,
    reader_limit: Option<usize>,
}

impl TrajectorySubscriberBuilder {
    /// Refuses to subscribe, with [`esgm_core::esgm::LimitReached`], when the
    /// trajectory already has `limit` subscribers: a long-lived reader counts itself
    /// against the trajectory's `readers`, and leaves the ports beyond them to
    /// short-lived tools ([`crate::DomainLimits`]). Default: no count (iceoryx2's own
    /// limit alone).
    pub fn reader_limit(mut self, limit: usize) -> Self {
        self.reader_limit = Some(limit);
        self
    }

    /// The domain (namespace) of the trajectory; default [`DEFAULT_DOMAIN`].
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = domain.into();
        self
    }

    /// The service settings, used if this subscriber creates the service (see
    /// `crate::data_plane::qos`); default [`TrajectoryQos::default`].
    pub fn qos(mut self, qos: TrajectoryQos) -> Self {
        self.qos = qos;
        self
    }

    /// How many of the publisher's last samples to receive on connecting (at most the
    /// service's history size); default: all the service keeps.
    pub fn history(mut self, last_n: usize) -> Self {
        self.history = Some(last_n);
        self
    }

    /// How [`TrajectorySubscriber::wait_for_sample`] waits; default
    /// [`WaitStrategy::default`].
    pub fn wait_strategy(mut self, wait: WaitStrategy) -> Self {
        self.wait = wait;
        self
    }

    /// When archives are validated; default [`Validation::InPlace`].
    pub fn validation(mut self, validation: Validation) -> Self {
        self.validation = validation;
        self
    }

    /// Opens (or creates) the trajectory's services and the subscriber port on `node`.
    pub fn create(self, node: &ShmNode) -> Result<TrajectorySubscriber, OpenError> {
        // A crashed process's ports hold their room until someone cleans up after it.
        with_room(OpenError::lacks_room, || self.open(node))
    }

    fn open(&self, node: &ShmNode) -> Result<TrajectorySubscriber, OpenError> {
        let names = TrajectoryServiceNames::new(&self.domain, &self.trajectory)?;
        let service = open_data_service(node, &names, &self.qos)?;
        if let Some(limit) = self.reader_limit {
            // Counted before the port is made, so the reserve beyond `limit` stays for
            // tools ([`crate::data_plane::capacity`]); iceoryx2's own count is the backstop.
            if service.dynamic_config().number_of_subscribers() >= limit {
                return Err(OpenError::LimitReached(LimitReached::trajectory(
                    Limit::Readers,
                    &self.trajectory,
                    limit,
                )));
            }
        }
        let mut port = service.subscriber_builder();
        if let Some(n) = self.history {
            port = port.history_request(n);
        }
        let port = port.create().map_err(OpenError::Subscriber)?;
        let sleeper = if self.wait.blocks() {
            Some(Sleeper::open(names.wake().as_str(), || {
                let wake = open_wake_service(node, &names, &self.qos)?;
                wake.listener_builder().create().map_err(OpenError::Listener)
            })?)
        } else {
            None
        };
        Ok(TrajectorySubscriber {
            expected_type_id: type_id(&self.type_name),
            trajectory: self.trajectory.clone(),
            type_name: self.type_name.clone(),
            service,
            port: Arc::new(port),
            waiter: Waiter::new(self.wait, sleeper),
            validation: self.validation,
            counters: Arc::default(),
            kept: parking_lot::Mutex::new(None),
            domain: self.domain.clone(),
        })
    }
}

/// The reading end of one trajectory in shared memory.
#[derive(Debug)]
pub struct TrajectorySubscriber {
    trajectory: String,
    type_name: String,
    expected_type_id: u64,
    service: DataService,
    /// Shared with every sample taken from it (see [`ReceivedSample`]): iceoryx2 gives a
    /// publisher back every chunk of a subscriber port that is gone, so the port lives
    /// as long as the last sample that reads one.
    port: Arc<SubscriberPort>,
    waiter: Waiter,
    validation: Validation,
    counters: Arc<Counters>,
    /// The trajectory's kept history, where samples of [`SampleHeader::KIND_KEPT`] are
    /// read; opened at the first.
    kept: parking_lot::Mutex<Option<KeptReader>>,
    domain: String,
}

impl TrajectorySubscriber {
    /// A builder for a subscriber to `trajectory`, whose structures are of the entity
    /// structure type `type_name`.
    pub fn builder(
        trajectory: impl Into<String>,
        type_name: impl Into<String>,
    ) -> TrajectorySubscriberBuilder {
        TrajectorySubscriberBuilder {
            trajectory: trajectory.into(),
            type_name: type_name.into(),
            domain: DEFAULT_DOMAIN.to_owned(),
            qos: TrajectoryQos::default(),
            history: None,
            wait: WaitStrategy::default(),
            validation: Validation::default(),
            reader_limit: None,
        }
    }

    /// The trajectory's name.
    pub fn trajectory(&self) -> &str {
        &self.trajectory
    }

    /// The entity structure type this subscriber accepts.
    pub fn type_name(&self) -> &str {
        &self.type_name
    }

    /// Publishers currently connected to the trajectory (for start-up handshakes).
    pub fn publisher_count(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }

    /// Counters of samples seen and rejected.
    pub fn stats(&self) -> SubscriberStats {
        SubscriberStats {
            received: self.counters.received.load(Ordering::Relaxed),
            malformed: self.counters.malformed.load(Ordering::Relaxed),
            type_mismatch: self.counters.type_mismatch.load(Ordering::Relaxed),
        }
    }

    /// Takes the next sample if one is queued; never blocks.
    pub fn receive(&self) -> Result<Option<ReceivedSample>, ReceiveError> {
        let sample = match self.port.receive() {
            Ok(Some(sample)) => sample,
            Ok(None) => return Ok(None),
            Err(iceoryx2::port::ReceiveError::ExceedsMaxBorrows) => {
                return Err(ReceiveError::TooManyHeld);
            }
            Err(e) => return Err(ReceiveError::Connection(e)),
        };
        let c = &self.counters;
        c.received.fetch_add(1, Ordering::Relaxed);
        let header = *sample.user_header();
        let checked = check_sample(
            &header,
            as_bytes(sample.payload()),
            self.expected_type_id,
            self.validation,
        );
        let (archive_len, validated) = match checked {
            Ok(SampleVerdict::Structure { bytes, archived }) => (bytes.len(), archived.is_some()),
            Ok(SampleVerdict::Kept { file_id, index, start, len }) => {
                let publisher = sample.header().publisher_id();
                // The descriptor goes back to the publisher at once: the entry is in the
                // file, held by the sample made of it.
                drop(sample);
                let lineage = header.has_flag(SampleHeader::FLAG_LINEAGE);
                let at = KeptAt { index, file_id, start, len, lineage };
                return self.take_kept(header, publisher, at).map(Some);
            }
            Ok(SampleVerdict::Reset { sequence }) => {
                return Err(ReceiveError::Reset {
                    sequence,
                    publisher: sample.header().publisher_id(),
                });
            }
            Err(e @ ReceiveError::TypeMismatch { .. }) => {
                if c.type_mismatch.fetch_add(1, Ordering::Relaxed) == 0 {
                    tracing::warn!(trajectory = %self.trajectory, expected = %self.type_name,
                        found = header.type_id, "dropping a sample of another type");
                }
                return Err(e);
            }
            Err(e) => {
                if c.count_malformed() {
                    tracing::warn!(trajectory = %self.trajectory, error = %e,
                        "dropping a malformed sample (later ones are only counted)");
                }
                return Err(e);
            }
        };
        Ok(Some(if validated {
            ReceivedSample::new(sample, &self.port, archive_len, Checked::Valid, None)
        } else {
            ReceivedSample::new(
                sample,
                &self.port,
                archive_len,
                Checked::No,
                Some(Arc::clone(&self.counters)),
            )
        }))
    }

    /// The kept entry a sample of [`SampleHeader::KIND_KEPT`] named, taken from the
    /// trajectory's kept history and checked there.
    fn take_kept(
        &self,
        header: SampleHeader,
        publisher: UniquePublisherId,
        at: KeptAt,
    ) -> Result<ReceivedSample, ReceiveError> {
        let index = at.index;
        let taken = {
            let mut kept = self.kept.lock();
            let reader =
                kept.get_or_insert_with(|| KeptReader::new(&self.domain, &self.trajectory));
            reader.take(at)
        };
        let malformed = |e: CodecError| {
            if self.counters.count_malformed() {
                tracing::warn!(trajectory = %self.trajectory, error = %e,
                    "dropping a malformed kept entry (later ones are only counted)");
            }
            ReceiveError::Malformed(e)
        };
        match taken {
            Ok(Some(taken)) => ReceivedSample::kept(taken, header, publisher).map_err(malformed),
            Ok(None) => Err(ReceiveError::KeptGone { index }),
            Err(e) => Err(ReceiveError::KeptUnreadable(e.to_string())),
        }
    }

    /// Waits up to `timeout` for the next sample, with the subscriber's
    /// [`WaitStrategy`]. `Ok(None)` means the timeout passed; a rejected sample ends the
    /// wait with its error (call again to keep waiting).
    pub fn wait_for_sample(
        &self,
        timeout: Duration,
    ) -> Result<Option<ReceivedSample>, ReceiveError> {
        self.waiter.wait(deadline_after(timeout), || self.receive())
    }
}
