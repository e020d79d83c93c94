//! The domain's administration channel: the whole-ESGM operations (E7 `reset`,
//! `stats`, `memory_stats`, `set_log_level`, T5 resets through any handle, and
//! `flush`) asked of every connected process, and their answers collected.
//!
//! Two publish-subscribe services of the domain carry it, sized by its limits
//! ([`crate::data_plane::capacity::DomainLimits`]) and created by the coordinator:
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

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use esgm_core::esgm::{Esgm, LimitReached, LogLevel, MemoryStats, Peer, Unreachable};
use esgm_core::{DropCause, InProcessEsgm, QueryError, ResetForwarder};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::{AllocationStrategy, PortFactory as _};
use parking_lot::Mutex;
use serde::{Deserialize, Serialize};

use super::mirrors::SharedMirrors;
use super::shared_node::SharedNode;
use super::stats_row::{Figures, StatsRow};
pub(crate) use crate::control::admin_services::ASKERS;
use crate::control::admin_services::AdminServices;
use crate::control::client::answer_poll_cap;
use crate::data_plane::capacity::DomainLimits;
use crate::data_plane::service::ShmService;

/// The largest question or answer, in bytes: statistics of every trajectory a process
/// holds (a few hundred bytes each) fit thousands. Messages are loaned from a
/// fixed-size pool mapped (not committed) for the askers' queues.
const MAX_MESSAGE: usize = 4 << 20;
/// The longest the admin thread sleeps before it looks for its stop (stopping rings
/// it awake; this is the backstop). Every 2 s it was a wake-up a second in every
/// process of an idle robot.
const RECHECK: Duration = Duration::from_secs(30);
/// The longest an asker sleeps between two looks for answers once they are slow to
/// come (often before: [`crate::control::client::answer_poll_cap`]; a writer of 1,000
/// trajectories takes a few milliseconds to report them), and between two tries for a
/// port while every one is taken.
const POLL: Duration = Duration::from_millis(1);

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
    /// Why `trajectory` has not produced since `since`: answered by its writer.
    Why {
        /// The trajectory.
        trajectory: String,
        /// The time asked about.
        since: esgm_core::Time,
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
    /// it (the writer's are the trajectory's own; a replica's are what it received), as
    /// compact rows that the asker joins with the coordinator's listing.
    Stats(Vec<StatsRow>),
    /// This process's memory.
    Memory(MemoryStats),
    /// The level was applied (`filter`: to a reloadable tracing filter too).
    LogLevel {
        /// True if this process is the one named.
        applied: bool,
        /// True if its tracing filter was replaced.
        filter: bool,
    },
    /// The writer's answer to [`AdminOp::Why`].
    Why(Box<esgm_core::esgm::Why>),
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

/// The channel's one decoder: a question or an answer, as another process published
/// it. Its bytes are that process's to choose, so what reads the result (the answering
/// thread, the asker's sums) must not trust any number in it.
fn decode(bytes: &[u8]) -> Result<Envelope, serde_json::Error> {
    serde_json::from_slice(bytes)
}

/// A message as [`decode`] reads it.
fn encode(envelope: &Envelope) -> Result<Vec<u8>, serde_json::Error> {
    serde_json::to_vec(envelope)
}

/// The answer `envelope` carries to question `id` of `host`, with the process that
/// gave it; `None` for another asker's, a question, or an answer to a question given
/// up on.
fn answer_to(envelope: Envelope, host: &str, id: u64) -> Option<(String, AdminAnswer)> {
    match envelope.body {
        Body::Answer { to, answer } if envelope.id == id && to == host => {
            Some((envelope.from, answer))
        }
        _ => None,
    }
}

/// Every trajectory's figures across the processes' answers: the writer's, with what
/// readers alone saw dropped (lost on the way, rejected bytes) added, so every sample
/// is accounted for; a replica's own where no writer answered. The counts come from
/// other processes: they saturate, never wrap. The listing joins them
/// ([`super::stats_row::with_listing`]).
pub(crate) fn combine_stats(answers: Answers) -> HashMap<String, Figures> {
    // Each trajectory's figures, and whether they are its writer's (a hash map: the
    // listing that joins them is in name order already).
    let rows = answers.iter().map(|(_, a)| if let AdminAnswer::Stats(r) = a { r.len() } else { 0 });
    let mut stats: HashMap<String, (bool, Figures)> = HashMap::with_capacity(rows.sum());
    let mut at_readers: Vec<(String, DropCause, u64)> = Vec::new();
    for (_, answer) in answers {
        let AdminAnswer::Stats(rows) = answer else { continue };
        for row in rows {
            let (name, writes, report) = row.into_parts();
            if !writes {
                for (cause, n) in &report.stats.dropped {
                    // What only a reader sees: its losses, its rejections, and an
                    // exporting bridge's losses on the way out.
                    if matches!(
                        cause,
                        DropCause::Lost | DropCause::Rejected(_) | DropCause::Bridge(_)
                    ) {
                        at_readers.push((name.clone(), *cause, *n));
                    }
                }
            }
            match stats.entry(name) {
                std::collections::hash_map::Entry::Vacant(slot) => {
                    slot.insert((writes, report));
                }
                // The writer's figures replace a replica's, never the other way.
                std::collections::hash_map::Entry::Occupied(mut slot) => {
                    if writes && !slot.get().0 {
                        slot.insert((writes, report));
                    }
                }
            }
        }
    }
    for (name, cause, n) in at_readers {
        // Where no writer answered, the report is a reader's own, already counting it.
        let Some((true, report)) = stats.get_mut(&name) else { continue };
        match report.stats.dropped.iter_mut().find(|(c, _)| *c == cause) {
            Some((_, total)) => *total = total.saturating_add(n),
            None => report.stats.dropped.push((cause, n)),
        }
        report.stats.dropped_total = report.stats.dropped_total.saturating_add(n);
    }
    stats.into_iter().map(|(name, (_, figures))| (name, figures)).collect()
}

/// The memory of every answering process added up (saturating: the numbers are other
/// processes').
pub(crate) fn combine_memory(answers: &Answers) -> MemoryStats {
    let mut total = MemoryStats::default();
    for (_, answer) in answers {
        if let AdminAnswer::Memory(m) = answer {
            total.trajectories = total.trajectories.saturating_add(m.trajectories);
            total.stored_samples = total.stored_samples.saturating_add(m.stored_samples);
            total.held_samples = total.held_samples.saturating_add(m.held_samples);
            total.approx_bytes = total.approx_bytes.saturating_add(m.approx_bytes);
        }
    }
    total
}

/// What a flush round compares to the one before: per trajectory, what entered its
/// stream (added and dropped, saturating) and its worker's calls.
pub(crate) fn progress(stats: HashMap<String, Figures>) -> Vec<(String, u64, u64)> {
    let mut progress: Vec<_> = stats
        .into_iter()
        .map(|(n, r)| (n, r.stats.added.saturating_add(r.stats.dropped_total), r.worker.calls))
        .collect();
    // In name order, so that two rounds compare equal when nothing moved.
    progress.sort_unstable();
    progress
}

/// Trajectories the answering processes reset (saturating).
fn resets(answers: &Answers) -> usize {
    answers
        .iter()
        .map(|(_, a)| match a {
            AdminAnswer::Done { reset } => *reset,
            _ => 0,
        })
        .fold(0, usize::saturating_add)
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
    /// The question could not be sent, or a process refused it (see the reason).
    #[error("cannot ask the domain's processes: {reason}")]
    Send {
        /// Why.
        reason: Unreachable,
    },
    /// No connected process has this name (`esgm ps` lists the supervised ones; a
    /// program's name is the host it connected as).
    #[error("no connected process is called `{name}`")]
    NoSuchProcess {
        /// The name asked for.
        name: String,
    },
    /// The domain has as many processes as it admits ([`crate::DomainLimits`]).
    #[error(transparent)]
    LimitReached(LimitReached),
    /// The administration channel is not running in this process.
    #[error("the administration channel is not running: {reason}")]
    Unavailable {
        /// Why.
        reason: Unreachable,
    },
}

impl From<AdminError> for Unreachable {
    /// The cause of an `Unavailable` error of the seed's operations: a question to
    /// the domain's processes that failed.
    fn from(e: AdminError) -> Self {
        match e {
            AdminError::Send { reason } | AdminError::Unavailable { reason } => reason,
            AdminError::Incomplete { timeout, .. } => {
                Unreachable::no_answer(Peer::Processes, timeout)
            }
            e => Unreachable::refused(Peer::Processes, e),
        }
    }
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
            reason: Unreachable::transport(Peer::Processes, format!("{what}: {e:?}")),
        };
        let services = node
            .with(|node| AdminServices::open(node, domain, &DomainLimits::default()))
            .map_err(|reason| AdminError::Unavailable { reason })?;
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
        let (subscriber, listener) = crate::data_plane::service::with_room(lacks_room, || {
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
            .map_err(|e| AdminError::Unavailable {
                reason: Unreachable::transport(Peer::Connection, format!("no admin thread: {e}")),
            })?;
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
        let (collected, expected) = self.ask_until(op, timeout, |_| false)?;
        if collected.len() < expected {
            return Err(AdminError::Incomplete { answered: collected.len(), expected, timeout });
        }
        Ok(collected)
    }

    /// Asks every connected process `op`, and returns what was answered when every
    /// process answered, when `enough` says the answers so far suffice, or at
    /// `timeout`, with how many answers were expected: a question one process answers
    /// (the writer's `why`) does not wait for a stopped process that will not.
    pub fn ask_until(
        &self,
        op: AdminOp,
        timeout: Duration,
        enough: impl Fn(&Answers) -> bool,
    ) -> Result<(Answers, usize), AdminError> {
        let started = Instant::now();
        let deadline = started + timeout;
        let send = |reason: String| AdminError::Send {
            reason: Unreachable::transport(Peer::Processes, reason),
        };
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let bytes = encode(&Envelope { from: self.host.clone(), id, body: Body::Ask(op) })
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
        while collected.len() < expected && !enough(&collected) {
            if !cleaned && Instant::now() >= clean_after {
                cleaned = true;
                crate::control::server::log_cleanup(
                    crate::data_plane::service::cleanup_dead_nodes(),
                    crate::data_plane::service::CleanupReporter::Bystander,
                );
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
                match decode(sample.payload()) {
                    Ok(envelope) => collected.extend(answer_to(envelope, &self.host, id)),
                    Err(e) => tracing::warn!(error = %e, "malformed admin answer dropped"),
                }
            }
            if !any {
                if Instant::now() >= deadline {
                    break;
                }
                std::thread::sleep(answer_poll_cap(started.elapsed(), POLL));
            }
        }
        drop(publisher);
        Ok((collected, expected))
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
            if let Err(e) = crate::data_plane::wait::timed_wait(&self.listener, RECHECK) {
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
                let envelope = match decode(sample.payload()) {
                    Ok(e) => e,
                    Err(e) => {
                        tracing::warn!(error = %e, "malformed admin question dropped");
                        continue;
                    }
                };
                drop(sample);
                let Body::Ask(op) = envelope.body else { continue };
                let answer = answer(&self.host, &self.local, &self.mirrors, op);
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
        let bytes = encode(envelope).map_err(|e| e.to_string())?;
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
}

/// The trajectories this process writes.
fn written(mirrors: &SharedMirrors) -> Vec<String> {
    mirrors.exports().into_iter().map(|(name, _)| name).collect()
}

/// This process's answer (it is `host`) to `op`, from its runtime and mirrors. The
/// question comes from another process: nothing in it may make this panic.
fn answer(host: &str, local: &InProcessEsgm, mirrors: &SharedMirrors, op: AdminOp) -> AdminAnswer {
    match op {
        AdminOp::Reset { trajectory } => {
            let written = written(mirrors);
            let targets: Vec<&String> = match &trajectory {
                Some(t) => written.iter().filter(|w| *w == t).collect(),
                None => written.iter().collect(),
            };
            let mut reset = 0;
            for name in targets {
                let done = local
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
            mirrors.pump();
            AdminAnswer::Done { reset: 0 }
        }
        AdminOp::Why { trajectory, since } => {
            if !mirrors.lock().exports.contains_key(&trajectory) {
                // Only the writer knows its producer's calls and its gate's drops.
                return AdminAnswer::Done { reset: 0 };
            }
            // The evidence only: the asker adds what the registry knows and explains.
            match local.why_evidence(&trajectory, since) {
                Ok(mut why) => {
                    why.writer_alive = Some(true);
                    super::why::inputs_alive(&mut why, mirrors);
                    AdminAnswer::Why(Box::new(why))
                }
                Err(e) => AdminAnswer::Failed { reason: e.to_string() },
            }
        }
        AdminOp::Stats => {
            let figures = local.figures_here();
            // Looked up in the mirrors' own map, under one lock: a writer of 1,000
            // trajectories answers without copying their names into a set first.
            let mirrors = mirrors.lock();
            AdminAnswer::Stats(
                figures
                    .into_iter()
                    .map(|(name, stats, worker)| {
                        let writes = mirrors.exports.contains_key(&name);
                        StatsRow::new(name, writes, stats, worker)
                    })
                    .collect(),
            )
        }
        AdminOp::Memory => AdminAnswer::Memory(local.memory_here()),
        AdminOp::SetLogLevel { level, process } => {
            if process.as_ref().is_some_and(|p| p != host) {
                return AdminAnswer::LogLevel { applied: false, filter: false };
            }
            local.set_log_level_here(level);
            match crate::process::apply_log_level(level) {
                Ok(filter) => {
                    tracing::info!(?level, "log level set by the domain");
                    AdminAnswer::LogLevel { applied: true, filter }
                }
                Err(e) => AdminAnswer::Failed { reason: e.to_string() },
            }
        }
        AdminOp::Flush { timeout } => {
            // The asker's timeout, read from its bytes: one past what an instant holds
            // is refused, not added (the addition panics).
            let Some(deadline) = Instant::now().checked_add(timeout) else {
                return AdminAnswer::Failed {
                    reason: format!("a flush timeout of {timeout:?} is past any deadline"),
                };
            };
            mirrors.pump();
            match local.flush(deadline) {
                Ok(()) => AdminAnswer::Done { reset: 0 },
                Err(e) => AdminAnswer::Failed { reason: e.to_string() },
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
        let unavailable = |reason: Unreachable| QueryError::Unavailable {
            trajectory: trajectory.to_owned(),
            reason,
        };
        let admin = self.admin.upgrade().ok_or_else(|| unavailable(Unreachable::Closing))?;
        let op = AdminOp::Reset { trajectory: Some(trajectory.to_owned()) };
        let answers = admin.ask(op, self.timeout).map_err(|e| unavailable(e.into()))?;
        if resets(&answers) == 0 {
            return Err(unavailable(Unreachable::refused(
                Peer::Writer,
                "no connected process writes it",
            )));
        }
        if blocking {
            admin.ask(AdminOp::CatchUp, self.timeout).map_err(|e| unavailable(e.into()))?;
        }
        Ok(())
    }
}

/// What [`AdminReader::read`] made of a batch of messages.
#[doc(hidden)]
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AdminRead {
    /// Messages that did not decode (the channel drops them with a warning).
    pub malformed: usize,
    /// Questions answered.
    pub questions: usize,
    /// Answers taken as answers to the asker's question.
    pub answers: usize,
    /// Trajectories the answers say were reset.
    pub reset: usize,
    /// The answers' memory, added up.
    pub memory: MemoryStats,
    /// Trajectories in the answers' statistics, combined.
    pub trajectories: usize,
}

/// Both ends of the admin channel reading other processes' bytes, without the
/// channel: each message decoded as the admin thread and the asker decode it, a
/// question answered from an empty runtime and the reply encoded and read back, the
/// answers to the asker's question combined as `domain_stats`, `domain_memory`, a flush
/// round and a domain reset combine them.
///
/// Public and hidden for esgm-fuzz alone: any process of the domain may publish on the
/// channel, so the fuzzer must run this code on hostile bytes, and the channel's types
/// stay private.
#[doc(hidden)]
#[derive(Debug, Default)]
pub struct AdminReader {
    local: InProcessEsgm,
    mirrors: SharedMirrors,
}

impl AdminReader {
    /// Reads `messages` as process `host` would that asked question `id`. `Err`: a
    /// reply this process made did not encode or read back (the asker could not read
    /// it), which no input may cause.
    pub fn read(
        &self,
        host: &str,
        id: u64,
        messages: &[&[u8]],
    ) -> Result<AdminRead, serde_json::Error> {
        let mut read = AdminRead::default();
        let mut answers = Answers::new();
        for bytes in messages {
            let Ok(envelope) = decode(bytes) else {
                read.malformed += 1;
                continue;
            };
            if let Body::Ask(op) = envelope.body {
                read.questions += 1;
                let answer = answer(host, &self.local, &self.mirrors, op);
                let reply = Envelope {
                    from: host.to_owned(),
                    id: envelope.id,
                    body: Body::Answer { to: envelope.from, answer },
                };
                decode(&encode(&reply)?)?;
                continue;
            }
            answers.extend(answer_to(envelope, host, id));
        }
        read.answers = answers.len();
        read.reset = resets(&answers);
        read.memory = combine_memory(&answers);
        read.trajectories = combine_stats(answers).len();
        Ok(read)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use esgm_core::esgm::{TrajectoryReport, TrajectorySpec};

    /// A report of a real trajectory, its counts as large as another process may claim.
    fn huge_report() -> TrajectoryReport {
        let local = InProcessEsgm::default();
        local.create_trajectory(TrajectorySpec::primitive("r", "RobotState")).unwrap();
        let mut report = local.stats_here().trajectories.remove("r").unwrap();
        report.stats.added = u64::MAX;
        report.stats.dropped = vec![(DropCause::Lost, u64::MAX)];
        report.stats.dropped_total = u64::MAX;
        report
    }

    #[test]
    fn sums_of_other_processes_numbers_saturate() {
        let report = huge_report();
        let answers = vec![(
            "w".to_owned(),
            AdminAnswer::Stats(vec![
                StatsRow::new("r".into(), true, report.stats.clone(), report.worker),
                StatsRow::new("r".into(), false, report.stats, report.worker),
            ]),
        )];
        let stats = combine_stats(answers);
        let r = &stats["r"].stats;
        assert_eq!((r.dropped_total, r.dropped[0].1), (u64::MAX, u64::MAX));
        assert_eq!(progress(stats)[0].1, u64::MAX);

        let memory = MemoryStats {
            trajectories: usize::MAX,
            stored_samples: usize::MAX,
            held_samples: usize::MAX,
            approx_bytes: usize::MAX,
        };
        let answers: Answers = vec![
            ("a".to_owned(), AdminAnswer::Memory(memory)),
            ("b".to_owned(), AdminAnswer::Memory(memory)),
        ];
        assert_eq!(combine_memory(&answers), memory);

        let done = || AdminAnswer::Done { reset: usize::MAX };
        assert_eq!(resets(&vec![("a".to_owned(), done()), ("b".to_owned(), done())]), usize::MAX);
    }

    #[test]
    fn a_flush_timeout_past_any_instant_is_refused() {
        let (local, mirrors) = (InProcessEsgm::default(), SharedMirrors::default());
        let op = AdminOp::Flush { timeout: Duration::MAX };
        assert!(matches!(answer("h", &local, &mirrors, op), AdminAnswer::Failed { .. }));
        let op = AdminOp::Flush { timeout: Duration::from_millis(10) };
        assert!(matches!(answer("h", &local, &mirrors, op), AdminAnswer::Done { .. }));
    }

    #[test]
    fn the_reader_answers_questions_and_combines_answers() {
        let reader = AdminReader::default();
        let question = br#"{"from":"b","id":7,"body":{"Ask":{"Flush":{"timeout":{"secs":18446744073709551615,"nanos":999999999}}}}}"#;
        let answer =
            br#"{"from":"b","id":1,"body":{"Answer":{"to":"a","answer":{"Done":{"reset":3}}}}}"#;
        let read = reader.read("a", 1, &[question, answer, answer, b"{"]).unwrap();
        assert_eq!((read.questions, read.answers, read.reset, read.malformed), (1, 2, 6, 1));
    }
}
