//! The domain's administration channel: the whole-ESGM operations (E7 `reset`,
//! `stats`, `memory_stats`, `set_log_level`, T5 resets through any handle, and
//! `flush`) asked of every connected process, and their answers collected.
//!
//! Every connection publishes and subscribes on one publish-subscribe service of the
//! domain (`esgm/<domain>/admin`) and wakes the others through its event service. A
//! question goes to everyone (the asking process included: one path for all); each
//! process's *admin thread* answers it from its own runtime and mirrors, and the asker
//! waits until as many answers came as the service had subscribers when it asked —
//! every connected process — or its deadline passes (an error naming how many
//! answered). Answers are addressed to the asker; the others drop them.
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

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::Sender;
use esgm_core::esgm::{Esgm, LogLevel, MemoryStats, TrajectoryReport};
use esgm_core::{InProcessEsgm, QueryError, ResetForwarder};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{AllocationStrategy, PortFactory as _, ServiceName};
use parking_lot::Mutex;
use serde::{Deserialize, Serialize};

use super::mirrors::SharedMirrors;
use super::shared_node::SharedNode;
use crate::service::{ShmService, open_event_service};

/// How many processes of one domain the channel serves.
const MAX_PROCESSES: usize = 32;
/// Messages a process may have waiting before the oldest is dropped.
const BUFFER: usize = 16;
/// The longest the admin thread sleeps before it looks for its stop.
const RECHECK: Duration = Duration::from_millis(500);

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
    publisher: Mutex<Publisher<ShmService, [u8], ()>>,
    service: iceoryx2::service::port_factory::publish_subscribe::PortFactory<ShmService, [u8], ()>,
    wake: Notifier<ShmService>,
    pending: Mutex<HashMap<u64, Sender<(String, AdminAnswer)>>>,
    next: AtomicU64,
    stop: Arc<AtomicBool>,
    thread: Mutex<Option<JoinHandle<()>>>,
}

impl std::fmt::Debug for Admin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Admin").field("host", &self.host).finish_non_exhaustive()
    }
}

fn names(domain: &str) -> Result<(ServiceName, ServiceName), AdminError> {
    let name = |s: String| {
        ServiceName::new(&s).map_err(|e| AdminError::Unavailable { reason: format!("{s}: {e:?}") })
    };
    Ok((
        name(format!("{}/{domain}/admin", crate::service_name::SERVICE_PREFIX))?,
        name(format!("{}/{domain}/admin-wake", crate::service_name::SERVICE_PREFIX))?,
    ))
}

impl Admin {
    /// Joins the channel of `domain` as `host` and starts the thread that answers
    /// from `local` and `mirrors`.
    pub fn start(
        node: &SharedNode,
        domain: &str,
        host: &str,
        local: InProcessEsgm,
        mirrors: Arc<SharedMirrors>,
    ) -> Result<Arc<Self>, AdminError> {
        let (data, wake) = names(domain)?;
        let unavailable = |what: &str, e: &dyn std::fmt::Debug| AdminError::Unavailable {
            reason: format!("{what}: {e:?}"),
        };
        let (service, publisher, subscriber, notifier, listener) = node.with(|node| {
            let service = node
                .service_builder(&data)
                .publish_subscribe::<[u8]>()
                .max_publishers(MAX_PROCESSES)
                .max_subscribers(MAX_PROCESSES)
                .max_nodes(MAX_PROCESSES * 2)
                .subscriber_max_buffer_size(BUFFER)
                .history_size(0)
                .open_or_create()
                .map_err(|e| unavailable("the admin service", &e))?;
            let publisher = service
                .publisher_builder()
                .initial_max_slice_len(1024)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .create()
                .map_err(|e| unavailable("the admin publisher", &e))?;
            let subscriber = service
                .subscriber_builder()
                .create()
                .map_err(|e| unavailable("the admin subscriber", &e))?;
            let events = open_event_service(node, &wake)
                .map_err(|e| unavailable("the admin wake-up", &e))?;
            let notifier = events
                .notifier_builder()
                .create()
                .map_err(|e| unavailable("the admin notifier", &e))?;
            let listener = events
                .listener_builder()
                .create()
                .map_err(|e| unavailable("the admin listener", &e))?;
            Ok::<_, AdminError>((service, publisher, subscriber, notifier, listener))
        })?;
        let admin = Arc::new(Self {
            host: host.to_owned(),
            publisher: Mutex::new(publisher),
            service,
            wake: notifier,
            pending: Mutex::default(),
            next: AtomicU64::new(0),
            stop: Arc::default(),
            thread: Mutex::new(None),
        });
        let answerer = Answerer {
            admin: Arc::downgrade(&admin),
            host: host.to_owned(),
            local,
            mirrors,
            subscriber,
            listener,
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

    fn ring(&self) {
        if let Err(e) = self.wake.notify() {
            tracing::debug!(error = ?e, "cannot wake the admin threads; they look again soon");
        }
    }

    fn send(&self, envelope: &Envelope) -> Result<(), AdminError> {
        let bytes =
            serde_json::to_vec(envelope).map_err(|e| AdminError::Send { reason: e.to_string() })?;
        let publisher = self.publisher.lock();
        let loan = publisher
            .loan_slice_uninit(bytes.len())
            .map_err(|e| AdminError::Send { reason: format!("{e:?}") })?;
        loan.write_from_slice(&bytes)
            .send()
            .map_err(|e| AdminError::Send { reason: format!("{e:?}") })?;
        drop(publisher);
        self.ring();
        Ok(())
    }

    /// Asks every connected process `op` and waits up to `timeout` for all of them.
    pub fn ask(&self, op: AdminOp, timeout: Duration) -> Result<Answers, AdminError> {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = crossbeam_channel::unbounded();
        self.pending.lock().insert(id, tx);
        let expected = self.service.dynamic_config().number_of_subscribers();
        let envelope = Envelope { from: self.host.clone(), id, body: Body::Ask(op) };
        let sent = self.send(&envelope);
        let mut answers = Vec::with_capacity(expected);
        if sent.is_ok() {
            let deadline = Instant::now() + timeout;
            while answers.len() < expected {
                let left = deadline.saturating_duration_since(Instant::now());
                match rx.recv_timeout(left) {
                    Ok(a) => answers.push(a),
                    Err(_) => break,
                }
            }
        }
        self.pending.lock().remove(&id);
        sent?;
        if answers.len() < expected {
            return Err(AdminError::Incomplete { answered: answers.len(), expected, timeout });
        }
        Ok(answers)
    }

    fn deliver(&self, id: u64, from: String, answer: AdminAnswer) {
        if let Some(tx) = self.pending.lock().get(&id) {
            // The asker stopped waiting (its deadline passed): nothing to deliver to.
            let _late = tx.send((from, answer));
        }
    }
}

/// The admin thread: answers every question from this process's runtime.
struct Answerer {
    admin: std::sync::Weak<Admin>,
    host: String,
    local: InProcessEsgm,
    mirrors: Arc<SharedMirrors>,
    subscriber: Subscriber<ShmService, [u8], ()>,
    listener: Listener<ShmService>,
    stop: Arc<AtomicBool>,
}

impl Answerer {
    fn run(self) {
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
                        tracing::warn!(error = %e, "malformed admin message dropped");
                        continue;
                    }
                };
                drop(sample);
                let Some(admin) = self.admin.upgrade() else { return };
                match envelope.body {
                    Body::Ask(op) => {
                        let answer = self.answer(op);
                        let reply = Envelope {
                            from: self.host.clone(),
                            id: envelope.id,
                            body: Body::Answer { to: envelope.from, answer },
                        };
                        if let Err(e) = admin.send(&reply) {
                            tracing::warn!(error = %e, "cannot answer an admin question");
                        }
                    }
                    Body::Answer { to, answer } if to == self.host => {
                        admin.deliver(envelope.id, envelope.from, answer);
                    }
                    Body::Answer { .. } => {}
                }
            }
        }
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
                let stats = self.local.stats();
                AdminAnswer::Stats(
                    stats
                        .trajectories
                        .into_iter()
                        .map(|(name, report)| (written.contains(&name), report))
                        .collect(),
                )
            }
            AdminOp::Memory => AdminAnswer::Memory(self.local.memory_stats()),
            AdminOp::SetLogLevel { level, process } => {
                if process.as_ref().is_some_and(|p| *p != self.host) {
                    return AdminAnswer::LogLevel { applied: false, filter: false };
                }
                self.local.set_log_level(level);
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
