//! The trajectory store: the representational structure behind every kind of
//! trajectory (a fluent stream, seed 3.3.3), with its constraints, queries and
//! subscriptions.
//!
//! A store is a plain single-owner value (`&mut self` to add): the runtimes wrap it in
//! whatever locking or process boundary they need. Everything timed reads the
//! [`Clock`](crate::Clock) it was built with.
//!
//! ## What happens to an offered structure
//! 1. Samples held for reordering whose delay window has passed are released first.
//! 2. Type check: a structure that does not fit the type is refused with
//!    [`AddError::InvalidType`] (bad input, not a policy matter) and counted.
//! 3. Arrival constraints: duration (C4), delay (C6, add time − valid time), filter (C3).
//! 4. With a monotone order, a maximum delay and `reorder` on, the structure is held
//!    until valid time + delay and released in valid-time order (C6).
//! 5. Sequence constraints against the previous sample in the stream: order (C5),
//!    change (C1), and a time cache's window (C2).
//! 6. It enters the stream: stored, the cache evicts its oldest, subscribers get it.
//!
//! A structure that breaks a constraint is dropped, counted under that constraint and
//! sent to violation subscribers; the blocking add forms also return it as
//! [`AddError::PolicyViolation`] (C7, T4). Nothing is lost silently:
//! `added + dropped + held` always equals the number of structures offered.

pub(crate) mod history;
mod query;
mod stats;
mod subscription;
mod violation;

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};
use std::sync::Arc;

use crate::clock::SharedClock;
use crate::filter::Filter;
use crate::lineage::Lineage;
use crate::pixel_buffer::OctetsAllocator;
use crate::policy::{
    CacheConstraint, ChangeConstraint, Constraint, DelayConstraint, DurationConstraint,
    FluentStreamPolicy, OrderConstraint, PolicyError,
};
use crate::sample::Sample;
use crate::structure::SharedStructure;
use crate::time::Time;
use crate::type_check::TypeChecker;
use crate::types::EntityStructureType;
use crate::value::frame::AttributeList;
use crate::value::frame::EntityStructure;
use history::{Entry, History};
use stats::StatsRecorder;
use subscription::Subscribers;

pub use query::QueryError;
pub use stats::TrajectoryStats;
pub use subscription::{
    CallbackError, CallbackHandle, FanIn, FeedWaiter, RecvError, ReplicaFeed, SubscribeOptions,
    Subscription, SubscriptionId,
};
pub use violation::{
    AddError, AddForwarder, AddOutcome, BridgeLoss, DropCause, DropRecord, PolicyViolation,
    RECENT_DROPS, Rejection,
};

/// A sample waiting in the reorder buffer, ordered by (valid time, add sequence).
#[derive(Debug)]
struct Held {
    es: SharedStructure,
    lineage: Option<Arc<Lineage>>,
    seq: u64,
    release_at: Time,
}

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        self.key() == other.key()
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Held {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key().cmp(&other.key())
    }
}
impl Held {
    fn key(&self) -> (Time, u64) {
        (self.es.valid_time(), self.seq)
    }
}

/// A generation for a store built in this process: distinct from every other store's
/// here, so a trajectory destroyed and created again under its name is told apart.
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// Builds a [`TrajectoryStore`].
#[derive(Debug)]
pub struct TrajectoryStoreBuilder {
    name: String,
    checker: TypeChecker,
    policy: FluentStreamPolicy,
    clock: Option<SharedClock>,
}

impl TrajectoryStoreBuilder {
    /// The policy (default: unconstrained).
    #[must_use]
    pub fn policy(mut self, policy: FluentStreamPolicy) -> Self {
        self.policy = policy;
        self
    }

    /// The clock timing rules read (default: the system clock).
    #[must_use]
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// Validates the policy, compiles its filter against the type, resolves the
    /// duration's zero rules against the clock, and creates the store.
    pub fn create(self) -> Result<TrajectoryStore, PolicyError> {
        self.policy.validate()?;
        let filter = match &self.policy.filter {
            Some(src) => Some(Filter::compile(src, &self.checker)?),
            None => None,
        };
        let clock = self.clock.unwrap_or_else(crate::clock::SystemClock::shared);
        let window = match self.policy.duration {
            DurationConstraint::Unbounded => None,
            DurationConstraint::Between { from, to } => {
                let from = if from == 0 { clock.now() } else { from };
                Some((from, (to != 0).then_some(to)))
            }
        };
        if let Some((from, Some(to))) = window {
            if to < from {
                return Err(PolicyError::illegal(
                    "duration.to",
                    to,
                    "is before the start (from = 0 means now)",
                ));
            }
        }
        Ok(TrajectoryStore {
            name: self.name,
            checker: self.checker,
            policy: self.policy,
            filter,
            clock,
            window,
            history: History::default(),
            held: BinaryHeap::new(),
            last: None,
            next_seq: 0,
            subscribers: Subscribers::default(),
            violation_subscribers: Subscribers::default(),
            stats: StatsRecorder::default(),
            resets: Arc::default(),
            generation: Arc::new(std::sync::atomic::AtomicU64::new(next_generation())),
            recent_drops: VecDeque::new(),
            tap: None,
            forward: None,
            adopted: false,
            feed: None,
            octets_allocator: None,
            reset_forwarder: None,
        })
    }
}

/// A fluent stream of entity structures with history: one trajectory's content.
#[derive(Debug)]
pub struct TrajectoryStore {
    name: String,
    checker: TypeChecker,
    policy: FluentStreamPolicy,
    filter: Option<Filter>,
    clock: SharedClock,
    /// The duration constraint with its zero rules resolved: `[from, to]`, `None` = ∞.
    window: Option<(Time, Option<Time>)>,
    pub(crate) history: History,
    held: BinaryHeap<Reverse<Held>>,
    /// The last sample that entered the stream, kept after eviction: order and change
    /// are relations between consecutive samples, whatever the cache keeps.
    last: Option<SharedStructure>,
    next_seq: u64,
    subscribers: Subscribers<Sample>,
    violation_subscribers: Subscribers<PolicyViolation>,
    stats: StatsRecorder,
    /// Bumped by every reset, so readers that remember samples (units' latest inputs)
    /// know to forget them.
    resets: Arc<std::sync::atomic::AtomicU64>,
    /// The trajectory's generation, named in the lineage of what is made from it
    /// ([`crate::lineage::InputRef::generation`]).
    generation: Arc<std::sync::atomic::AtomicU64>,
    /// The gate's most recent drops with their details, for "why did it not
    /// produce?" (bounded: [`RECENT_DROPS`]).
    recent_drops: VecDeque<DropRecord>,
    /// Everything that happens to the stream, in order, for one observer (a bridge
    /// that mirrors the stream into another process), told inline.
    tap: Option<(TapId, Box<dyn StoreTap>)>,
    /// A replica's adds go to the trajectory's writer elsewhere.
    forward: Option<Arc<dyn AddForwarder>>,
    /// This replica became the writer's store ([`Self::adopt_adds`]).
    adopted: bool,
    /// A replica's subscribers may wait for its writer themselves.
    feed: Option<Arc<dyn ReplicaFeed>>,
    /// Where this trajectory's producers get image buffers (its shared memory).
    octets_allocator: Option<Arc<dyn OctetsAllocator>>,
    /// Where a reset of this trajectory through a handle goes, if the trajectory
    /// lives in more than one process.
    reset_forwarder: Option<Arc<dyn ResetForwarder>>,
}

/// Carries a reset asked through a handle (T5) to every process that holds the
/// trajectory: its writer, which empties the stream, and every replica, which forgets
/// it. Set with [`TrajectoryStore::forward_resets`]; the transport implements it. It is
/// called without the store's lock held, so it may wait for other processes.
pub trait ResetForwarder: Send + Sync + std::fmt::Debug {
    /// Resets `trajectory` everywhere. Not `blocking`: returns once the reset is on its
    /// way (the writer's own stream is empty on return when the caller is the writer).
    /// `blocking`: returns once the writer has reset and every connected reader has
    /// forgotten the stream.
    fn reset(&self, trajectory: &str, blocking: bool) -> Result<(), QueryError>;
}

/// One thing that happened to a stream, as a [`StoreTap`] is told it.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum StoreEvent {
    /// A structure entered the stream (directly or on release from the hold).
    Entered(Sample),
    /// A structure was dropped for breaking the policy.
    Violation(PolicyViolation),
    /// The stream was emptied (T5).
    Reset,
}

/// An observer of everything that happens to one stream, told synchronously, in stream
/// order, by the thread that made it happen, while the store is locked.
///
/// Why inline and not a channel: a bridge that mirrors the stream into other
/// processes publishes each event from the adding thread itself, so a structure
/// reaches shared memory without waking another thread first (a wake-up costs tens of
/// microseconds, more than the publish). Whatever a tap does delays the add that
/// caused it, so it must be short and must never block: count and report failures,
/// never wait for a reader.
pub trait StoreTap: Send + 'static {
    /// One event of the stream, in order. A structure that enters is told to
    /// [`StoreTap::entering`] instead.
    fn observe(&mut self, event: &StoreEvent);

    /// A structure is entering the stream (admitted by the gate, or released from the
    /// hold), before it is stored and delivered here: a mirror publishes it now, so
    /// other processes see it no later than this one. It may answer the structure that
    /// enters in its place — the same content with its bytes elsewhere, e.g. pixels
    /// this process wrote into a loan and just sent, now read through a received
    /// sample — which is then what the store keeps and its subscribers get.
    fn entering(&mut self, sample: &Sample) -> Option<SharedStructure> {
        self.observe(&StoreEvent::Entered(sample.clone()));
        None
    }

    /// How many entries the tap could not pass on since it was last asked: the store
    /// counts them ([`DropCause::Unpublished`]), so a mirror's failure shows in the
    /// trajectory's stats. Asked after every entry.
    fn take_unpublished(&mut self) -> u64 {
        0
    }
}

impl<F: FnMut(&StoreEvent) + Send + 'static> StoreTap for F {
    fn observe(&mut self, event: &StoreEvent) {
        self(event);
    }
}

/// Names the tap [`TrajectoryStore::set_tap`] installed, so that its owner removes
/// its own tap and never a successor's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TapId(u64);

impl std::fmt::Debug for dyn StoreTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StoreTap")
    }
}

impl TrajectoryStore {
    /// Starts building a store named `name` whose structures `checker` checks.
    pub fn builder(name: impl Into<String>, checker: TypeChecker) -> TrajectoryStoreBuilder {
        TrajectoryStoreBuilder {
            name: name.into(),
            checker,
            policy: FluentStreamPolicy::default(),
            clock: None,
        }
    }

    /// The trajectory's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The registered name of the trajectory's type.
    pub fn type_name(&self) -> &str {
        self.checker.type_name()
    }

    /// The trajectory's type (the seed's `type` attribute).
    pub fn entity_type(&self) -> &Arc<EntityStructureType> {
        self.checker.entity_type()
    }

    /// The type checker (shared with units and filters that need the same types).
    pub fn checker(&self) -> &TypeChecker {
        &self.checker
    }

    /// The policy (the seed's `pol` attribute).
    pub fn policy(&self) -> &FluentStreamPolicy {
        &self.policy
    }

    /// The clock this store reads.
    pub fn clock(&self) -> &SharedClock {
        &self.clock
    }

    /// Adds a structure; a constraint violation drops it, counts it and notifies
    /// violation subscribers (`Ok(AddOutcome::Dropped)`).
    pub fn add(&mut self, es: EntityStructure) -> Result<AddOutcome, AddError> {
        self.offer(es.into(), false)
    }

    /// Adds a structure; a constraint violation is also returned as
    /// [`AddError::PolicyViolation`].
    pub fn add_blocking(&mut self, es: EntityStructure) -> Result<AddOutcome, AddError> {
        self.offer(es.into(), true)
    }

    /// Adds an already shared structure without copying it (what runtimes use to pass
    /// one structure to several stores), owned or archived in place.
    pub fn add_shared(
        &mut self,
        es: impl Into<SharedStructure>,
        blocking: bool,
    ) -> Result<AddOutcome, AddError> {
        self.offer(es.into(), blocking)
    }

    /// [`Self::add_shared`] for a structure made from other structures: `lineage` names
    /// them, and is stored and delivered with it ([`Sample::lineage`]). A store that
    /// forwards its adds to a writer elsewhere forwards the structure only.
    pub fn add_produced(
        &mut self,
        es: impl Into<SharedStructure>,
        lineage: Option<Arc<Lineage>>,
        blocking: bool,
    ) -> Result<AddOutcome, AddError> {
        self.offer_with(es.into(), lineage, blocking)
    }

    /// Creates a structure valid at `valid_time`, created now, and adds it.
    pub fn create_at(
        &mut self,
        name: impl Into<String>,
        valid_time: Time,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, AddError> {
        let es = self.make(name, Some(valid_time), attributes);
        self.offer(es.into(), false)
    }

    /// [`TrajectoryStore::create_at`], returning violations.
    pub fn create_at_blocking(
        &mut self,
        name: impl Into<String>,
        valid_time: Time,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, AddError> {
        let es = self.make(name, Some(valid_time), attributes);
        self.offer(es.into(), true)
    }

    /// Creates a structure valid and created now, and adds it.
    pub fn create_at_now(
        &mut self,
        name: impl Into<String>,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, AddError> {
        let es = self.make(name, None, attributes);
        self.offer(es.into(), false)
    }

    /// [`TrajectoryStore::create_at_now`], returning violations.
    pub fn create_at_now_blocking(
        &mut self,
        name: impl Into<String>,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, AddError> {
        let es = self.make(name, None, attributes);
        self.offer(es.into(), true)
    }

    fn make(
        &self,
        name: impl Into<String>,
        valid_time: Option<Time>,
        attributes: impl Into<AttributeList>,
    ) -> EntityStructure {
        let now = self.clock.now();
        EntityStructure {
            name: name.into(),
            valid_time: valid_time.unwrap_or(now),
            create_time: now,
            attributes: attributes.into().0,
        }
    }

    /// Empties the stream (T5): stored and held samples go (held ones are counted as
    /// dropped for [`DropCause::Reset`]); policy, subscribers and stats stay.
    pub fn reset(&mut self) {
        self.resets.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        for _ in self.held.drain() {
            self.stats.record_dropped(DropCause::Reset);
        }
        self.history.clear();
        self.last = None;
        self.tell_tap(StoreEvent::Reset);
    }

    /// A counter bumped by every reset: whoever remembers samples of this trajectory
    /// compares it to forget them after a reset.
    pub fn reset_counter(&self) -> Arc<std::sync::atomic::AtomicU64> {
        Arc::clone(&self.resets)
    }

    /// The trajectory's generation: a number each store gets when it is built, unless
    /// its owner says otherwise ([`Self::set_generation`]). Shared with whoever names
    /// this trajectory's structures as inputs (lineage), so they follow a change.
    pub fn generation(&self) -> Arc<std::sync::atomic::AtomicU64> {
        Arc::clone(&self.generation)
    }

    /// Sets the trajectory's generation: across processes, the coordinator's registry
    /// generation, so every process names the same stream the same way.
    pub fn set_generation(&self, generation: u64) {
        self.generation.store(generation, std::sync::atomic::Ordering::Relaxed);
    }

    /// The gate's most recent drops, oldest first, with what each broke.
    pub fn recent_drops(&self) -> Vec<DropRecord> {
        self.recent_drops.iter().cloned().collect()
    }

    /// When a structure last entered the stream (`None`: never), and how many of the
    /// last adds remembered (128) entered at or after `since`.
    pub fn adds_since(&self, since: Time) -> (Option<Time>, u64) {
        self.stats.adds_since(since)
    }

    fn remember_drop(&mut self, at: Time, cause: DropCause, valid_time: Time, detail: String) {
        if self.recent_drops.len() == RECENT_DROPS {
            self.recent_drops.pop_front();
        }
        self.recent_drops.push_back(DropRecord { at, cause, valid_time, detail });
    }

    /// The same as [`TrajectoryStore::reset`]: in process, every reset completes
    /// before it returns.
    pub fn reset_blocking(&mut self) {
        self.reset();
    }

    /// Releases held samples whose delay window has passed; returns how many entered
    /// the stream. Runtimes call it at [`TrajectoryStore::next_release_time`].
    pub fn release_due(&mut self) -> usize {
        let now = self.clock.now();
        self.release_due_at(now)
    }

    /// When the next held sample is due, if any is held.
    pub fn next_release_time(&self) -> Option<Time> {
        self.held.peek().map(|Reverse(h)| h.release_at)
    }

    /// Subscribes to every structure that enters the stream from now on (after the
    /// last `options.last` stored ones), in add order.
    pub fn subscribe(&mut self, options: SubscribeOptions) -> Subscription<Sample> {
        let backlog: Vec<Sample> = self
            .history
            .last_n(options.last)
            .map(|e| {
                Sample::new(e.es.clone(), e.add_time, e.add_time).with_lineage(e.lineage.clone())
            })
            .collect();
        // A replay longer than the buffer keeps its newest samples; the rest count as
        // overflow, like any sample a subscriber had no room for.
        self.stats.record_overflow(backlog.len().saturating_sub(options.capacity.max(1)) as u64);
        let waiter = self.feed.as_ref().and_then(|f| f.waiter());
        self.subscribers.subscribe(options.capacity, backlog.into_iter()).with_waiter(waiter)
    }

    /// Makes producers of this trajectory (its sampler, or whoever asks) write images
    /// into buffers from `allocator` — the trajectory's shared memory — instead of the
    /// heap ([`crate::pixel_buffer`]).
    pub fn set_octets_allocator(&mut self, allocator: Arc<dyn OctetsAllocator>) {
        self.octets_allocator = Some(allocator);
    }

    /// Where producers of this trajectory get image buffers, if it has a place of its
    /// own.
    pub fn octets_allocator(&self) -> Option<Arc<dyn OctetsAllocator>> {
        self.octets_allocator.clone()
    }

    /// A waiter on this store's writer for a runtime's worker, if it is a replica
    /// whose writer can be waited on (see [`ReplicaFeed::worker_waiter`]).
    pub fn feed_waiter(&self) -> Option<Box<dyn FeedWaiter>> {
        self.feed.as_ref().and_then(|f| f.worker_waiter())
    }

    /// Lets this store's subscribers (a replica's) wait for its writer themselves, from
    /// the next subscription on (see [`ReplicaFeed`]).
    pub fn set_feed(&mut self, feed: Arc<dyn ReplicaFeed>) {
        self.feed = Some(feed);
    }

    /// Subscribes `fan_in` to every structure that enters the stream from now on,
    /// tagged with `tag`: a unit's worker reads all its inputs from one channel, in the
    /// order they were added across inputs.
    pub fn subscribe_tagged(&mut self, fan_in: &FanIn<Sample>, tag: usize) -> SubscriptionId {
        self.subscribers.subscribe_tagged(fan_in, tag)
    }

    /// Ends a subscription; false if it was not a subscription of this store.
    pub fn unsubscribe(&mut self, id: SubscriptionId) -> bool {
        self.subscribers.unsubscribe(id)
    }

    /// Subscribes to this trajectory's policy violations.
    pub fn subscribe_violations(&mut self, capacity: usize) -> Subscription<PolicyViolation> {
        self.violation_subscribers.subscribe(capacity, std::iter::empty())
    }

    /// Ends a violation subscription.
    pub fn unsubscribe_violations(&mut self, id: SubscriptionId) -> bool {
        self.violation_subscribers.unsubscribe(id)
    }

    /// Takes over from `old` when a name is re-pointed to this store (E5): every
    /// subscriber (stream and violations) moves here and sees this stream from now on,
    /// and samples `old` held for reordering are offered here, under this policy, so
    /// none is lost uncounted.
    pub fn adopt(&mut self, old: &mut TrajectoryStore) {
        self.subscribers.adopt(&mut old.subscribers);
        self.violation_subscribers.adopt(&mut old.violation_subscribers);
        if self.tap.is_none() {
            self.tap = old.tap.take();
        }
        let mut held: Vec<Held> = old.held.drain().map(|Reverse(h)| h).collect();
        held.sort();
        for h in held {
            // Outcomes are counted in this store's stats.
            let _ = self.offer_with(h.es, h.lineage, false);
        }
    }

    /// Makes this store (a replica of a trajectory written elsewhere) send what is added
    /// to it to `forwarder` after the type check, instead of admitting it: the writer's
    /// gate decides and the structure comes back through replication.
    pub fn forward_adds(&mut self, forwarder: Arc<dyn AddForwarder>) {
        self.forward = Some(forwarder);
    }

    /// Makes resets asked through handles go to `forwarder` (see [`ResetForwarder`]),
    /// which resets this store itself where this process writes it.
    pub fn forward_resets(&mut self, forwarder: Arc<dyn ResetForwarder>) {
        self.reset_forwarder = Some(forwarder);
    }

    /// Where resets through handles go, if this trajectory lives in other processes
    /// too.
    pub fn reset_forwarder(&self) -> Option<Arc<dyn ResetForwarder>> {
        self.reset_forwarder.clone()
    }

    /// Makes this replica the writer's store: adds are admitted here, through this
    /// store's own gate, from now on; none are forwarded. The history it holds stays.
    /// What a transport does when this process takes over a trajectory whose writer
    /// is gone ([`AddForwarder::take_over`]).
    pub fn adopt_adds(&mut self) {
        self.forward = None;
        self.adopted = true;
        // Its subscribers are fed by its own adds now, not by a writer elsewhere.
        self.feed = None;
    }

    /// True if adds may be made through this store: it forwards them to a writer
    /// elsewhere, or it was adopted as the writer's ([`Self::adopt_adds`]).
    pub fn accepts_adds(&self) -> bool {
        self.forward.is_some() || self.adopted
    }

    /// The forwarder of adds, if they go to a writer elsewhere.
    pub fn add_forwarder(&self) -> Option<Arc<dyn AddForwarder>> {
        self.forward.clone()
    }

    /// True if adds are forwarded to a writer elsewhere.
    pub fn forwards_adds(&self) -> bool {
        self.forward.is_some()
    }

    /// A snapshot of the statistics.
    pub fn stats(&self) -> TrajectoryStats {
        self.stats.snapshot(self.history.len(), self.held.len(), self.subscribers.len())
    }

    fn offer(&mut self, es: SharedStructure, blocking: bool) -> Result<AddOutcome, AddError> {
        self.offer_with(es, None, blocking)
    }

    fn offer_with(
        &mut self,
        es: SharedStructure,
        lineage: Option<Arc<Lineage>>,
        blocking: bool,
    ) -> Result<AddOutcome, AddError> {
        let now = self.clock.now();
        self.release_due_at(now);
        if let Err(source) = self.checker.check_structure(&es) {
            self.stats.record_dropped(DropCause::InvalidType);
            self.remember_drop(now, DropCause::InvalidType, es.valid_time(), source.to_string());
            tracing::debug!(trajectory = %self.name, error = %source, "structure refused");
            return Err(AddError::InvalidType { trajectory: self.name.clone(), source });
        }
        if let Some(f) = &self.forward {
            return f.forward(es, blocking);
        }
        if let Some((constraint, detail)) = self.arrival_violation(&es, now) {
            return self.violated(&es, now, constraint, detail, blocking);
        }
        if let (true, DelayConstraint::Max(d)) = (self.policy.holds_samples(), self.policy.delay) {
            let release_at = es.valid_time().saturating_add(d);
            if release_at > now {
                let seq = self.next_seq;
                self.next_seq += 1;
                self.held.push(Reverse(Held { es, lineage, seq, release_at }));
                return Ok(AddOutcome::Held { release_at });
            }
        }
        self.enter(es, lineage, now, blocking)
    }

    fn release_due_at(&mut self, now: Time) -> usize {
        let mut released = 0;
        while self.held.peek().is_some_and(|Reverse(h)| h.release_at <= now) {
            let Some(Reverse(h)) = self.held.pop() else { break };
            if let Ok(AddOutcome::Added) = self.enter(h.es, h.lineage, now, false) {
                released += 1;
            }
        }
        released
    }

    fn arrival_violation(&self, es: &SharedStructure, now: Time) -> Option<(Constraint, String)> {
        let vt = es.valid_time();
        if let Some((from, to)) = self.window {
            if vt < from {
                return Some((
                    Constraint::Duration,
                    format!("valid time {vt} is before the start {from}"),
                ));
            }
            if let Some(to) = to.filter(|to| vt > *to) {
                return Some((
                    Constraint::Duration,
                    format!("valid time {vt} is after the end {to}"),
                ));
            }
        }
        if let DelayConstraint::Max(d) = self.policy.delay {
            let delay = now.saturating_sub(vt);
            if delay > d {
                return Some((Constraint::Delay, format!("delay {delay} exceeds the maximum {d}")));
            }
        }
        if let Some(f) = &self.filter {
            if !f.matches_structure(es) {
                return Some((Constraint::Filter, format!("`{}` is false", f.source())));
            }
        }
        None
    }

    fn sequence_violation(&self, es: &SharedStructure) -> Option<(Constraint, String)> {
        let vt = es.valid_time();
        if let Some(last) = &self.last {
            let lvt = last.valid_time();
            match self.policy.order {
                OrderConstraint::Monotone if vt < lvt => {
                    return Some((
                        Constraint::Order,
                        format!("valid time {vt} is before the previous {lvt}"),
                    ));
                }
                OrderConstraint::StrictMonotone if vt <= lvt => {
                    return Some((
                        Constraint::Order,
                        format!("valid time {vt} is not after the previous {lvt}"),
                    ));
                }
                _ => {}
            }
            let same_value = || {
                es.ptr_eq(last)
                    || (es.name() == last.name()
                        && es.attribute_count() == last.attribute_count()
                        && es.attributes().zip(last.attributes()).all(|(a, b)| a == b))
            };
            match self.policy.change {
                ChangeConstraint::AnyChange if same_value() => {
                    return Some((Constraint::Change, "value equals the previous sample's".into()));
                }
                ChangeConstraint::AnyUpdate
                    if same_value() && vt == lvt && es.create_time() == last.create_time() =>
                {
                    return Some((Constraint::Change, "identical to the previous sample".into()));
                }
                ChangeConstraint::SampleEvery(p) if vt.saturating_sub(lvt) < p => {
                    return Some((
                        Constraint::Change,
                        format!(
                            "valid time {vt} is {} after the previous, period {p}",
                            vt.saturating_sub(lvt)
                        ),
                    ));
                }
                _ => {}
            }
        }
        if let (CacheConstraint::Duration(t), Some(newest)) =
            (self.policy.cache, self.history.max_valid_time())
        {
            if newest.saturating_sub(vt) >= t {
                return Some((
                    Constraint::Cache,
                    format!("valid time {vt} is outside the cache window ({t} before {newest})"),
                ));
            }
        }
        None
    }

    fn enter(
        &mut self,
        es: SharedStructure,
        lineage: Option<Arc<Lineage>>,
        now: Time,
        blocking: bool,
    ) -> Result<AddOutcome, AddError> {
        if let Some((constraint, detail)) = self.sequence_violation(&es) {
            return self.violated(&es, now, constraint, detail, blocking);
        }
        if let (ChangeConstraint::SampleEvery(p), Some(last)) = (self.policy.change, &self.last) {
            let skipped = es.valid_time().saturating_sub(last.valid_time()) / p - 1;
            if skipped > 0 {
                self.stats.record_missed_sample_points(skipped as u64);
            }
        }
        self.admit(es, lineage, now);
        crate::probe::mark(crate::probe::Step::Stored);
        crate::probe::settle(now);
        Ok(AddOutcome::Added)
    }

    /// Stores a structure that passed every check, added at `add_time`: evicts as the
    /// cache says and tells subscribers and the tap.
    fn admit(&mut self, es: SharedStructure, lineage: Option<Arc<Lineage>>, add_time: Time) {
        let now = add_time;
        // The tap first: mirrors publish before this process delivers, and may hand
        // back the structure to keep instead (see `StoreTap::entering`).
        let es = match &mut self.tap {
            Some((_, tap)) => {
                crate::probe::mark(crate::probe::Step::Gate);
                let entering = Sample::new(es, now, now).with_lineage(lineage.clone());
                let kept = tap.entering(&entering).unwrap_or(entering.structure);
                self.stats.record_dropped_n(DropCause::Unpublished, tap.take_unpublished());
                kept
            }
            None => es,
        };
        let seq = self.next_seq;
        self.next_seq += 1;
        self.stats.record_added(now, es.valid_time());
        self.last = Some(es.clone());
        self.history.push(Entry {
            vt: es.valid_time(),
            es: es.clone(),
            add_time: now,
            seq,
            lineage: lineage.clone(),
        });
        let evicted = match self.policy.cache {
            CacheConstraint::All | CacheConstraint::Elements(0) => 0,
            CacheConstraint::Elements(n) => {
                let mut k = 0;
                while self.history.len() > n && self.history.pop_oldest().is_some() {
                    k += 1;
                }
                k
            }
            CacheConstraint::Duration(t) => match self.history.max_valid_time() {
                Some(newest) => {
                    self.history.remove_older_than(newest.saturating_sub(t).saturating_add(1))
                }
                None => 0,
            },
        };
        self.stats.record_evicted(evicted);
        let sample = Sample::new(es, now, now).with_lineage(lineage);
        let overflow = self.subscribers.publish(&sample);
        self.stats.record_overflow(overflow);
    }

    /// Enters a structure that another store's gate already admitted — this store is a
    /// replica of a trajectory written in another process. No type check and no
    /// constraint but the cache apply (the writer applied them), and the writer's add
    /// time is kept, so queries, subscribers and stats agree with the writer's, and so
    /// is the lineage the writer stored with it.
    pub fn replicate(
        &mut self,
        es: SharedStructure,
        add_time: Time,
        lineage: Option<Arc<Lineage>>,
    ) {
        self.admit(es, lineage, add_time);
        crate::probe::mark(crate::probe::Step::Replicated);
        crate::probe::settle(add_time);
    }

    /// Counts `n` messages a bridge to another middleware lost on their way into or
    /// out of this trajectory ([`DropCause::Bridge`]).
    pub fn count_bridge_loss(&mut self, loss: BridgeLoss, n: u64) {
        self.stats.record_dropped_n(DropCause::Bridge(loss), n);
    }

    /// Counts `n` structures the writer of this replica admitted that never reached
    /// it ([`DropCause::Lost`]).
    pub fn replicate_loss(&mut self, n: u64) {
        self.stats.record_dropped_n(DropCause::Lost, n);
    }

    /// Counts bytes that arrived on a replicated trajectory's service and were not a
    /// valid sample of it ([`DropCause::Rejected`]).
    pub fn replicate_rejection(&mut self, why: Rejection) {
        self.stats.record_dropped(DropCause::Rejected(why));
    }

    /// Reports a violation the writer of a replicated trajectory found: counted and
    /// passed to this store's violation subscribers, as if found here.
    pub fn replicate_violation(&mut self, v: PolicyViolation) {
        self.stats.record_dropped(DropCause::Violation(v.constraint));
        let overflow = self.violation_subscribers.publish(&v);
        self.stats.record_overflow(overflow);
    }

    /// Tells `tap` everything that happens to the stream from now on — entries,
    /// violations, resets — in order, inline (see [`StoreTap`]). One tap per store; a
    /// new tap replaces the old one. This is how a stream is mirrored elsewhere:
    /// subscribers see entries only, and a reset seen on a second channel could not be
    /// ordered against them. Returns the stored samples at this moment, oldest first,
    /// so that the mirror starts from the same content with nothing in between.
    pub fn set_tap(&mut self, tap: Box<dyn StoreTap>) -> (TapId, Vec<Sample>) {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let id = TapId(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed));
        self.tap = Some((id, tap));
        (id, self.samples())
    }

    /// Stops telling the tap `id`, if it is still this store's (a re-pointed name's
    /// new store adopts the old one's tap; see [`TrajectoryStore::adopt`]).
    pub fn clear_tap(&mut self, id: TapId) {
        if self.tap.as_ref().is_some_and(|(current, _)| *current == id) {
            self.tap = None;
        }
    }

    fn tell_tap(&mut self, event: StoreEvent) {
        if let Some((_, tap)) = &mut self.tap {
            tap.observe(&event);
        }
    }

    fn violated(
        &mut self,
        es: &SharedStructure,
        now: Time,
        constraint: Constraint,
        detail: String,
        blocking: bool,
    ) -> Result<AddOutcome, AddError> {
        self.stats.record_dropped(DropCause::Violation(constraint));
        self.remember_drop(now, DropCause::Violation(constraint), es.valid_time(), detail.clone());
        let v = PolicyViolation {
            trajectory: self.name.clone(),
            constraint,
            valid_time: es.valid_time(),
            create_time: es.create_time(),
            add_time: now,
            detail,
        };
        tracing::debug!(trajectory = %self.name, %constraint, detail = %v.detail, "sample dropped");
        let overflow = self.violation_subscribers.publish(&v);
        self.stats.record_overflow(overflow);
        if self.tap.is_some() {
            self.tell_tap(StoreEvent::Violation(v.clone()));
        }
        if blocking {
            Err(AddError::PolicyViolation(Box::new(v)))
        } else {
            Ok(AddOutcome::Dropped(v))
        }
    }
}

#[cfg(test)]
mod tests;
