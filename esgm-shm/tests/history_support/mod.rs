//! Helpers shared by the trajectory history tests: the `Reading` type, scripts run on
//! a shared-memory writer and on an in-process store, and the comparison of every
//! query answer.
#![allow(dead_code)] // each test binary uses a different subset
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::sync::Arc;
use std::time::Instant;

use esgm_core::{
    AddError, AddOutcome, AttributeList, EntityStructure, EntityStructureType, FluentStreamPolicy,
    PolicyViolation, QueryError, Sample, SimClock, SubscribeOptions, Time, TrajectoryStore,
    TypeChecker, TypeRegistry, ValueApproximation, ValueSort,
};
use esgm_shm::{CachedSample, HistoryError, ShmTrajectoryReader, ShmTrajectoryWriter, WriteError};

use crate::common::TIMEOUT;

pub const TRAJECTORY: &str = "readings";

pub fn checker() -> TypeChecker {
    let mut r = TypeRegistry::with_library();
    r.create_entity_structure_type(
        "Reading",
        EntityStructureType::new("Reading")
            .attr("x", ValueSort::Double)
            .attr("n", ValueSort::Long)
            .attr("label", ValueSort::String),
    )
    .unwrap();
    TypeChecker::new(&r, "Reading").unwrap()
}

pub fn reading(vt: Time, x: f64) -> EntityStructure {
    EntityStructure::new("r", vt, vt).with("x", x).with("n", x as i64).with("label", "l")
}

pub fn attributes(x: f64) -> AttributeList {
    AttributeList(reading(0, x).attributes)
}

/// A structure that does not fit `Reading` (no `n`, no `label`).
pub fn misfit(vt: Time) -> EntityStructure {
    EntityStructure::new("r", vt, vt).with("x", 1.0)
}

/// What one step of a script does.
#[derive(Debug, Clone)]
pub enum Op {
    Add(EntityStructure),
    AddBlocking(EntityStructure),
    CreateAt(Time, f64),
    CreateAtNowBlocking(f64),
    ReleaseDue,
}

/// At clock time `.0`, do `.1`.
pub type Step = (Time, Op);

/// What a step did, comparable between the two implementations.
#[derive(Debug, Clone, PartialEq)]
pub enum Did {
    Add(Result<AddOutcome, AddError>),
    Released(usize),
}

/// The same script on an in-process store: its outcomes, the whole stream (a
/// subscription from the start) and every violation.
pub struct InProcess {
    pub clock: Arc<SimClock>,
    pub store: TrajectoryStore,
    pub did: Vec<Did>,
    pub stream: Vec<Sample>,
    pub violations: Vec<PolicyViolation>,
}

pub fn in_process(policy: &FluentStreamPolicy, start: Time, script: &[Step]) -> InProcess {
    let clock = SimClock::shared(start);
    let mut store = TrajectoryStore::builder(TRAJECTORY, checker())
        .policy(policy.clone())
        .clock(clock.clone())
        .create()
        .unwrap();
    let stream = store.subscribe(SubscribeOptions::default().capacity(4096));
    let violations = store.subscribe_violations(4096);
    let mut did = Vec::new();
    for (at, op) in script {
        clock.set(*at);
        did.push(match op.clone() {
            Op::Add(es) => Did::Add(store.add(es)),
            Op::AddBlocking(es) => Did::Add(store.add_blocking(es)),
            Op::CreateAt(vt, x) => Did::Add(store.create_at("r", vt, attributes(x))),
            Op::CreateAtNowBlocking(x) => {
                Did::Add(store.create_at_now_blocking("r", attributes(x)))
            }
            Op::ReleaseDue => Did::Released(store.release_due()),
        });
    }
    let stream = stream.drain();
    let violations = violations.drain();
    InProcess { clock, store, did, stream, violations }
}

/// Monotone order, delay 100 with reordering, a cache of 4: structures held, released
/// in valid-time order by later adds and by `release_due`, late ones dropped.
pub fn hold_and_reorder() -> (FluentStreamPolicy, Time, Vec<Step>) {
    let policy = FluentStreamPolicy::reasonable(100, 4).unwrap();
    let script = vec![
        (1_000, Op::Add(reading(950, 1.0))),         // held until 1050
        (1_010, Op::Add(reading(940, 2.0))),         // held until 1040
        (1_020, Op::AddBlocking(reading(900, 3.0))), // delay 120: violation
        (1_045, Op::Add(reading(1_000, 4.0))),       // releases 940, held
        (1_055, Op::Add(reading(960, 5.0))),         // releases 950, held
        (1_070, Op::Add(reading(1_000, 6.0))),       // releases 960, equal valid time held
        (1_080, Op::CreateAt(990, 7.0)),             // held until 1090
        (1_120, Op::ReleaseDue),                     // 990, 1000, 1000
        (1_130, Op::Add(reading(1_125, 8.0))),
        (1_300, Op::ReleaseDue),
        (1_300, Op::Add(reading(1_000, 9.0))), // delay 300: dropped
        (1_301, Op::Add(misfit(1_300))),       // invalid type
        (1_302, Op::Add(reading(1_301, 10.0))), // held, never released: counted as held
    ];
    (policy, 1_000, script)
}

/// Runs `script` on a shared-memory writer whose clock is `clock`.
pub fn run_script(w: &mut ShmTrajectoryWriter, clock: &SimClock, script: Vec<Step>) -> Vec<Did> {
    let mut results = Vec::new();
    for (at, op) in script {
        clock.set(at);
        let r = match op {
            Op::Add(es) => w.add(es),
            Op::AddBlocking(es) => w.add_blocking(es),
            Op::CreateAt(vt, x) => w.create_at("r", vt, attributes(x)),
            Op::CreateAtNowBlocking(x) => w.create_at_now_blocking("r", attributes(x)),
            Op::ReleaseDue => {
                results.push(Did::Released(w.release_due().unwrap()));
                continue;
            }
        };
        results.push(Did::Add(match r {
            Ok(outcome) => Ok(outcome),
            Err(WriteError::Add(e)) => Err(e),
            Err(e) => panic!("publishing failed: {e}"),
        }));
    }
    results
}

/// Takes `n` samples through `next_sample`, as a subscriber would, and returns them
/// owned; fails the test if they do not arrive in time.
pub fn take(reader: &mut ShmTrajectoryReader, n: usize) -> Vec<Sample> {
    let deadline = Instant::now() + TIMEOUT;
    let mut got = Vec::new();
    while got.len() < n {
        let left = deadline.saturating_duration_since(Instant::now());
        match reader.next_sample(left).unwrap() {
            Some(s) => got.push(s.to_sample().unwrap()),
            None => panic!("{} of {n} samples arrived", got.len()),
        }
    }
    got
}

pub fn owned(r: Result<CachedSample<'_>, QueryError>) -> Result<Sample, QueryError> {
    r.map(|s| s.to_sample().unwrap())
}

pub fn approximations() -> Vec<ValueApproximation> {
    vec![
        ValueApproximation::None,
        ValueApproximation::Closest,
        ValueApproximation::MostRecent,
        ValueApproximation::Linear,
        ValueApproximation::Default(reading(0, 42.0).attributes),
        // Does not fit the type: InvalidDefault from both.
        ValueApproximation::Default(misfit(0).attributes),
    ]
}

/// The stream as it entered, minus the query time (a subscriber's sample is stamped
/// with its add time, a reader's with the time it was taken).
pub fn entered(stream: &[Sample]) -> Vec<(EntityStructure, Time)> {
    stream.iter().map(|s| ((*s.structure).clone(), s.add_time)).collect()
}

/// Every query of the reader answers what the store answers, at the same query time.
pub fn assert_same_answers(store: &TrajectoryStore, reader: &ShmTrajectoryReader) {
    assert_eq!(reader.len(), store.len(), "stored samples");
    let stored: Vec<Sample> = reader.iter().map(|s| s.to_sample().unwrap()).collect();
    assert_eq!(stored, store.samples(), "stored samples in add order");
    assert_eq!(owned(reader.get_latest()), store.get_latest(), "get_latest");
    for n in 0..=store.len() + 1 {
        assert_eq!(owned(reader.get_nth_latest(n)), store.get_nth_latest(n), "get_nth_latest({n})");
    }
    assert_eq!(reader.start_time(), store.start_time(), "start_time");
    assert_eq!(reader.end_time(), store.end_time(), "end_time");

    // Every stored valid time, its neighbours, and beyond both ends.
    let mut times: Vec<Time> = store.samples().iter().map(|s| s.valid_time).collect();
    let mut sorted = times.clone();
    sorted.sort_unstable();
    // Neighbours, and midpoints (where `Closest` breaks a tie).
    times.extend(sorted.iter().flat_map(|t| [t - 1, t + 1]));
    times.extend(sorted.windows(2).map(|w| w[0] + (w[1] - w[0]) / 2));
    times.extend([Time::MIN, -1, 0, Time::MAX]);
    times.sort_unstable();
    times.dedup();
    for &t in &times {
        assert_eq!(owned(reader.get_at(t)), store.get_at(t), "get_at({t})");
        assert_eq!(
            owned(reader.get_closest_at_or_before(t)),
            store.get_closest_at_or_before(t),
            "get_closest_at_or_before({t})"
        );
        for a in approximations() {
            let shm = match reader.get_at_approximating(t, &a) {
                Ok(answer) => Ok(answer.to_sample().unwrap()),
                Err(HistoryError::Query(e)) => Err(e),
                Err(e) => panic!("get_at_approximating({t}, {a:?}): {e}"),
            };
            assert_eq!(shm, store.get_at_approximating(t, &a), "get_at_approximating({t}, {a:?})");
        }
    }
    for (i, &from) in times.iter().enumerate() {
        for &to in times.iter().skip(i.saturating_sub(1)).step_by(2) {
            let shm: Vec<Sample> =
                reader.get_between(from, to).iter().map(|s| s.to_sample().unwrap()).collect();
            assert_eq!(shm, store.get_between(from, to), "get_between({from}, {to})");
        }
    }
}
