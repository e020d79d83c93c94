//! The coordinator: serves the [`Registry`] on `esgm/<domain>/control`, and cleans up
//! after processes that died.

use crate::data_plane::kept::KeptHistory;
use crate::data_plane::service::ShmService;
use crate::data_plane::service_name::generation_domain;
use iceoryx2::port::listener::Listener;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::server::Server;
use iceoryx2::port::{LoanError, ReceiveError, SendError};
use iceoryx2::prelude::{AllocationStrategy, NodeBuilder};
use iceoryx2::service::builder::request_response::{
    RequestResponseCreateError, RequestResponseOpenError,
};
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::request_response::PortFactory;
use iceoryx2::service::port_factory::server::ServerCreateError;

use super::admin_services::AdminServices;
use super::limits::MAX_REQUEST_BYTES;
use super::persistence::Persistence;
use super::protocol::{ControlError, Request, Response, decode, encode};
use super::registry::{Origin, Registry, changes_registry};
use super::state::{StateDir, StateError};
use crate::data_plane::capacity::{DomainLimits, EventCapacity};
use crate::data_plane::service::ShmNode;
use crate::data_plane::service_name::{NameError, control_service};

/// Control clients a domain with `limits` admits: one per process (its connection's
/// location thread) with the tools' reserve, and a margin for supervisors and for
/// clients being replaced.
pub fn control_clients(limits: &DomainLimits) -> usize {
    limits.process_ports() + 16
}

/// The coordinator could not start or serve.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CoordinatorError {
    /// The domain cannot be part of a service name.
    #[error(transparent)]
    InvalidDomain(#[from] NameError),
    /// The iceoryx2 node could not be created (shared memory unavailable?).
    #[error("cannot create the coordinator's node: {0}")]
    Node(#[source] NodeCreationFailure),
    /// The control service exists: another coordinator serves this domain.
    #[error("a coordinator already serves domain `{domain}` (or its service is stale): {source}")]
    AlreadyRunning {
        /// The domain.
        domain: String,
        /// iceoryx2's reason.
        source: RequestResponseCreateError,
    },
    /// The control service was left by a coordinator that died (its clients keep it)
    /// but could not be taken over.
    #[error(
        "cannot take over the control service of domain `{domain}` left by a stopped coordinator: {source}"
    )]
    TakeOver {
        /// The domain.
        domain: String,
        /// iceoryx2's reason.
        source: RequestResponseOpenError,
    },
    /// The domain's state could not be locked, read or restored.
    #[error("the state of domain `{domain}`: {source}")]
    State {
        /// The domain.
        domain: String,
        /// The cause.
        source: StateError,
    },
    /// The saved registry could not be restored.
    #[error("cannot restore the registry of domain `{domain}` from {}: {source}", path.display())]
    Restore {
        /// The domain.
        domain: String,
        /// The state file.
        path: std::path::PathBuf,
        /// What could not be restored.
        source: Box<ControlError>,
    },
    /// The server port could not be created.
    #[error("cannot create the control server: {0}")]
    Server(#[source] ServerCreateError),
    /// Receiving a request failed.
    #[error("cannot receive a request: {0}")]
    Receive(#[source] ReceiveError),
    /// Loaning memory for a response failed.
    #[error("cannot loan a response: {0}")]
    Loan(#[source] LoanError),
    /// Sending a response failed.
    #[error("cannot send a response: {0}")]
    Send(#[source] SendError),
    /// An answer could not be encoded.
    #[error("cannot encode an answer: {0}")]
    Encode(#[source] serde_json::Error),
    /// The coordinator's thread could not be started.
    #[error("cannot start the coordinator thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// The coordinator's thread ended before it was serving.
    #[error("the coordinator thread stopped while starting")]
    Stopped,
}

/// Responses the coordinator keeps room for, per client: a client has one question
/// out at a time (and may leave one abandoned answer behind after a timeout).
const RESPONSES_PER_CLIENT: usize = 2;

/// The largest answer the coordinator sends, in bytes: a listing of thousands of
/// trajectories fits. Answers are loaned from one fixed-size pool: mapped for every
/// client's responses, committed only as answers are written. A growable pool kept,
/// in every client's connection, a used-chunk list for its 255 possible segments,
/// about 3 MB of shared memory committed per connected process.
pub const MAX_RESPONSE_BYTES: usize = 4 << 20;

/// The most requests answered after one save of the registry ([`Coordinator::serve_pending`]).
const MAX_BATCH: usize = 256;

/// A request a client sent the coordinator, until it is answered.
type ControlRequest = iceoryx2::active_request::ActiveRequest<ShmService, [u8], (), [u8], ()>;

/// How often a serving coordinator cleans up after processes that died unsupervised.
/// Each cleanup reads every iceoryx2 node of the host: about 150 ms for a domain of
/// 60 processes (180 nodes), so every 2 s it was 2 % of a core and every 30 s still
/// half the whole domain's idle budget. Nothing waits for it: a process that needs a
/// dead one's room cleans up itself ([`crate::data_plane::service::with_room`]), an admin question
/// that misses answers does too, and a supervised worker's exit cleans up at once.
/// What it still reclaims is the memory of processes that crashed and left nothing
/// waiting, within five minutes.
const CLEANUP_EVERY: Duration = Duration::from_secs(300);

/// The longest an idle coordinator sleeps before it looks at its stop flag (dropping
/// a [`CoordinatorThread`] rings it awake at once).
const IDLE_WAIT: Duration = Duration::from_secs(1);

/// How often a coordinator asked to shut down looks whether its last answers were
/// taken.
const LEAVING_WAIT: Duration = Duration::from_millis(20);

/// Opens the control wake-up of `domain`, sized for every client of a domain with
/// `limits` (opened as it is if it was made with others): every client rings it, the
/// coordinator alone listens.
pub(crate) fn open_control_wake(
    node: &ShmNode,
    domain: &str,
    limits: &DomainLimits,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ShmService>, String> {
    let name =
        crate::data_plane::service_name::control_wake_service(domain).map_err(|e| e.to_string())?;
    let capacity = EventCapacity {
        listeners: 4,
        notifiers: control_clients(limits),
        nodes: limits.process_nodes(),
    };
    crate::data_plane::service::open_event_service(node, &name, capacity).map_err(|e| e.to_string())
}

/// The service on which the coordinator announces its registry's version
/// (`esgm/<domain>/registry-version`, the last value kept for processes that join):
/// a process's audit and its look for assignments read it from shared memory and ask
/// the coordinator only when it changed, so an idle domain costs the coordinator
/// nothing per process.
pub(crate) fn open_version_service(
    node: &ShmNode,
    domain: &str,
    limits: &DomainLimits,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ShmService, u64, ()>,
    String,
> {
    let text =
        format!("{}/{domain}/registry-version", crate::data_plane::service_name::SERVICE_PREFIX);
    let name = iceoryx2::prelude::ServiceName::new(&text).map_err(|e| format!("{text}: {e:?}"))?;
    let sized = node
        .service_builder(&name)
        .publish_subscribe::<u64>()
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .max_publishers(2)
        .max_subscribers(limits.process_ports())
        .max_nodes(limits.process_nodes())
        .open_or_create();
    match sized {
        Ok(service) => Ok(service),
        // Made for another domain size: used as it is.
        Err(_) => node
            .service_builder(&name)
            .publish_subscribe::<u64>()
            .history_size(1)
            .open()
            .map_err(|e| format!("{e:?}")),
    }
}

/// Serves one domain's registry.
#[derive(Debug)]
pub struct Coordinator {
    domain: String,
    registry: Registry,
    server: Server<ShmService, [u8], (), [u8], ()>,
    _service: PortFactory<ShmService, [u8], (), [u8], ()>,
    node: ShmNode,
    /// Rung by clients after each request (`None`: polled, if it could not be made).
    wake: Option<Listener<ShmService>>,
    served: u64,
    failures: u64,
    shutdown_requested: bool,
    /// A supervised process changed: clean up after dead processes now.
    cleanup_soon: bool,
    /// Trajectory generations the batch being served ends (destroyed, or re-pointed
    /// to a new generation): their kept histories are removed once the change is
    /// saved, never before (a change the save undoes keeps its history).
    ended: Vec<(String, u64)>,
    /// Where the registry is kept after each change (`None`: in memory only).
    state: Option<Persistence>,
    /// The domain's coordinator lock, held while serving.
    _lock: Option<std::fs::File>,
    /// The domain's administration services, made here with the domain's limits (and
    /// kept while the coordinator serves, so a process joining finds them sized).
    _admin: Option<AdminServices>,
    /// Announces the registry's version ([`open_version_service`]), and the last
    /// version announced.
    version: Option<VersionOut>,
    /// Requests handled that could change the registry, whatever their outcome, and
    /// saves made: the listing below was encoded at one of these counts.
    changes: u64,
    /// The answer to [`Request::ListTrajectories`], encoded at [`Coordinator::changes`]
    /// (`None`: not yet, or changed since). Every CLI listing and every process that
    /// sees the registry change asks for it; at 1,000 trajectories, cloning and
    /// encoding it for each was most of the coordinator's work.
    listing: Option<(u64, Arc<[u8]>)>,
}

/// An answer to send: made for this request, or the listing encoded before.
enum Answer {
    Made(Response),
    Encoded(Arc<[u8]>),
}

/// The coordinator's end of the registry-version service.
#[derive(Debug)]
struct VersionOut {
    publisher: iceoryx2::port::publisher::Publisher<ShmService, u64, ()>,
    _service: iceoryx2::service::port_factory::publish_subscribe::PortFactory<ShmService, u64, ()>,
    announced: Option<u64>,
}

impl VersionOut {
    /// Announces `version` if it is new; hands processes that joined since the last
    /// announcement the last version.
    fn announce(&mut self, version: u64) {
        let sent = match self.announced == Some(version) {
            true => iceoryx2::port::update_connections::UpdateConnections::update_connections(
                &self.publisher,
            )
            .map_err(|e| format!("{e:?}")),
            false => self.publisher.send_copy(version).map(|_| ()).map_err(|e| format!("{e:?}")),
        };
        match sent {
            Ok(()) => self.announced = Some(version),
            Err(e) => {
                tracing::debug!(error = %e, "cannot announce the registry's version; processes ask")
            }
        }
    }
}

impl Coordinator {
    /// Starts a coordinator for `domain` with `registry`, kept in memory only. Dead
    /// nodes left by crashed processes are cleaned first.
    pub fn create(domain: &str, registry: Registry) -> Result<Self, CoordinatorError> {
        // A new registry: kept histories a former one left would be taken for its
        // trajectories' (generations start again).
        KeptHistory::remove_domain(domain);
        Self::serve_registry(domain, registry, None, None)
    }

    /// Starts the coordinator of `domain` whose registry is kept in `state` (see
    /// [`crate::control::StateDir`]): takes the domain's lock, restores the registry a crashed
    /// coordinator left there (else starts one with `types`), takes over the control
    /// service if the crashed one's clients still hold it, and saves the registry
    /// after every change. Returns how many trajectories were recovered, too.
    pub fn recover(
        domain: &str,
        types: esgm_core::TypeRegistry,
        state: StateDir,
        limits: DomainLimits,
    ) -> Result<(Self, usize), CoordinatorError> {
        let failed = |source| CoordinatorError::State { domain: domain.to_owned(), source };
        let lock = state.lock().map_err(failed)?;
        let registry = match state.load().map_err(failed)? {
            Some(snapshot) => Registry::restore(types.clone(), snapshot).map_err(|source| {
                CoordinatorError::Restore {
                    domain: domain.to_owned(),
                    path: state.registry_file(),
                    source: Box::new(source),
                }
            })?,
            None => {
                // A new registry: kept histories a former one left would be taken for
                // its trajectories' (generations start again).
                KeptHistory::remove_domain(domain);
                Registry::new(types.clone())
            }
        }
        .with_limits(limits);
        let recovered = registry.catalog().trajectories().count();
        let persistence = Persistence::new(state, types, &registry);
        let mut coordinator =
            Self::serve_registry(domain, registry, Some(persistence), Some(lock))?;
        // What was restored is what is on disk: a failure here undoes nothing.
        let _counted_and_logged = coordinator.save_state();
        Ok((coordinator, recovered))
    }

    fn serve_registry(
        domain: &str,
        registry: Registry,
        state: Option<Persistence>,
        lock: Option<std::fs::File>,
    ) -> Result<Self, CoordinatorError> {
        let name = control_service(domain)?;
        let limits = registry.limits();
        let node = NodeBuilder::new()
            .config(&crate::data_plane::service::node_config(
                crate::data_plane::service::Cleanup::OnCreation,
            ))
            .name(&crate::data_plane::service_name::node_name(domain, "coordinator"))
            .create::<ShmService>()
            .map_err(CoordinatorError::Node)?;
        log_cleanup(cleanup_dead_nodes(), crate::data_plane::service::CleanupReporter::Owner);
        let builder = || {
            node.service_builder(&name)
                .request_response::<[u8], [u8]>()
                .max_clients(control_clients(&limits))
                .max_nodes(limits.process_nodes())
                .max_active_requests_per_client(4)
        };
        let service = match builder().create() {
            Ok(service) => service,
            // The clients of a coordinator that died keep its service: take it over,
            // unless a coordinator still serves it.
            Err(RequestResponseCreateError::AlreadyExists) => {
                let service = builder().open().map_err(|source| CoordinatorError::TakeOver {
                    domain: domain.to_owned(),
                    source,
                })?;
                if service.dynamic_config().number_of_servers() > 0 {
                    return Err(CoordinatorError::AlreadyRunning {
                        domain: domain.to_owned(),
                        source: RequestResponseCreateError::AlreadyExists,
                    });
                }
                tracing::info!(
                    domain,
                    "taking over the control service a stopped coordinator left"
                );
                service
            }
            Err(source) => {
                return Err(CoordinatorError::AlreadyRunning { domain: domain.to_owned(), source });
            }
        };
        let server = service
            .server_builder()
            .initial_max_slice_len(MAX_RESPONSE_BYTES)
            .allocation_strategy(AllocationStrategy::Static)
            // iceoryx2 sizes the response pool for every client holding its maximum
            // of responses; clients ask one question at a time, so a few responses
            // per client suffice (a pool of MAX_RESPONSE_BYTES chunks, mapped, not
            // committed). A fixed-size pool keeps every client's connection to a
            // used-chunk list of one segment: 11 KiB where a growable pool's 255
            // segments committed 2.9 MB of shared memory per connected process.
            .override_response_preallocation(move |_| {
                RESPONSES_PER_CLIENT * control_clients(&limits)
            })
            .create()
            .map_err(CoordinatorError::Server)?;
        let admin = AdminServices::open(&node, domain, &limits)
            .map_err(|e| tracing::warn!(error = %e, "cannot make the domain's administration services; the first process makes them with the default limits"))
            .ok();
        let version = open_version_service(&node, domain, &limits)
            .and_then(|service| {
                let publisher =
                    service.publisher_builder().create().map_err(|e| format!("{e:?}"))?;
                Ok(VersionOut { publisher, _service: service, announced: None })
            })
            .map_err(|e| tracing::warn!(error = %e, "cannot announce the registry's version; processes ask"))
            .ok();
        let wake = open_control_wake(&node, domain, &limits)
            .and_then(|w| w.listener_builder().create().map_err(|e| format!("{e:?}")))
            .map_err(|e| tracing::warn!(error = %e, "no control wake-up; the coordinator polls"))
            .ok();
        tracing::info!(domain, "coordinator serving");
        Ok(Self {
            wake,
            domain: domain.to_owned(),
            registry,
            server,
            _service: service,
            node,
            served: 0,
            failures: 0,
            shutdown_requested: false,
            cleanup_soon: false,
            ended: Vec::new(),
            state,
            _lock: lock,
            _admin: admin,
            version,
            changes: 0,
            listing: None,
        })
    }

    /// Writes the registry to the state directory, if it has one. On failure the
    /// registry is back to what was last saved, and the error is what each change
    /// since is answered with ([`Persistence`]).
    fn save_state(&mut self) -> Result<(), ControlError> {
        let Some(state) = &mut self.state else { return Ok(()) };
        state.save(&mut self.registry)
    }

    /// Who sent `active`: the pid of the node its client port belongs to, as iceoryx2
    /// recorded it when the port was made.
    fn origin(&self, active: &ControlRequest) -> Origin {
        let client = active.origin();
        let mut origin = Origin::Unknown;
        self._service.dynamic_config().list_clients(|details| {
            if details.client_id == client {
                if let Ok(pid) = details.node_id.pid::<ShmService>() {
                    let pid = pid.value();
                    origin = match u32::try_from(pid) {
                        Ok(p) if p == std::process::id() => Origin::Coordinator,
                        Ok(p) => Origin::Process(p),
                        // A pid beyond u32 is none this host has: unknown, as when there is none.
                        Err(_) => Origin::Unknown,
                    };
                }
                return iceoryx2::prelude::CallbackProgression::Stop;
            }
            iceoryx2::prelude::CallbackProgression::Continue
        });
        origin
    }

    /// The domain served.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// The registry, read-only.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// Requests answered so far.
    pub fn served(&self) -> u64 {
        self.served
    }

    /// The coordinator's iceoryx2 node.
    pub fn node(&self) -> &ShmNode {
        &self.node
    }

    /// Answers every request waiting now; returns how many were answered.
    ///
    /// Requests are taken in batches (a group commit): every request waiting is
    /// handled, the registry is saved once if any of them changed it, and only then is
    /// each answered, so a change is acknowledged once it is on disk. A save writes the
    /// whole registry and syncs it (about 30 ms here): one per change made 60 processes
    /// creating their trajectories at once wait more than 10 s in the queue.
    ///
    /// One bad request or one failed answer (a client that vanished, no memory for a
    /// large response) is logged and counted in [`Coordinator::failures`], never fatal:
    /// the coordinator keeps serving everyone else and keeps cleaning up.
    pub fn serve_pending(&mut self) -> Result<usize, CoordinatorError> {
        let mut n = 0;
        loop {
            let mut batch = Vec::new();
            let mut changed = false;
            while batch.len() < MAX_BATCH {
                let active = match self.server.receive() {
                    Ok(Some(active)) => active,
                    Ok(None) => break,
                    Err(e) => {
                        self.fail(CoordinatorError::Receive(e));
                        break;
                    }
                };
                let (response, changes) = self.handle(&active);
                changed |= changes;
                batch.push((active, response, changes));
            }
            if batch.is_empty() {
                return Ok(n);
            }
            if changed {
                // A save that fails rolls the registry back: a listing encoded within
                // this batch may show what no longer stands.
                self.changes += 1;
                match self.save_state() {
                    Ok(()) => self.remove_ended(),
                    Err(refusal) => {
                        // Undone: no change of the batch stands, and each is told so.
                        self.ended.clear();
                        for (_, response, changes) in &mut batch {
                            if *changes {
                                *response = Answer::Made(Response::Error(refusal.clone()));
                            }
                        }
                    }
                }
            }
            for (active, response, _) in batch {
                let sent = match response {
                    Answer::Made(response) => self.respond(&active, &response),
                    Answer::Encoded(bytes) => self.send(&active, &bytes),
                };
                if sent {
                    n += 1;
                }
            }
        }
    }

    /// Removes the kept histories of the generations the last saved batch ended.
    fn remove_ended(&mut self) {
        for (trajectory, generation) in self.ended.drain(..) {
            let domain = generation_domain(&self.domain, generation);
            KeptHistory::remove(&domain, &trajectory);
        }
    }

    /// The generation `request` ends if it succeeds: a destroyed trajectory's, or the
    /// former one of a name re-pointed.
    fn ending(&self, request: &Request) -> Option<(String, u64)> {
        let name = match request {
            Request::DestroyEntityTrajectoryStructure { name } => name,
            Request::CreateTrajectory { spec, .. } if spec.replace => &spec.name,
            _ => return None,
        };
        let generation = self.registry.generation_of(name)?;
        Some((name.clone(), generation))
    }

    /// The answer to one request, and whether it changed the registry.
    fn handle(&mut self, active: &ControlRequest) -> (Answer, bool) {
        let payload = active.payload();
        if payload.len() > MAX_REQUEST_BYTES {
            tracing::warn!(bytes = payload.len(), "control request too large; refused");
            let refusal = ControlError::TooLarge { bytes: payload.len(), max: MAX_REQUEST_BYTES };
            return (Answer::Made(Response::Error(refusal)), false);
        }
        let request = decode::<Request>(payload);
        if let Ok(Request::ListTrajectories) = request {
            if let Some(bytes) = self.listing() {
                return (Answer::Encoded(bytes), false);
            }
        }
        let (response, changed) = self.handle_made(active, request);
        (Answer::Made(response), changed)
    }

    /// The listing of every trajectory, encoded once per change of the registry;
    /// `None` if it cannot be encoded or sent whole (then it is made and refused as any
    /// answer is).
    fn listing(&mut self) -> Option<Arc<[u8]>> {
        if let Some((at, bytes)) = &self.listing {
            if *at == self.changes {
                return Some(Arc::clone(bytes));
            }
        }
        let response = self.registry.handle(Request::ListTrajectories);
        let bytes: Arc<[u8]> = match encode(&response) {
            Ok(b)
                if b.len() <= MAX_RESPONSE_BYTES
                    && matches!(response, Response::Trajectories(_)) =>
            {
                b.into()
            }
            _ => return None,
        };
        self.listing = Some((self.changes, Arc::clone(&bytes)));
        Some(bytes)
    }

    /// The answer made for one request (as decoded from `active`), and whether it
    /// changed the registry.
    fn handle_made(
        &mut self,
        active: &ControlRequest,
        request: Result<Request, serde_json::Error>,
    ) -> (Response, bool) {
        match request {
            Ok(Request::Shutdown) => {
                tracing::info!(domain = %self.domain, "shutdown requested");
                self.shutdown_requested = true;
                // An orderly stop: the next coordinator starts empty, and workers that
                // find no coordinator and no state leave.
                if let Some(state) = &self.state {
                    if let Err(e) = state.dir().remove_registry() {
                        tracing::error!(error = %e, "cannot forget the registry");
                    }
                }
                (Response::Done, false)
            }
            Ok(request) => {
                let persist = changes_registry(&request);
                if persist {
                    self.changes += 1;
                }
                let origin = match &request {
                    Request::ReportProcess { .. }
                    | Request::ReportWriter { .. }
                    | Request::ReleaseWriter { .. } => self.origin(active),
                    _ => Origin::Unknown,
                };
                // A supervised process changed (it exited, perhaps crashed): what it
                // held is reclaimed at once, not at the next round.
                if matches!(request, Request::ReportProcess { .. }) {
                    self.cleanup_soon = true;
                }
                let ending = self.ending(&request);
                let mut response = self.registry.handle_from(request, origin);
                if let (Response::Pong { saves, .. }, Some(state)) = (&mut response, &self.state) {
                    *saves = state.health().clone();
                }
                let changed = persist && !matches!(response, Response::Error(_));
                if let Some(ended) = ending.filter(|_| changed) {
                    self.ended.push(ended);
                }
                (response, changed)
            }
            Err(e) => {
                tracing::warn!(error = %e, "control request in another protocol");
                let mismatch = ControlError::ProtocolMismatch {
                    coordinator_version: env!("CARGO_PKG_VERSION").to_owned(),
                    reason: e.to_string(),
                };
                (Response::Error(mismatch), false)
            }
        }
    }

    /// Sends `response` to the client of `active`; false (logged and counted) if it
    /// could not.
    fn respond(&mut self, active: &ControlRequest, response: &Response) -> bool {
        let bytes = match encode(response) {
            Ok(b) if b.len() > MAX_RESPONSE_BYTES => {
                // The client learns why at once, instead of waiting its deadline.
                tracing::warn!(bytes = b.len(), "control answer too large; refused");
                let refusal = Response::Error(ControlError::TooLarge {
                    bytes: b.len(),
                    max: MAX_RESPONSE_BYTES,
                });
                match encode(&refusal) {
                    Ok(b) => b,
                    Err(e) => {
                        self.fail(CoordinatorError::Encode(e));
                        return false;
                    }
                }
            }
            Ok(b) => b,
            Err(e) => {
                // Not expected (every answer is plain data); the client times out.
                self.fail(CoordinatorError::Encode(e));
                return false;
            }
        };
        self.send(active, &bytes)
    }

    /// Sends the encoded answer `bytes` to the client of `active`; false (logged and
    /// counted) if it could not.
    fn send(&mut self, active: &ControlRequest, bytes: &[u8]) -> bool {
        let sent = match active.loan_slice_uninit(bytes.len()) {
            Ok(loan) => loan.write_from_slice(bytes).send().map_err(CoordinatorError::Send),
            Err(e) => Err(CoordinatorError::Loan(e)),
        };
        match sent {
            Ok(()) => {
                self.served += 1;
                true
            }
            Err(e) => {
                self.fail(e);
                false
            }
        }
    }

    /// True once a client asked the coordinator to stop ([`Request::Shutdown`]).
    pub fn shutdown_requested(&self) -> bool {
        self.shutdown_requested
    }

    /// Requests that could not be answered (logged where they failed).
    pub fn failures(&self) -> u64 {
        self.failures
    }

    fn fail(&mut self, e: CoordinatorError) {
        self.failures += 1;
        tracing::warn!(error = %e, failures = self.failures, "control request not answered");
    }

    /// Starts a coordinator for `domain` on a thread of its own (iceoryx2 ports stay on
    /// the thread that made them); it serves until the returned handle is dropped.
    pub fn spawn(domain: &str, registry: Registry) -> Result<CoordinatorThread, CoordinatorError> {
        Self::spawn_with(domain, move |d| Coordinator::create(d, registry))
    }

    /// [`Coordinator::recover`] on a thread of its own (see [`Coordinator::spawn`]);
    /// also returns how many trajectories were recovered.
    pub fn spawn_recovering(
        domain: &str,
        types: esgm_core::TypeRegistry,
        state: StateDir,
        limits: DomainLimits,
    ) -> Result<(CoordinatorThread, usize), CoordinatorError> {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        let thread = Self::spawn_with(domain, move |d| {
            let (c, recovered) = Coordinator::recover(d, types, state, limits)?;
            if tx.send(recovered).is_err() {
                tracing::debug!("nobody waits for the recovery count");
            }
            Ok(c)
        })?;
        let recovered = rx.try_recv().unwrap_or(0);
        Ok((thread, recovered))
    }

    fn spawn_with(
        domain: &str,
        make: impl FnOnce(&str) -> Result<Coordinator, CoordinatorError> + Send + 'static,
    ) -> Result<CoordinatorThread, CoordinatorError> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready, started) = std::sync::mpsc::sync_channel(1);
        let (d, s) = (domain.to_owned(), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name(format!("esgm-coordinator-{domain}"))
            .spawn(move || {
                let mut coordinator = match make(&d) {
                    Ok(c) => c,
                    Err(e) => {
                        if let Err(e) = ready.send(Err(e)) {
                            tracing::error!(error = ?e.0, "the coordinator could not start");
                        }
                        return;
                    }
                };
                if ready.send(Ok(())).is_err() {
                    tracing::debug!("nobody waits for the coordinator to start");
                }
                if let Err(e) = coordinator.run(&s, CLEANUP_EVERY) {
                    tracing::error!(error = %e, "coordinator stopped");
                }
            })
            .map_err(CoordinatorError::Spawn)?;
        match started.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e),
            // The thread ended without a word: it stopped (a panic is printed by the hook).
            Err(_) => return Err(CoordinatorError::Stopped),
        }
        Ok(CoordinatorThread { domain: domain.to_owned(), stop, thread: Some(thread) })
    }

    /// The serving loop of [`Coordinator::run`]: asks `janitor` for a cleanup when a
    /// supervised process changed.
    fn serve_until(
        &mut self,
        stop: &AtomicBool,
        janitor: &crossbeam_channel::Sender<()>,
    ) -> Result<(), CoordinatorError> {
        let mut leaving: Option<Instant> = None;
        while !stop.load(Ordering::Relaxed) {
            // After a shutdown request, answer for a moment longer: the answer lives in
            // this server's memory until the client has taken it.
            if self.shutdown_requested {
                let since = *leaving.get_or_insert_with(Instant::now);
                if since.elapsed() > Duration::from_millis(300) {
                    break;
                }
            }
            let served = self.serve_pending()?;
            let version = self.registry.version();
            if let Some(out) = &mut self.version {
                out.announce(version);
            }
            if std::mem::take(&mut self.cleanup_soon) {
                // One asked for is enough: a cleanup sees every dead node at once.
                let _ = janitor.try_send(());
            }
            if served == 0 {
                // Asleep until a client rings (after sending), or a look at `stop`.
                let idle = if self.shutdown_requested { LEAVING_WAIT } else { IDLE_WAIT };
                self.sleep(idle);
            }
        }
        Ok(())
    }

    /// Sleeps up to `timeout` on the control wake-up (or, without it, polls).
    fn sleep(&self, timeout: Duration) {
        let Some(wake) = &self.wake else {
            return std::thread::sleep(timeout.min(Duration::from_millis(1)));
        };
        if let Err(e) = crate::data_plane::wait::timed_wait(wake, timeout) {
            tracing::warn!(error = ?e, "cannot wait for requests; polling");
            std::thread::sleep(timeout.min(Duration::from_millis(1)));
        }
    }

    /// Serves until `stop` is set — asleep while nobody asks: clients ring the
    /// coordinator's wake-up after each request — while a janitor thread cleans up dead
    /// processes' resources every `cleanup_every`, and soon after a supervised process
    /// changed. A cleanup reads every node of the host and takes from milliseconds to
    /// seconds (a debug build, a loaded machine): done inline, it kept requests waiting
    /// that long, and a supervisor's reports timed out while workers were being killed.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        cleanup_every: Duration,
    ) -> Result<(), CoordinatorError> {
        let (soon, asked) = crossbeam_channel::bounded::<()>(1);
        std::thread::scope(|scope| {
            let thread = std::thread::Builder::new()
                .name("esgm-janitor".into())
                .spawn_scoped(scope, || janitor(&asked, stop, cleanup_every));
            if let Err(e) = &thread {
                tracing::warn!(error = %e, "no janitor thread; dead processes are cleaned up by whoever needs their room");
            }
            let served = self.serve_until(stop, &soon);
            // The janitor ends with the channel (after a cleanup it is in, if any).
            drop(soon);
            served
        })?;
        if self.shutdown_requested {
            // The domain is going down: the words its crashed processes kept mapped
            // (counted as users for ever) go with it, and the kept histories.
            crate::process::remove_domain_files(&self.domain);
        } else if self.state.is_none() {
            // Nothing remembers this registry: its trajectories' histories end with it.
            KeptHistory::remove_domain(&self.domain);
        }
        Ok(())
    }
}

/// The coordinator's janitor: cleans up dead processes' resources every `every`, and
/// when `asked`, until the coordinator drops its end or `stop` is set.
fn janitor(asked: &crossbeam_channel::Receiver<()>, stop: &AtomicBool, every: Duration) {
    loop {
        match asked.recv_timeout(every) {
            Ok(()) | Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => return,
        }
        if stop.load(Ordering::Relaxed) {
            return;
        }
        log_cleanup(cleanup_dead_nodes(), crate::data_plane::service::CleanupReporter::Owner);
    }
}

/// A coordinator serving on its own thread ([`Coordinator::spawn`]); dropping it stops
/// and joins the thread.
#[derive(Debug)]
pub struct CoordinatorThread {
    domain: String,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl CoordinatorThread {
    /// The domain served.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// True once the coordinator has stopped serving (after [`Request::Shutdown`], or
    /// an error it logged): the process hosting it can wind down.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(std::thread::JoinHandle::is_finished)
    }
}

/// Wakes the coordinator of `domain` (to look at its stop flag); best effort, since
/// it looks anyway within [`IDLE_WAIT`].
fn ring_coordinator(domain: &str) {
    let rung = NodeBuilder::new()
        .config(&crate::data_plane::service::node_config(crate::data_plane::service::Cleanup::None))
        .create::<ShmService>()
        .map_err(|e| format!("{e:?}"))
        .and_then(|node| open_control_wake(&node, domain, &DomainLimits::default()))
        .and_then(|wake| wake.notifier_builder().create().map_err(|e| format!("{e:?}")))
        .and_then(|ring| ring.notify().map_err(|e| format!("{e:?}")));
    if let Err(e) = rung {
        tracing::debug!(error = %e, "cannot ring the coordinator to stop; it looks within a second");
    }
}

impl Drop for CoordinatorThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        ring_coordinator(&self.domain);
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                tracing::error!(domain = %self.domain, "the coordinator thread panicked");
            }
        }
    }
}

use crate::data_plane::service::cleanup_dead_nodes;

/// Logs the outcome of a [`cleanup_dead_nodes`] that runs in the background, as
/// `reporter` should ([`DeadNodeCleanup::log`](crate::data_plane::service::DeadNodeCleanup::log)).
pub fn log_cleanup(
    outcome: Result<crate::data_plane::service::DeadNodeCleanup, iceoryx2::node::NodeListFailure>,
    reporter: crate::data_plane::service::CleanupReporter,
) {
    match outcome {
        Ok(cleaned) => cleaned.log(reporter),
        Err(e) => tracing::warn!(error = %e, "cannot list nodes to clean up after dead processes"),
    }
}
