//! The `robot-publisher` binary end to end: a coordinator in this process, the real
//! binary publishing into it, and this process steering the robot and reading its
//! states through shared memory. Every wait has a watchdog that fails the test, and
//! the robot is killed when a test ends, also when it fails ([`Watched`]).

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

// One copy of the watched-process helper for both publishers' tests.
#[path = "../../camera-publisher/tests/support/watched.rs"]
mod watched;

use esgm_core::library::{DrivingDirection, RobotState};
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, Time, TypeRegistry};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};
use robot_publisher::Kinematics;
use watched::Watched;

const ROBOT: &str = env!("CARGO_BIN_EXE_robot-publisher");

/// The states read so far (none while the replica has no sample yet).
fn states(t: &impl EntityTrajectoryStructure) -> Vec<(Time, RobotState)> {
    t.get_between(0, Time::MAX)
        .unwrap_or_default()
        .iter()
        .map(|s| {
            assert_eq!(s.name(), "robot1");
            (s.valid_time(), RobotState::from_shared(s).unwrap())
        })
        .collect()
}

#[test]
fn publishes_states_steered_by_the_driving_direction_and_leaves_with_the_coordinator() {
    let domain = unique_domain("robot-e2e");
    let coordinator =
        Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library())).unwrap();
    let mut robot = Watched::start(
        ROBOT,
        &["--domain", &domain, "--trajectory", "rs", "--follow", "dd", "--period", "50ms"],
    );
    let esgm = ShmEsgm::builder().domain(&domain).connect().unwrap();
    let robot_state =
        robot.wait_for("the trajectory `rs`", || esgm.get_entity_trajectory_structure("rs").ok());
    // The robot waits for what it follows: created after it started.
    let directions = esgm
        .create_primitive_entity_trajectory_structure("dd", DrivingDirection::TYPE_NAME)
        .unwrap();
    let still = robot.wait_for("three states", || {
        let s = states(&robot_state);
        (s.len() >= 3).then_some(s)
    });
    assert!(still.windows(2).all(|w| w[0].0 < w[1].0), "valid times not increasing: {still:?}");
    let start = Kinematics::default().state();
    assert!(still.iter().all(|(_, s)| *s == start), "moved without a command: {still:?}");

    // Turn left to 90° (the seed's robot heads 3°) and drive.
    let command = DrivingDirection { dir: 90.0, speed: 0.5 };
    directions.create_at_now("driving_dir", command.to_attributes().into()).unwrap();
    let moving = robot.wait_for("a state turned toward the command", || {
        let s = states(&robot_state);
        s.last()
            .is_some_and(|(_, last)| last.dir > start.dir + 10.0 && last.y > start.y)
            .then_some(s)
    });
    assert!(moving.windows(2).all(|w| w[0].0 < w[1].0), "valid times not increasing: {moving:?}");

    drop((robot_state, directions, esgm, coordinator));
    let (status, stderr) = robot.wait_exit("after the coordinator was gone");
    assert!(status.success(), "robot-publisher failed ({status}):\n{stderr}");
}

#[test]
fn without_a_coordinator_it_fails_with_one_line() {
    let domain = unique_domain("robot-e2e-none");
    let (status, stderr) =
        Watched::start(ROBOT, &["--domain", &domain]).wait_exit("without a system");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!("robot-publisher: cannot reach the system `{domain}`")),
        "{stderr}"
    );

    let (status, stderr) = Watched::start(ROBOT, &["--period", "soon"]).wait_exit("misused");
    assert_eq!(status.code(), Some(2), "a usage error: {stderr}");
}
