//! [`connect`]: the [`Esgm`] interface of a whole system — a coordinator and any number
//! of processes — from one process, over shared memory.
//!
//! Each process runs the trajectories it *writes* in a local [`InProcessEsgm`] (so the
//! policy gate, workers, queries and subscriptions are exactly the in-process ones) and
//! mirrors into it every trajectory it *reads* from another process:
//!
//! - The coordinator decides who writes what: the creator of a primitive, sync or merge
//!   trajectory; the sensor's process for a sampled one; the unit's process for a
//!   computed one. A process serving sensors or units polls for trajectories placed on
//!   it and builds them (so a camera process samples its camera and publishes the image
//!   once, from its own memory, for every reader).
//! - Everything a local trajectory admits is published on its iceoryx2 service with
//!   the gate's add time; violations and resets too, in order.
//! - A trajectory written elsewhere becomes a local replica fed from its service
//!   (starting with the writer's history), which local units, syncs and merges read.
//!
//! Names, types and errors are system-wide: every registration and creation is checked
//! by the coordinator, and its errors are the seed's, as if the call were local.
//!
//! Trajectory handles are [`InProcessTrajectory`] handles on the local runtime: the
//! trait answers with owned [`esgm_core::Sample`]s, whose images read the writer's
//! shared-memory chunk in place ([`holdings`]).
//!
//! ## One wake-up per process boundary
//! No sample passes through a thread that hands it on:
//! - **The adding thread publishes.** The writer's store tap ([`esgm_core::StoreTap`])
//!   publishes each admitted structure inline, under the trajectory's lock, before the
//!   store keeps it (`client/export.rs`). iceoryx2's thread-safe service variant
//!   ([`crate::ShmService`]) makes the ports usable from any thread.
//! - **Readers wake on the writer's event.** A replica's subscription, and a unit or
//!   operator worker whose one input is a replica, wait on the writer's wake-up
//!   service themselves and feed the replica ([`esgm_core::ReplicaFeed`]), so a sample
//!   wakes the thread that uses it once. The connection's *receiver thread*
//!   (`client/receiver.rs`) waits on every mirrored service too, and feeds what nobody waits
//!   for: the caches, other workers, violations, and other processes' adds to the
//!   trajectories this process writes.
//! - **The location thread is the control plane only** (`client/location.rs`): creates,
//!   assignments, history for late joiners, and a periodic audit against the
//!   registry (destroyed names, new generations).
//!
//! ## Images never copied
//! A trajectory of images hands its producers buffers that are loans of its publisher
//! ([`InProcessTrajectory::image_buffer`], and the sampler's
//! [`esgm_core::SensorInterface::get_current_value_with`]): a camera renders into shared
//! memory, the tap sends the loan after the gate admitted the frame
//! (`client/image_loans.rs`), and every reader — the writer's own store included — reads those
//! pixels where the camera wrote them. [`ShmEsgm::holding_stats`] counts what was held,
//! sent in place and (if anything) copied.
//!
//! - Any process may add to a primitive trajectory: where it is a replica, the
//!   structure is type-checked and published on the writer's inbox by the adding
//!   thread ([`esgm_core::AddOutcome::Forwarded`]); the writer's gate orders, checks and
//!   counts every process's adds alike. The blocking forms wait for the gate's outcome
//!   (`client/blocking_add.rs`).
//!
//! - Each generation of a trajectory has its own services, so a name destroyed and
//!   created again never meets its former self (whose images may still be read).
//!   Re-pointing a name (E5) moves readers in every process to the new generation
//!   with their subscribers; a re-pointed name keeps its type.

pub(crate) mod admin;
pub mod attach;
mod blocking_add;
mod coordinator_watch;
mod coverage;
mod export;
pub(crate) mod holdings;
mod image_loans;
mod import;
mod location;
mod mirrors;
pub mod prelude;
mod receiver;
mod settings;
mod shared_node;
mod stats_row;
mod takeover;
mod why;

use crate::data_plane::service::ShmService;
use std::sync::Arc;
use std::time::Duration;

use crossbeam_channel::Sender;
use esgm_core::clock::SharedClock;
use esgm_core::esgm::{
    CompUnit, CreateError, Esgm, EsgmStats, FlushError, InputType, LogLevel, LookupError,
    MemoryStats, Peer, RegistrationError, SensorInterface, SystemError, TrajectoryInfo,
    TrajectorySpec, Unreachable,
};
use esgm_core::{EntityStructureType, InProcessEsgm, InProcessTrajectory, TypeRegistryError};
use iceoryx2::prelude::NodeBuilder;

use crate::client::holdings::{HoldingStats, Holdings};
use crate::control::protocol::{ControlError, Request, Response};
use crate::control::{ControlClient, ControlClientError};
pub use admin::AdminError;
use admin::{Admin, AdminAnswer, AdminOp, DomainReset};
pub use admin::{AdminRead, AdminReader};
pub use blocking_add::{
    read_answer as read_blocking_add_answer, serve_request as serve_blocking_add,
};
pub use coordinator_watch::CoordinatorWatch;
use location::{Command, Location, install};
use mirrors::SharedMirrors;
use receiver::Receiver as SampleReceiver;
pub use receiver::ReceiverError;
pub use settings::bridge_qos as trajectory_qos;
use shared_node::SharedNode;

/// How long a control call may take by default (the coordinator answers in
/// milliseconds; a longer wait means it is gone or stuck).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(5);

/// [`connect`] failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConnectError {
    /// The domain has as many processes as it admits (`esgm up --max-processes`; see
    /// [`crate::DomainLimits`]): this process was refused, every other is served.
    #[error(transparent)]
    LimitReached(esgm_core::esgm::LimitReached),
    /// No coordinator answered (see the reason; start one with `esgm up`).
    #[error(transparent)]
    Control(#[from] ControlClientError),
    /// The location thread could not be started.
    #[error("cannot start the location thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// The receiver thread, which takes samples from other processes, could not be
    /// started.
    #[error(transparent)]
    Receiver(#[from] ReceiverError),
    /// The domain or host cannot name an iceoryx2 service; rename it.
    #[error(transparent)]
    Name(#[from] crate::data_plane::service_name::NameError),
    /// The domain's administration channel (domain-wide reset, stats, log level,
    /// flush) could not be joined.
    #[error(transparent)]
    Admin(#[from] AdminError),
}

/// Connects to the coordinator of `domain` with the default settings.
pub fn connect(domain: &str) -> Result<ShmEsgm, ConnectError> {
    ShmEsgm::builder().domain(domain).connect()
}

/// Builds a [`ShmEsgm`].
#[derive(Debug, Default)]
pub struct ShmEsgmBuilder {
    domain: Option<String>,
    clock: Option<SharedClock>,
    host: Option<String>,
    timeout: Option<Duration>,
    tool: bool,
}

/// The environment variable naming the domain of the system a worker belongs to.
pub const DOMAIN_ENV: &str = "ESGM_DOMAIN";
/// The environment variable naming a worker process (its host name in the registry);
/// set by the supervisor for every process it starts.
pub const WORKER_ENV: &str = "ESGM_WORKER";

impl ShmEsgmBuilder {
    /// Domain and host as the supervisor passes them to a worker it starts
    /// ([`DOMAIN_ENV`], [`WORKER_ENV`]); unset variables keep the defaults. A user's
    /// unit executable named in a configuration starts with
    /// `ShmEsgm::builder().from_env().connect()`.
    #[must_use]
    pub fn from_env(mut self) -> Self {
        if let Ok(d) = std::env::var(DOMAIN_ENV) {
            self.domain = Some(d);
        }
        if let Ok(h) = std::env::var(WORKER_ENV) {
            self.host = Some(h);
        }
        self
    }

    /// The system's domain (default [`crate::data_plane::service_name::SYSTEM_DOMAIN`], `esgm`, as
    /// the `esgm` command's).
    #[must_use]
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = Some(domain.into());
        self
    }

    /// The clock of this process's trajectories (default: the system clock, the one
    /// timeline every process shares).
    #[must_use]
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// The name this process goes by in the registry (default: program name, process
    /// id and a counter — unique per connection).
    #[must_use]
    pub fn host(mut self, host: impl Into<String>) -> Self {
        self.host = Some(host.into());
        self
    }

    /// Connects as a short-lived tool (a command such as `esgm latest`): it may use the
    /// ports every domain-wide and trajectory service keeps beyond its limits
    /// ([`crate::DomainLimits`]), so a domain whose processes or a trajectory whose
    /// readers reached their limit can still be looked at and added to. A long-lived
    /// process must not: it would take the room the tools need.
    #[must_use]
    pub fn tool(mut self) -> Self {
        self.tool = true;
        self
    }

    /// How long a control call may take (`DEFAULT_TIMEOUT`).
    #[must_use]
    pub fn timeout(mut self, timeout: Duration) -> Self {
        self.timeout = Some(timeout);
        self
    }

    /// Connects: starts the location thread, which opens the control service.
    pub fn connect(self) -> Result<ShmEsgm, ConnectError> {
        raise_file_limit();
        let domain = self
            .domain
            .unwrap_or_else(|| crate::data_plane::service_name::SYSTEM_DOMAIN.to_owned());
        let host = self.host.unwrap_or_else(default_host);
        let timeout = self.timeout.unwrap_or(DEFAULT_TIMEOUT);
        let mut local = InProcessEsgm::builder();
        if let Some(c) = self.clock {
            local = local.clock(c);
        }
        let local = local.create();
        let node = NodeBuilder::new()
            .config(&crate::data_plane::service::node_config(
                crate::data_plane::service::Cleanup::None,
            ))
            .name(&crate::data_plane::service_name::node_name(&domain, &host))
            .create::<ShmService>()
            .map_err(ControlClientError::node)?;
        let control = ControlClient::connect(&domain, timeout).map_err(|e| match e {
            ControlClientError::LimitReached(limit) => ConnectError::LimitReached(limit),
            e => ConnectError::Control(e),
        })?;
        let node = SharedNode::new(node);
        let mirrors = Arc::new(SharedMirrors::default());
        let holdings = Arc::new(Holdings::default());
        let receiver = SampleReceiver::start(
            &node,
            crate::data_plane::service_name::node_name(&domain, &format!("{host}/receiver")),
            crate::data_plane::service_name::doorbell_service(&domain, &host)?,
            Arc::clone(&mirrors),
        )?;
        let admin =
            Admin::start(&node, &domain, &host, self.tool, local.clone(), Arc::clone(&mirrors))
                .map_err(|e| match e {
                    AdminError::LimitReached(limit) => ConnectError::LimitReached(limit),
                    e => ConnectError::Admin(e),
                })?;
        let resets: Arc<dyn esgm_core::ResetForwarder> =
            Arc::new(DomainReset { admin: Arc::downgrade(&admin), timeout });
        let looked = node.with(|n| location::Looked::subscribe(n, &domain));
        let (commands, inbox) = crossbeam_channel::unbounded();
        let location = Location {
            domain: domain.clone(),
            host: host.clone(),
            local: local.clone(),
            node,
            control,
            mirrors: Arc::clone(&mirrors),
            holdings: Arc::clone(&holdings),
            failed: Default::default(),
            serving: false,
            reported: (HoldingStats::default(), std::time::Instant::now()),
            resets,
            verify: crossbeam_channel::bounded(1),
            unnamed: None,
            takeovers: crossbeam_channel::unbounded(),
            tool: self.tool,
            looked,
            _receiver: receiver,
        };
        let thread = std::thread::Builder::new()
            .name(format!("esgm-location-{host}"))
            .spawn(move || location.run(&inbox))
            .map_err(ConnectError::Spawn)?;
        tracing::info!(%domain, %host, "connected");
        let thread = parking_lot::Mutex::new(Some(thread));
        Ok(ShmEsgm {
            inner: Arc::new(Inner {
                domain,
                host,
                local,
                commands,
                timeout,
                holdings,
                mirrors,
                thread,
                admin,
            }),
        })
    }
}

/// Raises this process's limit of open files to the most it may have, once: iceoryx2
/// keeps a descriptor open for every service a process opens and every port it holds
/// (about ten for a trajectory it writes), and the usual soft limit, 1,024, would stop
/// a process at a hundred trajectories where its hard limit allows thousands.
fn raise_file_limit() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        // SAFETY: `limit` is a valid rlimit for the calls to read and write.
        let raised = unsafe {
            libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) == 0
                && (limit.rlim_cur >= limit.rlim_max || {
                    limit.rlim_cur = limit.rlim_max;
                    libc::setrlimit(libc::RLIMIT_NOFILE, &limit) == 0
                })
        };
        if !raised {
            tracing::debug!("cannot raise the limit of open files; the system's holds");
        }
    });
}

fn default_host() -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let program = std::env::args()
        .next()
        .and_then(|p| {
            std::path::Path::new(&p).file_name().map(|f| f.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "process".into());
    let clean: String = program
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' })
        .collect();
    format!("{clean}-{}-{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed))
}

#[derive(Debug)]
struct Inner {
    domain: String,
    host: String,
    local: InProcessEsgm,
    commands: Sender<Command>,
    timeout: Duration,
    holdings: Arc<Holdings>,
    /// The trajectories read here (whether their history was handed over), and for
    /// the tests, what asks the receiver thread to panic.
    mirrors: Arc<SharedMirrors>,
    thread: parking_lot::Mutex<Option<std::thread::JoinHandle<()>>>,
    admin: Arc<Admin>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        // Disconnect the command channel: the location thread closes its ports and
        // ends; wait for it, so nothing of this connection outlives it.
        let (closed, _) = crossbeam_channel::bounded(0);
        drop(std::mem::replace(&mut self.commands, closed));
        if let Some(t) = self.thread.lock().take() {
            if t.thread().id() != std::thread::current().id() {
                // A panic there was printed by the panic hook; a drop has nothing to add.
                let _ = t.join();
            }
        }
        self.admin.stop();
        self.local.shutdown();
    }
}

/// The ESGM of a shared-memory system, seen from this process (see the module docs).
/// Cheap to clone; the process leaves the system when the last clone is dropped.
#[derive(Debug, Clone)]
pub struct ShmEsgm {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Command {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Command")
    }
}

impl ShmEsgm {
    /// Starts building a connection.
    pub fn builder() -> ShmEsgmBuilder {
        ShmEsgmBuilder::default()
    }

    /// The system's domain.
    pub fn domain(&self) -> &str {
        &self.inner.domain
    }

    /// This process's name in the registry.
    pub fn host(&self) -> &str {
        &self.inner.host
    }

    /// The local runtime holding this process's trajectories and replicas.
    pub fn local(&self) -> &InProcessEsgm {
        &self.inner.local
    }

    /// Makes this process write the trajectories the coordinator places on it even
    /// though it serves no sensor or unit (registering one does this too): primitive,
    /// sync and merge trajectories created for it by others, e.g. the system's own
    /// location in `esgm up`, which writes what the command line creates.
    pub fn serve_assignments(&self) {
        if self.inner.commands.send(Command::Serving).is_err() {
            tracing::warn!("cannot serve assignments: the location thread has stopped");
        }
    }

    /// Whether the history of `trajectory` is all here: true for one this process
    /// writes, and for one it reads whose writer handed this connection its history
    /// when the connection began to read it (answered its join); false for a
    /// trajectory not read here yet, or whose writer did not answer in time (its
    /// history then comes with the writer's next sample or maintenance). A program
    /// that reads a trajectory once and leaves (`esgm latest`) answers at once when
    /// it is true, and waits for the history to settle otherwise.
    pub fn history_received(&self, trajectory: &str) -> bool {
        match self.inner.mirrors.import(trajectory) {
            Some(import) => import.lock().history_received(),
            None => self.inner.local.get_entity_trajectory_structure(trajectory).is_ok(),
        }
    }

    /// Images (octet sequences) received from other processes that this process reads
    /// in shared memory, and those it had to copy: a replica's cache, its units, its
    /// subscribers and query answers share the writer's chunk, borrowed until the last
    /// value reading it is dropped (see [`crate::HoldingStats`]). `None` if this
    /// process's location thread has stopped (never, since values own what they
    /// hold; kept for callers that match on it).
    pub fn holding_stats(&self) -> Option<HoldingStats> {
        Some(self.inner.holdings.stats())
    }

    /// Test support, not an API: makes this connection's location thread and
    /// receiver thread panic, to check that nothing a value reads depends on them.
    /// Only with the `test-seams` feature, which esgm-shm's own tests turn on.
    #[doc(hidden)]
    #[cfg(feature = "test-seams")]
    pub fn inject_thread_panics_for_tests(&self) {
        if self.inner.commands.send(Command::Panic).is_err() {
            tracing::debug!("the location thread has stopped already");
        }
        self.inner.mirrors.request_panic();
    }

    /// Blocks while the coordinator answers; returns once it has been gone for
    /// `patience` (a worker's main loop: it leaves with its system).
    pub fn serve_until_coordinator_gone(&self, patience: Duration) {
        self.serve_while(patience, || true);
    }

    /// [`ShmEsgm::serve_until_coordinator_gone`], also leaving as soon as `go_on`
    /// (asked every quarter second) says false: a worker hosted by another runtime,
    /// such as Python's, looks at its signals there. Returns true if the coordinator
    /// went, false if `go_on` stopped it.
    pub fn serve_while(&self, patience: Duration, mut go_on: impl FnMut() -> bool) -> bool {
        const PING_EVERY: Duration = Duration::from_millis(250);
        let mut watch = CoordinatorWatch::new(patience).every(Duration::ZERO);
        loop {
            std::thread::sleep(PING_EVERY);
            if !go_on() {
                return false;
            }
            if watch.gone(self) {
                return true;
            }
        }
    }

    /// Sends a command and waits for its answer, with a deadline a little longer than
    /// a control call's (the location thread may be making one for someone else).
    fn ask<T>(
        &self,
        make: impl FnOnce(Sender<T>) -> Command,
        unavailable: impl FnOnce(Unreachable) -> T,
    ) -> T {
        let (reply, answer) = crossbeam_channel::bounded(1);
        if self.inner.commands.send(make(reply)).is_err() {
            return unavailable(Unreachable::Closing);
        }
        match answer.recv_timeout(self.inner.timeout * 3) {
            Ok(t) => t,
            // Timed out, or the thread ended without answering: unavailable either way.
            Err(_) => unavailable(Unreachable::no_answer(Peer::Connection, self.inner.timeout * 3)),
        }
    }

    /// E7 across the system: every process empties the trajectories it writes, then
    /// every process takes what it was sent, so every replica has forgotten on return.
    pub fn reset_domain(&self) -> Result<(), AdminError> {
        let timeout = self.inner.timeout;
        self.inner.admin.ask(AdminOp::Reset { trajectory: None }, timeout)?;
        self.inner.admin.ask(AdminOp::CatchUp, timeout)?;
        Ok(())
    }

    /// E7 across the system: every trajectory's statistics from the process that
    /// writes it (a replica's, what it received, where no writer answered).
    pub fn domain_stats(&self) -> Result<EsgmStats, AdminError> {
        self.domain_stats_listed().map(|(stats, _)| stats)
    }

    /// [`ShmEsgm::domain_stats`], and the listed trajectories that no process reported
    /// (a trajectory whose writer is gone and that nobody reads): with the reports, every
    /// trajectory [`Esgm::trajectories`] lists. The coordinator's listing and the
    /// processes' answers are asked for at once.
    pub fn domain_stats_listed(&self) -> Result<(EsgmStats, Vec<TrajectoryInfo>), AdminError> {
        let (listing, answers) = std::thread::scope(|s| {
            let listing = s.spawn(|| self.control(Request::ListTrajectories));
            let answers = self.inner.admin.ask(AdminOp::Stats, self.inner.timeout);
            (listing.join(), answers)
        });
        let listing = match listing {
            Ok(Ok(Response::Trajectories(t))) => t,
            Ok(other) => return Err(AdminError::Unavailable { reason: not_given(other) }),
            Err(_) => {
                let reason =
                    Unreachable::transport(Peer::Connection, "the listing thread panicked");
                return Err(AdminError::Unavailable { reason });
            }
        };
        Ok(stats_row::with_listing(admin::combine_stats(answers?), listing))
    }

    /// E7 across the system: the memory of every connected process added up (a
    /// replica is memory of its process, so a trajectory read in three processes
    /// counts three times).
    pub fn domain_memory(&self) -> Result<MemoryStats, AdminError> {
        let answers = self.inner.admin.ask(AdminOp::Memory, self.inner.timeout)?;
        Ok(admin::combine_memory(&answers))
    }

    /// E7: sets the log level of the process named `process` (its host name in the
    /// registry, the process name `esgm ps` shows for supervised workers), or of every
    /// process. A process logging through `esgm_shm::process::init_logging` replaces
    /// its tracing filter at once. Returns the processes it applied to; none matching
    /// `process` is an error.
    pub fn set_log_level_of(
        &self,
        process: Option<&str>,
        level: LogLevel,
    ) -> Result<Vec<String>, AdminError> {
        let op = AdminOp::SetLogLevel { level, process: process.map(str::to_owned) };
        let answers = self.inner.admin.ask(op, self.inner.timeout)?;
        let mut applied = Vec::new();
        for (host, answer) in answers {
            match answer {
                AdminAnswer::LogLevel { applied: true, .. } => applied.push(host),
                AdminAnswer::Failed { reason } => {
                    return Err(AdminError::Send {
                        reason: Unreachable::refused(Peer::Processes, format!("{host}: {reason}")),
                    });
                }
                _ => {}
            }
        }
        if applied.is_empty() {
            return Err(AdminError::NoSuchProcess { name: process.unwrap_or("*").to_owned() });
        }
        applied.sort();
        Ok(applied)
    }

    /// `flush` across the system: rounds in which every process takes what other
    /// processes sent and waits for its own workers, until a round changes nothing
    /// anywhere (a chain of units across processes settles hop by hop).
    fn flush_domain(&self, deadline: std::time::Instant) -> Result<(), FlushError> {
        let mut previous = None;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Err(FlushError::DeadlinePassed { waiting_for: "the system".into() });
            }
            // Each process gives up at the deadline and says so; the asker waits a
            // control call's time longer for those answers.
            let op = AdminOp::Flush { timeout: left };
            let answers = match self.inner.admin.ask(op, left + self.inner.timeout) {
                Ok(a) => a,
                Err(AdminError::Incomplete { answered, expected, .. }) => {
                    return Err(FlushError::DeadlinePassed {
                        waiting_for: format!("{} of {expected} processes", expected - answered),
                    });
                }
                Err(e) => return Err(FlushError::Unavailable { reason: e.into() }),
            };
            for (host, answer) in &answers {
                if let AdminAnswer::Failed { reason } = answer {
                    return Err(FlushError::DeadlinePassed {
                        waiting_for: format!("{host}: {reason}"),
                    });
                }
            }
            let answers = self
                .inner
                .admin
                .ask(AdminOp::Stats, self.inner.timeout)
                .map_err(|e| FlushError::Unavailable { reason: e.into() })?;
            let progress = admin::progress(admin::combine_stats(answers));
            if previous.as_ref() == Some(&progress) {
                return Ok(());
            }
            previous = Some(progress);
        }
    }

    /// One control request, answered by the coordinator.
    pub fn control(&self, request: Request) -> Result<Response, ControlClientError> {
        self.ask(
            |reply| Command::Control(Box::new(request), reply),
            |reason| Err(ControlClientError::LocationUnavailable { reason }),
        )
    }

    /// Registers `type_name` (and every element type it names) locally from the
    /// coordinator, if it is not known here yet.
    fn sync_type(&self, type_name: &str) -> Result<(), ControlClientError> {
        if self.inner.local.get_entity_structure_type(type_name).is_ok() {
            return Ok(());
        }
        let request = Request::GetTypeDefinitions { type_name: type_name.to_owned() };
        if let Response::Definitions(defs) = self.control(request)? {
            install(&self.inner.local, &defs);
        }
        Ok(())
    }
}

/// A listing the coordinator did not give, as the caller's error (never this
/// process's own view, which would look complete and not be).
fn unanswered(operation: &str, answer: Result<Response, ControlClientError>) -> SystemError {
    SystemError::Unavailable { operation: operation.to_owned(), reason: not_given(answer) }
}

/// Why the coordinator did not give what was asked: the call failed, or it answered
/// something else.
fn not_given(answer: Result<Response, ControlClientError>) -> Unreachable {
    match answer {
        Err(e) => e.into(),
        Ok(other) => Unreachable::malformed(Peer::Coordinator, format!("{other:?}")),
    }
}

/// A domain-wide question that did not reach every process, as the caller's error.
fn unreached(operation: &str, e: AdminError) -> SystemError {
    let operation = operation.to_owned();
    match e {
        AdminError::Incomplete { answered, expected, timeout } => {
            SystemError::Incomplete { operation, answered, expected, timeout }
        }
        e => SystemError::Unavailable { operation, reason: e.into() },
    }
}

fn type_error(e: ControlClientError) -> TypeRegistryError {
    match e {
        ControlClientError::Remote(ControlError::Type(e)) => e,
        e => TypeRegistryError::Unavailable { reason: e.into() },
    }
}

fn registration_error(e: ControlClientError) -> RegistrationError {
    match e {
        ControlClientError::Remote(ControlError::Registration(e)) => e,
        ControlClientError::Remote(ControlError::Type(
            TypeRegistryError::NoSuchEntityStructureType { name, suggestion },
        )) => RegistrationError::NoSuchEntityStructureType { name, suggestion },
        e => RegistrationError::Unavailable { reason: e.into() },
    }
}

impl Esgm for ShmEsgm {
    type Trajectory = InProcessTrajectory;

    fn create_entity_structure_type(
        &self,
        type_name: &str,
        entity_type: EntityStructureType,
    ) -> Result<(), TypeRegistryError> {
        let request = Request::CreateEntityStructureType {
            type_name: type_name.to_owned(),
            entity_type: entity_type.clone(),
        };
        self.control(request).map_err(type_error)?;
        // Already known here (e.g. from a destroyed-and-recreated name): take the
        // coordinator's, which is the one just registered.
        let _not_known_here = self.inner.local.destroy_entity_structure_type(type_name);
        if let Err(e) = self.inner.local.create_entity_structure_type(type_name, entity_type) {
            tracing::warn!(type_name, error = %e,
                "registered in the system but not in this process; it is fetched when used");
        }
        Ok(())
    }

    fn destroy_entity_structure_type(&self, type_name: &str) -> Result<(), TypeRegistryError> {
        let request = Request::DestroyEntityStructureType { type_name: type_name.to_owned() };
        self.control(request).map_err(type_error)?;
        let _not_known_here = self.inner.local.destroy_entity_structure_type(type_name);
        Ok(())
    }

    fn get_entity_structure_type(
        &self,
        type_name: &str,
    ) -> Result<EntityStructureType, TypeRegistryError> {
        let request = Request::GetEntityStructureType { type_name: type_name.to_owned() };
        match self.control(request).map_err(type_error)? {
            Response::Type(t) => Ok(t),
            other => Err(TypeRegistryError::Unavailable {
                reason: Unreachable::malformed(Peer::Coordinator, format!("{other:?}")),
            }),
        }
    }

    fn entity_structure_type_names(&self) -> Result<Vec<String>, SystemError> {
        match self.control(Request::ListEntityStructureTypes) {
            Ok(Response::Names(names)) => Ok(names),
            other => Err(unanswered("list the types", other)),
        }
    }

    fn create_trajectory(&self, spec: TrajectorySpec) -> Result<InProcessTrajectory, CreateError> {
        self.ask(
            |reply| Command::Create(Box::new(spec), reply),
            |reason| Err(CreateError::Unavailable { reason }),
        )
    }

    fn get_entity_trajectory_structure(
        &self,
        name: &str,
    ) -> Result<InProcessTrajectory, LookupError> {
        let name = name.to_owned();
        self.ask(
            |reply| Command::Get(name, reply),
            |reason| Err(LookupError::Unavailable { reason }),
        )
    }

    fn get_entity_trajectory_structure_type(
        &self,
        name: &str,
    ) -> Result<EntityStructureType, LookupError> {
        let request = Request::GetEntityTrajectoryStructure { name: name.to_owned() };
        let record = location::trajectory_record(self.control(request))?;
        match record.types.into_iter().find(|(n, _)| *n == record.info.type_name) {
            Some((_, t)) => Ok(t),
            // A synthesized type (state over generators) lives with its writer.
            None => self.get_entity_trajectory_structure(name).and_then(|h| {
                esgm_core::EntityTrajectoryStructure::entity_type(&h).map_err(|e| {
                    LookupError::Unavailable { reason: Unreachable::transport(Peer::Writer, e) }
                })
            }),
        }
    }

    fn destroy_entity_trajectory_structure(&self, name: &str) -> Result<(), LookupError> {
        let name = name.to_owned();
        self.ask(
            |reply| Command::Destroy(name, reply),
            |reason| Err(LookupError::Unavailable { reason }),
        )
    }

    fn trajectories(&self) -> Result<Vec<TrajectoryInfo>, SystemError> {
        match self.control(Request::ListTrajectories) {
            Ok(Response::Trajectories(t)) => Ok(t),
            other => Err(unanswered("list the trajectories", other)),
        }
    }

    fn why(
        &self,
        trajectory: &str,
        since: esgm_core::Time,
    ) -> Result<esgm_core::esgm::Why, LookupError> {
        self.why_anywhere(trajectory, since)
    }

    fn add_sensor_interface(
        &self,
        sensor: &str,
        type_name: &str,
        iface: Arc<dyn SensorInterface>,
    ) -> Result<(), RegistrationError> {
        // Registered here already: the coordinator would take it for a restarted
        // worker taking its place back, and the rollback below would remove the one
        // that serves.
        if self.inner.local.sensors_here().iter().any(|(s, _)| s == sensor) {
            return Err(RegistrationError::SensorAlreadyExists { name: sensor.to_owned() });
        }
        let request = Request::AddSensorInterface {
            sensor: sensor.to_owned(),
            type_name: type_name.to_owned(),
            host: self.inner.host.clone(),
        };
        self.control(request).map_err(registration_error)?;
        let local = self
            .sync_type(type_name)
            .map_err(registration_error)
            .and_then(|()| self.inner.local.add_sensor_interface(sensor, type_name, iface));
        if let Err(e) = local {
            let undo = self.control(Request::RemoveSensorInterface { sensor: sensor.to_owned() });
            if let Err(undo) = undo {
                tracing::warn!(sensor, error = %undo,
                    "a sensor that failed to register here stays registered in the system");
            }
            return Err(e);
        }
        self.serve_assignments();
        Ok(())
    }

    fn remove_sensor_interface(&self, sensor: &str) -> Result<(), RegistrationError> {
        let request = Request::RemoveSensorInterface { sensor: sensor.to_owned() };
        self.control(request).map_err(registration_error)?;
        // Registered in another process, it is not known here.
        let _served_elsewhere = self.inner.local.remove_sensor_interface(sensor);
        Ok(())
    }

    fn add_comp_unit(
        &self,
        name: &str,
        type_name: &str,
        input_types: Vec<InputType>,
        cu: Arc<dyn CompUnit>,
    ) -> Result<(), RegistrationError> {
        // As for sensors: a second registration here must not undo the first.
        if self.inner.local.units_here().iter().any(|(u, _, _)| u == name) {
            return Err(RegistrationError::CompUnitAlreadyExists { name: name.to_owned() });
        }
        let request = Request::AddCompUnit {
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            input_types: input_types.clone(),
            host: self.inner.host.clone(),
        };
        self.control(request).map_err(registration_error)?;
        let mut local = self.sync_type(type_name).map_err(registration_error);
        for t in &input_types {
            if let (Ok(()), InputType::Type(t)) = (&local, t) {
                local = self.sync_type(t).map_err(registration_error);
            }
        }
        let local =
            local.and_then(|()| self.inner.local.add_comp_unit(name, type_name, input_types, cu));
        if let Err(e) = local {
            let undo = self.control(Request::RemoveCompUnit { name: name.to_owned() });
            if let Err(undo) = undo {
                tracing::warn!(unit = name, error = %undo,
                    "a unit that failed to register here stays registered in the system");
            }
            return Err(e);
        }
        self.serve_assignments();
        Ok(())
    }

    fn remove_comp_unit(&self, name: &str) -> Result<(), RegistrationError> {
        let request = Request::RemoveCompUnit { name: name.to_owned() };
        self.control(request).map_err(registration_error)?;
        // Registered in another process, it is not known here.
        let _served_elsewhere = self.inner.local.remove_comp_unit(name);
        Ok(())
    }

    fn sensors(&self) -> Result<Vec<(String, String)>, SystemError> {
        match self.control(Request::ListSensors) {
            Ok(Response::Sensors(s)) => Ok(s.into_iter().map(|s| (s.name, s.type_name)).collect()),
            other => Err(unanswered("list the sensors", other)),
        }
    }

    fn comp_units(&self) -> Result<Vec<(String, String, Vec<InputType>)>, SystemError> {
        match self.control(Request::ListCompUnits) {
            Ok(Response::CompUnits(u)) => {
                Ok(u.into_iter().map(|u| (u.name, u.type_name, u.input_types)).collect())
            }
            other => Err(unanswered("list the units", other)),
        }
    }

    fn ping(&self) -> bool {
        matches!(self.control(Request::Ping), Ok(Response::Pong { .. }))
    }

    fn flush(&self, deadline: std::time::Instant) -> Result<(), FlushError> {
        self.flush_domain(deadline)
    }

    fn reset(&self) -> Result<(), SystemError> {
        self.reset_domain().map_err(|e| unreached("reset the system", e))
    }

    fn stats(&self) -> Result<EsgmStats, SystemError> {
        self.domain_stats().map_err(|e| unreached("gather the statistics", e))
    }

    fn memory_stats(&self) -> Result<MemoryStats, SystemError> {
        self.domain_memory().map_err(|e| unreached("gather the memory statistics", e))
    }

    fn log_level(&self) -> LogLevel {
        self.inner.local.log_level()
    }

    fn set_log_level(&self, level: LogLevel) -> Result<(), SystemError> {
        self.set_log_level_of(None, level)
            .map(|_applied| ())
            .map_err(|e| unreached("set the log level", e))
    }
}
