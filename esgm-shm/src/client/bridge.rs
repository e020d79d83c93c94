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
//! Both live on the location thread, which owns every iceoryx2 port of the process.

use std::sync::Arc;

use crossbeam_channel::Receiver;
use esgm_core::policy::FluentStreamPolicy;
use esgm_core::{InProcessTrajectory, StoreEvent};

use crate::history::{DEFAULT_MAX_HISTORY, history_bound, history_qos};
use crate::publisher::TrajectoryPublisher;
use crate::qos::TrajectoryQos;
use crate::service::{OpenError, ShmNode};
use crate::subscriber::{ReceiveError, TrajectorySubscriber};
use crate::violations::{ViolationPublisher, ViolationSubscriber};

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

/// The service settings both ends of a bridged trajectory use: the publisher keeps
/// the cache's bound of samples, so a replica made late starts with the writer's view.
pub(crate) fn bridge_qos(policy: &FluentStreamPolicy) -> TrajectoryQos {
    history_qos(history_bound(policy.cache, DEFAULT_MAX_HISTORY), TrajectoryQos::default())
}

/// A local trajectory published for other processes.
#[derive(Debug)]
pub(crate) struct Export {
    pub publisher: TrajectoryPublisher,
    pub violations: ViolationPublisher,
    pub events: Receiver<StoreEvent>,
    /// Events that could not be published (logged once each kind).
    pub failures: u64,
}

impl Export {
    /// Publishes `handle`'s stream from now on (and its current content, so readers
    /// that connect later receive the history).
    pub fn start(
        node: &ShmNode,
        domain: &str,
        handle: &InProcessTrajectory,
        type_name: &str,
        policy: &FluentStreamPolicy,
    ) -> Result<Self, BridgeError> {
        let name = esgm_core::EntityTrajectoryStructure::name(handle).to_owned();
        let publisher = TrajectoryPublisher::builder(&name, type_name)
            .domain(domain)
            .qos(bridge_qos(policy))
            .create(node)?;
        let violations = ViolationPublisher::create(node, domain, &name)?;
        // Content and tap under one lock: nothing falls between the two.
        let (backlog, events) = handle
            .with_store(|s| (s.samples(), s.tap(TAP_CAPACITY)))
            .map_err(|_| BridgeError::Gone { trajectory: name.clone() })?;
        let mut export = Self { publisher, violations, events, failures: 0 };
        for sample in backlog {
            export.publish(StoreEvent::Entered(sample));
        }
        Ok(export)
    }

    /// Publishes every queued event; returns how many there were.
    pub fn pump(&mut self) -> usize {
        let mut n = 0;
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
}

impl Import {
    /// Subscribes to `replica`'s trajectory, receiving the writer's history first.
    pub fn start(
        node: &ShmNode,
        domain: &str,
        replica: InProcessTrajectory,
        type_name: &str,
        policy: &FluentStreamPolicy,
    ) -> Result<Self, OpenError> {
        let name = esgm_core::EntityTrajectoryStructure::name(&replica).to_owned();
        let subscriber = TrajectorySubscriber::builder(&name, type_name)
            .domain(domain)
            .qos(bridge_qos(policy))
            .create(node)?;
        let violations = ViolationSubscriber::builder(&name).domain(domain).create(node)?;
        Ok(Self { subscriber, violations, replica, rejected: 0 })
    }

    /// Feeds every waiting sample, reset and violation into the replica; returns how
    /// many there were.
    pub fn pump(&mut self) -> usize {
        let mut n = 0;
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    n += 1;
                    let add_time = sample.header().add_time;
                    match sample.to_owned() {
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
