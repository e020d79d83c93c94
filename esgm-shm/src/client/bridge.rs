//! The two halves of mirroring a trajectory through shared memory.
//!
//! - An [`Export`] takes every event of a trajectory this process writes (the local
//!   store's [`esgm_core::TrajectoryStore::tap`]: entries, violations, resets, in
//!   order) and publishes it on the trajectory's services, stamped with the gate's add
//!   time.
//! - An [`Import`] receives a trajectory another process writes and feeds a local
//!   replica ([`esgm_core::InProcessEsgm::create_replica`]), so local units, syncs,
//!   queries and subscriptions read it like a local trajectory.
//!
//! - Adding to a primitive trajectory another process writes goes through its
//!   *inbox*: the replica forwards the structure (after the type check) to the location
//!   thread, which publishes it on the inbox service (`<domain>:inbox`); the writer's
//!   export takes it from there and adds it through its policy gate, so every process
//!   can push into one trajectory and the one gate orders, checks and counts them all.
//!
//! Both live on the location thread, which owns every iceoryx2 port of the process.

use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use esgm_core::policy::FluentStreamPolicy;
use esgm_core::value::ValueSort;
use esgm_core::{
    AddError, AddForwarder, AddOutcome, CacheConstraint, EntityStructure, EntityStructureType,
    EntityTrajectoryStructure, InProcessTrajectory, StoreEvent,
};

use crate::history::{DEFAULT_MAX_HISTORY, history_bound, history_qos};
use crate::holdings::{Holdings, OwnerId};
use crate::publisher::TrajectoryPublisher;
use crate::qos::TrajectoryQos;
use crate::service::{OpenError, ShmNode};
use crate::service_name::{NameError, TrajectoryServiceNames};
use crate::subscriber::{ReceiveError, TrajectorySubscriber};
use crate::violations::{ViolationPublisher, ViolationSubscriber, violation_service_name};
use crate::wait::WaitStrategy;
use iceoryx2::prelude::ServiceName;

/// A bridge could not be set up.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BridgeError {
    /// The services could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// The local trajectory was destroyed meanwhile.
    #[error("trajectory `{trajectory}` was destroyed meanwhile")]
    Gone { trajectory: String },
}

/// Events a trajectory's tap can queue before the location thread drains them (more
/// are counted as overflow in the trajectory's stats).
pub(crate) const TAP_CAPACITY: usize = 4096;

/// The most samples of a trajectory carrying octets (images, blobs of bytes) kept in
/// shared memory for late readers when its cache has no element bound: every kept
/// sample reserves its full size in every reader's segment, so `All` with the default
/// 1024 would map gigabytes for a camera.
pub(crate) const MAX_OCTET_HISTORY: usize = 16;

/// Samples a replica may keep borrowed beyond its cache's bound: images that units,
/// subscriptions and query answers still read after the cache evicted them (see
/// [`crate::holdings`]). Past it, images are copied (and counted).
pub(crate) const HOLD_SLACK: usize = 8;

/// The service settings both ends of a bridged trajectory use: the publisher keeps
/// the cache's bound of samples, so a replica made late starts with the writer's view,
/// and a replica may borrow that many plus [`HOLD_SLACK`], so the images it holds stay
/// in shared memory. A trajectory of `entity_type` with octets and no element bound
/// keeps [`MAX_OCTET_HISTORY`] (both ends derive the same bound from the same inputs).
pub(crate) fn bridge_qos(
    policy: &FluentStreamPolicy,
    entity_type: &EntityStructureType,
) -> TrajectoryQos {
    let octets = entity_type.attributes.iter().any(|a| a.sort == ValueSort::OctetSeq);
    let bound = match policy.cache {
        CacheConstraint::Elements(n) if n > 0 => n,
        _ if octets => MAX_OCTET_HISTORY,
        _ => history_bound(policy.cache, DEFAULT_MAX_HISTORY),
    };
    let qos = history_qos(bound, TrajectoryQos::default());
    TrajectoryQos { max_borrowed_samples: qos.max_borrowed_samples + HOLD_SLACK, ..qos }
}

/// The bridged history of `handle`'s trajectory, warning once where a cache without
/// an element bound is cut to [`MAX_OCTET_HISTORY`] for other processes.
fn handle_qos(handle: &InProcessTrajectory, policy: &FluentStreamPolicy) -> TrajectoryQos {
    let entity_type = handle.entity_type().unwrap_or_else(|_| EntityStructureType::new(""));
    let qos = bridge_qos(policy, &entity_type);
    let unbounded = !matches!(policy.cache, CacheConstraint::Elements(n) if n > 0);
    if unbounded && qos.history_size == MAX_OCTET_HISTORY {
        tracing::warn!(trajectory = %handle.name(), kept = MAX_OCTET_HISTORY,
            "a trajectory of octets (images) without an element cache: other processes \
             receive the last {MAX_OCTET_HISTORY} of its history; set `cache = N`");
    }
    qos
}

/// The domain of inbox services: other processes' adds to a primitive trajectory.
fn inbox_domain(domain: &str) -> String {
    format!("{domain}:inbox")
}

/// Inbox services keep nothing for late subscribers (an add is delivered once) and
/// queue generously: a full queue loses adds.
fn inbox_qos() -> TrajectoryQos {
    TrajectoryQos {
        history_size: 0,
        subscriber_buffer_size: 1024,
        max_publishers: 16,
        max_nodes: 32,
        ..TrajectoryQos::default()
    }
}

/// Adds forwarded to the location thread that have not been published yet.
const OUTBOX_CAPACITY: usize = 4096;

/// A replica's side of forwarding: hands structures to the location thread.
#[derive(Debug)]
struct Outbox {
    trajectory: String,
    sender: Sender<Arc<EntityStructure>>,
}

impl AddForwarder for Outbox {
    fn forward(&self, es: Arc<EntityStructure>) -> Result<AddOutcome, AddError> {
        let reason = match self.sender.try_send(es) {
            Ok(()) => return Ok(AddOutcome::Forwarded),
            Err(TrySendError::Full(_)) => "the outbox is full (the writer is not keeping up)",
            Err(TrySendError::Disconnected(_)) => "this process has left the system",
        };
        Err(AddError::Unavailable { trajectory: self.trajectory.clone(), reason: reason.into() })
    }
}

/// A local trajectory published for other processes.
#[derive(Debug)]
pub(crate) struct Export {
    pub publisher: TrajectoryPublisher,
    pub violations: ViolationPublisher,
    pub events: Receiver<StoreEvent>,
    /// Events that could not be published (logged once each kind).
    pub failures: u64,
    /// Primitive trajectories: other processes' adds, and the handle they go to.
    inbox: Option<(TrajectorySubscriber, InProcessTrajectory)>,
    /// The inbox's wake-up service, for the location's waker.
    inbox_wake: Option<ServiceName>,
}

impl Export {
    /// The wake-up services other processes' adds to this trajectory notify (its inbox).
    pub fn wake_services(&self) -> Vec<ServiceName> {
        self.inbox_wake.iter().cloned().collect()
    }

    /// Publishes `handle`'s stream from now on (and its current content, so readers
    /// that connect later receive the history). A `repointed` name starts with a reset
    /// marker: readers elsewhere forget the stream the name denoted before.
    pub fn start(
        node: &ShmNode,
        domain: &str,
        handle: &InProcessTrajectory,
        type_name: &str,
        policy: &FluentStreamPolicy,
        primitive: bool,
        repointed: bool,
    ) -> Result<Self, BridgeError> {
        let name = esgm_core::EntityTrajectoryStructure::name(handle).to_owned();
        let publisher = TrajectoryPublisher::builder(&name, type_name)
            .domain(domain)
            .qos(handle_qos(handle, policy))
            .create(node)?;
        let violations = ViolationPublisher::create(node, domain, &name)?;
        // Content and tap under one lock: nothing falls between the two.
        let (backlog, events) = handle
            .with_store(|s| (s.samples(), s.tap(TAP_CAPACITY)))
            .map_err(|_| BridgeError::Gone { trajectory: name.clone() })?;
        let inbox = match primitive {
            true => Some((
                TrajectorySubscriber::builder(&name, type_name)
                    .domain(inbox_domain(domain))
                    .qos(inbox_qos())
                    // The location never waits on it: its waker does (see `waker`).
                    .wait_strategy(WaitStrategy::BusySpin)
                    .create(node)?,
                handle.clone(),
            )),
            false => None,
        };
        let inbox_wake = match primitive {
            true => Some(
                *TrajectoryServiceNames::new(&inbox_domain(domain), &name)
                    .map_err(OpenError::from)?
                    .wake(),
            ),
            false => None,
        };
        let mut export = Self { publisher, violations, events, failures: 0, inbox, inbox_wake };
        if repointed {
            export.publish(StoreEvent::Reset);
        }
        for sample in backlog {
            export.publish(StoreEvent::Entered(sample));
        }
        Ok(export)
    }

    /// Adds what other processes sent to the inbox, then publishes every queued
    /// event; returns how many there were.
    pub fn pump(&mut self) -> usize {
        let mut n = 0;
        if let Some((inbox, handle)) = &mut self.inbox {
            loop {
                match inbox.receive() {
                    Ok(Some(sample)) => {
                        n += 1;
                        // Through the gate: type, policy and order are checked here,
                        // and whatever is refused is counted in this trajectory's stats.
                        match sample.to_owned() {
                            Ok(es) => {
                                let _ = handle.add(es);
                            }
                            Err(e) => {
                                tracing::warn!(error = %e, "malformed add from another process")
                            }
                        }
                    }
                    Ok(None) => break,
                    Err(e) => {
                        n += 1;
                        tracing::warn!(error = %e, "add from another process refused");
                        if matches!(e, ReceiveError::Connection(_) | ReceiveError::TooManyHeld) {
                            break;
                        }
                    }
                }
            }
        }
        while let Ok(event) = self.events.try_recv() {
            self.publish(event);
            n += 1;
        }
        n
    }

    fn publish(&mut self, event: StoreEvent) {
        let result = match &event {
            StoreEvent::Entered(s) => {
                self.publisher.publish_added(&s.structure, s.add_time).map(|_| ())
            }
            StoreEvent::Violation(v) => self.violations.publish(v),
            StoreEvent::Reset => self.publisher.publish_reset().map(|_| ()),
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.failures += 1;
            if self.failures == 1 {
                tracing::warn!(trajectory = %self.publisher.trajectory(), error = %e,
                    "cannot publish to other processes (later failures are only counted)");
            }
        }
    }
}

/// A trajectory of another process, mirrored into a local replica.
#[derive(Debug)]
pub(crate) struct Import {
    pub subscriber: TrajectorySubscriber,
    pub violations: ViolationSubscriber,
    pub replica: InProcessTrajectory,
    /// Samples that could not be taken (already counted by the subscriber).
    pub rejected: u64,
    /// Primitive trajectories: adds made here, on their way to the writer.
    pub outbox: Option<Receiver<Arc<EntityStructure>>>,
    /// The inbox publisher, opened at the first add.
    inbox: Option<TrajectoryPublisher>,
    domain: String,
    type_name: String,
    /// Whose samples this import's held images count as, and how many it may hold.
    owner: OwnerId,
    budget: usize,
    /// The wake-up services of the samples and the violations, for the location's waker.
    wakes: Vec<ServiceName>,
}

impl Import {
    /// The wake-up services a publish on this import's trajectory notifies.
    pub fn wake_services(&self) -> Vec<ServiceName> {
        self.wakes.clone()
    }

    /// Subscribes to `replica`'s trajectory, receiving the writer's history first.
    /// Images it receives stay in shared memory, borrowed in `holdings`.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        node: &ShmNode,
        domain: &str,
        replica: InProcessTrajectory,
        type_name: &str,
        policy: &FluentStreamPolicy,
        primitive: bool,
        holdings: &mut Holdings,
    ) -> Result<Self, OpenError> {
        let name = esgm_core::EntityTrajectoryStructure::name(&replica).to_owned();
        let entity_type = replica.entity_type().unwrap_or_else(|_| EntityStructureType::new(""));
        let qos = bridge_qos(policy, &entity_type);
        // The location never waits on these: its waker does (see `waker`), so they
        // need no listeners of their own.
        let subscriber = TrajectorySubscriber::builder(&name, type_name)
            .domain(domain)
            .qos(qos)
            .wait_strategy(WaitStrategy::BusySpin)
            .create(node)?;
        let violations = ViolationSubscriber::builder(&name)
            .domain(domain)
            .wait_strategy(WaitStrategy::BusySpin)
            .create(node)?;
        let violations_wake = violation_service_name(domain, &name);
        let wakes = vec![
            *TrajectoryServiceNames::new(domain, &name)?.wake(),
            ServiceName::new(&violations_wake).map_err(|_| NameError::TooLong {
                service: violations_wake.clone(),
                max: ServiceName::max_len(),
            })?,
        ];
        let outbox = primitive.then(|| {
            let (sender, receiver) = crossbeam_channel::bounded(OUTBOX_CAPACITY);
            let outbox = Outbox { trajectory: name.clone(), sender };
            let _ = replica.with_store(|s| s.forward_adds(Arc::new(outbox)));
            receiver
        });
        Ok(Self {
            subscriber,
            violations,
            replica,
            rejected: 0,
            outbox,
            inbox: None,
            domain: domain.to_owned(),
            type_name: type_name.to_owned(),
            owner: holdings.new_owner(),
            // One borrow stays free to receive into.
            budget: qos.max_borrowed_samples.saturating_sub(1),
            wakes,
        })
    }

    /// Publishes the adds made here to the writer's inbox; returns how many.
    fn send_outbox(&mut self, node: &ShmNode) -> usize {
        let Some(outbox) = &self.outbox else { return 0 };
        let mut n = 0;
        while let Ok(es) = outbox.try_recv() {
            n += 1;
            if self.inbox.is_none() {
                let name = self.replica.name().to_owned();
                match TrajectoryPublisher::builder(&name, &self.type_name)
                    .domain(inbox_domain(&self.domain))
                    .qos(inbox_qos())
                    .create(node)
                {
                    Ok(p) => self.inbox = Some(p),
                    Err(e) => {
                        tracing::warn!(trajectory = %name, error = %e, "cannot open the writer's inbox; add lost");
                        continue;
                    }
                }
            }
            if let Some(inbox) = &self.inbox {
                if let Err(e) = inbox.publish(&es) {
                    tracing::warn!(trajectory = %inbox.trajectory(), error = %e, "add not sent to the writer");
                }
            }
        }
        n
    }

    /// Sends the adds made here to the writer, then feeds every waiting sample, reset
    /// and violation into the replica; returns how many there were.
    pub fn pump(&mut self, node: &ShmNode, holdings: &mut Holdings) -> usize {
        let mut n = self.send_outbox(node);
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    n += 1;
                    let add_time = sample.header().add_time;
                    match holdings.decode(self.owner, self.budget, sample) {
                        Ok(es) => {
                            let es = Arc::new(es);
                            let _ = self.replica.with_store(|s| s.replicate(es, add_time));
                        }
                        Err(e) => self.reject(&ReceiveError::Malformed(e)),
                    }
                }
                Ok(None) => break,
                Err(ReceiveError::Reset { .. }) => {
                    n += 1;
                    let _ = self.replica.with_store(|s| s.reset());
                }
                Err(e) => {
                    n += 1;
                    self.reject(&e);
                    if matches!(e, ReceiveError::Connection(_) | ReceiveError::TooManyHeld) {
                        break;
                    }
                }
            }
        }
        while let Ok(Some(v)) = self.violations.receive() {
            n += 1;
            let _ = self.replica.with_store(|s| s.replicate_violation(v));
        }
        n
    }

    fn reject(&mut self, e: &ReceiveError) {
        self.rejected += 1;
        if self.rejected == 1 {
            tracing::warn!(trajectory = %self.subscriber.trajectory(), error = %e,
                "sample from another process rejected (later ones are only counted)");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octet_trajectories_without_an_element_cache_keep_a_short_history() {
        let image = EntityStructureType::new("Image").attr("image_data", ValueSort::OctetSeq);
        let reading = EntityStructureType::new("Reading").attr("x", ValueSort::Double);
        let all = FluentStreamPolicy::default();
        assert_eq!(bridge_qos(&all, &image).history_size, MAX_OCTET_HISTORY);
        assert_eq!(bridge_qos(&all, &reading).history_size, DEFAULT_MAX_HISTORY);
        let hundred = FluentStreamPolicy::default().cache(CacheConstraint::Elements(100));
        assert_eq!(bridge_qos(&hundred, &image).history_size, 100, "an explicit bound is kept");
    }
}
