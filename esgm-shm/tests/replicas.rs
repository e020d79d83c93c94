//! Replicas through `connect`: what crosses the boundary between a trajectory's writer
//! and the locations that read it — the history a replica made late starts with, and a
//! writer in a real child process whose gated stream, violations, reset and history
//! reach replicas made before and after it wrote.
//!
//! A replica answers queries with esgm-core's store, like its writer; the conformance
//! suite compares every query of the two (`tests/src/conformance/queries.rs`). Each
//! test has its own coordinator in a unique domain; every wait has a deadline.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{TIMEOUT, coordinator, reap, spawn_child, wait_for};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    AddError, AddOutcome, CacheConstraint, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, OrderConstraint, PolicyViolation, QueryError, Sample, SharedClock,
    SimClock, SubscribeOptions, Time, TrajectoryStore, TypeChecker, TypeRegistry,
    ValueApproximation,
};
use esgm_shm::{DEFAULT_MAX_HISTORY, ShmEsgm};

const ROLE: &str = "ESGM_REPLICAS_ROLE";
const DOMAIN: &str = "ESGM_REPLICAS_DOMAIN";
const TRAJECTORY: &str = "readings";

fn location(domain: &str, host: &str, clock: Option<SharedClock>) -> ShmEsgm {
    let builder = ShmEsgm::builder().domain(domain).host(host);
    match clock {
        Some(clock) => builder.clock(clock),
        None => builder,
    }
    .connect()
    .unwrap_or_else(|e| panic!("connect `{host}`: {e}"))
}

fn state(vt: Time, x: f64) -> EntityStructure {
    EntityStructure::new("robot1", vt, vt).with("x", x).with("y", 0.0).with("dir", 0.0)
}

/// Every stored sample as (add time, structure), oldest first.
fn contents<T: EntityTrajectoryStructure>(
    t: &T,
) -> Result<Vec<(Time, EntityStructure)>, QueryError> {
    let all = t.get_between(Time::MIN, Time::MAX)?;
    Ok(all.iter().map(|s| (s.add_time, s.structure.to_structure())).collect())
}

#[test]
fn a_late_replica_of_an_unbounded_cache_starts_with_the_last_max_history() {
    let c = coordinator("replica-late-all");
    let a = location(c.domain(), "a", None);
    let b = location(c.domain(), "b", None);
    // No cache constraint: the writer keeps everything, shared memory the last 1024.
    let written = a.create_trajectory(TrajectorySpec::primitive(TRAJECTORY, "RobotState")).unwrap();
    let n = DEFAULT_MAX_HISTORY + 10;
    for i in 0..n {
        written.add(state(i as Time, i as f64)).unwrap();
    }
    assert_eq!(written.stats().unwrap().stored, n);

    let there = b.get_entity_trajectory_structure(TRAJECTORY).unwrap();
    let ok = wait_for(|| there.stats().map(|s| s.stored) == Ok(DEFAULT_MAX_HISTORY));
    assert!(ok, "the late replica holds {:?}", there.stats().map(|s| s.stored));
    let all = contents(&written).unwrap();
    assert_eq!(contents(&there).unwrap(), all[10..], "the last 1024, with add times");
    assert_eq!(there.start_time(), Ok(10));

    // From then on the replica keeps what its cache says: everything it receives.
    written.add(state(n as Time, 0.5)).unwrap();
    let ok = wait_for(|| there.stats().map(|s| s.stored) == Ok(DEFAULT_MAX_HISTORY + 1));
    assert!(ok, "the replica holds {:?}", there.stats().map(|s| s.stored));
}

/// What one step of the cross-process script does, at a time of the writer's clock.
#[derive(Debug, Clone)]
enum Op {
    Add(EntityStructure),
    AddBlocking(EntityStructure),
    Reset,
}

/// What a step did.
#[derive(Debug, Clone, PartialEq)]
enum Did {
    Add(Result<AddOutcome, AddError>),
    Reset,
}

/// Monotone order, a filter and a cache of 3.
fn policy() -> FluentStreamPolicy {
    FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .filter("x >= 0.0")
        .cache(CacheConstraint::Elements(3))
}

/// Adds the gate admits, drops, returns as violations and refuses for their type, and
/// a reset between two streams. It publishes 8 samples and markers, no more than a
/// replica's queue holds (8 for a cache of 3), so a replica that takes them in only
/// after the writer is done still gets them all.
fn script() -> Vec<(Time, Op)> {
    let mut script = vec![
        (100, Op::Add(state(100, 1.0))),
        (110, Op::Add(state(110, 2.0))),
        (120, Op::Add(state(105, 3.0))),                   // order
        (130, Op::Add(state(130, -1.0))),                  // filter
        (140, Op::Add(state(140, 4.0).with("x", "text"))), // refused for its type
        (150, Op::AddBlocking(state(120, 5.0))),           // admitted: not before 110
        (160, Op::AddBlocking(state(115, 6.0))),           // order, returned
        (170, Op::Reset),
    ];
    // Four after the reset: the cache keeps the last three.
    script.extend((0..4).map(|i| (180 + 10 * i, Op::Add(state(180 + 10 * i, 10.0 + i as f64)))));
    script.push((250, Op::Add(state(195, 9.0)))); // order, after the reset
    script
}

/// The script on an esgm-core store (what the writer's location runs it on), with a
/// subscription and a violation subscription from the start.
struct Reference {
    clock: Arc<SimClock>,
    store: TrajectoryStore,
    did: Vec<Did>,
    stream: Vec<Sample>,
    violations: Vec<PolicyViolation>,
}

impl Reference {
    fn run() -> Self {
        let clock = SimClock::shared(0);
        let checker = TypeChecker::new(&TypeRegistry::with_library(), "RobotState").unwrap();
        let mut store = TrajectoryStore::builder(TRAJECTORY, checker)
            .policy(policy())
            .clock(clock.clone())
            .create()
            .unwrap();
        let stream = store.subscribe(SubscribeOptions::default().capacity(64));
        let violations = store.subscribe_violations(64);
        let mut did = Vec::new();
        for (at, op) in script() {
            clock.set(at);
            did.push(match op {
                Op::Add(es) => Did::Add(store.add(es)),
                Op::AddBlocking(es) => Did::Add(store.add_blocking(es)),
                Op::Reset => {
                    store.reset();
                    Did::Reset
                }
            });
        }
        let (stream, violations) = (stream.drain(), violations.drain());
        Self { clock, store, did, stream, violations }
    }

    fn contents(&self) -> Vec<(Time, EntityStructure)> {
        self.store.samples().iter().map(|s| (s.add_time, s.structure.to_structure())).collect()
    }
}

/// The stream as it entered: structures and add times (a query time is the reader's).
fn entered(stream: &[Sample]) -> Vec<(EntityStructure, Time)> {
    stream.iter().map(|s| (s.structure.to_structure(), s.add_time)).collect()
}

fn key(v: &PolicyViolation) -> (esgm_core::Constraint, Time, Time, Time) {
    (v.constraint, v.valid_time, v.create_time, v.add_time)
}

/// Waits until `esgm` reads a sample of trajectory `name` (made by the other process).
fn wait_for_signal(esgm: &ShmEsgm, name: &str, patience: Duration) -> bool {
    let deadline = Instant::now() + patience;
    while Instant::now() < deadline {
        if esgm.get_entity_trajectory_structure(name).is_ok_and(|t| t.get_latest().is_ok()) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

/// Runs only inside the child process: the writer. Creates the trajectory, runs the
/// script once the parent's replica is ready (checking each outcome against the
/// store's), then keeps its history for late replicas until the parent is done.
#[test]
fn child_writer() {
    if std::env::var(ROLE).as_deref() != Ok("writer") {
        return;
    }
    let domain = std::env::var(DOMAIN).unwrap();
    let clock = SimClock::shared(0);
    let esgm = location(&domain, "child-writer", Some(clock.clone()));
    let written = esgm
        .create_trajectory(TrajectorySpec::primitive(TRAJECTORY, "RobotState").policy(policy()))
        .unwrap();
    assert!(wait_for_signal(&esgm, "ready", TIMEOUT), "the parent's replica was never ready");
    let reference = Reference::run();
    for ((at, op), expected) in script().into_iter().zip(reference.did) {
        clock.set(at);
        let did = match op {
            Op::Add(es) => Did::Add(written.add(es)),
            Op::AddBlocking(es) => Did::Add(written.add_blocking(es)),
            Op::Reset => {
                written.reset().unwrap();
                Did::Reset
            }
        };
        assert_eq!(did, expected, "the outcome of the step at {at}");
    }
    assert!(wait_for_signal(&esgm, "done", TIMEOUT * 2), "the parent never said done");
}

#[test]
fn a_writer_in_another_process_reaches_replicas_made_before_and_after() {
    let c = coordinator("replica-child");
    // The parent queries at one time on both its replicas and its reference store.
    let clock = SimClock::shared(10_000);
    let here = location(c.domain(), "parent", Some(clock.clone()));
    let child = spawn_child("child_writer", (ROLE, "writer"), (DOMAIN, c.domain()));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let expected = Reference::run();
        // A replica made before anything is written: it sees the whole stream.
        assert!(wait_for(|| here.get_entity_trajectory_structure(TRAJECTORY).is_ok()));
        let early = here.get_entity_trajectory_structure(TRAJECTORY).unwrap();
        let stream = early.subscribe(SubscribeOptions::default().capacity(64)).unwrap();
        let violations = early.subscribe_violations(64).unwrap();
        let ready = here.create_primitive_entity_trajectory_structure("ready", "RobotState");
        ready.unwrap().add(state(1, 1.0)).unwrap();

        // The gated stream, with the writer's add times, in stream order; every
        // violation the writer's gate found (the misfit was refused, not gated).
        let got: Vec<Sample> =
            expected.stream.iter().map(|_| stream.recv_timeout(TIMEOUT).unwrap()).collect();
        assert_eq!(entered(&got), entered(&expected.stream), "the stream replicas receive");
        let seen: Vec<PolicyViolation> =
            expected.violations.iter().map(|_| violations.recv_timeout(TIMEOUT).unwrap()).collect();
        assert_eq!(
            seen.iter().map(key).collect::<Vec<_>>(),
            expected.violations.iter().map(key).collect::<Vec<_>>(),
            "violations"
        );
        // The reset emptied the replica; it holds what the writer's store holds.
        let ok = wait_for(|| contents(&early) == Ok(expected.contents()));
        assert!(ok, "early replica {:?}\n expected {:?}", contents(&early), expected.contents());

        // A replica made now, in another location, starts from the writer's history.
        let there = location(c.domain(), "late", Some(clock.clone()));
        let late = there.get_entity_trajectory_structure(TRAJECTORY).unwrap();
        let ok = wait_for(|| contents(&late) == Ok(expected.contents()));
        assert!(ok, "late replica {:?}\n expected {:?}", contents(&late), expected.contents());

        // Both answer queries as the writer's store does, at the same query time.
        expected.clock.set(clock.now());
        let store = &expected.store;
        for replica in [&early, &late] {
            assert_eq!(replica.get_latest(), store.get_latest());
            assert_eq!(replica.get_nth_latest(3), store.get_nth_latest(3));
            for t in [185, 195, 205, 215] {
                let a = ValueApproximation::Linear;
                assert_eq!(replica.get_at_approximating(t, &a), store.get_at_approximating(t, &a));
            }
        }
        let done = here.create_primitive_entity_trajectory_structure("done", "RobotState");
        done.unwrap().add(state(1, 1.0)).unwrap();
    }));
    let (status, output) = reap(child, TIMEOUT * 3);
    if let Err(panic) = result {
        eprintln!("writer output:\n{output}");
        std::panic::resume_unwind(panic);
    }
    assert!(status.success(), "writer process failed ({status}):\n{output}");
}
