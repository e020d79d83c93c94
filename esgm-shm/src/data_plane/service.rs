//! Opening a trajectory's two iceoryx2 services (data and wake-up), shared by
//! publishers and subscribers, and the error of doing so.

use iceoryx2::node::Node;
use iceoryx2::port::listener::ListenerCreateError;
use iceoryx2::port::notifier::NotifierCreateError;
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::prelude::ServiceName;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::payload::{Block16, SampleHeader};
use crate::qos::{Delivery, TrajectoryQos};
use crate::service_name::{NameError, TrajectoryServiceNames};

/// The iceoryx2 service type of every esgm port: inter-process services whose ports
/// are `Send + Sync`.
///
/// Why the thread-safe variant: a sample must be able to go where its reader goes. A
/// structure added on any thread is published by that thread, inline, under the
/// trajectory's own lock (no hand-off to a port-owning thread); a sample received on
/// one thread is read, and finally released, on whichever thread drops the last value
/// that borrows it. The shared memory is the same as `ipc::Service`'s (the two differ
/// only in the in-process lock around a port), so processes built either way meet on
/// the same services; the lock costs an uncontended mutex per port call.
pub type ShmService = iceoryx2::prelude::ipc_threadsafe::Service;

/// The iceoryx2 node type esgm uses: inter-process services.
pub type ShmNode = Node<ShmService>;

/// A trajectory's data service.
pub(crate) type DataService = publish_subscribe::PortFactory<ShmService, [Block16], SampleHeader>;

/// A trajectory's wake-up service.
pub(crate) type WakeService = event::PortFactory<ShmService>;

/// A publisher or subscriber could not be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// The domain or trajectory name cannot be a service name; rename it.
    #[error(transparent)]
    InvalidName(#[from] NameError),
    /// The data service exists with incompatible settings (history, buffer, port
    /// counts, overflow behaviour, payload or header type) or could not be created;
    /// open it with the [`TrajectoryQos`] it was created with.
    #[error("cannot open or create the data service `{service}`: {source}")]
    DataService {
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        source: PublishSubscribeOpenOrCreateError,
    },
    /// The wake-up event service could not be opened or created.
    #[error("cannot open or create the wake-up service `{service}`: {source}")]
    WakeService {
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        source: EventOpenOrCreateError,
    },
    /// The publisher port could not be created (too many publishers, or no shared
    /// memory for its data segment); raise `max_publishers` or free memory.
    #[error("cannot create the publisher port: {0}")]
    Publisher(#[source] PublisherCreateError),
    /// The subscriber port could not be created (too many subscribers, or a buffer or
    /// history request larger than the service supports).
    #[error("cannot create the subscriber port: {0}")]
    Subscriber(#[source] SubscriberCreateError),
    /// The wake-up notifier could not be created (too many notifiers).
    #[error("cannot create the wake-up notifier: {0}")]
    Notifier(#[source] NotifierCreateError),
    /// The wake-up listener could not be created (too many listeners); use
    /// [`crate::WaitStrategy::BusySpin`], which needs none, or raise the limit.
    #[error("cannot create the wake-up listener: {0}")]
    Listener(#[source] ListenerCreateError),
}

/// Opens (or creates) the data service of a trajectory with `qos`.
pub(crate) fn open_data_service(
    node: &ShmNode,
    names: &TrajectoryServiceNames,
    qos: &TrajectoryQos,
) -> Result<DataService, OpenError> {
    let lossless = qos.delivery == Delivery::Lossless;
    // Lossless delivery needs room for the whole history in each subscriber buffer.
    let buffer = if lossless {
        qos.subscriber_buffer_size.max(qos.history_size)
    } else {
        qos.subscriber_buffer_size
    };
    node.service_builder(names.data())
        .publish_subscribe::<[Block16]>()
        .user_header::<SampleHeader>()
        .history_size(qos.history_size)
        .subscriber_max_buffer_size(buffer)
        .subscriber_max_borrowed_samples(qos.max_borrowed_samples)
        .max_publishers(qos.max_publishers)
        .max_subscribers(qos.max_subscribers)
        .max_nodes(qos.max_nodes)
        .enable_safe_overflow(!lossless)
        .open_or_create()
        .map_err(|source| OpenError::DataService {
            service: names.data().as_str().to_owned(),
            source,
        })
}

/// Listeners an esgm wake-up service admits: one per reading process (its receiver
/// thread) and one per subscription waiting on it directly, across every process.
pub const MAX_WAKE_LISTENERS: usize = 64;

/// Opens (or creates) an esgm wake-up event service. Every opener creates it with
/// the same limits, so whichever process comes first, the others fit.
pub(crate) fn open_event_service(
    node: &ShmNode,
    name: &ServiceName,
) -> Result<WakeService, OpenError> {
    node.service_builder(name)
        .event()
        .max_listeners(MAX_WAKE_LISTENERS)
        .max_nodes(MAX_WAKE_LISTENERS + 16)
        .open_or_create()
        .map_err(|source| OpenError::WakeService { service: name.as_str().to_owned(), source })
}

/// Opens (or creates) the wake-up service of a trajectory.
pub(crate) fn open_wake_service(
    node: &ShmNode,
    names: &TrajectoryServiceNames,
) -> Result<WakeService, OpenError> {
    open_event_service(node, names.wake())
}
