//! The tutorial's pipeline (seed chapters 8–10) on the in-process runtime with a
//! simulated clock: camera → blobs → current blob → driving direction → robot, checked
//! against the synthetic scene's ground truth.
//!
//! Time is advanced by hand, 50 ms at a time. Images are sampled on whole seconds and
//! the robot publishes at 50 ms past every 100 ms, so no two events share a time, and
//! after each step the test waits (with a timeout that fails it) until the runtime has
//! handled the step's event. Every unit call is then determined, and the test checks
//! them one by one.

// Helpers outside `#[test]` functions: a failed unwrap there is a failed test too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;
use std::time::{Duration, Instant};

use camera_publisher::{CameraSensor, SyntheticScene};
use cu_workers::{DrivingDirectionUnit, register_tutorial_units};
use esgm_core::esgm::WorkerStats;
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::store::QueryError;
use esgm_core::time::{millis, secs};
use esgm_core::{
    Entity, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, InProcessEsgm, SimClock, Time,
    TrajectorySpec,
};
use robot_publisher::{Kinematics, RobotPublisher};

const START: Time = secs(1_000);
const IMAGE_PERIOD: Time = secs(1);
const ROBOT_PERIOD: Time = millis(100);
/// The robot publishes this long after each image.
const ROBOT_OFFSET: Time = millis(50);
const STEP: Time = millis(50);
/// How long any single wait may take in real time before the test fails.
const TIMEOUT: Duration = Duration::from_secs(20);

/// Polls `cond` until it holds; fails the test naming `what` after [`TIMEOUT`].
fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + TIMEOUT;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// The signed turn from `from` to `to` the short way, counter-clockwise positive.
fn turn(from: f64, to: f64) -> f64 {
    let d = (to - from).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

/// The tutorial's trajectories, created on any runtime exactly as the seed's main
/// program does (with the seed's reasonable policy on `robot_state`).
struct Trajectories<T> {
    robot_state: T,
    images: T,
    blobs: T,
    current_blob: T,
    driving_direction: T,
}

fn create_pipeline<E: Esgm>(esgm: &E, scene: &SyntheticScene) -> Trajectories<E::Trajectory> {
    let policy = FluentStreamPolicy::reasonable(millis(50), 600).unwrap().reorder(false);
    let robot_state = esgm
        .create_trajectory(TrajectorySpec::primitive("robot_state", "RobotState").policy(policy))
        .unwrap();
    esgm.add_sensor_interface("camera", "Image", Arc::new(CameraSensor::new(scene.clone())))
        .unwrap();
    let images = esgm
        .create_entity_trajectory_structure("images", "camera", 0, 0, IMAGE_PERIOD, 0, 5)
        .unwrap();
    register_tutorial_units(esgm).unwrap();
    let blobs = esgm
        .create_computed_entity_trajectory_structure("blobs", "BlobDetection", &["images"])
        .unwrap();
    let current_blob = esgm
        .create_computed_entity_trajectory_structure("current_blob", "BlobSelection", &["blobs"])
        .unwrap();
    let driving_direction = esgm
        .create_computed_entity_trajectory_structure(
            "driving_direction",
            "DrivingDirection",
            &["robot_state", "current_blob"],
        )
        .unwrap();
    Trajectories { robot_state, images, blobs, current_blob, driving_direction }
}

fn worker(esgm: &impl Esgm, name: &str) -> WorkerStats {
    esgm.stats().unwrap().get(name).map(|r| r.worker).unwrap_or_default()
}

/// Calls a unit has finished (its output, if any, may still be entering the store).
fn finished(w: WorkerStats) -> u64 {
    w.outputs + w.no_value + w.failures + w.panics
}

fn latest_time(t: &impl EntityTrajectoryStructure) -> Option<Time> {
    t.get_latest().ok().map(|s| s.valid_time())
}

fn all<T: Entity>(t: &impl EntityTrajectoryStructure) -> Vec<(Time, T)> {
    t.get_between(Time::MIN, Time::MAX)
        .unwrap()
        .iter()
        .map(|s| (s.valid_time(), T::from_shared(s).unwrap()))
        .collect()
}

/// What the run produced, for the checks.
struct Run {
    trajectories: Trajectories<esgm_core::InProcessTrajectory>,
    /// Driving-direction unit calls refused because the blob was newer than the robot.
    refused_as_unsynchronized: u64,
    esgm: InProcessEsgm,
}

/// Runs the pipeline on `scene` for `duration` of simulated time, waiting after every
/// event for the units it triggers. Checks on the way that exactly the expected unit
/// calls happen.
fn run(scene: &SyntheticScene, duration: Time) -> Run {
    let clock = SimClock::shared(START);
    let esgm = InProcessEsgm::builder().clock(clock.clone()).create();
    let tr = create_pipeline(&esgm, scene);

    let mut images = 0u64;
    let mut empty_images = 0u64;
    let mut blob_seen = false;
    let mut robot_seen = false;
    let mut dd_calls = 0u64;
    let mut refused = 0u64;
    let mut robot: Option<RobotPublisher> = None;

    let mut now = START;
    loop {
        if (now - START) % IMAGE_PERIOD == 0 {
            // An image: detection always answers; selection answers when the scene has
            // a blob; the driving direction is asked but must refuse, its robot state
            // being older than the new blob.
            images += 1;
            wait_until("the image", || latest_time(&tr.images) == Some(now));
            wait_until("blob detection", || {
                finished(worker(&esgm, "blobs")) == images && latest_time(&tr.blobs) == Some(now)
            });
            wait_until("blob selection", || finished(worker(&esgm, "current_blob")) == images);
            if scene.truth(now).is_empty() {
                empty_images += 1;
                assert_eq!(worker(&esgm, "current_blob").no_value, empty_images);
            } else {
                wait_until("the current blob", || latest_time(&tr.current_blob) == Some(now));
                blob_seen = true;
                if robot_seen {
                    dd_calls += 1;
                    refused += 1;
                    wait_until("the refused direction", || {
                        finished(worker(&esgm, "driving_direction")) == dd_calls
                    });
                    assert!(latest_time(&tr.driving_direction) < Some(now));
                }
            }
        }
        if now == START + ROBOT_OFFSET {
            // Start the robot between two images, so its ticks never meet them.
            let publisher = RobotPublisher::builder(tr.robot_state.clone(), clock.clone())
                .period(ROBOT_PERIOD)
                .follow(tr.driving_direction.clone())
                .create()
                .unwrap();
            robot = Some(publisher);
        }
        if (now - START - ROBOT_OFFSET) % ROBOT_PERIOD == 0 && robot.is_some() {
            // A robot state: a direction follows once there is a blob to steer to.
            wait_until("the robot state", || latest_time(&tr.robot_state) == Some(now));
            robot_seen = true;
            if blob_seen {
                dd_calls += 1;
                wait_until("the driving direction", || {
                    finished(worker(&esgm, "driving_direction")) == dd_calls
                        && latest_time(&tr.driving_direction) == Some(now)
                });
            }
        }
        // Stop on the last event: one more step would let the robot publish again.
        if now + STEP > START + duration {
            break;
        }
        now = clock.advance(STEP);
    }
    if let Some(robot) = robot {
        assert_eq!(robot.stats().failures, 0);
        robot.stop();
    }
    let dd = worker(&esgm, "driving_direction");
    assert_eq!((dd.calls, dd.failures, dd.panics), (dd_calls, 0, 0));
    assert_eq!(dd.no_value, refused, "directions refused other than for synchronization");
    Run { trajectories: tr, refused_as_unsynchronized: refused, esgm }
}

#[test]
fn driving_directions_turn_toward_the_largest_blob() {
    let scene = SyntheticScene::builder().blobs(3).seed(1).create().unwrap();
    let duration = secs(3);
    // The check needs an unambiguous largest blob off the image's centre line.
    let unit = DrivingDirectionUnit::default();
    for j in 0..=3 {
        let mut truth = scene.truth(START + j * IMAGE_PERIOD);
        truth.sort_by_key(|b| std::cmp::Reverse(b.size));
        assert!(truth[1].size * 10 < truth[0].size * 9, "scene precondition at {j} s: {truth:?}");
        assert!(unit.computation().bearing(truth[0].x).abs() > 2.0, "precondition at {j} s");
    }

    let Run { trajectories: tr, refused_as_unsynchronized, esgm } = run(&scene, duration);

    let directions: Vec<(Time, DrivingDirection)> = all(&tr.driving_direction);
    let states: Vec<(Time, RobotState)> = all(&tr.robot_state);
    let blobs: Vec<(Time, Blob)> = all(&tr.current_blob);
    // A direction for every robot state (each comes after the first image), none for
    // an image.
    assert_eq!(states.len(), 30);
    assert_eq!(
        directions.iter().map(|d| d.0).collect::<Vec<_>>(),
        states.iter().map(|s| s.0).collect::<Vec<_>>()
    );
    assert_eq!(blobs.len(), 4);
    assert_eq!(refused_as_unsynchronized, 3, "images at 1, 2 and 3 s came after a robot state");

    let expected_robot = Kinematics::default();
    let mut robot = expected_robot;
    let mut previous_command: Option<DrivingDirection> = None;
    for ((t, direction), (_, state)) in directions.iter().zip(&states) {
        // The robot stepped by the previous direction (or held still before the first).
        if let Some(command) = previous_command {
            robot.step(ROBOT_PERIOD, &command);
        }
        let want = robot.state();
        assert!(
            (want.x - state.x).abs() < 1e-9
                && (want.y - state.y).abs() < 1e-9
                && turn(want.dir, state.dir).abs() < 1e-9,
            "robot at {t}: {state:?}, expected {want:?}"
        );
        previous_command = Some(*direction);

        // The direction points at the largest disc of the newest image, to within the
        // detector's centroid error.
        let image_time = START + (t - START) / IMAGE_PERIOD * IMAGE_PERIOD;
        let (_, selected) = blobs.iter().find(|(bt, _)| *bt == image_time).unwrap();
        let largest = scene.truth(image_time).into_iter().max_by_key(|b| b.size).unwrap();
        assert!((selected.x - largest.x).abs() <= 1 && (selected.y - largest.y).abs() <= 1);
        let bearing = unit.computation().bearing(largest.x);
        let told = turn(state.dir, direction.dir);
        assert_eq!(told.signum(), bearing.signum(), "at {t}: turn {told} vs bearing {bearing}");
        assert!((told - bearing).abs() < 0.2, "at {t}: turn {told} vs bearing {bearing}");
        assert!(direction.speed >= 0.0 && direction.speed < 1.0);
    }
    esgm.shutdown();
}

#[test]
fn a_scene_without_blobs_produces_no_blob_and_no_direction() {
    let scene = SyntheticScene::builder().blobs(0).create().unwrap();
    let Run { trajectories: tr, refused_as_unsynchronized, esgm } = run(&scene, secs(2));

    // Every image was looked at and gave an empty sequence of blobs …
    assert_eq!(tr.images.get_between(Time::MIN, Time::MAX).unwrap().len(), 3);
    let sequences: Vec<(Time, esgm_core::library::BlobSeq)> = all(&tr.blobs);
    assert_eq!(sequences.len(), 3);
    assert!(sequences.iter().all(|(_, s)| s.items.is_empty()));
    // … so selection had no value each time, and nothing downstream was computed.
    let selection = worker(&esgm, "current_blob");
    assert_eq!((selection.calls, selection.no_value, selection.outputs), (3, 3, 0));
    assert!(matches!(tr.current_blob.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    assert!(matches!(tr.driving_direction.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    assert_eq!(worker(&esgm, "driving_direction").calls, 0);
    assert_eq!(refused_as_unsynchronized, 0);
    // The robot, with nothing to follow, held still.
    let states: Vec<(Time, RobotState)> = all(&tr.robot_state);
    assert_eq!(states.len(), 20);
    assert!(states.iter().all(|(_, s)| *s == Kinematics::default().state()));
    esgm.shutdown();
}
