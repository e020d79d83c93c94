//! Policy violations across processes (C7): the writer of a trajectory publishes every
//! structure its policy drops on the trajectory's violations service, and any process
//! can subscribe.
//!
//! | service                     | pattern           | carries                              |
//! |-----------------------------|-------------------|--------------------------------------|
//! | `esgm/<domain>/viol/<name>` | publish-subscribe | one [`ViolationRecord`] per drop     |
//! | `esgm/<domain>/viol/<name>` | event             | wake-ups for blocking subscribers    |
//!
//! iceoryx2 tells services apart by name *and* messaging pattern, so the wake-up event
//! shares the data service's name.
//!
//! A record is a fixed-size, plain-integer struct: which constraint, the structure's
//! valid and create times and when it was offered — what a monitor needs to count and
//! plot drops, and nothing a hostile peer could make undefined (an unknown constraint
//! code is a typed rejection). The human-readable detail of the in-process
//! [`PolicyViolation`] stays in the writer's log; a subscriber gets a generic one.
//!
//! Violations are not history: like the in-process store's violation subscription, a
//! subscriber sees the drops from when it connected. A slow subscriber loses the
//! oldest ones rather than stall the writer; the record's sequence number shows the gap
//! ([`ViolationSubscriberStats::lost`]).

use crate::data_plane::capacity::{EventCapacity, Readers};
use crate::data_plane::service::ShmService;
use std::cell::{Cell, RefCell};
use std::time::Duration;

use bytemuck::{Pod, Zeroable};
use esgm_core::{Constraint, PolicyViolation, Time};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{ServiceName, ZeroCopySend};
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::data_plane::publisher::PublishError;
use crate::data_plane::sequence_gaps::SequenceGaps;
use crate::data_plane::service::{OpenError, ShmNode, with_room};
use crate::data_plane::service_name::{
    DEFAULT_DOMAIN, NameError, SERVICE_PREFIX, TrajectoryServiceNames,
};
use crate::data_plane::subscriber::ReceiveError;
use crate::data_plane::wait::{Sleeper, WaitStrategy, Waiter, deadline_after};

/// Unread violations a subscriber can queue before the oldest are overwritten.
pub const VIOLATION_BUFFER: usize = 64;

/// `esgm/<domain>/viol/<trajectory>`, unchecked.
pub fn violation_service_name(domain: &str, trajectory: &str) -> String {
    format!("{SERVICE_PREFIX}/{domain}/viol/{trajectory}")
}

/// One dropped structure, as it travels between processes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[repr(C)]
#[type_name("esgm.ViolationRecord.v1")]
pub struct ViolationRecord {
    /// The structure's valid time.
    pub valid_time: Time,
    /// The structure's create time.
    pub create_time: Time,
    /// When it was offered to the writer (the writer's clock).
    pub add_time: Time,
    /// Per-writer counter, +1 per record; a gap means records were overwritten.
    pub sequence: u64,
    /// The constraint broken: `constraint_code`; 0 is never written.
    pub constraint: u32,
    /// Zero; room to grow.
    pub reserved: u32,
}

const _: () = assert!(std::mem::size_of::<ViolationRecord>() == 40);

/// The wire code of a constraint (1–6, in the seed's C1–C6 order of [`Constraint`]).
pub fn constraint_code(c: Constraint) -> u32 {
    match c {
        Constraint::Change => 1,
        Constraint::Cache => 2,
        Constraint::Filter => 3,
        Constraint::Duration => 4,
        Constraint::Order => 5,
        Constraint::Delay => 6,
    }
}

/// The constraint of a wire code, if it names one.
pub fn constraint_from_code(code: u32) -> Option<Constraint> {
    Constraint::ALL.into_iter().find(|c| constraint_code(*c) == code)
}

impl ViolationRecord {
    /// The record of `v`.
    pub fn new(v: &PolicyViolation, sequence: u64) -> Self {
        Self {
            valid_time: v.valid_time,
            create_time: v.create_time,
            add_time: v.add_time,
            sequence,
            constraint: constraint_code(v.constraint),
            reserved: 0,
        }
    }

    /// The constraint broken, if the code names one.
    pub fn constraint(&self) -> Option<Constraint> {
        constraint_from_code(self.constraint)
    }

    /// The violation as the in-process store reports it, with a generic detail; `None`
    /// if the constraint code is unknown.
    pub fn to_violation(&self, trajectory: &str) -> Option<PolicyViolation> {
        let constraint = self.constraint()?;
        Some(PolicyViolation {
            trajectory: trajectory.to_owned(),
            constraint,
            valid_time: self.valid_time,
            create_time: self.create_time,
            add_time: self.add_time,
            detail: format!("broke the {constraint} constraint (reported by the writer)"),
        })
    }
}

type ViolationService = publish_subscribe::PortFactory<ShmService, ViolationRecord, ()>;

struct ViolationServices {
    data: ViolationService,
    wake: event::PortFactory<ShmService>,
}

fn open_services(
    node: &ShmNode,
    domain: &str,
    trajectory: &str,
    readers: Readers,
) -> Result<ViolationServices, OpenError> {
    // Checks the domain and name characters the same way as for the data services.
    TrajectoryServiceNames::new(domain, trajectory)?;
    let text = violation_service_name(domain, trajectory);
    let name = ServiceName::new(&text)
        .map_err(|_| NameError::TooLong { service: text.clone(), max: ServiceName::max_len() })?;
    // Settings every opener derives alike: fixed, but for the trajectory's readers.
    let data = node
        .service_builder(&name)
        .publish_subscribe::<ViolationRecord>()
        .history_size(0)
        .subscriber_max_buffer_size(VIOLATION_BUFFER)
        .subscriber_max_borrowed_samples(2)
        .max_publishers(2)
        .max_subscribers(readers.ports())
        .max_nodes(readers.nodes())
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|source| OpenError::DataService { service: text.clone(), source })?;
    let wake = crate::data_plane::service::open_event_service(
        node,
        &name,
        EventCapacity::violations(readers),
    )?;
    Ok(ViolationServices { data, wake })
}

/// Publishes a trajectory's violations; used by the writer's tap in [`crate::connect`].
#[derive(Debug)]
pub struct ViolationPublisher {
    port: Publisher<ShmService, ViolationRecord, ()>,
    notifier: Notifier<ShmService>,
    sequence: Cell<u64>,
}

impl ViolationPublisher {
    /// Opens (or creates) the violations service of `trajectory` in `domain`, read by
    /// `readers` processes.
    pub fn create(
        node: &ShmNode,
        domain: &str,
        trajectory: &str,
        readers: Readers,
    ) -> Result<Self, OpenError> {
        with_room(OpenError::lacks_room, || {
            let services = open_services(node, domain, trajectory, readers)?;
            let port = services.data.publisher_builder().create().map_err(OpenError::Publisher)?;
            let notifier =
                services.wake.notifier_builder().create().map_err(OpenError::Notifier)?;
            Ok(Self { port, notifier, sequence: Cell::new(0) })
        })
    }

    /// Sends `v` to every subscriber and wakes sleeping ones.
    pub fn publish(&self, v: &PolicyViolation) -> Result<(), PublishError> {
        let sequence = self.sequence.get();
        self.port.send_copy(ViolationRecord::new(v, sequence)).map_err(PublishError::Send)?;
        self.sequence.set(sequence + 1);
        // A lost wake-up only delays a blocking subscriber until its timeout.
        let _ = self.notifier.notify();
        Ok(())
    }
}

/// What a violation subscriber has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ViolationSubscriberStats {
    /// Records received, good or bad.
    pub received: u64,
    /// Records with an unknown constraint code (dropped).
    pub malformed: u64,
    /// Records overwritten before this subscriber read them (sequence gaps).
    pub lost: u64,
}

/// Builds a [`ViolationSubscriber`].
#[derive(Debug, Clone)]
pub struct ViolationSubscriberBuilder {
    trajectory: String,
    domain: String,
    wait: WaitStrategy,
    readers: Readers,
}

impl ViolationSubscriberBuilder {
    /// The trajectory's readers, which size its violations service; default
    /// [`Readers::default`].
    pub fn readers(mut self, readers: Readers) -> Self {
        self.readers = readers;
        self
    }

    /// The domain of the trajectory; default [`DEFAULT_DOMAIN`].
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = domain.into();
        self
    }

    /// How [`ViolationSubscriber::wait`] waits; default [`WaitStrategy::Block`]
    /// (violations are rare and not worth a spinning core).
    pub fn wait_strategy(mut self, wait: WaitStrategy) -> Self {
        self.wait = wait;
        self
    }

    /// Opens (or creates) the violations service and the subscriber port on `node`.
    pub fn create(self, node: &ShmNode) -> Result<ViolationSubscriber, OpenError> {
        // A crashed process's ports hold their room until someone cleans up after it.
        with_room(OpenError::lacks_room, || self.open(node))
    }

    fn open(&self, node: &ShmNode) -> Result<ViolationSubscriber, OpenError> {
        let services = open_services(node, &self.domain, &self.trajectory, self.readers)?;
        let port = services.data.subscriber_builder().create().map_err(OpenError::Subscriber)?;
        let listener = if self.wait.blocks() {
            Some(services.wake.listener_builder().create().map_err(OpenError::Listener)?)
        } else {
            None
        };
        Ok(ViolationSubscriber {
            trajectory: self.trajectory.clone(),
            port,
            waiter: Waiter::new(self.wait, listener.map(|l| Sleeper::Listener(Box::new(l)))),
            stats: Cell::new(ViolationSubscriberStats::default()),
            gaps: RefCell::new(SequenceGaps::default()),
        })
    }
}

/// Receives a trajectory's policy violations from its writer, in another process.
#[derive(Debug)]
pub struct ViolationSubscriber {
    trajectory: String,
    port: Subscriber<ShmService, ViolationRecord, ()>,
    waiter: Waiter,
    stats: Cell<ViolationSubscriberStats>,
    gaps: RefCell<SequenceGaps>,
}

impl ViolationSubscriber {
    /// A builder for a subscriber to the violations of `trajectory`.
    pub fn builder(trajectory: impl Into<String>) -> ViolationSubscriberBuilder {
        ViolationSubscriberBuilder {
            trajectory: trajectory.into(),
            domain: DEFAULT_DOMAIN.to_owned(),
            wait: WaitStrategy::Block,
            readers: Readers::default(),
        }
    }

    /// The trajectory whose violations arrive here.
    pub fn trajectory(&self) -> &str {
        &self.trajectory
    }

    /// Counters of records seen, rejected and lost.
    pub fn stats(&self) -> ViolationSubscriberStats {
        self.stats.get()
    }

    /// The next violation if one is queued; never blocks. A record with an unknown
    /// constraint code is counted and returned as [`ReceiveError::UnknownKind`].
    pub fn receive(&self) -> Result<Option<PolicyViolation>, ReceiveError> {
        let (record, publisher) = match self.port.receive() {
            Ok(Some(sample)) => (*sample.payload(), sample.header().publisher_id()),
            Ok(None) => return Ok(None),
            Err(iceoryx2::port::ReceiveError::ExceedsMaxBorrows) => {
                return Err(ReceiveError::TooManyHeld);
            }
            Err(e) => return Err(ReceiveError::Connection(e)),
        };
        let mut stats = self.stats.get();
        stats.received += 1;
        let lost = self.gaps.borrow_mut().observe(publisher, record.sequence);
        stats.lost = stats.lost.saturating_add(lost);
        let violation = record.to_violation(&self.trajectory);
        if violation.is_none() {
            stats.malformed += 1;
        }
        self.stats.set(stats);
        match violation {
            Some(v) => Ok(Some(v)),
            None => Err(ReceiveError::UnknownKind { kind: record.constraint }),
        }
    }

    /// Waits up to `timeout` for the next violation; `Ok(None)` if none came.
    pub fn wait(&self, timeout: Duration) -> Result<Option<PolicyViolation>, ReceiveError> {
        self.waiter.wait(deadline_after(timeout), || self.receive())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constraint_codes_round_trip() {
        for c in Constraint::ALL {
            assert_eq!(constraint_from_code(constraint_code(c)), Some(c));
        }
        assert_eq!(constraint_from_code(0), None);
        assert_eq!(constraint_from_code(7), None);
    }

    #[test]
    fn records_carry_the_violation() {
        let v = PolicyViolation {
            trajectory: "t".into(),
            constraint: Constraint::Delay,
            valid_time: 1,
            create_time: 2,
            add_time: 3,
            detail: "late".into(),
        };
        let r = ViolationRecord::new(&v, 9);
        assert_eq!((r.sequence, r.constraint()), (9, Some(Constraint::Delay)));
        let back = r.to_violation("t").unwrap();
        assert_eq!(
            (back.constraint, back.valid_time, back.create_time, back.add_time),
            (v.constraint, v.valid_time, v.create_time, v.add_time)
        );
        assert_eq!(ViolationRecord { constraint: 99, ..r }.to_violation("t"), None);
    }
}
