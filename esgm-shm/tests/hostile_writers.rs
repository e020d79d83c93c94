//! Only the writer writes: what a process other than a trajectory's writer puts on
//! the trajectory's data service never reaches a reader's replica, and every such
//! sample is counted by cause.
//!
//! The forger is a raw iceoryx2 publisher in this test process, doing what a hostile
//! local process would. Each test has its own coordinator in a unique domain; every
//! wait has a deadline.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{RawPublisher, coordinator, location, state, wait_for, x};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    DropCause, EntityStructure, EntityTrajectoryStructure, Esgm, InProcessTrajectory, Rejection,
    Time, TrajectoryStats,
};
use esgm_shm::ShmEsgm;
use esgm_shm::control::{CoordinatorThread, Request, Response, TrajectoryRecord};

fn record(at: &ShmEsgm, name: &str) -> TrajectoryRecord {
    match at.control(Request::GetEntityTrajectoryStructure { name: name.into() }) {
        Ok(Response::Trajectory(r)) => *r,
        other => panic!("no record of `{name}`: {other:?}"),
    }
}

/// The services of a trajectory's generation live in `<domain>.g<generation>`.
fn service_domain(c: &CoordinatorThread, generation: u64) -> String {
    format!("{}.g{generation}", c.domain())
}

/// The generation the next trajectory created gets: one more than a probe's made now
/// (the registry counts generations up, never reusing one).
fn next_generation(at: &ShmEsgm) -> u64 {
    at.create_trajectory(TrajectorySpec::primitive("probe", "RobotState")).unwrap();
    record(at, "probe").generation + 1
}

fn rejected(stats: &TrajectoryStats, why: Rejection) -> u64 {
    stats.dropped_for(DropCause::Rejected(why))
}

fn rejected_here(t: &InProcessTrajectory, why: Rejection) -> u64 {
    t.stats().map(|s| rejected(&s, why)).unwrap_or(0)
}

/// A trajectory's data service admits its writer's publisher alone: while the writer
/// lives, another process cannot open a second one, so nothing reaches readers around
/// the writer's gate. The writer has registered its port.
#[test]
fn no_second_publisher_opens_on_a_live_trajectory() {
    let c = coordinator("hostile-one-publisher");
    let a = location(&c, "a");
    let robot = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    robot.add(state(10, 1.0)).unwrap();
    let record = record(&a, "robot");
    let forger =
        RawPublisher::try_open(&common::node(), &service_domain(&c, record.generation), "robot");
    let why = forger.err().expect("a second publisher opened on the writer's service");
    assert!(why.contains("ExceedsMaxSupportedPublishers"), "{why}");
    assert_eq!(record.port.map(|p| p.pid), Some(std::process::id()), "{record:?}");
}

/// A process that created a trajectory's service before esgm did, with room for more
/// publishers, forges well-formed samples: a RobotState with attributes the type does
/// not have, a RobotState valid one hour ahead, and a reset marker. Readers take none
/// of them (they come from a port the registry does not name as the writer) and count
/// each; the writer's samples keep flowing, and the history stays.
#[test]
fn forged_samples_and_resets_from_another_port_are_rejected_and_counted() {
    let c = coordinator("hostile-not-writer");
    let a = location(&c, "a");
    let b = location(&c, "b");
    let generation = next_generation(&a);
    let forger =
        RawPublisher::create_first(&common::node(), &service_domain(&c, generation), "robot");
    let robot = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    assert_eq!(record(&a, "robot").generation, generation, "the forger guessed the generation");
    robot.add(state(10, 1.0)).unwrap();
    let there = b.get_entity_trajectory_structure("robot").unwrap();
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(1.0)), "{:?}", there.stats());

    let hour: Time = 3_600_000_000_000;
    forger.send_structure(
        &EntityStructure::new("robot1", 20, 20).with("bogus", 1.0),
        "RobotState",
        0,
    );
    forger.send_structure(&state(hour, 99.0), "RobotState", 1);
    forger.send_reset("RobotState", 2);
    robot.add(state(30, 3.0)).unwrap();

    let ok = wait_for(|| rejected_here(&there, Rejection::NotWriter) == 3);
    assert!(ok, "{:?}", there.stats());
    assert_eq!(there.get_latest().map(|s| x(&s)), Ok(3.0), "the writer's latest, not +1 h");
    let xs: Vec<f64> = there.get_between(0, 2 * hour).unwrap().iter().map(x).collect();
    assert_eq!(xs, [1.0, 3.0], "no forged sample, and no reset forgot the history");
    // `esgm stats` adds every reader's rejections to the writer's report.
    let domain = a.domain_stats().unwrap();
    let all = &domain.get("robot").unwrap().stats;
    assert!(rejected(all, Rejection::NotWriter) >= 3, "{all:?}");
}

/// The port the registry names is the only one readers take samples from, and even
/// its samples must match the trajectory's type: a RobotState with an attribute the
/// type lacks is rejected as a wrong layout, the next valid one is taken.
#[test]
fn samples_of_the_named_writer_are_checked_against_the_type() {
    let c = coordinator("hostile-layout");
    let b = location(&c, "b");
    let generation;
    {
        let a = location(&c, "a");
        generation = next_generation(&a);
        let robot = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
        robot.add(state(10, 1.0)).unwrap();
        let there = b.get_entity_trajectory_structure("robot").unwrap();
        assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(1.0)));
        // The writer goes (its process ends): its publisher with it, its record stays.
    }
    let forger = RawPublisher::try_open(&common::node(), &service_domain(&c, generation), "robot")
        .expect("the writer's publisher is gone");
    // This test process held the record (it was `a`'s), so it may name another port.
    let named = b.control(Request::ReportWriter {
        trajectory: "robot".into(),
        generation,
        publisher: forger.id(),
    });
    assert!(matches!(named, Ok(Response::Done)), "{named:?}");
    let there = b.get_entity_trajectory_structure("robot").unwrap();
    forger.send_structure(
        &EntityStructure::new("robot1", 20, 20).with("bogus", 1.0),
        "RobotState",
        0,
    );
    forger.send_structure(&state(40, 4.0), "RobotState", 1);
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(4.0)), "{:?}", there.stats());
    assert_eq!(rejected_here(&there, Rejection::WrongLayout), 1, "{:?}", there.stats());
    assert_eq!(rejected_here(&there, Rejection::NotWriter), 0, "{:?}", there.stats());
}

/// Bytes another process writes straight into a trajectory's data service are
/// rejected by the readers, counted by cause in their stats and in the domain's
/// (`esgm stats`), and the valid samples keep flowing.
#[test]
fn forged_bytes_in_a_live_trajectory_are_rejected_counted_and_survived() {
    let c = coordinator("hostile-bytes");
    let a = location(&c, "a");
    let b = location(&c, "b");
    let generation = next_generation(&a);
    let raw = RawPublisher::create_first(&common::node(), &service_domain(&c, generation), "robot");
    let robot = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    robot.add(state(10, 1.0)).unwrap();
    let there = b.get_entity_trajectory_structure("robot").unwrap();
    assert!(wait_for(|| there.get_latest().is_ok()));
    raw.send(&[0xAB; 96], common::header_for(96, 20, 20));
    raw.send(&[0; 64], esgm_shm::SampleHeader { type_id: 7, ..common::header_for(64, 21, 21) });
    robot.add(state(30, 3.0)).unwrap();
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(3.0)), "valid samples flow");
    let mine = there.stats().unwrap();
    assert_eq!(rejected(&mine, Rejection::Malformed), 1, "{mine:?}");
    assert_eq!(rejected(&mine, Rejection::WrongType), 1, "{mine:?}");
    let domain = a.domain_stats().unwrap();
    let all = &domain.get("robot").unwrap().stats;
    assert!(rejected(all, Rejection::Malformed) >= 1, "{all:?}");
}
