//! A reader of a trajectory that keeps its history: samples stay in shared memory,
//! where the writer put them, and queries (T1, T2) are answered here, without asking
//! another process.
//!
//! The reader holds the iceoryx2 samples themselves ([`ReceivedSample`]) up to the
//! cache bound ([`crate::history`]), evicting as the policy's cache constraint says,
//! and looks them up by the times in their headers: a query touches the payload only
//! of the samples it answers with — and not even those if the caller reads the
//! archived structure in place ([`CachedSample::structure`]). An owned answer
//! ([`CachedSample::to_sample`]) decodes, i.e. copies, one structure.
//!
//! The answers equal those of an in-process [`esgm_core::TrajectoryStore`] with the
//! same policy fed the same structures, error messages included, with two exceptions:
//! an `All` or `Duration` cache holds at most the configured maximum, and a reader that
//! connected late starts from the history the writer kept.
//!
//! Every sample is validated when it is received (bytecheck, header against archive);
//! a malformed one is counted and never stored.
//!
//! iceoryx2 ports are bound to their thread, so a reader is single-threaded; for
//! queries from many threads host it on one ([`crate::HostedTrajectoryReader`]).

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::EntityStructure;
use esgm_core::approximation::interpolate;
use esgm_core::codec::{ArchivedEntityStructure, CodecError};
use esgm_core::{
    CacheConstraint, FluentStreamPolicy, PolicyError, QueryError, Sample, SharedClock, SystemClock,
    Time, TypeChecker, ValueApproximation,
};

use crate::history::{DEFAULT_MAX_HISTORY, Entry, History, history_bound, history_qos};
use crate::payload::SampleHeader;
use crate::qos::TrajectoryQos;
use crate::received::ReceivedSample;
use crate::sequence_gaps::SequenceGaps;
use crate::service::{OpenError, ShmNode};
use crate::service_name::DEFAULT_DOMAIN;
use crate::subscriber::{ReceiveError, SubscriberStats, TrajectorySubscriber};
use crate::wait::{WaitStrategy, deadline_after};

/// A reader could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReaderCreateError {
    /// The policy is illegal; fix the named field.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// A service or port could not be opened (e.g. the writer created the service with
    /// other settings: build both ends from the same policy, maximum and base qos).
    #[error(transparent)]
    Open(#[from] OpenError),
}

/// A query on the history has no answer, or its answer could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HistoryError {
    /// The in-process store's answer: no value available, or a default that does not
    /// fit the type.
    #[error(transparent)]
    Query(#[from] QueryError),
    /// A cached sample could not be decoded. It was validated when received, so this
    /// is a bug in esgm; report it.
    #[error("cannot decode a cached sample of `{trajectory}`: {source}")]
    Decode {
        /// The trajectory.
        trajectory: String,
        /// The codec's reason.
        source: CodecError,
    },
    /// The thread hosting the reader has stopped (it could not create its node or
    /// reader, or it panicked); create a new hosted reader.
    #[error("the thread hosting the reader of `{trajectory}` has stopped")]
    ReaderStopped {
        /// The trajectory.
        trajectory: String,
    },
    /// A job running on the reader's own thread asked that thread to run another job
    /// and wait for it: it would wait for itself forever. Use the `&mut` reader the job
    /// was given instead.
    #[error("a job of the reader of `{trajectory}` called back into the same reader")]
    Reentrant {
        /// The trajectory.
        trajectory: String,
    },
    /// The reader's thread did not answer in time (a job took too long).
    #[error("the reader of `{trajectory}` did not answer within {timeout:?}")]
    Timeout {
        /// The trajectory.
        trajectory: String,
        /// How long the caller waited.
        timeout: std::time::Duration,
    },
}

/// What a reader has seen and kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReaderStats {
    /// Samples taken from shared memory, and those rejected (malformed, wrong type):
    /// rejected samples are never stored.
    pub subscriber: SubscriberStats,
    /// Samples stored in the history.
    pub added: u64,
    /// Samples stored now.
    pub stored: usize,
    /// Samples the cache constraint evicted.
    pub evicted: u64,
    /// Samples evicted beyond the bound: an `All` or `Duration` cache over its
    /// maximum, or room made when iceoryx2 refused another held sample.
    pub evicted_over_bound: u64,
    /// Samples the writer sent that never reached this reader (overwritten in its
    /// queue while it was not reading): gaps in the header's sequence numbers.
    pub lost: u64,
    /// Resets (T5) the writer announced; each emptied the history.
    pub resets: u64,
}

/// Builds a [`ShmTrajectoryReader`]; every setting but the name and type has a default.
#[derive(Debug, Clone)]
pub struct ShmTrajectoryReaderBuilder {
    name: String,
    checker: TypeChecker,
    domain: String,
    policy: FluentStreamPolicy,
    clock: Option<SharedClock>,
    qos: TrajectoryQos,
    max_history: usize,
    wait: WaitStrategy,
}

impl ShmTrajectoryReaderBuilder {
    /// The domain (namespace) of the trajectory; default [`DEFAULT_DOMAIN`].
    pub fn domain(mut self, domain: impl Into<String>) -> Self {
        self.domain = domain.into();
        self
    }

    /// The trajectory's policy (its cache constraint decides what is kept); default
    /// unconstrained. Use the writer's.
    pub fn policy(mut self, policy: FluentStreamPolicy) -> Self {
        self.policy = policy;
        self
    }

    /// The clock that stamps query times (and default and interpolated values);
    /// default the system clock.
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// Service settings other than the history ones; default
    /// [`TrajectoryQos::default`]. Use the writer's.
    pub fn qos(mut self, qos: TrajectoryQos) -> Self {
        self.qos = qos;
        self
    }

    /// The history kept for `All` and `Duration` caches; default
    /// [`DEFAULT_MAX_HISTORY`]. Use the writer's.
    pub fn max_history(mut self, n: usize) -> Self {
        self.max_history = n;
        self
    }

    /// How [`ShmTrajectoryReader::next_sample`] waits; default
    /// [`WaitStrategy::default`].
    pub fn wait_strategy(mut self, wait: WaitStrategy) -> Self {
        self.wait = wait;
        self
    }

    /// The trajectory's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Opens (or creates) the trajectory's services and subscribes on `node`; the
    /// writer's history arrives with its next publish or
    /// [`crate::ShmTrajectoryWriter::update_connections`].
    pub fn create(self, node: &ShmNode) -> Result<ShmTrajectoryReader, ReaderCreateError> {
        self.policy.validate()?;
        let bound = history_bound(self.policy.cache, self.max_history);
        let subscriber = TrajectorySubscriber::builder(&self.name, self.checker.type_name())
            .domain(&self.domain)
            .qos(history_qos(bound, self.qos))
            .wait_strategy(self.wait)
            .create(node)?;
        Ok(ShmTrajectoryReader {
            name: self.name,
            checker: self.checker,
            cache: self.policy.cache,
            bound,
            clock: self.clock.unwrap_or_else(SystemClock::shared),
            subscriber,
            history: History::default(),
            counts: Counts::default(),
            gaps: SequenceGaps::default(),
        })
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    added: u64,
    evicted: u64,
    evicted_over_bound: u64,
    lost: u64,
    resets: u64,
}

/// A sample in a reader's history, as a query answers it: the sample in shared memory
/// and the time of the query.
#[derive(Debug, Clone, Copy)]
pub struct CachedSample<'a> {
    sample: &'a ReceivedSample,
    query_time: Time,
}

impl<'a> CachedSample<'a> {
    /// The header: times, sequence, type id.
    pub fn header(&self) -> &'a SampleHeader {
        self.sample.header()
    }

    /// The structure's valid time.
    pub fn valid_time(&self) -> Time {
        self.header().valid_time
    }

    /// The structure's create time.
    pub fn create_time(&self) -> Time {
        self.header().create_time
    }

    /// When the structure entered the trajectory's stream (the writer's gate).
    pub fn add_time(&self) -> Time {
        self.header().add_time
    }

    /// When the query this answers was asked.
    pub fn query_time(&self) -> Time {
        self.query_time
    }

    /// The archived structure, read in place in shared memory (validated on receipt,
    /// so this costs nothing).
    pub fn structure(&self) -> Result<&'a ArchivedEntityStructure, CodecError> {
        self.sample.structure()
    }

    /// The iceoryx2 sample itself.
    pub fn received(&self) -> &'a ReceivedSample {
        self.sample
    }

    /// The answer as the in-process store gives it: an owned structure (decoded, so
    /// copied — images included) with its add and query times.
    pub fn to_sample(&self) -> Result<Sample, CodecError> {
        Ok(Sample {
            structure: Arc::new(self.sample.to_owned()?),
            add_time: self.add_time(),
            query_time: self.query_time,
        })
    }
}

/// The answer of [`ShmTrajectoryReader::get_at_approximating`]: a stored sample, or a
/// value made for the query (interpolated, or the default).
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum Approximated<'a> {
    /// A sample in the history, still in shared memory.
    Stored(CachedSample<'a>),
    /// A structure valid at the queried time, created at the query time.
    Computed(Sample),
}

impl Approximated<'_> {
    /// The answer's valid time.
    pub fn valid_time(&self) -> Time {
        match self {
            Approximated::Stored(s) => s.valid_time(),
            Approximated::Computed(s) => s.valid_time,
        }
    }

    /// The answer as the in-process store gives it (decoding a stored sample).
    pub fn to_sample(&self) -> Result<Sample, CodecError> {
        match self {
            Approximated::Stored(s) => s.to_sample(),
            Approximated::Computed(s) => Ok(s.clone()),
        }
    }
}

fn cached(e: &Entry<ReceivedSample>, query_time: Time) -> CachedSample<'_> {
    CachedSample { sample: &e.item, query_time }
}

/// A trajectory's reader with the trajectory's history (see the module docs).
#[derive(Debug)]
pub struct ShmTrajectoryReader {
    name: String,
    checker: TypeChecker,
    cache: CacheConstraint,
    bound: usize,
    clock: SharedClock,
    subscriber: TrajectorySubscriber,
    history: History<ReceivedSample>,
    counts: Counts,
    /// The sequence number each publisher's next sample should carry.
    gaps: SequenceGaps,
}

impl ShmTrajectoryReader {
    /// A builder for a reader of trajectory `name`, whose structures `checker` checks
    /// (its type name selects the samples; its type checks default values).
    pub fn builder(name: impl Into<String>, checker: TypeChecker) -> ShmTrajectoryReaderBuilder {
        ShmTrajectoryReaderBuilder {
            name: name.into(),
            checker,
            domain: DEFAULT_DOMAIN.to_owned(),
            policy: FluentStreamPolicy::default(),
            clock: None,
            qos: TrajectoryQos::default(),
            max_history: DEFAULT_MAX_HISTORY,
            wait: WaitStrategy::default(),
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

    /// The cache constraint the history follows.
    pub fn cache(&self) -> CacheConstraint {
        self.cache
    }

    /// The most samples the history holds.
    pub fn bound(&self) -> usize {
        self.bound
    }

    /// Samples stored.
    pub fn len(&self) -> usize {
        self.history.len()
    }

    /// True if no sample is stored.
    pub fn is_empty(&self) -> bool {
        self.history.is_empty()
    }

    /// Writers connected now (0 or 1 for a well-run trajectory).
    pub fn publisher_count(&self) -> usize {
        self.subscriber.publisher_count()
    }

    /// A snapshot of the statistics.
    pub fn stats(&self) -> ReaderStats {
        let c = &self.counts;
        ReaderStats {
            subscriber: self.subscriber.stats(),
            added: c.added,
            stored: self.history.len(),
            evicted: c.evicted,
            evicted_over_bound: c.evicted_over_bound,
            lost: c.lost,
            resets: c.resets,
        }
    }

    /// Takes every sample waiting in shared memory into the history, without blocking;
    /// returns how many were stored. Rejected samples are counted and skipped.
    pub fn update(&mut self) -> Result<usize, ReceiveError> {
        let mut stored = 0;
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    self.insert(sample);
                    stored += 1;
                }
                Ok(None) => return Ok(stored),
                Err(e) => self.handle(e)?,
            }
        }
    }

    /// Waits up to `timeout` for the next sample, stores it, and returns it (the
    /// subscription of this reader: each sample once, in stream order). Rejected
    /// samples are counted and skipped; `Ok(None)` when the timeout passed.
    pub fn next_sample(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<CachedSample<'_>>, ReceiveError> {
        let deadline = deadline_after(timeout);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.subscriber.wait_for_sample(left) {
                Ok(Some(sample)) => {
                    if self.insert(sample) {
                        let query_time = self.clock.now();
                        return Ok(self.history.nth_latest(0).map(|e| cached(e, query_time)));
                    }
                }
                Ok(None) => return Ok(None),
                Err(e) => self.handle(e)?,
            }
            if left.is_zero() {
                return Ok(None);
            }
        }
    }

    /// Every stored sample in add order (for inspection and recording).
    pub fn iter(&self) -> impl DoubleEndedIterator<Item = CachedSample<'_>> {
        let query_time = self.clock.now();
        self.history.iter().map(move |e| cached(e, query_time))
    }

    /// Handles a receive error: rejected samples (already counted by the subscriber)
    /// are skipped, a full hand makes room; anything else is the caller's.
    fn handle(&mut self, e: ReceiveError) -> Result<(), ReceiveError> {
        match e {
            ReceiveError::Reset { sequence, publisher } => {
                // T5 across processes: what came before the marker is gone.
                while self.history.pop_oldest().is_some() {}
                self.gaps.expect_after(publisher, sequence);
                self.counts.resets += 1;
                Ok(())
            }
            ReceiveError::TypeMismatch { .. }
            | ReceiveError::UnknownKind { .. }
            | ReceiveError::Truncated { .. }
            | ReceiveError::Malformed(_) => Ok(()),
            // The service lets this reader hold fewer samples than its bound (created
            // by another with other settings): give up the oldest.
            ReceiveError::TooManyHeld if self.history.pop_oldest().is_some() => {
                self.counts.evicted_over_bound += 1;
                Ok(())
            }
            e => Err(e),
        }
    }

    /// Stores `sample` and evicts; false if the cache evicted it at once.
    fn insert(&mut self, sample: ReceivedSample) -> bool {
        let h = *sample.header();
        let lost = self.gaps.observe(sample.publisher_id(), h.sequence);
        self.counts.lost = self.counts.lost.saturating_add(lost);
        self.history.push(h.valid_time, sample);
        let stored = self.history.nth_latest(0).map(|e| e.seq);
        self.counts.added += 1;
        let evicted = self.history.evict(self.cache, self.bound);
        self.counts.evicted += evicted.by_policy as u64;
        self.counts.evicted_over_bound += evicted.by_bound as u64;
        self.history.nth_latest(0).map(|e| e.seq) == stored
    }

    fn not_available(&self, query: impl Into<String>) -> QueryError {
        QueryError::ValueNotAvailable { trajectory: self.name.clone(), query: query.into() }
    }

    /// The latest sample added.
    pub fn get_latest(&self) -> Result<CachedSample<'_>, QueryError> {
        self.get_nth_latest(0)
            .map_err(|_| self.not_available("get_latest: the trajectory is empty"))
    }

    /// The `n`-th latest sample in add order (0 = latest).
    pub fn get_nth_latest(&self, n: usize) -> Result<CachedSample<'_>, QueryError> {
        let now = self.clock.now();
        self.history.nth_latest(n).map(|e| cached(e, now)).ok_or_else(|| {
            self.not_available(format!(
                "get_nth_latest({n}): {} samples stored",
                self.history.len()
            ))
        })
    }

    /// Every sample with valid time in `[from, to]`, by valid time (ties in add order).
    pub fn get_between(&self, from: Time, to: Time) -> Vec<CachedSample<'_>> {
        let now = self.clock.now();
        self.history.between(from, to).into_iter().map(|e| cached(e, now)).collect()
    }

    /// The sample valid exactly at `t` (the latest added if several are).
    pub fn get_at(&self, t: Time) -> Result<CachedSample<'_>, QueryError> {
        let now = self.clock.now();
        self.history
            .at_or_before(t)
            .filter(|e| e.vt == t)
            .map(|e| cached(e, now))
            .ok_or_else(|| self.not_available(format!("get_at({t}): no sample valid at {t}")))
    }

    /// The sample with the largest valid time not after `t`.
    pub fn get_closest_at_or_before(&self, t: Time) -> Result<CachedSample<'_>, QueryError> {
        let now = self.clock.now();
        self.history.at_or_before(t).map(|e| cached(e, now)).ok_or_else(|| {
            self.not_available(format!("get_closest_at_or_before({t}): no sample at or before {t}"))
        })
    }

    /// The value at `t`, approximated by `aprx` when no sample is valid exactly at `t`
    /// (esgm-core's approximations; linear interpolation decodes the two samples
    /// around `t`, nothing else is decoded).
    pub fn get_at_approximating(
        &self,
        t: Time,
        aprx: &ValueApproximation,
    ) -> Result<Approximated<'_>, HistoryError> {
        let now = self.clock.now();
        if let Some(e) = self.history.at_or_before(t).filter(|e| e.vt == t) {
            return Ok(Approximated::Stored(cached(e, now)));
        }
        let q = |what: &str| format!("get_at_approximating({t}, {what})");
        let stored = |e| Approximated::Stored(cached(e, now));
        match aprx {
            ValueApproximation::None => {
                Err(self.not_available(q("none: no sample valid at that time")).into())
            }
            ValueApproximation::MostRecent => self
                .history
                .before(t)
                .map(stored)
                .ok_or_else(|| self.not_available(q("most recent: nothing before it")).into()),
            ValueApproximation::Closest => {
                let pick = match (self.history.before(t), self.history.after(t)) {
                    (Some(b), Some(a)) => {
                        // Wide arithmetic: valid times come from another process and
                        // may be anywhere in `i64`.
                        if i128::from(t) - i128::from(b.vt) <= i128::from(a.vt) - i128::from(t) {
                            b
                        } else {
                            a
                        }
                    }
                    (Some(x), None) | (None, Some(x)) => x,
                    (None, None) => {
                        return Err(self
                            .not_available(q("closest: the trajectory is empty"))
                            .into());
                    }
                };
                Ok(stored(pick))
            }
            ValueApproximation::Default(attributes) => {
                self.checker.check(attributes).map_err(|source| QueryError::InvalidDefault {
                    trajectory: self.name.clone(),
                    source,
                })?;
                let es = EntityStructure {
                    name: self.name.clone(),
                    valid_time: t,
                    create_time: now,
                    attributes: attributes.clone(),
                };
                Ok(Approximated::Computed(Sample {
                    structure: Arc::new(es),
                    add_time: now,
                    query_time: now,
                }))
            }
            ValueApproximation::Linear => match (self.history.before(t), self.history.after(t)) {
                (Some(b), Some(a)) => {
                    let decode = |s: &ReceivedSample| {
                        s.to_owned().map_err(|source| HistoryError::Decode {
                            trajectory: self.name.clone(),
                            source,
                        })
                    };
                    let es = interpolate(&decode(&b.item)?, &decode(&a.item)?, t, now);
                    Ok(Approximated::Computed(Sample {
                        structure: Arc::new(es),
                        add_time: now,
                        query_time: now,
                    }))
                }
                (None, _) => Err(self.not_available(q("linear: nothing before it")).into()),
                (_, None) => Err(self.not_available(q("linear: nothing after it")).into()),
            },
        }
    }

    /// The earliest valid time stored.
    pub fn start_time(&self) -> Result<Time, QueryError> {
        self.history.min_valid_time().ok_or_else(|| self.not_available("start_time: empty"))
    }

    /// The latest valid time stored.
    pub fn end_time(&self) -> Result<Time, QueryError> {
        self.history.max_valid_time().ok_or_else(|| self.not_available("end_time: empty"))
    }
}
