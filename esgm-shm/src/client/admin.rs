//! The domain's administration channel: the whole-ESGM operations (E7 `reset`,
//! `stats`, `memory_stats`, `set_log_level`, T5 resets through any handle, and
//! `flush`) asked of every connected process, and their answers collected.
//!
//! Two publish-subscribe services of the domain carry it, sized by its limits
//! ([`crate::capacity::DomainLimits`]) and created by the coordinator:
//! - **questions** (`esgm/<domain>/admin`): every connected process subscribes, and
//!   its *admin thread* waits on the domain's admin wake-up. An asker opens a
//!   publisher for its question alone (at most [`ASKERS`] at once; one more waits its
//!   turn), rings the wake-up, and drops both once answered.
//! - **answers** (`esgm/<domain>/admin-answers`): an asker subscribes for the
//!   question's time; each process answers with a publisher of its own, opened at its
//!   first answer, and the asker polls (a question is rare; waking every process for
//!   every answer would cost more).
//!
//! So a process's standing cost is one subscriber and one listener, whatever the
//! domain's size, and no port connects every process to every other: a question
//! costs one connection per process, made and dropped with it.
//!
//! The asker waits until as many answers came as the questions service had
//! subscribers when it asked — every connected process, itself included — or its
//! deadline passes (an error naming how many answered).
//!
//! A process killed without leaving still counts as a subscriber until the
//! coordinator's dead-node cleanup removes its ports; until then a question waits its
//! whole deadline and fails as [`AdminError::Incomplete`] (E7's `reset` logs it;
//! `stats` and `memory_stats` log it and answer with this process's own view;
//! `reset_blocking`, `flush` and the `domain_*` methods return it).
//!
//! Why not the coordinator: it knows trajectories, not what each process holds, and a
//! reset must reach the writer's store and every replica, in the processes that hold
//! them. The coordinator stays out of the data's way.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use esgm_core::esgm::{Esgm, LimitReached, LogLevel, MemoryStats, TrajectoryReport};
use esgm_core::{InProcessEsgm, QueryError, ResetForwarder};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::{AllocationStrategy, PortFactory as _, ServiceName};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};
use parking_lot::Mutex;
use serde::{Deserialize, Serialize};

use super::mirrors::SharedMirrors;
use super::shared_node::SharedNode;
use crate::capacity::{DomainLimits, EventCapacity, TOOL_RESERVE};
use crate::service::{ShmNode, ShmService, open_event_service};

/// Processes that may ask the domain at once; one more waits until one is answered.
pub(crate) const ASKERS: usize = 8;
/// The largest question or answer, in bytes: statistics of every trajectory a process
/// holds (a few hundred bytes each) fit thousands. Messages are loaned from a
/// fixed-size pool mapped (not committed) for the askers' queues.
const MAX_MESSAGE: usize = 4 << 20;
/// Questions a process may have waiting before the oldest is dropped.
const BUFFER: usize = 4;
/// The longest the admin thread sleeps before it looks for its stop (stopping rings
/// it awake; this is the backstop). Every 2 s it was a wake-up a second in every
/// process of an idle robot.
const RECHECK: Duration = Duration::from_secs(30);
/// The longest an asker sleeps between two looks for answers.
const POLL: Duration = Duration::from_millis(1);

type Channel = publish_subscribe::PortFactory<ShmService, [u8], ()>;

/// The domain's administration services (see the module docs): opened by every
/// process, created by the coordinator with the domain's limits.
#[derive(Debug)]
pub(crate) struct AdminServices {
    questions: Channel,
    answers: Channel,
    wake: event::PortFactory<ShmService>,
}

impl AdminServices {
    /// Opens (or creates, sized for `limits`) the administration services of `domain`
    /// on `node`. A domain made with other limits is opened as it is.
    pub fn open(node: &ShmNode, domain: &str, limits: &DomainLimits) -> Result<Self, AdminError> {
        let (questions, answers, wake) = names(domain)?;
        let unavailable = |what: &str, e: &dyn std::fmt::Debug| AdminError::Unavailable {
            reason: format!("{what}: {e:?}"),
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
    /// that is not a tool may take; see [`crate::capacity`]).
    fn max_processes(&self) -> usize {
        self.questions.static_config().max_subscribers().saturating_sub(TOOL_RESERVE)
    }
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

/// A question to every process.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) enum AdminOp {
    /// Empty `trajectory` (every trajectory if `None`) where it is written.
    Reset {
        /// The trajectory, or all.
        trajectory: Option<String>,
    },
    /// Take everything other processes sent (replicas' samples and resets, inboxes)
    /// into this process's stores now.
    CatchUp,
    /// This process's trajectories' statistics.
    Stats,
    /// This process's memory.
    Memory,
    /// Apply `level` (in `process` only, if named).
    SetLogLevel {
        /// The level.
        level: LogLevel,
        /// The process (its host name), or every process.
        process: Option<String>,
    },
    /// Take what other processes sent, then wait until this process's workers have
    /// processed everything they were given (`InProcessEsgm::flush`).
    Flush {
        /// How long the process may wait.
        timeout: Duration,
    },
}

/// A process's answer.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) enum AdminAnswer {
    /// Done (for a reset: how many trajectories this process emptied).
    Done {
        /// Trajectories reset here.
        reset: usize,
    },
    /// Statistics of every local trajectory, each marked true if this process writes
    /// it (the writer's are the trajectory's own; a replica's are what it received).
    Stats(Vec<(bool, TrajectoryReport)>),
    /// This process's memory.
    Memory(MemoryStats),
    /// The level was applied (`filter`: to a reloadable tracing filter too).
    LogLevel {
        /// True if this process is the one named.
        applied: bool,
        /// True if its tracing filter was replaced.
        filter: bool,
    },
    /// The question failed here.
    Failed {
        /// Why.
        reason: String,
    },
}

#[derive(Debug, Serialize, Deserialize)]
enum Body {
    Ask(AdminOp),
    Answer { to: String, answer: AdminAnswer },
}

#[derive(Debug, Serialize, Deserialize)]
struct Envelope {
    from: String,
    id: u64,
    body: Body,
}

/// A domain-wide question failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AdminError {
    /// Fewer processes answered than were connected when it was asked (one is stuck or
    /// gone); what did answer is in `answered`.
    #[error("{answered} of {expected} processes answered within {timeout:?}")]
    Incomplete {
        /// Answers received.
        answered: usize,
        /// Processes connected when asked.
        expected: usize,
        /// The deadline.
        timeout: Duration,
    },
    /// The question could not be sent (see the reason).
    #[error("cannot ask the domain's processes: {reason}")]
    Send {
        /// Why.
        reason: String,
    },
    /// The domain has as many processes as it admits ([`crate::capacity`]).
    #[error(transparent)]
    LimitReached(LimitReached),
    /// The administration channel is not running in this process.
    #[error("the administration channel is not running: {reason}")]
    Unavailable {
        /// Why.
        reason: String,
    },
}

/// A collected set of answers: `(process, answer)`.
pub(crate) type Answers = Vec<(String, AdminAnswer)>;

/// This connection's end of the channel: asks, and owns the thread that answers.
pub(crate) struct Admin {
    host: String,
    node: SharedNode,
    services: Arc<AdminServices>,
    next: AtomicU64,
    stop: Arc<AtomicBool>,
    thread: Mutex<Option<JoinHandle<()>>>,
    /// Rings the admin threads (made at the first question or stop).
    ring: Mutex<Option<iceoryx2::port::notifier::Notifier<ShmService>>>,
}

impl std::fmt::Debug for Admin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Admin").field("host", &self.host).finish_non_exhaustive()
    }
}

fn names(domain: &str) -> Result<(ServiceName, ServiceName, ServiceName), AdminError> {
    let name = |s: String| {
        ServiceName::new(&s).map_err(|e| AdminError::Unavailable { reason: format!("{s}: {e:?}") })
    };
    let prefix = crate::service_name::SERVICE_PREFIX;
    Ok((
        name(format!("{prefix}/{domain}/admin"))?,
        name(format!("{prefix}/{domain}/admin-answers"))?,
        name(format!("{prefix}/{domain}/admin-wake"))?,
    ))
}

/// Retries `make` while iceoryx2 says every port is taken (`busy`), until `deadline`.
fn port_within<P, E: std::fmt::Debug>(
    deadline: Instant,
    mut make: impl FnMut() -> Result<P, E>,
    busy: impl Fn(&E) -> bool,
) -> Result<P, String> {
    loop {
        match make() {
            Ok(p) => return Ok(p),
            Err(e) if busy(&e) && Instant::now() < deadline => std::thread::sleep(POLL),
            Err(e) => return Err(format!("{e:?}")),
        }
    }
}

impl Admin {
    /// Joins the channel of `domain` as `host` and starts the thread that answers
    /// from `local` and `mirrors`; refuses with [`AdminError::LimitReached`] once the
    /// domain has as many processes as it admits. A `tool` (a short-lived command)
    /// only asks: it is not counted, and answers nothing.
    pub fn start(
        node: &SharedNode,
        domain: &str,
        host: &str,
        tool: bool,
        local: InProcessEsgm,
        mirrors: Arc<SharedMirrors>,
    ) -> Result<Arc<Self>, AdminError> {
        let unavailable = |what: &str, e: &dyn std::fmt::Debug| AdminError::Unavailable {
            reason: format!("{what}: {e:?}"),
        };
        let services =
            node.with(|node| AdminServices::open(node, domain, &DomainLimits::default()))?;
        let max = services.max_processes();
        let full = |connected: usize| {
            AdminError::LimitReached(LimitReached::processes(domain, max.min(connected)))
        };
        let services = Arc::new(services);
        let admin = Arc::new(Self {
            host: host.to_owned(),
            node: node.clone(),
            services: Arc::clone(&services),
            next: AtomicU64::new(0),
            stop: Arc::default(),
            thread: Mutex::new(None),
            ring: Mutex::new(None),
        });
        if tool {
            // A command asks and leaves: it holds nothing another process's question
            // is about, and is not counted among the domain's processes.
            return Ok(admin);
        }
        // The processes that crashed still count until someone cleans up after them.
        let lacks_room = |e: &AdminError| matches!(e, AdminError::LimitReached(_));
        let (subscriber, listener) = crate::service::with_room(lacks_room, || {
            let connected = services.questions.dynamic_config().number_of_subscribers();
            if connected >= max {
                return Err(full(connected));
            }
            node.with(|_| {
                let subscriber =
                    services.questions.subscriber_builder().create().map_err(|e| match e {
                        SubscriberCreateError::ExceedsMaxSupportedSubscribers => full(max),
                        e => unavailable("the admin subscriber", &e),
                    })?;
                let listener = services.wake.listener_builder().create().map_err(|e| match e {
                    iceoryx2::port::listener::ListenerCreateError::ExceedsMaxSupportedListeners => {
                        full(max)
                    }
                    e => unavailable("the admin listener", &e),
                })?;
                Ok::<_, AdminError>((subscriber, listener))
            })
        })?;
        let answerer = Answerer {
            host: host.to_owned(),
            node: node.clone(),
            local,
            mirrors,
            services,
            subscriber,
            listener,
            answers: None,
            stop: Arc::clone(&admin.stop),
        };
        let thread = std::thread::Builder::new()
            .name("esgm-admin".to_owned())
            .spawn(move || answerer.run())
            .map_err(|e| AdminError::Unavailable { reason: e.to_string() })?;
        *admin.thread.lock() = Some(thread);
        Ok(admin)
    }

    /// Stops the answering thread and waits for it.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
        self.ring();
        if let Some(t) = self.thread.lock().take() {
            if t.thread().id() != std::thread::current().id() && t.join().is_err() {
                tracing::warn!("the admin thread panicked");
            }
        }
    }

    /// Wakes every admin thread of the domain.
    fn ring(&self) {
        let mut ring = self.ring.lock();
        if ring.is_none() {
            match self.node.with(|_| self.services.wake.notifier_builder().create()) {
                Ok(n) => *ring = Some(n),
                Err(e) => {
                    tracing::debug!(error = ?e, "cannot wake the admin threads; they look again soon");
                    return;
                }
            }
        }
        if let Some(Err(e)) = ring.as_ref().map(iceoryx2::port::notifier::Notifier::notify) {
            tracing::debug!(error = ?e, "cannot wake the admin threads; they look again soon");
        }
    }

    /// Asks every connected process `op` and waits up to `timeout` for all of them.
    pub fn ask(&self, op: AdminOp, timeout: Duration) -> Result<Answers, AdminError> {
        let deadline = Instant::now() + timeout;
        let send = |reason: String| AdminError::Send { reason };
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let bytes =
            serde_json::to_vec(&Envelope { from: self.host.clone(), id, body: Body::Ask(op) })
                .map_err(|e| send(e.to_string()))?;
        // Subscribed before asking, so that no answer can come first.
        let answers = port_within(
            deadline,
            || self.node.with(|_| self.services.answers.subscriber_builder().create()),
            |e| matches!(e, SubscriberCreateError::ExceedsMaxSupportedSubscribers),
        )
        .map_err(|e| send(format!("no room to receive answers ({ASKERS} askers at once): {e}")))?;
        let publisher = port_within(
            deadline,
            || {
                self.node.with(|_| {
                    self.services
                        .questions
                        .publisher_builder()
                        .initial_max_slice_len(bytes.len())
                        .allocation_strategy(AllocationStrategy::Static)
                        .create()
                })
            },
            |e| matches!(e, PublisherCreateError::ExceedsMaxSupportedPublishers),
        )
        .map_err(|e| send(format!("no room to ask ({ASKERS} askers at once): {e}")))?;
        let connected = || self.services.questions.dynamic_config().number_of_subscribers();
        let mut expected = connected();
        publisher
            .loan_slice_uninit(bytes.len())
            .map_err(|e| send(format!("{e:?}")))?
            .write_from_slice(&bytes)
            .send()
            .map_err(|e| send(format!("{e:?}")))?;
        self.ring();
        let mut collected = Vec::with_capacity(expected);
        // A process that crashed is counted until someone cleans up after it: if some
        // have not answered by half the deadline, this asker cleans up once and
        // expects only the living. (Not sooner: a cleanup reads every node of the
        // host, and a loaded machine's processes may take a while to answer.)
        let mut cleaned = false;
        let clean_after = Instant::now() + timeout / 2;
        while collected.len() < expected {
            if !cleaned && Instant::now() >= clean_after {
                cleaned = true;
                crate::control::server::log_cleanup(crate::service::cleanup_dead_nodes());
                expected = expected.min(connected());
                continue;
            }
            let mut any = false;
            loop {
                let sample = match answers.receive() {
                    Ok(Some(s)) => s,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::debug!(error = ?e, "cannot receive an admin answer now");
                        break;
                    }
                };
                any = true;
                match serde_json::from_slice::<Envelope>(sample.payload()) {
                    Ok(Envelope { from, id: got, body: Body::Answer { to, answer } })
                        if got == id && to == self.host =>
                    {
                        collected.push((from, answer));
                    }
                    // Another asker's, or an answer to a question given up on.
                    Ok(_) => {}
                    Err(e) => tracing::warn!(error = %e, "malformed admin answer dropped"),
                }
            }
            if !any {
                if Instant::now() >= deadline {
                    break;
                }
                std::thread::sleep(POLL);
            }
        }
        drop(publisher);
        if collected.len() < expected {
            return Err(AdminError::Incomplete { answered: collected.len(), expected, timeout });
        }
        Ok(collected)
    }
}

/// The admin thread: answers every question from this process's runtime.
struct Answerer {
    host: String,
    node: SharedNode,
    local: InProcessEsgm,
    mirrors: Arc<SharedMirrors>,
    services: Arc<AdminServices>,
    subscriber: Subscriber<ShmService, [u8], ()>,
    listener: Listener<ShmService>,
    /// This process's answers' publisher, opened at its first answer.
    answers: Option<Publisher<ShmService, [u8], ()>>,
    stop: Arc<AtomicBool>,
}

impl Answerer {
    fn run(mut self) {
        let mut failures = 0u64;
        while !self.stop.load(Ordering::Acquire) {
            if let Err(e) = crate::wait::timed_wait(&self.listener, RECHECK) {
                failures += 1;
                if failures == 1 {
                    tracing::warn!(error = ?e, "the admin thread cannot wait; it polls");
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            loop {
                let sample = match self.subscriber.receive() {
                    Ok(Some(s)) => s,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(error = ?e, "the admin thread cannot receive");
                        break;
                    }
                };
                let envelope: Envelope = match serde_json::from_slice(sample.payload()) {
                    Ok(e) => e,
                    Err(e) => {
                        tracing::warn!(error = %e, "malformed admin question dropped");
                        continue;
                    }
                };
                drop(sample);
                let Body::Ask(op) = envelope.body else { continue };
                let answer = self.answer(op);
                let reply = Envelope {
                    from: self.host.clone(),
                    id: envelope.id,
                    body: Body::Answer { to: envelope.from, answer },
                };
                if let Err(e) = self.reply(&reply) {
                    tracing::warn!(error = %e, "cannot answer an admin question");
                }
            }
        }
    }

    fn reply(&mut self, envelope: &Envelope) -> Result<(), String> {
        let bytes = serde_json::to_vec(envelope).map_err(|e| e.to_string())?;
        if bytes.len() > MAX_MESSAGE {
            return Err(format!("the answer is {} bytes, more than {MAX_MESSAGE}", bytes.len()));
        }
        if self.answers.is_none() {
            let publisher = self
                .node
                .with(|_| {
                    self.services
                        .answers
                        .publisher_builder()
                        .initial_max_slice_len(MAX_MESSAGE)
                        .allocation_strategy(AllocationStrategy::Static)
                        .create()
                })
                .map_err(|e| format!("cannot open the answers' publisher: {e:?}"))?;
            self.answers = Some(publisher);
        }
        let Some(publisher) = &self.answers else { return Err("no publisher".into()) };
        publisher
            .loan_slice_uninit(bytes.len())
            .map_err(|e| format!("{e:?}"))?
            .write_from_slice(&bytes)
            .send()
            .map_err(|e| format!("{e:?}"))?;
        Ok(())
    }

    /// The trajectories this process writes.
    fn written(&self) -> Vec<String> {
        self.mirrors.lock().exports.keys().cloned().collect()
    }

    fn answer(&self, op: AdminOp) -> AdminAnswer {
        match op {
            AdminOp::Reset { trajectory } => {
                let written = self.written();
                let targets: Vec<&String> = match &trajectory {
                    Some(t) => written.iter().filter(|w| *w == t).collect(),
                    None => written.iter().collect(),
                };
                let mut reset = 0;
                for name in targets {
                    let done = self
                        .local
                        .get_entity_trajectory_structure(name)
                        .map_err(|e| e.to_string())
                        .and_then(|h| h.with_store(|s| s.reset()).map_err(|e| e.to_string()));
                    match done {
                        Ok(()) => reset += 1,
                        Err(e) => tracing::debug!(trajectory = %name, error = %e,
                            "a trajectory to reset went meanwhile"),
                    }
                }
                AdminAnswer::Done { reset }
            }
            AdminOp::CatchUp => {
                self.mirrors.lock().pump();
                AdminAnswer::Done { reset: 0 }
            }
            AdminOp::Stats => {
                let written = self.written();
                let stats = self.local.stats_here();
                AdminAnswer::Stats(
                    stats
                        .trajectories
                        .into_iter()
                        .map(|(name, report)| (written.contains(&name), report))
                        .collect(),
                )
            }
            AdminOp::Memory => AdminAnswer::Memory(self.local.memory_here()),
            AdminOp::SetLogLevel { level, process } => {
                if process.as_ref().is_some_and(|p| *p != self.host) {
                    return AdminAnswer::LogLevel { applied: false, filter: false };
                }
                self.local.set_log_level_here(level);
                match crate::process::apply_log_level(level) {
                    Ok(filter) => {
                        tracing::info!(?level, "log level set by the domain");
                        AdminAnswer::LogLevel { applied: true, filter }
                    }
                    Err(reason) => AdminAnswer::Failed { reason },
                }
            }
            AdminOp::Flush { timeout } => {
                let deadline = Instant::now() + timeout;
                self.mirrors.lock().pump();
                match self.local.flush(deadline) {
                    Ok(()) => AdminAnswer::Done { reset: 0 },
                    Err(e) => AdminAnswer::Failed { reason: e.to_string() },
                }
            }
        }
    }
}

/// Resets through a handle of a trajectory held here (written or replicated) go to
/// every process: the writer empties the stream (its readers forget it with the
/// reset it publishes); `blocking`, every process then takes what it was sent, so
/// every connected reader has forgotten on return.
#[derive(Debug)]
pub(crate) struct DomainReset {
    pub admin: std::sync::Weak<Admin>,
    pub timeout: Duration,
}

impl ResetForwarder for DomainReset {
    fn reset(&self, trajectory: &str, blocking: bool) -> Result<(), QueryError> {
        let unavailable =
            |reason: String| QueryError::Unavailable { trajectory: trajectory.to_owned(), reason };
        let admin = self.admin.upgrade().ok_or_else(|| unavailable("disconnected".into()))?;
        let op = AdminOp::Reset { trajectory: Some(trajectory.to_owned()) };
        let answers = admin.ask(op, self.timeout).map_err(|e| unavailable(e.to_string()))?;
        let reset: usize = answers
            .iter()
            .map(|(_, a)| match a {
                AdminAnswer::Done { reset } => *reset,
                _ => 0,
            })
            .sum();
        if reset == 0 {
            return Err(unavailable("no connected process writes it".into()));
        }
        if blocking {
            admin.ask(AdminOp::CatchUp, self.timeout).map_err(|e| unavailable(e.to_string()))?;
        }
        Ok(())
    }
}
