//! The domain's administration services, created by the coordinator with the domain's
//! limits and opened by every process: the channel that whole-domain questions
//! (E7's `reset` and `stats`, `flush`, log levels) travel on. What is asked and
//! answered on it is the client's ([`crate::client`]'s admin module); the services
//! themselves are here, beside the control service, so that the coordinator makes them
//! without depending on the client.

use esgm_core::esgm::{Peer, Unreachable};
use iceoryx2::prelude::{PortFactory as _, ServiceName};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::data_plane::capacity::{DomainLimits, EventCapacity, TOOL_RESERVE};
use crate::data_plane::service::{ShmNode, ShmService, open_event_service};

/// Processes that may ask the domain at once; one more waits until one is answered.
pub(crate) const ASKERS: usize = 8;
/// Questions a process may have waiting before the oldest is dropped.
const BUFFER: usize = 4;

/// One direction of the channel: JSON messages of any length.
pub(crate) type Channel = publish_subscribe::PortFactory<ShmService, [u8], ()>;

/// The domain's administration services: questions (every process subscribes; an
/// asker publishes), answers (each process publishes; an asker subscribes) and the
/// wake-up every admin thread waits on.
#[derive(Debug)]
pub(crate) struct AdminServices {
    /// `esgm/<domain>/admin`.
    pub(crate) questions: Channel,
    /// `esgm/<domain>/admin-answers`.
    pub(crate) answers: Channel,
    /// `esgm/<domain>/admin-wake`.
    pub(crate) wake: event::PortFactory<ShmService>,
}

impl AdminServices {
    /// Opens (or creates, sized for `limits`) the administration services of `domain`
    /// on `node`. A domain made with other limits is opened as it is.
    pub(crate) fn open(
        node: &ShmNode,
        domain: &str,
        limits: &DomainLimits,
    ) -> Result<Self, Unreachable> {
        let (questions, answers, wake) = names(domain)?;
        let unavailable = |what: &str, e: &dyn std::fmt::Debug| {
            Unreachable::transport(Peer::Processes, format!("{what}: {e:?}"))
        };
        let processes = limits.process_ports();
        let questions = open_channel(node, &questions, ASKERS, processes, limits)
            .map_err(|e| unavailable("the admin questions", &e))?;
        let answers = open_channel(node, &answers, processes, ASKERS, limits)
            .map_err(|e| unavailable("the admin answers", &e))?;
        let wake = open_event_service(node, &wake, EventCapacity::domain(limits))
            .map_err(|e| unavailable("the admin wake-up", &e))?;
        Ok(Self { questions, answers, wake })
    }

    /// The processes the domain admits, as its services were made (those a process
    /// that is not a tool may take; see [`crate::data_plane::capacity`]).
    pub(crate) fn max_processes(&self) -> usize {
        self.questions.static_config().max_subscribers().saturating_sub(TOOL_RESERVE)
    }
}

/// The three services' names in `domain`.
fn names(domain: &str) -> Result<(ServiceName, ServiceName, ServiceName), Unreachable> {
    let name = |s: String| {
        ServiceName::new(&s)
            .map_err(|e| Unreachable::transport(Peer::Processes, format!("{s}: {e:?}")))
    };
    let prefix = crate::data_plane::service_name::SERVICE_PREFIX;
    Ok((
        name(format!("{prefix}/{domain}/admin"))?,
        name(format!("{prefix}/{domain}/admin-answers"))?,
        name(format!("{prefix}/{domain}/admin-wake"))?,
    ))
}

/// Opens a channel with `publishers` and `subscribers`, or as it is if it was made
/// with other numbers.
fn open_channel(
    node: &ShmNode,
    name: &ServiceName,
    publishers: usize,
    subscribers: usize,
    limits: &DomainLimits,
) -> Result<Channel, PublishSubscribeOpenOrCreateError> {
    let opened = node
        .service_builder(name)
        .publish_subscribe::<[u8]>()
        .max_publishers(publishers)
        .max_subscribers(subscribers)
        .max_nodes(limits.process_nodes())
        .subscriber_max_buffer_size(BUFFER)
        .subscriber_max_borrowed_samples(1)
        .history_size(0)
        .open_or_create();
    match opened {
        Err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfPublishers
            | PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfSubscribers
            | PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfNodes,
        )) => node
            .service_builder(name)
            .publish_subscribe::<[u8]>()
            .subscriber_max_buffer_size(BUFFER)
            .open()
            .map_err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError),
        opened => opened,
    }
}
