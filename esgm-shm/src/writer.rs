//! The one writer of a trajectory in shared memory: runs the trajectory's policy
//! (type check, C1–C6, hold-and-reorder) and publishes exactly the stream that passes.
//!
//! # The gate
//! The writer owns an in-process [`TrajectoryStore`] with the trajectory's policy and
//! offers it every structure first; whatever enters the store's stream — at once, or
//! later when a held structure's delay window has passed — is published, stamped with
//! the store's add time; whatever the policy drops is published on the violations
//! service ([`crate::violations`]). So outcomes and errors are the in-process store's
//! ([`AddOutcome`], [`AddError`]), and every reader sees the same, already valid stream.
//!
//! The store is only a gate: the history lives in the readers
//! ([`crate::ShmTrajectoryReader`]), so the gate keeps one sample, never a window of
//! images. One constraint needs more than the previous sample: a time cache
//! (`CacheConstraint::Duration(t)`) drops a structure valid `t` or more before the
//! newest valid time. Under a monotone order that can never happen (the newest is the
//! previous sample, and anything older already breaks the order), so only with
//! `OrderConstraint::Any` does the gate keep the policy's time cache to know the newest
//! valid time; the structures in that window stay in the writer's heap.
//!
//! # Held structures
//! With a monotone order, a maximum delay and `reorder` on, structures are held until
//! valid time + delay. They are released by the next add, or by
//! [`ShmTrajectoryWriter::release_due`], which the writer's owner calls at
//! [`ShmTrajectoryWriter::next_release_time`].
//!
//! ```no_run
//! use std::time::Duration;
//! use esgm_core::{EntityStructure, FluentStreamPolicy, TypeChecker, TypeRegistry};
//! use esgm_shm::{ShmTrajectoryReader, ShmTrajectoryWriter};
//! use esgm_shm::ShmService;
//! use iceoryx2::prelude::NodeBuilder;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let registry = TypeRegistry::with_library();
//! let checker = TypeChecker::new(&registry, "RobotState")?;
//! // Monotone order, 50 ms delay with reordering, the last 100 kept.
//! let policy = FluentStreamPolicy::reasonable(50_000_000, 100)?;
//!
//! // In the producing process:
//! let node = NodeBuilder::new().create::<ShmService>()?;
//! let mut writer = ShmTrajectoryWriter::builder("robot_state", checker.clone())
//!     .domain("lab")
//!     .policy(policy.clone())
//!     .create(&node)?;
//! let state = EntityStructure::new("robot1", 0, 0).with("x", 1.0).with("y", 2.0);
//! writer.add(state.with("dir", 0.0))?; // held for the delay, then published in order
//! writer.release_due()?;
//!
//! // In any other process, with the same policy:
//! let node = NodeBuilder::new().create::<ShmService>()?;
//! let mut reader = ShmTrajectoryReader::builder("robot_state", checker)
//!     .domain("lab")
//!     .policy(policy)
//!     .create(&node)?;
//! if let Some(sample) = reader.next_sample(Duration::from_millis(100))? {
//!     let archived = sample.structure()?; // read in place, in shared memory
//!     println!("{} valid at {}", archived.name, sample.valid_time());
//! }
//! let latest = reader.get_latest()?; // a lookup in this process, no round trip
//! println!("latest valid at {}", latest.valid_time());
//! # Ok(())
//! # }
//! ```
//!
//! # Costs
//! A structure is type-checked and filtered on the writer's heap, then encoded once,
//! into the loaned shared memory; readers then use it in place. Images pass the gate
//! like any structure (one encode into the loan): the in-place image loans of
//! [`crate::ImageLoan`] bypass the gate and suit trajectories without a policy.

use crate::service::ShmService;
use std::cell::Cell;
use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::Duration;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::service::port_factory::PortFactory;

use esgm_core::{
    AddError, AddOutcome, AttributeList, CacheConstraint, Clock, EntityStructure,
    FluentStreamPolicy, OrderConstraint, PolicyError, PolicyViolation, Sample, SharedClock,
    SubscribeOptions, Subscription, SystemClock, Time, TrajectoryStats, TrajectoryStore,
    TypeChecker,
};

use crate::history::{DEFAULT_MAX_HISTORY, history_bound, history_qos};
use crate::publisher::{
    DEFAULT_INITIAL_MAX_LEN, DEFAULT_LOSSLESS_TIMEOUT, PublishError, SampleSizing,
    TrajectoryPublisher,
};
use crate::qos::TrajectoryQos;
use crate::service::{OpenError, ShmNode, WakeService, open_data_service, open_wake_service};
use crate::service_name::{DEFAULT_DOMAIN, TrajectoryServiceNames};
use crate::violations::ViolationPublisher;

/// Initial room in the gate's internal subscriptions; grown with the held structures.
const INITIAL_GATE_CAPACITY: usize = 16;

/// A writer could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriterCreateError {
    /// The policy is illegal, or its filter does not fit the type; fix the named field.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// A service or port could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// Another process (or writer) already publishes on the trajectory. A trajectory has
    /// exactly one writer, which gates its stream; stop the other one, or read instead.
    #[error("trajectory `{trajectory}` already has a writer ({publishers} publishers)")]
    AlreadyWritten {
        /// The trajectory.
        trajectory: String,
        /// Publishers connected, this writer's included.
        publishers: usize,
    },
}

/// A structure could not be added or published.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The in-process store's error, unchanged: the structure does not fit the type, or
    /// (blocking forms) broke a constraint. Nothing was published but the violation.
    #[error(transparent)]
    Add(#[from] AddError),
    /// The structure entered the stream (the policy counts it as the previous sample)
    /// but did not reach every reader: with [`PublishError::NotDelivered`] it reached
    /// all but the readers whose buffers stayed full (they count it as lost), otherwise
    /// none. Do not add it again; fix the cause (e.g. readers holding every sample).
    #[error("entered the stream of `{trajectory}` but was not published to every reader: {source}")]
    Publish {
        /// The trajectory.
        trajectory: String,
        /// Why publishing failed.
        source: PublishError,
    },
}

/// What a writer has done.
#[derive(Debug, Clone, PartialEq)]
pub struct WriterStats {
    /// The stream as the gate counts it: added, dropped per cause, held, rate, delays.
    /// `stored` and `evicted` refer to the samples iceoryx2 keeps for late readers
    /// (the last `history_size` published), `subscribers` to the connected readers;
    /// each reader counts its own cache ([`crate::ReaderStats`]).
    pub stream: TrajectoryStats,
    /// Structures published.
    pub published: u64,
    /// Structures that entered the stream but could not be published (each failure is
    /// logged once per kind of cause; see [`WriteError::Publish`]).
    pub publish_failures: u64,
    /// Violations published on the violations service.
    pub violations_published: u64,
    /// Violations that could not be published (counted in `stream` all the same).
    pub violation_publish_failures: u64,
}

/// Builds a [`ShmTrajectoryWriter`]; every setting but the name and type has a default.
#[derive(Debug)]
pub struct ShmTrajectoryWriterBuilder {
    name: String,
    checker: TypeChecker,
    domain: String,
    policy: FluentStreamPolicy,
    clock: Option<SharedClock>,
    qos: TrajectoryQos,
    max_history: usize,
    max_len: usize,
    sizing: SampleSizing,
    lossless_timeout: Duration,
}

impl ShmTrajectoryWriterBuilder {
    /// The domain (namespace) of the trajectory; default [`DEFAULT_DOMAIN`].
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = domain.into();
        self
    }

    /// The trajectory's policy; default unconstrained. Readers must be built with the
    /// same cache constraint (it sizes the shared history).
    pub fn policy(mut self, policy: FluentStreamPolicy) -> Self {
        self.policy = policy;
        self
    }

    /// The clock the policy's timing rules and the add times read; default the system
    /// clock.
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// Service settings other than the history ones, which follow from the policy
    /// ([`history_qos`]); default [`TrajectoryQos::default`]. Give readers the same.
    pub fn qos(mut self, qos: TrajectoryQos) -> Self {
        self.qos = qos;
        self
    }

    /// The history kept for `All` and `Duration` caches; default
    /// [`DEFAULT_MAX_HISTORY`]. Give readers the same.
    pub fn max_history(mut self, n: usize) -> Self {
        self.max_history = n;
        self
    }

    /// Initial maximum sample size in bytes; see
    /// [`crate::publisher::TrajectoryPublisherBuilder::max_len`].
    pub fn max_len(mut self, bytes: usize) -> Self {
        self.max_len = bytes;
        self
    }

    /// Whether samples may outgrow [`Self::max_len`]; default [`SampleSizing::Grow`].
    pub fn sizing(mut self, sizing: SampleSizing) -> Self {
        self.sizing = sizing;
        self
    }

    /// How long a lossless publish waits for a full reader; see
    /// [`crate::publisher::TrajectoryPublisherBuilder::lossless_timeout`].
    pub fn lossless_timeout(mut self, timeout: Duration) -> Self {
        self.lossless_timeout = timeout;
        self
    }

    /// Checks the policy, opens the trajectory's data, wake-up and violations services
    /// on `node`, and creates the writer. Fails if the trajectory already has a writer.
    pub fn create(self, node: &ShmNode) -> Result<ShmTrajectoryWriter, WriterCreateError> {
        self.policy.validate()?;
        let clock = self.clock.unwrap_or_else(SystemClock::shared);
        let mut gate = TrajectoryStore::builder(self.name.clone(), self.checker.clone())
            .policy(gate_policy(&self.policy))
            .clock(Arc::clone(&clock))
            .create()?;
        let history_size = history_bound(self.policy.cache, self.max_history);
        let qos = history_qos(history_size, self.qos);
        let add_time = Arc::new(AddTimeClock { inner: clock, stamp: AtomicI64::new(NO_STAMP) });
        let publisher = TrajectoryPublisher::builder(&self.name, self.checker.type_name())
            .domain(&self.domain)
            .qos(qos)
            .clock(Arc::clone(&add_time) as SharedClock)
            .max_len(self.max_len)
            .sizing(self.sizing)
            .lossless_timeout(self.lossless_timeout)
            .create(node)?;
        let names =
            TrajectoryServiceNames::new(&self.domain, &self.name).map_err(OpenError::from)?;
        let publishers =
            open_data_service(node, &names, &qos)?.dynamic_config().number_of_publishers();
        if publishers > 1 {
            return Err(WriterCreateError::AlreadyWritten { trajectory: self.name, publishers });
        }
        let wake_service = open_wake_service(node, &names)?;
        let wake = wake_service.notifier_builder().create().map_err(OpenError::Notifier)?;
        let violations = ViolationPublisher::create(node, &self.domain, &self.name)?;
        let capacity = INITIAL_GATE_CAPACITY;
        let entered = gate.subscribe(SubscribeOptions::default().capacity(capacity));
        let dropped = gate.subscribe_violations(capacity);
        Ok(ShmTrajectoryWriter {
            gate,
            entered,
            dropped,
            capacity,
            publisher,
            violations,
            wake,
            wake_service,
            readers_seen: Cell::new((0, 0)),
            add_time,
            policy: self.policy,
            domain: self.domain,
            history_size,
            counts: Counts::default(),
        })
    }
}

/// The gate's policy: the trajectory's, with a one-sample cache unless a time cache can
/// drop anything (see the module docs).
fn gate_policy(policy: &FluentStreamPolicy) -> FluentStreamPolicy {
    let cache = match policy.cache {
        CacheConstraint::Duration(t) if policy.order == OrderConstraint::Any => {
            CacheConstraint::Duration(t)
        }
        _ => CacheConstraint::Elements(1),
    };
    FluentStreamPolicy { cache, ..policy.clone() }
}

const NO_STAMP: Time = Time::MIN;

/// The publisher's clock: the gate's add time of the structure being published, so
/// that the header's add time is the time the structure entered the stream (a held
/// structure enters when it is released, not when the publisher gets to it).
#[derive(Debug)]
struct AddTimeClock {
    inner: SharedClock,
    stamp: AtomicI64,
}

impl Clock for AddTimeClock {
    fn now(&self) -> Time {
        match self.stamp.load(Ordering::Relaxed) {
            NO_STAMP => self.inner.now(),
            t => t,
        }
    }

    fn sleep_until(&self, deadline: Time, max_wait: Duration) -> Time {
        self.inner.sleep_until(deadline, max_wait)
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    /// Structures offered to the gate.
    offered: u64,
    /// Structures that entered the gate's stream.
    entered: u64,
    /// Structures the policy dropped.
    violated: u64,
    /// Structures refused for their type.
    invalid: u64,
    published: u64,
    publish_failures: u64,
    violations_published: u64,
    violation_publish_failures: u64,
}

impl Counts {
    /// Structures held in the gate now: every offered one is accounted for.
    fn held(&self) -> u64 {
        self.offered.saturating_sub(self.entered + self.violated + self.invalid)
    }
}

/// Which publish failure of a batch a call reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Report {
    /// The last structure's: the one the call offered, if it entered.
    Last,
    /// The first failure.
    First,
}

/// The writing end of a trajectory whose history lives in its readers (see the module
/// docs). Single-threaded, like the iceoryx2 ports it holds: create it on the thread
/// that uses it.
#[derive(Debug)]
pub struct ShmTrajectoryWriter {
    gate: TrajectoryStore,
    entered: Subscription<Sample>,
    dropped: Subscription<PolicyViolation>,
    /// Capacity of both gate subscriptions.
    capacity: usize,
    publisher: TrajectoryPublisher,
    violations: ViolationPublisher,
    /// Wakes readers that received the history in [`Self::update_connections`].
    wake: Notifier<ShmService>,
    wake_service: WakeService,
    /// Readers and wake-up listeners at the last [`Self::update_connections`].
    readers_seen: Cell<(usize, usize)>,
    add_time: Arc<AddTimeClock>,
    policy: FluentStreamPolicy,
    domain: String,
    history_size: usize,
    counts: Counts,
}

impl ShmTrajectoryWriter {
    /// A builder for the writer of trajectory `name`, whose structures `checker` checks.
    pub fn builder(name: impl Into<String>, checker: TypeChecker) -> ShmTrajectoryWriterBuilder {
        ShmTrajectoryWriterBuilder {
            name: name.into(),
            checker,
            domain: DEFAULT_DOMAIN.to_owned(),
            policy: FluentStreamPolicy::default(),
            clock: None,
            qos: TrajectoryQos::default(),
            max_history: DEFAULT_MAX_HISTORY,
            max_len: DEFAULT_INITIAL_MAX_LEN,
            sizing: SampleSizing::default(),
            lossless_timeout: DEFAULT_LOSSLESS_TIMEOUT,
        }
    }

    /// The trajectory's name.
    pub fn name(&self) -> &str {
        self.gate.name()
    }

    /// The trajectory's domain.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// The registered name of the trajectory's type.
    pub fn type_name(&self) -> &str {
        self.gate.type_name()
    }

    /// The trajectory's policy, as given (the gate's own cache differs; see the
    /// module docs).
    pub fn policy(&self) -> &FluentStreamPolicy {
        &self.policy
    }

    /// Samples iceoryx2 keeps for late readers: the history bound of the policy.
    pub fn history_size(&self) -> usize {
        self.history_size
    }

    /// Readers (subscribers) connected now.
    pub fn subscriber_count(&self) -> usize {
        self.publisher.subscriber_count()
    }

    /// Hands the history to readers that connected since the last publish, and wakes
    /// them; call it periodically if the trajectory is written rarely (see
    /// [`crate::publisher`]).
    ///
    /// iceoryx2 delivers the history without a wake-up, so a new reader blocked in
    /// [`crate::ShmTrajectoryReader::next_sample`] would sleep until its timeout with
    /// the history in its queue. The writer therefore notifies when the number of
    /// readers or of their wake-up listeners changed since the last call (a reader's
    /// listener appears a moment after its port; a publish notifies anyway).
    pub fn update_connections(&self) -> Result<(), PublishError> {
        self.publisher.update_connections()?;
        let readers = self.publisher.subscriber_count();
        let listeners = self.wake_service.dynamic_config().number_of_listeners();
        let now = (readers, listeners);
        if now != self.readers_seen.replace(now) && readers > 0 {
            // A lost wake-up only delays the new reader until its timeout.
            if let Err(e) = self.wake.notify() {
                tracing::debug!(trajectory = %self.name(), error = ?e, "cannot wake new readers");
            }
        }
        Ok(())
    }

    /// Adds a structure; a constraint violation drops it, counts it and publishes it
    /// as a violation (`Ok(AddOutcome::Dropped)`).
    pub fn add(&mut self, es: EntityStructure) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.add(es))
    }

    /// Adds a structure; a constraint violation is also returned as
    /// [`AddError::PolicyViolation`].
    pub fn add_blocking(&mut self, es: EntityStructure) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.add_blocking(es))
    }

    /// Creates a structure valid at `valid_time`, created now, and adds it.
    pub fn create_at(
        &mut self,
        name: impl Into<String>,
        valid_time: Time,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.create_at(name, valid_time, attributes))
    }

    /// [`Self::create_at`], returning violations.
    pub fn create_at_blocking(
        &mut self,
        name: impl Into<String>,
        valid_time: Time,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.create_at_blocking(name, valid_time, attributes))
    }

    /// Creates a structure valid and created now, and adds it.
    pub fn create_at_now(
        &mut self,
        name: impl Into<String>,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.create_at_now(name, attributes))
    }

    /// [`Self::create_at_now`], returning violations.
    pub fn create_at_now_blocking(
        &mut self,
        name: impl Into<String>,
        attributes: impl Into<AttributeList>,
    ) -> Result<AddOutcome, WriteError> {
        self.offer(|gate| gate.create_at_now_blocking(name, attributes))
    }

    /// Releases and publishes held structures whose delay window has passed; returns
    /// how many entered the stream. A publish failure is returned after every due
    /// structure was tried (the first failure; all are counted).
    pub fn release_due(&mut self) -> Result<usize, WriteError> {
        let released = self.gate.release_due();
        match self.pump(Report::First) {
            Some(source) => Err(WriteError::Publish { trajectory: self.name().to_owned(), source }),
            None => Ok(released),
        }
    }

    /// When the next held structure is due, if any is held.
    pub fn next_release_time(&self) -> Option<Time> {
        self.gate.next_release_time()
    }

    /// A snapshot of the statistics.
    pub fn stats(&self) -> WriterStats {
        let mut stream = self.gate.stats();
        let history = self.history_size as u64;
        let c = &self.counts;
        stream.stored = usize::try_from(c.published.min(history)).unwrap_or(self.history_size);
        stream.evicted = c.published.saturating_sub(history);
        stream.subscribers = self.publisher.subscriber_count();
        // iceoryx2 does not tell a publisher about overwritten samples; readers count
        // their losses ([`crate::ReaderStats::lost`]).
        stream.subscriber_overflow = 0;
        WriterStats {
            stream,
            published: c.published,
            publish_failures: c.publish_failures,
            violations_published: c.violations_published,
            violation_publish_failures: c.violation_publish_failures,
        }
    }

    fn offer(
        &mut self,
        add: impl FnOnce(&mut TrajectoryStore) -> Result<AddOutcome, AddError>,
    ) -> Result<AddOutcome, WriteError> {
        self.ensure_capacity();
        self.counts.offered += 1;
        let outcome = add(&mut self.gate);
        if let Err(AddError::InvalidType { .. }) = &outcome {
            self.counts.invalid += 1;
        }
        // Held structures released by this call are published first, in stream order;
        // their failures are counted and logged (their own add returned `Held`).
        let failed = self.pump(Report::Last);
        match (outcome?, failed) {
            (AddOutcome::Added, Some(source)) => {
                Err(WriteError::Publish { trajectory: self.name().to_owned(), source })
            }
            (outcome, _) => Ok(outcome),
        }
    }

    /// Makes sure one call can release every held structure (plus the one offered)
    /// without overflowing the gate's subscriptions: swaps them for larger ones, between
    /// calls, when the held structures outgrow them.
    fn ensure_capacity(&mut self) {
        let needed = usize::try_from(self.counts.held()).unwrap_or(usize::MAX).saturating_add(2);
        if needed <= self.capacity {
            return;
        }
        let capacity = needed.next_power_of_two().max(self.capacity * 2);
        // Both subscriptions were drained by the last call; nothing is in flight.
        self.gate.unsubscribe(self.entered.id());
        self.gate.unsubscribe_violations(self.dropped.id());
        self.entered = self.gate.subscribe(SubscribeOptions::default().capacity(capacity));
        self.dropped = self.gate.subscribe_violations(capacity);
        self.capacity = capacity;
    }

    /// Publishes what entered the gate's stream since the last call, then its
    /// violations. Returns the failure `report` asks for, if there was one.
    fn pump(&mut self, report: Report) -> Option<PublishError> {
        let mut reported = None;
        while let Some(sample) = self.entered.try_recv() {
            self.counts.entered += 1;
            match self.publish(&sample) {
                Ok(()) if report == Report::Last => reported = None,
                Ok(()) => {}
                Err(e) if report == Report::Last || reported.is_none() => reported = Some(e),
                Err(_) => {}
            }
        }
        while let Some(v) = self.dropped.try_recv() {
            self.counts.violated += 1;
            match self.violations.publish(&v) {
                Ok(()) => self.counts.violations_published += 1,
                Err(e) => {
                    self.counts.violation_publish_failures += 1;
                    if self.counts.violation_publish_failures == 1 {
                        tracing::warn!(trajectory = %self.name(), error = %e,
                            "cannot publish a violation (later failures are only counted)");
                    }
                }
            }
        }
        if self.entered.overflowed() > 0 || self.dropped.overflowed() > 0 {
            // `ensure_capacity` rules this out; if it ever happens, say so loudly.
            tracing::error!(trajectory = %self.name(),
                entered = self.entered.overflowed(), dropped = self.dropped.overflowed(),
                "the gate released more structures than its subscriptions hold");
        }
        reported
    }

    fn publish(&mut self, sample: &Sample) -> Result<(), PublishError> {
        self.add_time.stamp.store(sample.add_time, Ordering::Relaxed);
        let published = self.publisher.publish(&sample.structure);
        self.add_time.stamp.store(NO_STAMP, Ordering::Relaxed);
        match published {
            Ok(_) => {
                self.counts.published += 1;
                Ok(())
            }
            Err(e) => {
                self.counts.publish_failures += 1;
                if self.counts.publish_failures == 1 {
                    tracing::warn!(trajectory = %self.name(), error = %e,
                        "a structure entered the stream but was not published \
                         (later failures are only counted)");
                }
                Err(e)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::{ChangeConstraint, DelayConstraint};

    #[test]
    fn the_gate_keeps_a_time_cache_only_where_it_can_drop() {
        let any = FluentStreamPolicy::default().cache(CacheConstraint::Duration(50));
        assert_eq!(gate_policy(&any).cache, CacheConstraint::Duration(50));
        let monotone = any.clone().order(OrderConstraint::Monotone);
        assert_eq!(gate_policy(&monotone).cache, CacheConstraint::Elements(1));
        let counted = FluentStreamPolicy::default()
            .cache(CacheConstraint::Elements(100))
            .change(ChangeConstraint::AnyChange)
            .delay(DelayConstraint::Max(5));
        let gated = gate_policy(&counted);
        assert_eq!(gated.cache, CacheConstraint::Elements(1));
        assert_eq!(FluentStreamPolicy { cache: counted.cache, ..gated }, counted);
    }

    #[test]
    fn the_add_time_clock_reports_the_stamp_while_set() {
        let sim = esgm_core::SimClock::shared(100);
        let c = AddTimeClock { inner: sim.clone(), stamp: AtomicI64::new(NO_STAMP) };
        assert_eq!(Clock::now(&c), 100);
        c.stamp.store(42, Ordering::Relaxed);
        assert_eq!(Clock::now(&c), 42);
    }
}
