//! The reader's half of mirroring a trajectory: an [`Import`] receives a trajectory
//! another process writes and feeds a local replica
//! ([`esgm_core::InProcessEsgm::create_replica`]), so local units, syncs, queries and
//! subscriptions read it like a local trajectory.
//!
//! The connection's receiver thread, woken by the writer's notify, takes each sample
//! and enters it into the replica itself: the replica's subscribers and units are
//! told from there, with no other thread in between. Images stay in the writer's
//! chunk, owned by the values that read them ([`crate::client::holdings`]).
//!
//! Only the writer writes: a sample or reset is entered only if it comes from the
//! publisher port the registry names as the writer ([`TrajectoryRecord::port`]) and
//! its attributes match the trajectory's type. Anything else on the service bypassed
//! the writer's gate, and is rejected and counted. Until the registry names the port
//! (a writer just started or restarted), what arrives is held, in order, and the
//! location thread asks ([`Import::set_writer`]).
//!
//! Adding to a replica of a primitive trajectory forwards the structure, after the
//! type check, to the writer's *inbox* (`<domain>:inbox`), published inline by the
//! adding thread; the writer's gate decides, and the structure comes back through
//! replication.

use std::sync::{Arc, Weak};
use std::time::Duration;

use esgm_core::esgm::{Peer, TrajectoryKind, Unreachable};
use esgm_core::{
    AddError, AddForwarder, AddOutcome, EntityStructureType, EntityTrajectoryStructure, FeedWaiter,
    InProcessTrajectory, Lineage, Rejection, ReplicaFeed, SharedStructure, TypeChecker,
};
use iceoryx2::identifiers::UniquePublisherId;
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::ServiceName;
use parking_lot::Mutex;

use super::blocking_add::{AddClient, BlockingAddError};
use super::coverage::{Coverage, Receiving};
use super::mirrors::SharedMirrors;
use super::settings::{
    bridge_qos, fixed_sample_len, generation_domain, inbox_domain, inbox_qos, join_service,
    own_subscriber,
};
use super::shared_node::SharedNode;
use super::takeover::{TakeOverAsk, WriterLiveness};
use crate::client::holdings::{HoldingOwner, Holdings};
use crate::control::protocol::{TrajectoryRecord, WriterPort};
use crate::data_plane::capacity::{EventCapacity, Readers};
use crate::data_plane::kept::KeptHistory;
use crate::data_plane::publisher::{SampleSizing, TrajectoryPublisher};
use crate::data_plane::service::{EventSpec, OpenError, ShmService, open_event_service};
use crate::data_plane::service_name::{NameError, TrajectoryServiceNames};
use crate::data_plane::subscriber::{ReceiveError, TrajectorySubscriber};
use crate::data_plane::violations::{ViolationSubscriber, violation_service_name};
use crate::data_plane::wait::{Sleeper, WaitStrategy, timed_wait};
use crate::data_plane::wake_word::WakeWord;
use crate::data_plane::writer_check::{Decided, WriterCheck};

/// Where an import is made: the connection's node, domain, holdings and mirrors.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ImportSite<'a> {
    pub node: &'a SharedNode,
    pub domain: &'a str,
    pub holdings: &'a Arc<Holdings>,
    pub mirrors: &'a Arc<SharedMirrors>,
    /// Rings the location thread to ask the registry who writes (see `Import::arrive`).
    pub verify: &'a crossbeam_channel::Sender<()>,
    /// Where an adder asks the location thread to take the trajectory over once its
    /// writer is gone ([`super::takeover`]).
    pub take_over: &'a crossbeam_channel::Sender<TakeOverAsk>,
    /// True for a short-lived tool's connection, which may use the ports a trajectory
    /// keeps beyond its `readers` ([`crate::data_plane::capacity`]); a long-lived reader counts
    /// itself against them.
    pub tool: bool,
}

/// A trajectory of another process, mirrored into a local replica.
#[derive(Debug)]
pub(crate) struct Import {
    /// The registry generation of the trajectory when this import was made (a
    /// re-pointed name keeps its import and takes the new one).
    pub generation: u64,
    /// The trajectory's type name.
    pub type_name: String,
    subscriber: TrajectorySubscriber,
    violations: ViolationSubscriber,
    replica: InProcessTrajectory,
    /// Samples that could not be taken (already counted by the subscriber).
    rejected: u64,
    /// Whether an arrival is the writer's, and which of its samples never arrived
    /// (the check every reader of another process's trajectory makes).
    check: WriterCheck<Arrival>,
    /// What is known of the writer, shared with the replica's outbox (which asks to
    /// take the trajectory over once the writer is gone).
    writer: Arc<WriterLiveness>,
    /// Samples lost so far (the first is logged).
    lost: u64,
    /// Whose samples this import's held images count as, and how many it may hold.
    owner: HoldingOwner,
    /// The wake-up services of the samples and the violations, for the receiver.
    wakes: Vec<EventSpec>,
    /// Workers waiting on this import's writer themselves: while there is one, the
    /// receiver thread does not listen to its samples (the worker feeds the replica
    /// each time it wakes), so a sample wakes one thread in this process, not two.
    workers: Arc<std::sync::atomic::AtomicUsize>,
    /// Threads of this process asleep on this import's writer right now, workers and
    /// user subscriptions alike: when the import goes it wakes them, so they follow
    /// the trajectory (re-pointed, destroyed, disconnected) at once, not at the end of
    /// their sleep's slice.
    sleepers: Arc<std::sync::atomic::AtomicUsize>,
    /// This process's count in the writer's word as a receiver of its samples, covered
    /// while a thread sleeps on the word ([`super::coverage`]); `None` where the word
    /// cannot be mapped (the writer then always notifies).
    coverage: Option<Arc<Coverage>>,
    /// Checks each structure's attributes against the trajectory's type; `None` if
    /// the record's definitions do not resolve (logged at the start).
    checker: Option<TypeChecker>,
    /// Rings the location thread to ask the registry who writes, once per wait: what
    /// is held meanwhile borrows shared memory (an image a chunk).
    verify: crossbeam_channel::Sender<()>,
    /// This process's node, to wake the threads waiting on this import when it goes.
    node: SharedNode,
    /// The writer answered this import's join: its history was in the queue when the
    /// import was made ([`join`]), so a query right after sees all of it.
    history_received: bool,
    /// Set when the import goes (the trajectory destroyed, re-pointed, the connection
    /// closed): its waiters look the trajectory's import up again only then, not on
    /// every wait ([`ImportWaiter::listen`]).
    retired: Arc<std::sync::atomic::AtomicBool>,
    /// The highest kept-history index entered into the replica (a primitive
    /// trajectory's; [`crate::SampleHeader::kept`]): a structure at or below it is
    /// one this replica holds already (the history handed over again by a writer
    /// that restarted or took over), and is skipped.
    last_kept: Option<u64>,
    /// The last pump stopped before the queue was empty (too many held, a broken
    /// connection), whoever pumped: a waiter pumps again at its next feed even if the
    /// writer's word has not moved since, and sleeps at most [`LOOK_AGAIN`], or what is
    /// left would wait for the writer's next sample.
    stopped_early: Arc<std::sync::atomic::AtomicBool>,
}

impl Drop for Import {
    /// Wakes the threads of this process asleep on this import's writer (user
    /// subscriptions and workers): the trajectory was destroyed, re-pointed (they follow
    /// the new import) or the connection closed (they end).
    fn drop(&mut self) {
        self.retired.store(true, std::sync::atomic::Ordering::SeqCst);
        self.wake_sleepers();
    }
}

impl Import {
    /// Wakes the threads of this process asleep on this import's writer (user
    /// subscriptions and workers, counted in `sleepers` and `workers`), when something
    /// they wait for happened that the writer did not ring for: the import went, or
    /// samples held until the registry named the writer's port were entered by the
    /// location thread. They would sleep up to [`WAIT_SLICE`] otherwise.
    fn wake_sleepers(&self) {
        let asleep =
            |n: &std::sync::atomic::AtomicUsize| n.load(std::sync::atomic::Ordering::SeqCst);
        if asleep(&self.workers) == 0 && asleep(&self.sleepers) == 0 {
            return;
        }
        let Some(wake) = self.sample_wake() else { return };
        // Both ways a subscription may sleep: on the word, and on the event.
        if let Ok(word) = WakeWord::open(wake.name.as_str()) {
            word.ring();
        }
        let rung = self
            .node
            .with(|node| wake.open(node)?.notifier_builder().create().map_err(OpenError::Notifier));
        match rung.map(|n| n.notify()) {
            Ok(Ok(_)) => {}
            Ok(Err(e)) => tracing::debug!(error = ?e, "cannot wake the subscriptions"),
            Err(e) => tracing::debug!(error = %e, "cannot wake the subscriptions"),
        }
    }
}

/// A sample or reset taken from the trajectory's service, until the writer check
/// decides about it.
#[derive(Debug)]
enum Arrival {
    /// A structure, read in place where it arrived (held), with its index in the kept
    /// history (`None`: not kept) and the lineage the writer sent with it.
    Entry { es: SharedStructure, add_time: i64, kept: Option<u64>, lineage: Option<Arc<Lineage>> },
    /// A reset marker.
    Reset,
}

impl Import {
    /// Subscribes to `replica`'s trajectory, receiving the writer's history first.
    pub fn start(
        at: &ImportSite<'_>,
        replica: InProcessTrajectory,
        record: &TrajectoryRecord,
    ) -> Result<Self, OpenError> {
        let ImportSite { node, domain, holdings, mirrors, verify, take_over, tool } = *at;
        let readers = record.readers;
        let (type_name, policy) = (&record.info.type_name, &record.info.policy);
        let primitive = record.info.kind == TrajectoryKind::Primitive;
        let generation = record.generation;
        // Lineage names the registry's generation, the same in every process.
        let _destroyed = replica.with_store(|s| s.set_generation(generation));
        let domain = &generation_domain(domain, generation);
        let name = replica.name().to_owned();
        let checker = match TypeChecker::from_definitions(type_name, record.types.clone()) {
            Ok(c) => Some(c),
            Err(e) => {
                tracing::warn!(trajectory = %name, error = %e,
                    "the trajectory's type does not resolve here; attributes are not checked");
                None
            }
        };
        let entity_type = replica.entity_type().unwrap_or_else(|_| EntityStructureType::new(""));
        let qos = bridge_qos(policy, &entity_type, readers);
        // Nobody waits on these ports: the receiver thread waits on their wake-up
        // services, so they need no listeners of their own.
        let (subscriber, violations) = node
            .with(|node| {
                let mut subscriber = TrajectorySubscriber::builder(&name, type_name)
                    .domain(domain)
                    .qos(qos)
                    .wait_strategy(WaitStrategy::BusySpin);
                if !tool {
                    subscriber = subscriber.reader_limit(readers.0 + own_subscriber(&entity_type));
                }
                let subscriber = subscriber.create(node)?;
                let violations = ViolationSubscriber::builder(&name)
                    .domain(domain)
                    .readers(readers)
                    .wait_strategy(WaitStrategy::BusySpin)
                    .create(node)?;
                Ok::<_, OpenError>((subscriber, violations))
            })
            .map_err(|e| e.as_limit(&name, readers))?;
        let sample_wake = EventSpec {
            name: *TrajectoryServiceNames::new(domain, &name)?.wake(),
            capacity: qos.wake_capacity(),
        };
        let history_received = match join(node, domain, &name, &sample_wake, readers) {
            Ok(()) => true,
            Err(e) => {
                tracing::debug!(trajectory = %name, error = %e,
                    "the writer did not hand over its history at once; it comes with its next sample or maintenance");
                false
            }
        };
        let violations_wake = violation_service_name(domain, &name);
        let wakes = vec![
            sample_wake,
            EventSpec {
                name: ServiceName::new(&violations_wake).map_err(|_| NameError::TooLong {
                    service: violations_wake.clone(),
                    max: ServiceName::max_len(),
                })?,
                capacity: EventCapacity::violations(readers),
            },
        ];
        let feed = ImportFeed {
            trajectory: name.clone(),
            node: node.clone(),
            mirrors: Arc::downgrade(mirrors),
        };
        // A replica destroyed meanwhile has no subscribers to feed.
        let _destroyed = replica.with_store(|s| s.set_feed(Arc::new(feed)));
        let writer = Arc::new(WriterLiveness::new(record.port.map_or(0, |p| p.pid)));
        writer.set_released(record.released);
        if primitive {
            let outbox = Outbox {
                writer: Arc::clone(&writer),
                generation,
                take_over: take_over.clone(),
                trajectory: name.clone(),
                type_name: type_name.to_owned(),
                domain: domain.to_owned(),
                readers,
                fixed: fixed_sample_len(&entity_type),
                node: node.clone(),
                inbox: Mutex::new(None),
                blocking: Mutex::new(None),
            };
            // A replica destroyed meanwhile forwards nothing.
            let _destroyed = replica.with_store(|s| s.forward_adds(Arc::new(outbox)));
        }
        Ok(Self {
            generation,
            stopped_early: Arc::default(),
            type_name: type_name.clone(),
            subscriber,
            violations,
            replica,
            rejected: 0,
            check: WriterCheck::new(record.port.map(|p| p.publisher)).holding(
                match own_subscriber(&entity_type) {
                    0 => crate::data_plane::writer_check::MAX_HELD,
                    _ => crate::data_plane::writer_check::MAX_HELD_IMAGES,
                },
            ),
            writer,
            workers: Arc::default(),
            sleepers: Arc::default(),
            coverage: Coverage::new(sample_wake.name.as_str()),
            checker,
            verify: verify.clone(),
            lost: 0,
            // One borrow stays free to receive into.
            owner: holdings.owner(qos.max_borrowed_samples.saturating_sub(1)),
            node: node.clone(),
            wakes,
            history_received,
            retired: Arc::default(),
            last_kept: None,
        })
    }

    /// The highest kept-history index this replica entered (`None`: none).
    pub fn last_kept(&self) -> Option<u64> {
        self.last_kept
    }

    /// Enters the trajectory's kept history into the replica: the writer did not hand
    /// its history over (it is gone, or not serving yet), and the file holds what it
    /// acknowledged. What the writer sends later and this replica holds is skipped
    /// by its index. Returns how many entered.
    pub fn enter_kept(&mut self, domain: &str) -> usize {
        let domain = generation_domain(domain, self.generation);
        let kept = match KeptHistory::open(&domain, self.replica.name()) {
            Ok(Some(kept)) => kept.entries(),
            Ok(None) => return 0,
            Err(e) => {
                tracing::warn!(trajectory = %self.replica.name(), error = %e,
                    "the kept history cannot be read; only what the writer sends is");
                return 0;
            }
        };
        if kept.skipped > 0 {
            tracing::warn!(trajectory = %self.replica.name(), skipped = kept.skipped,
                "entries of the kept history could not be read (counted as rejected)");
            for _ in 0..kept.skipped {
                let _destroyed =
                    self.replica.with_store(|s| s.replicate_rejection(Rejection::Malformed));
            }
        }
        let mut n = 0;
        for entry in kept.entries {
            let arrival = Arrival::Entry {
                es: entry.structure,
                add_time: entry.add_time,
                kept: Some(entry.index),
                // Kept with it (a structure a bridge imported with its inputs), or none.
                lineage: entry.lineage.map(Arc::new),
            };
            let before = self.last_kept;
            self.enter(arrival);
            n += usize::from(self.last_kept != before);
        }
        n
    }

    /// Whether the writer handed this import the history when it was made (it answered
    /// the join); otherwise the history comes with its next sample or maintenance.
    pub fn history_received(&self) -> bool {
        self.history_received
    }

    /// The wake-up service of this import's samples.
    fn sample_wake(&self) -> Option<EventSpec> {
        self.wakes.first().copied()
    }

    /// The receiver thread's listener on `wake` counted in the writer's word, if `wake`
    /// is this import's samples' (see [`super::coverage`]): take it after the listener
    /// exists, drop it before the listener.
    pub fn receiving(&self, wake: &EventSpec) -> Option<Receiving> {
        let samples = self.sample_wake().is_some_and(|w| w.name == wake.name);
        self.coverage.as_ref().filter(|_| samples).map(Coverage::receiving)
    }

    /// The wake-up services the receiver thread listens to: without the samples'
    /// while a worker waits on them itself.
    pub fn receiver_wakes(&self) -> &[EventSpec] {
        match self.workers.load(std::sync::atomic::Ordering::Acquire) {
            0 => &self.wakes,
            _ => self.wakes.get(1..).unwrap_or_default(),
        }
    }

    /// Enters every waiting sample, reset and violation into the replica; returns how
    /// many there were.
    pub fn pump(&mut self) -> usize {
        esgm_core::probe::mark(esgm_core::probe::Step::Locked);
        let mut stopped_early = false;
        let mut n = 0;
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    esgm_core::probe::mark(esgm_core::probe::Step::Received);
                    n += 1;
                    let publisher = sample.publisher_id();
                    let header = sample.header();
                    let (sequence, add_time) = (header.sequence, header.add_time);
                    let kept = header.kept.checked_sub(1);
                    let lineage = match sample.lineage() {
                        Ok(lineage) => lineage.map(Arc::new),
                        Err(e) => {
                            self.reject(&ReceiveError::Malformed(e));
                            continue;
                        }
                    };
                    match self.owner.hold(sample) {
                        Ok(es) => {
                            esgm_core::probe::mark(esgm_core::probe::Step::Held);
                            let entry = Arrival::Entry { es, add_time, kept, lineage };
                            self.arrive(publisher, sequence, entry)
                        }
                        Err(e) => self.reject(&ReceiveError::Malformed(e)),
                    }
                }
                Ok(None) => break,
                Err(ReceiveError::Reset { sequence, publisher }) => {
                    n += 1;
                    self.arrive(publisher, sequence, Arrival::Reset);
                }
                Err(e) => {
                    n += 1;
                    self.reject(&e);
                    if matches!(e, ReceiveError::Connection(_) | ReceiveError::TooManyHeld) {
                        stopped_early = true;
                        break;
                    }
                }
            }
        }
        loop {
            match self.violations.receive() {
                Ok(Some(v)) => {
                    n += 1;
                    let _destroyed = self.replica.with_store(|s| s.replicate_violation(v));
                }
                Ok(None) => break,
                Err(e) => {
                    n += 1;
                    self.reject(&e);
                    if matches!(e, ReceiveError::Connection(_) | ReceiveError::TooManyHeld) {
                        stopped_early = true;
                        break;
                    }
                }
            }
        }
        self.stopped_early.store(stopped_early, std::sync::atomic::Ordering::Release);
        n
    }

    /// Enters what the writer sent; holds what another port sent until the registry
    /// names the writer's, and asks it once.
    fn arrive(&mut self, publisher: UniquePublisherId, sequence: u64, arrival: Arrival) {
        if let Some(decided) = self.check.arrive(publisher.value(), sequence, arrival) {
            self.decide(decided);
        }
        if self.check.should_ask() {
            // Full: a question is already out, which this one joins.
            let _pending = self.verify.try_send(());
        }
    }

    fn decide(&mut self, decided: Decided<Arrival>) {
        match decided {
            Decided::Enter { item, lost } => {
                self.count_lost(lost);
                self.enter(item);
            }
            Decided::NotWriter { port, item } => self.not_writer(port, &item),
        }
    }

    /// Enters a sample or reset of the writer's into the replica, if its attributes
    /// match the trajectory's type.
    fn enter(&mut self, arrival: Arrival) {
        match arrival {
            Arrival::Entry { es, add_time, kept, lineage } => {
                if let Some(index) = kept {
                    if self.last_kept.is_some_and(|last| index <= last) {
                        // Held already: the history handed over again.
                        return;
                    }
                }
                if let Some(Err(e)) = self.checker.as_ref().map(|c| c.check_structure(&es)) {
                    return self.count_rejection(Rejection::WrongLayout, &e);
                }
                if kept.is_some() {
                    self.last_kept = kept;
                }
                esgm_core::probe::mark(esgm_core::probe::Step::Checked);
                // A replica destroyed meanwhile needs nothing more.
                let _destroyed = self.replica.with_store(|s| s.replicate(es, add_time, lineage));
            }
            Arrival::Reset => {
                let _destroyed = self.replica.with_store(|s| s.reset());
            }
        }
    }

    /// The writer's pid as the registry last recorded it (0: none).
    pub fn writer_pid(&self) -> u32 {
        self.writer.pid()
    }

    /// The registry says whether the writer released the trajectory (an adder may
    /// take it over).
    pub fn set_released(&self, released: bool) {
        self.writer.set_released(released);
    }

    /// True while samples wait for the registry to name the writer's port.
    pub fn awaits_writer(&self) -> bool {
        self.check.awaits_writer()
    }

    /// True while the registry has not named the writer's port to this import.
    pub fn writer_unnamed(&self) -> bool {
        self.check.writer().is_none()
    }

    /// The registry names `port` as the writer's (`None`: not yet): what was held from
    /// it is entered, in order, and what was held from any other port is rejected.
    pub fn set_writer(&mut self, port: Option<WriterPort>) {
        self.writer.set_pid(port.map_or(0, |p| p.pid));
        let mut entered = false;
        for decided in self.check.set_writer(port.map(|p| p.publisher)) {
            entered |= matches!(decided, Decided::Enter { .. });
            self.decide(decided);
        }
        // The writer rang when it sent them, and the threads woken found them held: they
        // sleep again, and only this thread knows they are in now.
        if entered {
            self.wake_sleepers();
        }
    }

    fn not_writer(&mut self, port: u128, arrival: &Arrival) {
        let what = match arrival {
            Arrival::Entry { .. } => "a sample",
            Arrival::Reset => "a reset",
        };
        let detail = format!(
            "{what} from publisher {port:#x}, not the writer's ({})",
            self.check.writer().map_or_else(|| "not named".to_owned(), |w| format!("{w:#x}"))
        );
        self.count_rejection(Rejection::NotWriter, &detail);
    }

    /// Counts `lost` samples of the writer's, skipped before the one that entered, in
    /// the replica's stats (every sample accounted for).
    fn count_lost(&mut self, lost: u64) {
        if lost == 0 {
            return;
        }
        if self.lost == 0 {
            tracing::warn!(trajectory = %self.subscriber.trajectory(), lost,
                "samples from the writer were lost before this process read them \
                 (counted as dropped: lost); it fell behind");
        }
        self.lost += lost;
        let _destroyed = self.replica.with_store(|s| s.replicate_loss(lost));
    }

    fn reject(&mut self, e: &ReceiveError) {
        // Not a sample: the port could not receive (logged, retried at the next wake).
        let Some(why) = e.rejection() else {
            tracing::debug!(trajectory = %self.subscriber.trajectory(), error = %e,
                "cannot receive from the writer now");
            return;
        };
        self.count_rejection(why, e);
    }

    /// Counts one rejected sample in the replica's stats (the first is logged).
    fn count_rejection(&mut self, why: Rejection, detail: &dyn std::fmt::Display) {
        self.rejected += 1;
        if self.rejected == 1 {
            tracing::warn!(trajectory = %self.subscriber.trajectory(), cause = %why, error = %detail,
                "sample from another process rejected (later ones are only counted in its stats)");
        }
        // A replica destroyed meanwhile counts nothing.
        let _destroyed = self.replica.with_store(|s| s.replicate_rejection(why));
    }
}

/// Lets a subscriber of the replica wait on the writer's wake-up itself and feed the
/// replica, instead of waiting for the receiver thread to feed it and wake it: one
/// wake-up instead of two ([`esgm_core::ReplicaFeed`]).
#[derive(Debug)]
struct ImportFeed {
    trajectory: String,
    node: SharedNode,
    mirrors: Weak<SharedMirrors>,
}

impl ReplicaFeed for ImportFeed {
    fn waiter(&self) -> Option<Box<dyn FeedWaiter>> {
        Some(Box::new(ImportWaiter {
            listening: None,
            seen: None,
            left: None,
            trajectory: self.trajectory.clone(),
            node: self.node.clone(),
            mirrors: Weak::clone(&self.mirrors),
            import: Weak::new(),
            sleepers: None,
            coverage: None,
            worker: None,
            retired: None,
        }))
    }

    fn worker_waiter(&self) -> Option<Box<dyn FeedWaiter>> {
        Some(Box::new(ImportWaiter {
            listening: None,
            seen: None,
            left: None,
            trajectory: self.trajectory.clone(),
            node: self.node.clone(),
            mirrors: Weak::clone(&self.mirrors),
            import: Weak::new(),
            sleepers: None,
            coverage: None,
            worker: Some(None),
            retired: None,
        }))
    }
}

/// The longest one wait of a subscriber lasts before it looks again at what it
/// listens to. An import that goes (destroyed, re-pointed, disconnected) wakes its
/// waiting subscriptions itself, so this is only a backstop; each look costs a
/// waiting thread a wake-up, and a robot has hundreds of subscriptions waiting (every
/// 2 s it was 2 % of a core for 60 processes, twice an idle domain's budget).
const WAIT_SLICE: std::time::Duration = std::time::Duration::from_secs(30);

/// The longest sleep of a subscriber whose import left samples in its queue (a pump
/// that stopped at a broken connection or at its holding budget): it looks again this
/// soon, without spinning.
const LOOK_AGAIN: std::time::Duration = std::time::Duration::from_millis(10);

/// One subscription's sleep on its writer's wake-ups: the trajectory's futex word
/// ([`crate::data_plane::wake_word`]), or a listener on the writer's wake-up service where the
/// word cannot be mapped.
struct ImportWaiter {
    /// The generation listened to, and what it sleeps on.
    listening: Option<(u64, Sleeper)>,
    /// The word's sequence loaded before the last feed: the wait sleeps only while the
    /// word still holds it (a sample sent since changed it). `None` until the first
    /// feed after listening.
    seen: Option<u32>,
    /// Set while the import's last pump left samples in its queue
    /// ([`Import::pump`] stopped early): the next feed pumps even if the word has not
    /// moved, and a wait sleeps at most [`LOOK_AGAIN`].
    left: Option<Arc<std::sync::atomic::AtomicBool>>,
    trajectory: String,
    node: SharedNode,
    mirrors: Weak<SharedMirrors>,
    /// The import listened to, fed without a look-up in the set of mirrors; it is gone
    /// (the upgrade fails) once the set dropped it.
    import: Weak<parking_lot::Mutex<Import>>,
    /// The import's count of this process's threads asleep on it
    /// ([`ImportWaiter::fall_asleep`]).
    sleepers: Option<Arc<std::sync::atomic::AtomicUsize>>,
    /// The import's count of this process in the writer's word, covered while this
    /// waiter sleeps on the word ([`super::coverage`]).
    coverage: Option<Arc<Coverage>>,
    /// A worker's waiter: the import's count of waiting workers it is counted in (see
    /// [`Import::receiver_wakes`]); `None` for a user's subscription.
    worker: Option<Option<Arc<std::sync::atomic::AtomicUsize>>>,
    /// The listened import's flag, set when it goes: until then a wait listens as it
    /// did, without looking the import up under the set's lock.
    retired: Option<Arc<std::sync::atomic::AtomicBool>>,
}

impl Drop for ImportWaiter {
    fn drop(&mut self) {
        self.stand_down();
    }
}

impl ImportWaiter {
    /// Listens to the current import's wake-up service (again, if its generation
    /// changed); false if there is no import to listen to.
    fn listen(&mut self) -> bool {
        // Still listening to an import that has not gone: nothing to look up.
        let current =
            self.retired.as_ref().is_some_and(|r| !r.load(std::sync::atomic::Ordering::SeqCst));
        if current && self.listening.is_some() && self.import.strong_count() > 0 {
            return true;
        }
        let Some(mirrors) = self.mirrors.upgrade() else { return false };
        let import = mirrors.import(&self.trajectory);
        let current = import.as_ref().and_then(|i| {
            let i = i.lock();
            i.sample_wake().map(|w| {
                let counts = (Arc::clone(&i.sleepers), i.coverage.clone());
                let flags = (Arc::clone(&i.retired), Arc::clone(&i.stopped_early));
                (i.generation, w, Arc::clone(&i.workers), counts, flags)
            })
        });
        let (
            Some(import),
            Some((generation, wake, workers, (sleepers, coverage), (retired, left))),
        ) = (import, current)
        else {
            self.import = Weak::new();
            self.retired = None;
            self.left = None;
            self.stand_down();
            return false;
        };
        self.import = Arc::downgrade(&import);
        self.retired = Some(retired);
        self.left = Some(left);
        self.sleepers = Some(sleepers);
        self.coverage = coverage;
        if self.listening.as_ref().is_some_and(|(g, _)| *g == generation) {
            return true;
        }
        // Another generation: count in the import now served.
        self.stand_down();
        let sleeper = self.node.with(|node| {
            Sleeper::open(wake.name.as_str(), || {
                wake.open(node)?.listener_builder().create().map_err(OpenError::Listener)
            })
        });
        match sleeper {
            Ok(sleeper) => {
                self.listening = Some((generation, sleeper));
                self.seen = None;
                if let Some(counted) = &mut self.worker {
                    workers.fetch_add(1, std::sync::atomic::Ordering::AcqRel);
                    *counted = Some(workers);
                    // The receiver stops listening to these samples.
                    mirrors.change(|_| ());
                }
                true
            }
            Err(e) => {
                tracing::debug!(trajectory = %self.trajectory, error = %e,
                    "a subscriber cannot listen to its writer; the receiver thread wakes it");
                self.listening = None;
                false
            }
        }
    }
}

/// A waiter counted among its import's sleepers while this lives (see
/// [`ImportWaiter::fall_asleep`]), and covering its process's receiver if it sleeps on
/// the word.
struct Asleep {
    count: Arc<std::sync::atomic::AtomicUsize>,
    _covering: Option<super::coverage::Asleep>,
}

impl Drop for Asleep {
    fn drop(&mut self) {
        self.count.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
    }
}

impl ImportWaiter {
    /// Counts this waiter among its import's sleepers before it sleeps, so that the
    /// import wakes it when it goes; `None` if the import is already gone (look
    /// again instead of sleeping). Counted first, then the import looked at: either
    /// the import's drop sees the count and rings, or this sees the import gone.
    ///
    /// A waiter about to sleep on a word (`word`) also covers its connection's
    /// receiver ([`super::coverage`]) from now until the result is dropped, which must
    /// come before it feeds the replica, on every path: the writer may skip the notify
    /// meanwhile.
    fn fall_asleep(&self, word: Option<&WakeWord>) -> Option<Asleep> {
        let sleepers = self.sleepers.as_ref()?;
        sleepers.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let covering = self.coverage.as_ref().zip(word).and_then(|(c, w)| c.asleep(w));
        let asleep = Asleep { count: Arc::clone(sleepers), _covering: covering };
        self.import.upgrade().map(|_| asleep)
    }

    /// No longer counted as the import's waiting worker: the receiver listens again.
    fn stand_down(&mut self) {
        let Some(Some(workers)) = self.worker.as_mut().map(Option::take) else { return };
        workers.fetch_sub(1, std::sync::atomic::Ordering::AcqRel);
        if let Some(mirrors) = self.mirrors.upgrade() {
            mirrors.change(|_| ());
        }
    }
}

impl ImportWaiter {
    /// The listener it waits on, if [`ImportWaiter::listen`] made one.
    fn listener(&self) -> Option<&Listener<ShmService>> {
        match &self.listening {
            Some((_, Sleeper::Listener(l))) => Some(l),
            _ => None,
        }
    }

    /// The word it sleeps on, if [`ImportWaiter::listen`] mapped it, with the
    /// sequence seen at the last feed.
    fn word(&self) -> Option<(&WakeWord, Option<u32>)> {
        match &self.listening {
            Some((_, Sleeper::Word(w))) => Some((w, self.seen)),
            _ => None,
        }
    }

    /// The word and the sequence the last feed saw, if the word still holds it: what
    /// to sleep on. `None` if a sample was sent since (or nothing was seen yet): look
    /// again instead of sleeping.
    fn unchanged_word(&self) -> Option<(&WakeWord, u32)> {
        let (word, seen) = self.word()?;
        seen.filter(|&s| s == word.sequence()).map(|s| (word, s))
    }

    /// Whether the import's last pump left samples in its queue.
    fn left_in_queue(&self) -> bool {
        self.left.as_ref().is_some_and(|l| l.load(std::sync::atomic::Ordering::Acquire))
    }

    /// How long one sleep may last: at most [`LOOK_AGAIN`] while samples are left in
    /// the queue.
    fn slice(&self, timeout: std::time::Duration) -> std::time::Duration {
        match self.left_in_queue() {
            true => timeout.min(LOOK_AGAIN),
            false => timeout.min(WAIT_SLICE),
        }
    }

    /// After a sleep on the word that saw no change: a word whose file was made anew
    /// (the domain restarted with this process in it) is mapped again at the next
    /// wait, to meet the new writer.
    fn check_word(&mut self) {
        if let Some((word, Some(seen))) = self.word()
            && word.sequence() == seen
            && word.stale()
        {
            self.listening = None;
        }
    }
}

/// Several inputs' waiters as one ([`FeedWaiter::join`]): a worker with several inputs
/// from other processes sleeps on all their writers' wake-ups at once (`poll(2)` on
/// the listeners' descriptors, one system call whatever the number of inputs), and is
/// woken once by whichever writer publishes.
struct JoinedWaiter {
    waiters: Vec<ImportWaiter>,
}

impl FeedWaiter for JoinedWaiter {
    fn feed(&mut self) {
        for w in &mut self.waiters {
            w.feed();
        }
    }

    fn wait_and_feed(&mut self, timeout: std::time::Duration) -> bool {
        if !self.waiters.iter_mut().all(ImportWaiter::listen) {
            return false;
        }
        let timeout = self.waiters.iter().fold(timeout, |t, w| w.slice(t));
        if self.waiters.iter().all(|w| w.word().is_some()) {
            // Sleep only if no word changed since the last feed (nor was never seen).
            let seen: Option<Vec<(&WakeWord, u32)>> =
                self.waiters.iter().map(ImportWaiter::unchanged_word).collect();
            let slept = seen.map_or(Ok(()), |seen| {
                let asleep: Option<Vec<Asleep>> = self
                    .waiters
                    .iter()
                    .zip(&seen)
                    .map(|(w, (word, _))| w.fall_asleep(Some(word)))
                    .collect();
                // Counted out (the covers dropped) before any feed below.
                asleep.map_or(Ok(()), |_asleep| {
                    crate::data_plane::wake_word::sleep_any(&seen, timeout)
                })
            });
            esgm_core::probe::mark(esgm_core::probe::Step::Woken);
            if let Err(e) = slept {
                tracing::warn!(error = %e,
                    "cannot sleep on the inputs' words; waiting on the channel");
                // What a skipped notify left to this connection is fed before leaving.
                self.feed();
                return false;
            }
            self.waiters.iter_mut().for_each(ImportWaiter::check_word);
            self.feed();
            return true;
        }
        // Every input on a listener, or some on words and some not: a mix cannot be
        // waited on at once, so the worker waits on its channel.
        let listeners: Option<Vec<&Listener<ShmService>>> =
            self.waiters.iter().map(ImportWaiter::listener).collect();
        let Some(listeners) = listeners else { return false };
        let asleep: Option<Vec<Asleep>> =
            self.waiters.iter().map(|w| w.fall_asleep(None)).collect();
        let Some(_asleep) = asleep else {
            self.feed();
            return true;
        };
        match crate::data_plane::wait::wait_any(&listeners, timeout) {
            Ok(()) => {
                self.feed();
                true
            }
            Err(e) => {
                tracing::warn!(error = %e,
                    "cannot wait on the inputs' writers; waiting on the channel");
                false
            }
        }
    }

    fn join(mut self: Box<Self>, others: Vec<Box<dyn FeedWaiter>>) -> Option<Box<dyn FeedWaiter>> {
        for other in others {
            self.waiters.extend(ImportWaiter::own(other)?);
        }
        Some(self)
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send> {
        self
    }
}

impl ImportWaiter {
    /// The import waiters `waiter` is made of, if it is this transport's.
    fn own(waiter: Box<dyn FeedWaiter>) -> Option<Vec<ImportWaiter>> {
        let any = waiter.into_any();
        match any.downcast::<ImportWaiter>() {
            Ok(w) => Some(vec![*w]),
            Err(any) => any.downcast::<JoinedWaiter>().ok().map(|j| j.waiters),
        }
    }
}

impl FeedWaiter for ImportWaiter {
    fn join(self: Box<Self>, others: Vec<Box<dyn FeedWaiter>>) -> Option<Box<dyn FeedWaiter>> {
        Box::new(JoinedWaiter { waiters: vec![*self] }).join(others)
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send> {
        self
    }

    fn feed(&mut self) {
        // Loaded before the pump: what is sent after it changes the word. A word that
        // has not changed since the last feed means the writer sent nothing since:
        // nothing to take, and no lock or port to touch (a subscription that polls in
        // a loop costs a load per poll).
        if let Some((word, seen)) = self.word() {
            let now = word.sequence();
            if seen == Some(now) && !self.left_in_queue() && self.import.strong_count() > 0 {
                return;
            }
            self.seen = Some(now);
        }
        let import = match self.import.upgrade() {
            Some(import) => Some(import),
            None => self.mirrors.upgrade().and_then(|m| m.import(&self.trajectory)),
        };
        if let Some(import) = import {
            import.lock().pump();
        }
    }

    fn wait_and_feed(&mut self, timeout: std::time::Duration) -> bool {
        if !self.listen() {
            return false;
        }
        if self.word().is_some() {
            if let Some((word, seen)) = self.unchanged_word()
                && let Some(_asleep) = self.fall_asleep(Some(word))
            {
                word.sleep(seen, self.slice(timeout));
            }
            esgm_core::probe::mark(esgm_core::probe::Step::Woken);
            self.check_word();
            self.feed();
            return true;
        }
        let Some(listener) = self.listener() else { return false };
        let Some(_asleep) = self.fall_asleep(None) else {
            self.feed();
            return true;
        };
        match crate::data_plane::wait::timed_wait(listener, self.slice(timeout)) {
            Ok(_) => {
                esgm_core::probe::mark(esgm_core::probe::Step::Woken);
                self.feed();
                true
            }
            Err(e) => {
                tracing::warn!(trajectory = %self.trajectory, error = ?e,
                    "cannot wait on the writer's wake-up; waiting on the channel");
                false
            }
        }
    }
}

/// The longest a new reader waits for the writer to hand it the history.
const JOIN_TIMEOUT: Duration = Duration::from_secs(1);

/// Asks the writer of `trajectory` for the history of a subscriber just connected, and
/// waits until its queue holds it: rings the trajectory's join service, which the
/// writer answers by handing new subscribers their history and waking the readers
/// ([`super::export::Export::welcome`]). Any wake-up counts, since a send hands new
/// subscribers their history first. Without this, the history would arrive at the
/// writer's next sample or maintenance tick, and a first query on a trajectory
/// nobody adds to any more (a loaded recording) would answer "empty".
fn join(
    node: &SharedNode,
    domain: &str,
    trajectory: &str,
    sample_wake: &EventSpec,
    readers: Readers,
) -> Result<(), JoinError> {
    let join = join_service(domain, trajectory).map_err(OpenError::from)?;
    let (listener, bell) = node.with(|node| {
        let listener =
            sample_wake.open(node)?.listener_builder().create().map_err(JoinError::Listen)?;
        let bell = open_event_service(node, &join, EventCapacity::to_writer(readers))?
            .notifier_builder()
            .create()
            .map_err(JoinError::Ring)?;
        Ok::<_, JoinError>((listener, bell))
    })?;
    bell.notify().map_err(JoinError::Notify)?;
    match timed_wait(&listener, JOIN_TIMEOUT) {
        Ok(0) => Err(JoinError::NoAnswer { within: JOIN_TIMEOUT }),
        Ok(_) => Ok(()),
        Err(e) => Err(JoinError::Wait(e)),
    }
}

/// Why a new reader's ring for its history ([`join`]) went unanswered: logged, since
/// the history then comes with the writer's next sample or maintenance.
#[derive(Debug, thiserror::Error)]
enum JoinError {
    /// The wake-up or join service could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// No listener on the writer's wake-up.
    #[error("cannot listen to the writer: {0:?}")]
    Listen(iceoryx2::port::listener::ListenerCreateError),
    /// No notifier on the join service.
    #[error("cannot ring the writer: {0:?}")]
    Ring(iceoryx2::port::notifier::NotifierCreateError),
    /// The ring failed.
    #[error("cannot ring the writer: {0:?}")]
    Notify(iceoryx2::port::notifier::NotifierNotifyError),
    /// Waiting for the writer's answer failed.
    #[error("cannot wait for the writer: {0:?}")]
    Wait(iceoryx2::port::listener::ListenerWaitError),
    /// The writer did not answer in time.
    #[error("no answer within {within:?}")]
    NoAnswer {
        /// How long it had.
        within: Duration,
    },
}

/// How long a process's first add to a trajectory waits for the writer to open its
/// inbox: a round trip of the writer's receiver thread, or, for a trajectory just
/// created or re-pointed, until its writer has built it (its next look at the
/// registry, then its services; seconds on a loaded machine).
pub(crate) const WRITER_OPENS: Duration = Duration::from_secs(10);

/// Rings the writer (`ring`) until `listening`, for at most [`WRITER_OPENS`]; true if
/// it listens.
pub(crate) fn writer_listens<E: std::fmt::Display>(
    listening: impl Fn() -> bool,
    ring: impl Fn() -> Result<(), E>,
) -> bool {
    let deadline = std::time::Instant::now() + WRITER_OPENS;
    let mut next_ring = std::time::Instant::now();
    let mut pause = Duration::from_micros(50);
    while !listening() {
        let now = std::time::Instant::now();
        if now >= deadline {
            return false;
        }
        // Again now and then: a writer restarted meanwhile missed the first.
        if now >= next_ring {
            if let Err(e) = ring() {
                tracing::debug!(error = %e, "cannot ring the writer");
            }
            next_ring = now + Duration::from_millis(100);
        }
        std::thread::sleep(pause);
        pause = (pause * 2).min(Duration::from_millis(5));
    }
    true
}

/// A replica's side of forwarding: publishes each add on the writer's inbox, from the
/// adding thread.
#[derive(Debug)]
struct Outbox {
    trajectory: String,
    /// What is known of the writer, kept current by the location thread
    /// ([`Import::set_writer`], [`Import::set_released`]).
    writer: Arc<WriterLiveness>,
    /// The generation this replica mirrors (a take-over is asked for it).
    generation: u64,
    /// Where a take-over is asked ([`super::takeover`]).
    take_over: crossbeam_channel::Sender<TakeOverAsk>,
    type_name: String,
    domain: String,
    /// The trajectory's readers, which size its inbox and blocking-add services.
    readers: Readers,
    /// The largest structure of its type, if bounded (the inbox's fixed-size pool).
    fixed: Option<usize>,
    node: SharedNode,
    /// Opened at the first add: most replicas of a primitive trajectory only read.
    inbox: Mutex<Option<TrajectoryPublisher>>,
    /// Opened at the first blocking add.
    blocking: Mutex<Option<AddClient>>,
}

impl AddForwarder for Outbox {
    fn forward(&self, es: SharedStructure, blocking: bool) -> Result<AddOutcome, AddError> {
        let unavailable = |detail: String| AddError::Unavailable {
            trajectory: self.trajectory.clone(),
            reason: Unreachable::transport(Peer::Writer, detail),
        };
        // A writer that is gone serves no add: refuse, never acknowledge and lose. (The
        // handle asked to take the trajectory over before this add; a writer that went
        // since, or one nobody may replace, ends here.)
        let pid = self.writer.pid();
        let gone = || AddError::WriterGone { trajectory: self.trajectory.clone(), pid };
        if self.writer.gone() {
            return Err(gone());
        }
        if blocking {
            let mut client = self.blocking.lock();
            if client.is_none() {
                let names =
                    TrajectoryServiceNames::new(&inbox_domain(&self.domain), &self.trajectory)
                        .map_err(|e| unavailable(e.to_string()))?;
                let wake = EventSpec {
                    name: *names.wake(),
                    capacity: inbox_qos(self.readers).wake_capacity(),
                };
                let opened = self.node.with(|node| {
                    AddClient::open(node, &self.domain, &self.trajectory, self.readers, &wake)
                });
                *client = Some(opened.map_err(|e| match e {
                    BlockingAddError::Open(OpenError::LimitReached(limit)) => {
                        AddError::LimitReached(limit)
                    }
                    e => unavailable(e.to_string()),
                })?);
            }
            let Some(client) = client.as_ref() else {
                return Err(unavailable("the writer's blocking adds are not open".into()));
            };
            // The request carries an owned structure (an archived one is converted).
            return client.add(&es.to_arc());
        }
        let mut inbox = self.inbox.lock();
        if inbox.is_none() {
            let opened = self.node.with(|node| {
                let mut publisher = TrajectoryPublisher::builder(&self.trajectory, &self.type_name)
                    .domain(inbox_domain(&self.domain))
                    .qos(inbox_qos(self.readers));
                if let Some(len) = self.fixed {
                    publisher = publisher.sizing(SampleSizing::Fixed).max_len(len);
                }
                publisher.create(node)
            });
            let publisher =
                opened.map_err(|e| match e.as_limit(&self.trajectory, self.readers) {
                    OpenError::LimitReached(limit) => AddError::LimitReached(limit),
                    e => unavailable(format!("cannot open the writer's inbox: {e}")),
                })?;
            // The writer opens its inbox when an adder first rings (see `Export`); an
            // add sent before would reach nobody.
            if !writer_listens(|| publisher.subscriber_count() > 0, || publisher.welcome()) {
                return Err(AddError::Unavailable {
                    trajectory: self.trajectory.clone(),
                    reason: Unreachable::no_answer(Peer::Writer, WRITER_OPENS),
                });
            }
            *inbox = Some(publisher);
        }
        let Some(publisher) = inbox.as_ref() else {
            return Err(unavailable("the writer's inbox is not open".into()));
        };
        let sent = publisher
            .publish_shared(&es)
            .map_err(|e| unavailable(format!("cannot send to the writer's inbox: {e}")))?;
        // The writer's inbox is gone (it left since it opened it): nobody got it. The
        // next add asks to take the trajectory over.
        if sent.subscribers == 0 {
            self.writer.set_released(true);
            return Err(gone());
        }
        Ok(AddOutcome::Forwarded)
    }

    fn writer_gone(&self) -> bool {
        self.writer.gone()
    }

    fn take_over(&self, trajectory: &str) -> Result<(), AddError> {
        super::takeover::ask(&self.take_over, trajectory, self.generation)
    }
}
