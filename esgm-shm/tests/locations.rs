//! `connect` across locations: two connections (two "processes" in the registry, each
//! with its own ports and local runtime) in one test process, and then a real child
//! process that serves a sensor and a unit for trajectories its parent creates.
//!
//! Each test has its own coordinator in a unique domain; every wait has a deadline.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{TIMEOUT, coordinator, location, reap, spawn_child, state, wait_for, x};
use esgm_core::esgm::{
    ComputeError, CreateError, HowWriterChanged, InputType, LookupError, SensorError,
    TrajectorySpec,
};
use esgm_core::{
    AddError, AddOutcome, EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy,
    Sample, SubscribeOptions, Time, ValueApproximation, millis,
};
use esgm_shm::ShmEsgm;

const ROLE: &str = "ESGM_LOCATIONS_ROLE";
const DOMAIN: &str = "ESGM_LOCATIONS_DOMAIN";

#[test]
fn a_primitive_written_here_is_read_there_with_history_violations_and_reset() {
    let c = coordinator("loc-primitive");
    let a = location(&c, "a");
    let b = location(&c, "b");
    let policy = FluentStreamPolicy::default()
        .cache(esgm_core::CacheConstraint::Elements(3))
        .order(esgm_core::OrderConstraint::Monotone);
    let robot = a
        .create_trajectory(TrajectorySpec::primitive("robot", "RobotState").policy(policy))
        .unwrap();
    for i in 1..=4 {
        robot.add(state(i * 10, i as f64)).unwrap();
    }

    // A late reader starts with the writer's view: the cache's last 3.
    let there = b.get_entity_trajectory_structure("robot").unwrap();
    let ok = wait_for(|| there.stats().map(|s| s.stored) == Ok(3));
    assert!(ok, "{:?} / writer {:?}", there.stats(), robot.stats());
    let xs: Vec<f64> = there.get_between(0, 100).unwrap().iter().map(x).collect();
    assert_eq!(xs, [2.0, 3.0, 4.0]);
    assert_eq!(there.get_latest().unwrap().add_time, robot.get_latest().unwrap().add_time);
    let approx = there.get_at_approximating(25, &ValueApproximation::MostRecent).unwrap();
    assert_eq!(x(&approx), 2.0);

    // New samples and violations arrive in order; the writer's gate decided them.
    let sub = there.subscribe(SubscribeOptions::default()).unwrap();
    let violations = there.subscribe_violations(16).unwrap();
    robot.add(state(50, 5.0)).unwrap();
    robot.add(state(45, 4.5)).unwrap(); // out of order: monotone policy drops it
    assert_eq!(x(&sub.recv_timeout(TIMEOUT).unwrap()), 5.0);
    let v = violations.recv_timeout(TIMEOUT).unwrap();
    assert_eq!(v.valid_time, 45);

    // Reset (T5) empties the replica too.
    robot.reset().unwrap();
    assert!(wait_for(|| there.stats().map(|s| s.stored) == Ok(0)));
    robot.add(state(60, 6.0)).unwrap();
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(6.0)));
    assert_eq!(there.stats().unwrap().stored, 1);

    // Another process pushes too: its adds go to the writer's gate (which orders,
    // checks and counts everyone's) and come back through replication.
    assert_eq!(there.add(state(70, 7.0)), Ok(AddOutcome::Forwarded));
    assert!(wait_for(|| robot.get_latest().map(|s| x(&s)) == Ok(7.0)));
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(7.0)));
    assert_eq!(there.add(state(65, 6.5)), Ok(AddOutcome::Forwarded)); // out of order
    assert_eq!(there.add(state(80, 8.0)), Ok(AddOutcome::Forwarded));
    assert!(wait_for(|| there.get_latest().map(|s| x(&s)) == Ok(8.0)));
    let xs: Vec<f64> = robot.get_between(0, 100).unwrap().iter().map(x).collect();
    assert_eq!(xs, [6.0, 7.0, 8.0], "the writer's gate dropped the out-of-order add");
    assert_eq!(violations.recv_timeout(TIMEOUT).unwrap().valid_time, 65);
    // A structure of another type is refused here, at once, and nothing is sent.
    let wrong = EntityStructure::new("robot1", 90, 90).with("z", 1.0);
    assert!(matches!(there.add(wrong), Err(AddError::InvalidType { .. })));
}

/// A reader that connects to a trajectory nobody adds to any more (a loaded recording,
/// a sensor that stopped) answers its very first query from the writer's history: it
/// asks the writer for it when it subscribes, instead of waiting for a next sample
/// that never comes.
#[test]
fn a_late_reader_of_a_quiet_trajectory_answers_its_first_query_from_the_history() {
    let c = coordinator("loc-quiet");
    let a = location(&c, "a");
    let robot = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    for i in 1..=3 {
        robot.add(state(i * 10, i as f64)).unwrap();
    }
    // Quiet: past the writer's periodic maintenance, nothing new is sent.
    std::thread::sleep(Duration::from_millis(600));
    for host in ["b", "c", "d"] {
        let reader = location(&c, host);
        let there = reader.get_entity_trajectory_structure("robot").unwrap();
        // No waiting: the first answer is already the writer's.
        assert_eq!(there.get_latest().map(|s| x(&s)), Ok(3.0), "reader {host}");
        assert_eq!(there.get_between(0, 100).unwrap().len(), 3, "reader {host}");
    }
}

/// A temporal function (E6): `x` of the generator's value at `t`, plus the time in
/// seconds, stamped at `t`.
struct Drift;

impl esgm_core::CompUnit for Drift {
    fn compute(&self, _: &[Sample], _: Time) -> Result<EntityStructure, ComputeError> {
        Err(ComputeError::OperationNotSupported)
    }
    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        Ok(state(t, x(&inputs[0]) + 1.0))
    }
}

/// A trajectory sampled from a unit's temporal function of generators is written where
/// the unit runs (its `compute_at` is there), whoever asks for it, and reads the
/// generators `lag` behind each sample time.
#[test]
fn a_temporal_function_is_sampled_where_its_unit_runs() {
    let c = coordinator("loc-temporal");
    let robot = location(&c, "robot");
    let planner = location(&c, "planner");
    let user = location(&c, "user");
    let states = robot.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    planner
        .add_comp_unit(
            "drift",
            "RobotState",
            vec![InputType::Type("RobotState".into())],
            Arc::new(Drift),
        )
        .unwrap();
    let generator = esgm_core::GeneratorPolicy {
        approximation: ValueApproximation::Linear,
        merge: esgm_core::MergeRule::KeepLast,
    };
    // The robot's states are 0, 1, 2, … every 10 ms from 1 s ago to 1 s ahead, so
    // every sample time minus the lag (500 ms) falls between two of them.
    let now = esgm_core::Clock::now(&esgm_core::SystemClock);
    for i in 0..=200 {
        states.add(state(now - millis(1000) + i * millis(10), i as f64)).unwrap();
    }
    let spec =
        TrajectorySpec::sampled_function("drifting", "drift", [("robot", generator)], millis(5))
            .lag(millis(500));
    let drifting = user.create_trajectory(spec).unwrap();
    assert!(wait_for(|| drifting.stats().map(|s| s.stored >= 3).unwrap_or(false)));
    // Written in the unit's process: it holds the trajectory, the others mirror it.
    let writes = |e: &ShmEsgm| e.local().stats().unwrap().trajectories.contains_key("drifting");
    assert!(writes(&planner));
    let s = drifting.get_latest().unwrap();
    // Interpolated along x = (t - (now - 1 s)) / 10 ms, then + 1 by the unit.
    let expected = (s.structure.valid_time() - (now - millis(1000))) as f64 / millis(10) as f64;
    assert!((x(&s) - (expected + 1.0)).abs() < 1e-6, "{} vs {}", x(&s), expected + 1.0);
}

#[test]
fn sampling_runs_where_the_sensor_is_and_units_where_they_are() {
    let c = coordinator("loc-placement");
    let camera = location(&c, "camera");
    let planner = location(&c, "planner");
    let user = location(&c, "user");

    // The sensor lives in `camera`; `user` creates a trajectory sampling it.
    let calls = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let k = Arc::clone(&calls);
    let sensor = move |q: Time| -> Result<EntityStructure, SensorError> {
        k.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(state(q, (q / millis(10)) as f64))
    };
    camera.add_sensor_interface("odometry", "RobotState", Arc::new(sensor)).unwrap();
    // The unit lives in `planner`; it doubles x.
    let unit = |inputs: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        let s = &inputs[0].structure;
        Ok(state(s.valid_time(), 2.0 * s.get("x").and_then(|v| v.as_double()).unwrap_or(0.0)))
    };
    planner
        .add_comp_unit(
            "double",
            "RobotState",
            vec![InputType::Type("RobotState".into())],
            Arc::new(unit),
        )
        .unwrap();

    let sampled = user
        .create_entity_trajectory_structure("odom", "odometry", 0, 0, millis(10), 0, 0)
        .unwrap();
    let doubled =
        user.create_computed_entity_trajectory_structure("doubled", "double", &["odom"]).unwrap();
    assert!(wait_for(|| doubled.stats().map(|s| s.stored >= 3).unwrap_or(false)));
    assert!(calls.load(std::sync::atomic::Ordering::Relaxed) >= 3);
    // Written where the data is made: the sensor's and the unit's processes.
    let writers = |e: &ShmEsgm| e.local().stats().unwrap().trajectories.len();
    assert!(
        writers(&camera) >= 1 && writers(&planner) >= 2,
        "odom at camera, doubled (+ odom replica) at planner"
    );
    let latest = doubled.get_latest().unwrap();
    assert!(wait_for(|| sampled.get_at(latest.structure.valid_time()).is_ok()));
    let input = sampled.get_at(latest.structure.valid_time()).unwrap();
    assert_eq!(x(&latest), 2.0 * x(&input));

    // The seed's errors cross the boundary.
    assert!(matches!(
        user.get_entity_trajectory_structure("odon"),
        Err(LookupError::NoSuchEntityStructure { suggestion: Some(s), .. }) if s == "odom"
    ));
    assert!(matches!(
        user.create_entity_trajectory_structure("x", "odometri", 0, 0, millis(10), 0, 0),
        Err(CreateError::NoSuchSensor { .. })
    ));
    // In use across processes: the sensor cannot go while `odom` samples it.
    assert!(camera.remove_sensor_interface("odometry").is_err());
    user.destroy_entity_trajectory_structure("doubled").unwrap();
    user.destroy_entity_trajectory_structure("odom").unwrap();
    camera.remove_sensor_interface("odometry").unwrap();
}

/// A trajectory whose writer exited without destroying it is taken over by the next
/// process that adds to it (issue 24: such adds were acknowledged as forwarded and
/// lost). Its writer here is a short setup program, another process that exits before
/// anyone read it; its sample stays, from the trajectory's kept history (issue 39,
/// `kept_history.rs`), and a third process reads the stream from the new writer.
#[test]
fn a_trajectory_whose_writer_exited_is_taken_over_by_the_next_adder() {
    let c = coordinator("loc-orphan");
    let setup = spawn_child("child_location", (ROLE, "setup"), (DOMAIN, c.domain()));
    let (status, output) = reap(setup, TIMEOUT * 3);
    assert!(status.success(), "the setup program failed:\n{output}");
    let app = location(&c, "app");
    let made = app.get_entity_trajectory_structure("made_by_setup").unwrap();
    assert_eq!(made.add(state(2, 2.0)).unwrap(), AddOutcome::Added, "served here now");
    assert_eq!(made.add_blocking(state(3, 3.0)).unwrap(), AddOutcome::Added);
    let xs: Vec<f64> = made.get_between(0, 10).unwrap().iter().map(x).collect();
    assert_eq!(xs, [1.0, 2.0, 3.0]);
    // The registry names this process as the writer, and readers elsewhere follow.
    use esgm_shm::control::{Request, Response};
    let Ok(Response::Placements(placements)) = app.control(Request::ListPlacements) else {
        panic!("no placements")
    };
    let placed = placements.iter().find(|p| p.name == "made_by_setup").unwrap();
    assert_eq!(placed.writer, "app");
    let reader = location(&c, "reader");
    let there = reader.get_entity_trajectory_structure("made_by_setup").unwrap();
    let all = |t: &esgm_core::InProcessTrajectory| -> Vec<f64> {
        t.get_between(0, 10).map(|s| s.iter().map(x).collect()).unwrap_or_default()
    };
    assert!(wait_for(|| all(&there) == [1.0, 2.0, 3.0]), "the reader holds {:?}", all(&there));
    // And its adds reach the new writer.
    assert_eq!(there.add(state(4, 4.0)).unwrap(), AddOutcome::Forwarded);
    assert!(wait_for(|| all(&made) == [1.0, 2.0, 3.0, 4.0]), "the writer holds {:?}", all(&made));
    // `why`, asked from the new writer and from a reader, names the take-over: who
    // writes it now (this process), instead of whom.
    for asker in [&app, &reader] {
        let why = asker.why("made_by_setup", 0).unwrap();
        let change = why.writer_changed.as_ref().expect("the take-over is named");
        assert_eq!(change.how, HowWriterChanged::TakenOver);
        assert_eq!((change.from.as_str(), change.to.as_str()), ("setup", "app"));
        assert_eq!(change.to_pid, Some(std::process::id()));
        assert!(change.from_pid.is_some_and(|p| p != std::process::id()), "{change:?}");
        let said = why.reasons.iter().find(|r| r.contains("taken over"));
        let said = said.unwrap_or_else(|| panic!("no take-over among {:?}", why.reasons));
        assert!(said.contains("`app`") && said.contains("instead of `setup`"), "{said}");
    }
}

/// The same when the writer closes its connection while its process lives on (it
/// releases the trajectory), and a reader already sends it adds: until the reader has
/// taken it over, an add is refused with a typed error, never acknowledged and lost.
/// The new writer keeps the history its replica held, and another reader that was
/// already there follows it to the new writer with that history.
#[test]
fn a_trajectory_released_by_its_writer_is_taken_over_with_its_history() {
    let c = coordinator("loc-left");
    let writer = location(&c, "writer");
    let reader = location(&c, "reader");
    let own = writer.create_primitive_entity_trajectory_structure("left", "RobotState").unwrap();
    own.add(state(1, 1.0)).unwrap();
    let there = reader.get_entity_trajectory_structure("left").unwrap();
    let other = location(&c, "other");
    let elsewhere = other.get_entity_trajectory_structure("left").unwrap();
    assert_eq!(there.add(state(2, 2.0)).unwrap(), AddOutcome::Forwarded);
    assert!(wait_for(|| own.get_latest().is_ok_and(|s| x(&s) == 2.0)));
    assert!(wait_for(|| there.get_latest().is_ok_and(|s| x(&s) == 2.0)));
    drop(own);
    drop(writer);
    let deadline = Instant::now() + TIMEOUT;
    let taken = loop {
        match there.add(state(3, 3.0)) {
            Ok(outcome) => break outcome,
            Err(AddError::WriterGone { trajectory, .. }) if Instant::now() < deadline => {
                assert_eq!(trajectory, "left");
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => panic!("an add after the writer left: {e:?}"),
        }
    };
    assert_eq!(taken, AddOutcome::Added);
    let all = |t: &esgm_core::InProcessTrajectory| -> Vec<f64> {
        t.get_between(0, 10).map(|s| s.iter().map(x).collect()).unwrap_or_default()
    };
    assert_eq!(all(&there), [1.0, 2.0, 3.0]);
    assert!(
        wait_for(|| all(&elsewhere) == [1.0, 2.0, 3.0]),
        "the other reader holds {:?}",
        all(&elsewhere)
    );
    assert_eq!(elsewhere.add(state(4, 4.0)).unwrap(), AddOutcome::Forwarded);
    assert!(
        wait_for(|| all(&there) == [1.0, 2.0, 3.0, 4.0]),
        "the new writer holds {:?}",
        all(&there)
    );
}

#[test]
fn child_location() {
    if std::env::var(ROLE).as_deref() == Ok("setup") {
        let domain = std::env::var(DOMAIN).unwrap();
        let esgm = ShmEsgm::builder().domain(&domain).host("setup").connect().unwrap();
        esgm.create_primitive_entity_trajectory_structure("made_by_setup", "RobotState")
            .unwrap()
            .add(state(1, 1.0))
            .unwrap();
        return;
    }
    if std::env::var(ROLE).as_deref() != Ok("serve") {
        return;
    }
    let domain = std::env::var(DOMAIN).unwrap();
    let esgm = ShmEsgm::builder().domain(&domain).host("child").connect().unwrap();
    let sensor =
        |q: Time| -> Result<EntityStructure, SensorError> { Ok(state(q, (q % 1000) as f64)) };
    esgm.add_sensor_interface("counter", "RobotState", Arc::new(sensor)).unwrap();
    let unit = |inputs: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        let s = &inputs[0].structure;
        Ok(state(s.valid_time(), -s.get("x").and_then(|v| v.as_double()).unwrap_or(0.0)))
    };
    esgm.add_comp_unit(
        "negate",
        "RobotState",
        vec![InputType::Sort(esgm_core::ValueSort::EntityFrame)],
        Arc::new(unit),
    )
    .unwrap();
    esgm.create_primitive_entity_trajectory_structure("child_ready", "RobotState")
        .unwrap()
        .add(state(1, 1.0))
        .unwrap();
    let deadline = Instant::now() + TIMEOUT * 2;
    while Instant::now() < deadline {
        if let Ok(done) = esgm.get_entity_trajectory_structure("done") {
            if done.get_latest().is_ok() {
                return;
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("the parent never said done");
}

#[test]
fn a_child_process_serves_a_sensor_and_a_unit() {
    let c = coordinator("loc-child");
    let parent = location(&c, "parent");
    let child = spawn_child("child_location", (ROLE, "serve"), (DOMAIN, c.domain()));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        assert!(wait_for(|| parent
            .get_entity_trajectory_structure("child_ready")
            .is_ok_and(|t| t.get_latest().is_ok())));
        let counter = parent
            .create_entity_trajectory_structure("counter_10ms", "counter", 0, 0, millis(10), 0, 0)
            .unwrap();
        let negated = parent
            .create_computed_entity_trajectory_structure("negated", "negate", &["counter_10ms"])
            .unwrap();
        assert!(wait_for(|| negated.stats().map(|s| s.stored >= 3).unwrap_or(false)));
        let n = negated.get_latest().unwrap();
        // The input reaches this process on its own path; it may come a moment later.
        assert!(wait_for(|| counter.get_at(n.structure.valid_time()).is_ok()));
        let input = counter.get_at(n.structure.valid_time()).unwrap();
        assert_eq!(x(&n), -x(&input));
        parent
            .create_primitive_entity_trajectory_structure("done", "RobotState")
            .unwrap()
            .add(state(1, 1.0))
            .unwrap();
    }));
    let (status, output) = reap(child, TIMEOUT * 3);
    if let Err(panic) = result {
        eprintln!("child output:\n{output}");
        std::panic::resume_unwind(panic);
    }
    assert!(status.success(), "child failed ({status}):\n{output}");
}

#[test]
fn re_pointing_a_name_is_seen_by_readers_in_other_processes() {
    let c = coordinator("loc-repoint");
    let a = location(&c, "a");
    let b = location(&c, "b");
    let first = a.create_trajectory(TrajectorySpec::primitive("track", "RobotState")).unwrap();
    for i in 1..=3 {
        first.add(state(i * 10, i as f64)).unwrap();
    }
    let there = b.get_entity_trajectory_structure("track").unwrap();
    assert!(wait_for(|| there.stats().map(|s| s.stored) == Ok(3)), "{:?}", there.stats());
    let sub = there.subscribe(SubscribeOptions::default()).unwrap();

    // E5: the name now denotes a new trajectory; readers elsewhere follow it and see
    // the new stream from then on, not the old one's history.
    let second =
        a.create_trajectory(TrajectorySpec::primitive("track", "RobotState").replace()).unwrap();
    second.add(state(5, 100.0)).unwrap();
    assert_eq!(x(&sub.recv_timeout(TIMEOUT).unwrap()), 100.0);
    assert!(wait_for(|| there.stats().map(|s| s.stored) == Ok(1)), "{:?}", there.stats());
    assert_eq!(x(&there.get_latest().unwrap()), 100.0);
}

fn image(vt: Time, fill: u8) -> EntityStructure {
    EntityStructure::new("cam", vt, vt)
        .with("width", 256i64)
        .with("height", 256i64)
        .with("format", 0i64)
        .with("image_data", esgm_core::value::Octets::from(vec![fill; 256 * 256]))
}

fn pixels(s: &Sample) -> esgm_core::value::Octets {
    s.structure.get("image_data").and_then(|v| v.as_octets()).unwrap()
}

#[test]
fn images_from_another_process_are_read_in_shared_memory_by_cache_units_and_subscribers() {
    let c = coordinator("loc-images");
    let camera = location(&c, "camera");
    let reader = location(&c, "reader");
    let policy = FluentStreamPolicy::default().cache(esgm_core::CacheConstraint::Elements(3));
    let frames = camera
        .create_trajectory(TrajectorySpec::primitive("frames", "Image").policy(policy))
        .unwrap();

    // A unit in `reader` reports whether the pixels it was given were copied.
    let unit_saw_copies = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let copies = Arc::clone(&unit_saw_copies);
    let unit = move |inputs: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        let px = pixels(&inputs[0]);
        if !px.is_held() {
            copies.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        let vt = inputs[0].structure.valid_time();
        Ok(EntityStructure::new("px", vt, vt)
            .with("x", i64::from(px[0]))
            .with("y", i64::from(px[px.len() - 1]))
            .with("size", px.len() as i64))
    };
    let input = vec![InputType::Type("Image".into())];
    reader.add_comp_unit("measure", "Blob", input, Arc::new(unit)).unwrap();
    let measured = reader
        .create_computed_entity_trajectory_structure("measured", "measure", &["frames"])
        .unwrap();
    let there = reader.get_entity_trajectory_structure("frames").unwrap();
    let sub = there.subscribe(SubscribeOptions::default()).unwrap();

    // One at a time, each dropped once seen: every image arrives held, never copied.
    for i in 1..=20u8 {
        frames.add(image(Time::from(i) * 10, i)).unwrap();
        let s = sub.recv_timeout(TIMEOUT).unwrap();
        assert!(pixels(&s).is_held(), "image {i} was copied");
        assert!(pixels(&s).iter().all(|p| *p == i), "image {i}'s pixels");
    }
    assert!(wait_for(|| measured.get_latest().map(|s| s.structure.valid_time()) == Ok(200)));
    let last = measured.get_latest().unwrap();
    assert_eq!(last.structure.get("y").and_then(|v| v.as_long()), Some(20));
    assert_eq!(unit_saw_copies.load(std::sync::atomic::Ordering::Relaxed), 0);
    // The replica's cache (bound 3) answers queries with the chunks in place.
    let cached = there.get_between(0, 1000).unwrap();
    assert_eq!(cached.len(), 3);
    assert!(cached.iter().all(|s| pixels(s).is_held()));
    drop(cached);
    let stats = reader.holding_stats().unwrap();
    assert!(stats.held_total >= 20, "{stats:?}");
    assert_eq!(stats.copied_over_budget, 0, "{stats:?}");

    // A reader that keeps every image spends its borrow budget: later images are
    // copied and counted, and still correct.
    let kept: Vec<Sample> = (21..=40u8)
        .map(|i| {
            frames.add(image(Time::from(i) * 10, i)).unwrap();
            sub.recv_timeout(TIMEOUT).unwrap()
        })
        .collect();
    for (s, i) in kept.iter().zip(21..=40u8) {
        assert!(pixels(s).iter().all(|p| *p == i), "image {i}'s pixels");
    }
    assert!(kept.iter().any(|s| !pixels(s).is_held()));
    let stats = reader.holding_stats().unwrap();
    assert!(stats.copied_over_budget > 0, "{stats:?}");

    // Dropping them returns the chunks: the next images are held again.
    drop(kept);
    frames.add(image(410, 41)).unwrap();
    let s = sub.recv_timeout(TIMEOUT).unwrap();
    assert!(pixels(&s).is_held());
    let held = reader.holding_stats().unwrap().held_now;
    assert!(held <= 3 + 3, "cache, unit input, subscription: {held} held");

    // An image kept past its process's connection stays readable: the chunk is never
    // given back while a value reads it.
    drop((sub, there, measured));
    drop(reader);
    for i in 42..=60u8 {
        frames.add(image(Time::from(i) * 10, i)).unwrap(); // the writer goes on
    }
    assert!(pixels(&s).is_held());
    assert!(pixels(&s).iter().all(|p| *p == 41), "kept image changed under its reader");
}

#[test]
fn a_replica_accounts_for_every_sample_of_a_burst() {
    let c = coordinator("loc-burst");
    let writer = location(&c, "writer");
    let reader = location(&c, "reader");
    let policy = FluentStreamPolicy::default().cache(esgm_core::CacheConstraint::Elements(4));
    let here = writer
        .create_trajectory(TrajectorySpec::primitive("burst", "RobotState").policy(policy))
        .unwrap();
    let there = reader.get_entity_trajectory_structure("burst").unwrap();
    // Connected: the writer's publisher knows this reader (until then, what it sends
    // reaches a new reader only through its history).
    here.add(state(0, 0.0)).unwrap();
    assert!(wait_for(|| there.stats().map(|s| s.added) == Ok(1)), "{:?}", there.stats());
    const N: u64 = 20_000;
    for i in 1..N as Time {
        here.add(state(i, i as f64)).unwrap();
    }
    // Received or counted as lost on the way: never silently missing.
    let accounted =
        || there.stats().map(|s| s.added + s.dropped_for(esgm_core::DropCause::Lost)).unwrap_or(0);
    assert!(wait_for(|| accounted() == N), "reader stats {:?}", there.stats());
    let latest = there.get_latest().unwrap();
    assert_eq!(latest.structure.valid_time(), N as Time - 1, "the last one arrives");
}

/// A reader asleep in `recv` while the name is re-pointed is woken by the new
/// trajectory's first sample, not at the end of its sleep's slice: the import it slept
/// on rings its word when it goes.
#[test]
fn a_reader_asleep_while_the_name_is_re_pointed_wakes_for_the_new_stream() {
    let c = coordinator("loc-repoint-asleep");
    let a = location(&c, "a");
    let b = location(&c, "b");
    let first = a.create_trajectory(TrajectorySpec::primitive("track", "RobotState")).unwrap();
    first.add(state(10, 1.0)).unwrap();
    let there = b.get_entity_trajectory_structure("track").unwrap();
    assert!(wait_for(|| there.stats().map(|s| s.stored) == Ok(1)), "{:?}", there.stats());
    let sub = there.subscribe(SubscribeOptions::default()).unwrap();
    let asleep = std::thread::spawn(move || {
        let started = Instant::now();
        let got = sub.recv_timeout(TIMEOUT);
        (got.map(|s| x(&s)), started.elapsed())
    });
    // Asleep on the first trajectory's writer by now.
    std::thread::sleep(Duration::from_millis(300));
    let second =
        a.create_trajectory(TrajectorySpec::primitive("track", "RobotState").replace()).unwrap();
    let added = Instant::now();
    while !asleep.is_finished() && added.elapsed() < TIMEOUT {
        second.add(state(5 + added.elapsed().as_millis() as i64, 100.0)).unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let (got, waited) = asleep.join().unwrap();
    assert_eq!(got.ok(), Some(100.0), "the sleeping reader never saw the new stream");
    assert!(
        waited < Duration::from_secs(5),
        "the sleeping reader was woken only after {waited:?}, not by the new stream"
    );
}
