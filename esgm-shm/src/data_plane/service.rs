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

use esgm_core::esgm::{Limit, LimitReached};
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;

use crate::data_plane::capacity::{EventCapacity, Readers};
use crate::data_plane::payload::{Block16, SampleHeader};
use crate::data_plane::qos::{Delivery, TrajectoryQos};
use crate::data_plane::service_name::{NameError, TrajectoryServiceNames};

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

/// Expired connections a subscriber keeps room for (iceoryx2's default is 128): the
/// connections of publishers that left with samples unread. Each costs about 3.6 KiB
/// of private memory in every subscriber, whether used or not; a replica has one
/// writer, and an inbox is drained as soon as an adder rings it.
pub const EXPIRED_CONNECTIONS: usize = 16;

/// Which dead-node cleanup a node does ([`node_config`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cleanup {
    /// When it is made (iceoryx2's default): the coordinator's node, so that what a
    /// crashed predecessor left is gone before it serves.
    OnCreation,
    /// Never: every other node. A cleanup reads every node of the host (about 0.3 ms
    /// each), so a connect that cleaned took 80 ms in a domain of 60 processes. The
    /// room a crashed process's ports hold is reclaimed by whoever needs it
    /// (`with_room`), and the rest by the coordinator now and then.
    None,
}

/// What one [`cleanup_dead_nodes`] did: the dead nodes it cleaned, and those it could
/// not, with iceoryx2's reason for each. It logs nothing itself: the coordinator, whose
/// job the cleanup is, reports failures as warnings ([`DeadNodeCleanup::log`]), while a
/// process that only needed room reports them at debug level, so that a dead process
/// of another domain (or one a concurrent cleaner is finishing) never adds a line to a
/// user's command.
#[derive(Debug, Default)]
#[must_use = "a cleanup's failures are reported by logging or inspecting it"]
pub struct DeadNodeCleanup {
    /// Dead nodes whose resources this call removed.
    pub removed: usize,
    /// Dead nodes left in place.
    pub failed: Vec<CleanupFailure>,
}

/// A dead node [`cleanup_dead_nodes`] could not clean.
#[derive(Debug)]
pub struct CleanupFailure {
    /// The node's id.
    pub node: String,
    /// Its name, if its details could still be read (`None`: a remnant, whose details
    /// went with an earlier, interrupted cleanup; it holds no shared memory).
    pub name: Option<String>,
    /// iceoryx2's reason.
    pub error: iceoryx2::node::NodeCleanupFailure,
}

/// Who reports a [`DeadNodeCleanup`], which sets how loudly its failures are logged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CleanupReporter {
    /// The coordinator (or `esgm up`/`down`), which owns the domain's housekeeping: a
    /// dead node it cannot clean is a warning someone should act on.
    Owner,
    /// Any other process, which cleaned up only because it needed room or a server:
    /// failures are the owner's to report, and are logged at debug level.
    Bystander,
}

impl DeadNodeCleanup {
    /// Logs what this cleanup did as `reporter` should: removals at info level,
    /// failures at warn (owner) or debug (bystander) level, one line per node.
    pub fn log(&self, reporter: CleanupReporter) {
        if self.removed > 0 {
            tracing::info!(removed = self.removed, "cleaned up resources of dead processes");
        }
        for CleanupFailure { node, name, error } in &self.failed {
            // A remnant without details (an interrupted cleanup's leftovers: tags, no
            // memory) is not worth anyone's attention; it cannot be cleaned either.
            match (reporter, name) {
                (CleanupReporter::Owner, Some(name)) => {
                    tracing::warn!(%node, %name, ?error, "cannot clean up after a dead process")
                }
                _ => tracing::debug!(%node, ?name, ?error, "cannot clean up after a dead process"),
            }
        }
    }
}

/// Removes what crashed processes left in shared memory (iceoryx2's dead-node cleanup)
/// and says what it did ([`DeadNodeCleanup`]); an error means the nodes could not even
/// be listed. It reads every node of the host: call it when room is needed, or seldom.
pub fn cleanup_dead_nodes() -> Result<DeadNodeCleanup, iceoryx2::node::NodeListFailure> {
    use iceoryx2::node::{NodeCleanupFailure, NodeState, NodeView};
    let mut outcome = DeadNodeCleanup::default();
    Node::<ShmService>::list(iceoryx2_config(), |state| {
        if let NodeState::Dead(view) = state {
            let node = format!("{:?}", view.id());
            let name = view.details().as_ref().map(|d| d.name().as_str().to_owned());
            match view.try_remove_stale_resources() {
                Ok(()) => outcome.removed += 1,
                // Someone else cleans it (another coordinator, a process that needs
                // the room).
                Err(
                    NodeCleanupFailure::ResourcesAlreadyCleanedUp
                    | NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode,
                ) => {}
                Err(error) => outcome.failed.push(CleanupFailure { node, name, error }),
            }
        }
        iceoryx2::prelude::CallbackProgression::Continue
    })?;
    Ok(outcome)
}

/// How long opening a service of a shared domain is retried while iceoryx2 refuses it
/// for permissions: the owner's process widens a new service's files within 100 ms,
/// or, for a service listed while it was being created, within 5 s
/// (`process::access`).
pub const ACCESS_PATIENCE: std::time::Duration = std::time::Duration::from_secs(5);

/// Runs `open` again while it fails for permissions (`denied`), for at most
/// [`ACCESS_PATIENCE`]: in a domain shared with other users, a service another user's
/// process just made is closed until its owner widens it. In a private domain it ends
/// as it was refused.
pub fn with_access<T, E>(
    denied: impl Fn(&E) -> bool,
    mut open: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    let deadline = std::time::Instant::now() + ACCESS_PATIENCE;
    loop {
        match open() {
            Err(e) if denied(&e) && std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            r => return r,
        }
    }
}

/// Runs `open`, and once more after [`cleanup_dead_nodes`] if it failed for lack of
/// room (`lacks_room`): the ports of a process that crashed hold their room until
/// someone cleans up after it, and a process that needs the room does not wait for the
/// coordinator's next round. A limit really reached costs one cleanup, and is then
/// reported as it was.
pub fn with_room<T, E>(
    lacks_room: impl Fn(&E) -> bool,
    mut open: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    match open() {
        Err(e) if lacks_room(&e) => {
            match cleanup_dead_nodes() {
                Ok(cleaned) => cleaned.log(CleanupReporter::Bystander),
                Err(list) => tracing::debug!(error = %list, "cannot list nodes to clean up"),
            }
            // Again even if this cleanup found nobody: another process (the
            // coordinator) may have cleaned up meanwhile.
            drop(e);
            open()
        }
        r => r,
    }
}

/// The environment variable that moves iceoryx2's small files (static service
/// configurations, node details) to another directory. Every process of a domain must
/// see the same value.
pub const ICEORYX2_ROOT_ENV: &str = "ESGM_ICEORYX2_ROOT";

/// Where esgm keeps iceoryx2's small files unless told otherwise: on tmpfs, beside the
/// segments. iceoryx2's own default, `/tmp/iceoryx2/`, is on disk on many robots (an
/// eMMC or SD card): every node a process makes writes and syncs files there, about
/// 10 ms of a 20 ms CLI query on this project's machine, and wears the flash.
pub const DEFAULT_ICEORYX2_ROOT: &str = "/dev/shm/iceoryx2/";

/// iceoryx2's configuration as every esgm process uses it, for listing nodes and
/// services as well as making nodes: iceoryx2's global one (from its config file if
/// there is one, so its prefix and a root chosen there hold), with the root in
/// [`ICEORYX2_ROOT_ENV`], else in [`DEFAULT_ICEORYX2_ROOT`] where iceoryx2's config
/// kept its own default.
pub fn iceoryx2_config() -> &'static iceoryx2::config::Config {
    static CONFIG: std::sync::LazyLock<iceoryx2::config::Config> = std::sync::LazyLock::new(|| {
        let mut config = iceoryx2::config::Config::global_config().clone();
        let own_default =
            config.global.root_path() == iceoryx2::config::Global::default().root_path();
        let env = std::env::var(ICEORYX2_ROOT_ENV).ok();
        if let Some(root) = chosen_root(env.as_deref(), own_default) {
            let path = iceoryx2::prelude::Path::try_from(root.as_str()).or_else(|e| {
                tracing::error!(variable = ICEORYX2_ROOT_ENV, value = %root, error = ?e,
                    "not a usable directory for iceoryx2's files; using {DEFAULT_ICEORYX2_ROOT}");
                iceoryx2::prelude::Path::try_from(DEFAULT_ICEORYX2_ROOT)
            });
            if let Ok(path) = path {
                config.global.set_root_path(&path);
            }
        }
        config
    });
    &CONFIG
}

/// The root [`iceoryx2_config`] sets, with a trailing `/`, given [`ICEORYX2_ROOT_ENV`]'s
/// value `env` and whether iceoryx2's config kept its own default root; `None` keeps
/// the root of iceoryx2's config file. An empty value counts as unset, and a relative
/// one is refused loudly for the default: every process of a domain must meet on the
/// same files, wherever it was started.
fn chosen_root(env: Option<&str>, own_default: bool) -> Option<String> {
    let fallback = || own_default.then(|| DEFAULT_ICEORYX2_ROOT.to_owned());
    match env {
        None | Some("") => fallback(),
        Some(root) if !root.starts_with('/') => {
            tracing::error!(variable = ICEORYX2_ROOT_ENV, value = %root,
                "not an absolute path; using {DEFAULT_ICEORYX2_ROOT}");
            Some(DEFAULT_ICEORYX2_ROOT.to_owned())
        }
        Some(root) if root.ends_with('/') => Some(root.to_owned()),
        Some(root) => Some(format!("{root}/")),
    }
}

/// The iceoryx2 configuration of every esgm node: [`iceoryx2_config`] (its paths and
/// prefix, so that every process meets on the same files), with a subscriber's
/// room for expired connections cut to `EXPIRED_CONNECTIONS` (128 per subscriber
/// made a process reading 300 trajectories hold 140 MiB), dead-node cleanup when the
/// node is made as `cleanup` says, and none when a service is opened.
pub fn node_config(cleanup: Cleanup) -> iceoryx2::config::Config {
    let mut config = iceoryx2_config().clone();
    config.defaults.publish_subscribe.subscriber_expired_connection_buffer = EXPIRED_CONNECTIONS;
    config.global.node.cleanup_dead_nodes_on_creation = cleanup == Cleanup::OnCreation;
    config.global.node.cleanup_dead_nodes_on_destruction = false;
    // Opening a service would otherwise read every node attached to it (its details,
    // about 0.2 ms each) to find dead ones: a process joining a domain of 60 opens the
    // admin, control and registry-version services, each attached to every process,
    // and its connect took 50 ms more. Dead nodes are cleaned up by whoever needs
    // their room ([`with_room`]) and by the coordinator now and then.
    config.global.service.cleanup_dead_nodes_on_open = false;
    config
}

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
    /// A limit of the trajectory's services was reached ([`crate::DomainLimits`]); the
    /// error names the setting that raises it.
    #[error(transparent)]
    LimitReached(#[from] LimitReached),
}

impl OpenError {
    /// The limit this failure is, if iceoryx2 refused a port or a node for lack of
    /// room. A publisher refused on a trajectory's data service is not one: that
    /// service admits its writer alone.
    pub fn exceeded(&self) -> Option<Limit> {
        match self {
            Self::Subscriber(SubscriberCreateError::ExceedsMaxSupportedSubscribers)
            | Self::Notifier(NotifierCreateError::ExceedsMaxSupportedNotifiers) => {
                Some(Limit::Readers)
            }
            Self::Publisher(PublisherCreateError::ExceedsMaxSupportedPublishers) => {
                Some(Limit::Adders)
            }
            Self::Listener(ListenerCreateError::ExceedsMaxSupportedListeners) => {
                Some(Limit::Waiters)
            }
            Self::DataService {
                source:
                    PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                        PublishSubscribeOpenError::ExceedsMaxNumberOfNodes,
                    ),
                ..
            }
            | Self::WakeService {
                source:
                    EventOpenOrCreateError::EventOpenError(EventOpenError::ExceedsMaxNumberOfNodes),
                ..
            } => Some(Limit::Readers),
            _ => None,
        }
    }

    /// True if this failure is for lack of room ([`Self::exceeded`], or a limit esgm
    /// checked itself), which `with_room` retries after cleaning up.
    pub fn lacks_room(&self) -> bool {
        matches!(self, Self::LimitReached(_)) || self.exceeded().is_some()
    }

    /// This error as the limit of `trajectory` (whose services admit `readers`) it
    /// is, if it is one; else unchanged.
    #[must_use]
    pub fn as_limit(self, trajectory: &str, readers: Readers) -> Self {
        match self.exceeded() {
            Some(limit) => Self::LimitReached(readers.reached(limit, trajectory)),
            None => self,
        }
    }
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
    let failed =
        |source| OpenError::DataService { service: names.data().as_str().to_owned(), source };
    let samples = || {
        node.service_builder(names.data())
            .publish_subscribe::<[Block16]>()
            .user_header::<SampleHeader>()
            .history_size(qos.history_size)
            .subscriber_max_buffer_size(buffer)
            .subscriber_max_borrowed_samples(qos.max_borrowed_samples)
            .enable_safe_overflow(!lossless)
    };
    let denied = |e: &PublishSubscribeOpenOrCreateError| {
        matches!(
            e,
            PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                PublishSubscribeOpenError::InsufficientPermissions
            )
        )
    };
    let opened = with_access(denied, || {
        samples()
            .max_publishers(qos.max_publishers)
            .max_subscribers(qos.max_subscribers)
            .max_nodes(qos.max_nodes)
            .open_or_create()
    });
    match opened {
        // Made for other port counts (another `readers`, or a process that came
        // first): what this port needs of the samples is checked; a port past the
        // service's room is refused as the limit it is.
        Err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfPublishers
            | PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfSubscribers
            | PublishSubscribeOpenError::DoesNotSupportRequestedAmountOfNodes,
        )) => samples()
            .open()
            .map_err(|e| failed(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(e))),
        opened => opened.map_err(failed),
    }
}

/// An event service to listen to or ring: its name and how it is sized, which every
/// opener must agree on (the first creates it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EventSpec {
    /// The service's name.
    pub name: ServiceName,
    /// Its listeners, notifiers and nodes.
    pub capacity: EventCapacity,
}

impl EventSpec {
    /// Opens (or creates) it on `node`.
    pub(crate) fn open(&self, node: &ShmNode) -> Result<WakeService, OpenError> {
        open_event_service(node, &self.name, self.capacity)
    }
}

/// Opens (or creates) an esgm wake-up event service sized `capacity`
/// ([`crate::data_plane::capacity`]). Every opener asks for the same capacity, derived from the
/// trajectory's record or the domain's limits, so whichever process comes first, the
/// others fit.
pub(crate) fn open_event_service(
    node: &ShmNode,
    name: &ServiceName,
    capacity: EventCapacity,
) -> Result<WakeService, OpenError> {
    let failed = |source| OpenError::WakeService { service: name.as_str().to_owned(), source };
    let denied = |e: &EventOpenOrCreateError| {
        matches!(e, EventOpenOrCreateError::EventOpenError(EventOpenError::InsufficientPermissions))
    };
    let opened = with_access(denied, || {
        node.service_builder(name)
            .event()
            .max_listeners(capacity.listeners)
            .max_notifiers(capacity.notifiers)
            .max_nodes(capacity.nodes)
            .open_or_create()
    });
    match opened {
        // Made for fewer ports than this process would ask (another esgm's sizing, or
        // a trajectory re-declared with other `readers`): use it as it is; a port past
        // its room is refused as the limit it is.
        Err(EventOpenOrCreateError::EventOpenError(
            EventOpenError::DoesNotSupportRequestedAmountOfListeners
            | EventOpenError::DoesNotSupportRequestedAmountOfNotifiers
            | EventOpenError::DoesNotSupportRequestedAmountOfNodes,
        )) => node
            .service_builder(name)
            .event()
            .open()
            .map_err(|e| failed(EventOpenOrCreateError::EventOpenError(e))),
        opened => opened.map_err(failed),
    }
}

/// Opens (or creates) the wake-up service of a trajectory whose data service has
/// `qos`.
pub(crate) fn open_wake_service(
    node: &ShmNode,
    names: &TrajectoryServiceNames,
    qos: &TrajectoryQos,
) -> Result<WakeService, OpenError> {
    open_event_service(node, names.wake(), qos.wake_capacity())
}

#[cfg(test)]
mod root_tests {
    use super::*;

    #[test]
    fn the_root_is_the_variable_else_tmpfs_unless_iceoryx2_was_configured() {
        assert_eq!(chosen_root(None, true).as_deref(), Some(DEFAULT_ICEORYX2_ROOT));
        assert_eq!(chosen_root(None, false), None, "a root from iceoryx2's config file");
        assert_eq!(chosen_root(Some(""), true).as_deref(), Some(DEFAULT_ICEORYX2_ROOT));
        assert_eq!(chosen_root(Some("/run/x"), false).as_deref(), Some("/run/x/"));
        assert_eq!(chosen_root(Some("/run/x/"), true).as_deref(), Some("/run/x/"));
        assert_eq!(chosen_root(Some("x"), true).as_deref(), Some(DEFAULT_ICEORYX2_ROOT));
    }
}
