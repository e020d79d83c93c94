//! `load`: recorded trajectories made queryable in an ESGM with their recorded
//! policies; conflicts refused before anything is created.

// Test code: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;

use esgm_core::clock::SharedClock;
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::{Image, RobotState};
use esgm_core::type_registry::TypeRegistry;
use esgm_core::{
    Attr, CacheConstraint, DelayConstraint, Entity, EntityStructure, EntityTrajectoryStructure,
    Esgm, FluentStreamPolicy, InProcessEsgm, OrderConstraint, SimClock, ValueApproximation,
    ValueSort,
};
use esgm_recording::{
    LoadError, LoadOptions, RecordOptions, Recording, RecordingWriter, Relaxation, TypeSchema, load,
};

fn info(name: &str, type_name: &str, policy: FluentStreamPolicy) -> TrajectoryInfo {
    TrajectoryInfo::new(name, TrajectoryKind::Computed, type_name).source("unit").policy(policy)
}

fn robot(i: i64) -> EntityStructure {
    RobotState { x: i as f64, y: 0.0, dir: 0.0 }.to_structure(
        "robot",
        1_000 + i * 100,
        1_000 + i * 100,
    )
}

fn image(i: i64) -> EntityStructure {
    let pixels: Vec<u8> = (0..4 * 2 * 3).map(|p| (p as i64 + i) as u8).collect();
    Image { width: 4, height: 2, format: Image::FORMAT_RGB8, image_data: pixels.into() }
        .to_structure("camera", 1_000 + i * 100, 1_000 + i * 100)
}

/// Robot states at valid times 1000, 1100, … added 50 later; images likewise.
fn write(
    path: &Path,
    n: i64,
    robot_policy: FluentStreamPolicy,
    robot_type: EntityStructureTypeArg,
) {
    let mut w = RecordingWriter::create(path, RecordOptions::default()).expect("create");
    let r = w
        .add_trajectory(
            info("robot_state", "RobotState", robot_policy),
            TypeSchema::collect(robot_type.0, &|_| None),
        )
        .expect("add");
    let c = w
        .add_trajectory(
            info("images", "Image", FluentStreamPolicy::default()),
            TypeSchema::collect(Image::entity_structure_type(), &|_| None),
        )
        .expect("add");
    for i in 0..n {
        let vt = 1_000 + i * 100;
        w.write(r, &robot(i), vt + 50, vt + 60).expect("write");
        w.write(c, &image(i), vt + 55, vt + 60).expect("write");
    }
    w.finish().expect("finish");
}

struct EntityStructureTypeArg(esgm_core::EntityStructureType);

fn robot_type() -> EntityStructureTypeArg {
    EntityStructureTypeArg(RobotState::entity_structure_type())
}

fn sim_esgm() -> (InProcessEsgm, std::sync::Arc<SimClock>) {
    let clock = SimClock::shared(0);
    let shared: SharedClock = clock.clone();
    let esgm = InProcessEsgm::builder().clock(shared).types(TypeRegistry::new()).create();
    (esgm, clock)
}

fn x(s: &esgm_core::Sample) -> f64 {
    s.structure.get("x").and_then(|v| v.as_double()).unwrap_or(f64::NAN)
}

#[test]
fn loaded_trajectories_answer_latest_between_at_and_approximating() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    write(&path, 10, FluentStreamPolicy::default().order(OrderConstraint::Monotone), robot_type());
    let rec = Recording::open(&path).expect("open");
    let (esgm, clock) = sim_esgm();
    let report = load(&esgm, &rec, &LoadOptions::new().sim_clock(clock)).expect("load");
    assert!(report.simulated_clock);
    let mut registered = report.types_registered.clone();
    registered.sort();
    assert_eq!(registered, ["Image", "RobotState"], "missing types registered");
    for t in &report.trajectories {
        assert_eq!(
            (t.offered, t.added, t.stored, t.evicted, t.late_adds),
            (10, 10, 10, 0, 0),
            "{t:?}"
        );
        assert!(t.dropped.is_empty() && t.relaxed.is_empty(), "{t:?}");
    }
    let robot_t = esgm.get_entity_trajectory_structure("robot_state").expect("loaded");
    let latest = robot_t.get_latest().expect("latest");
    assert_eq!(latest.structure, robot(9));
    assert_eq!(latest.add_time, 1_000 + 900 + 50, "the recorded add time, on the simulated clock");
    let between: Vec<f64> =
        robot_t.get_between(1_200, 1_400).expect("between").iter().map(x).collect();
    assert_eq!(between, [2.0, 3.0, 4.0]);
    assert_eq!(robot_t.get_at(1_500).expect("at").structure, robot(5));
    let linear =
        robot_t.get_at_approximating(1_550, &ValueApproximation::Linear).expect("approximating");
    assert_eq!(x(&linear), 5.5);
    let recent = robot_t
        .get_at_approximating(1_590, &ValueApproximation::MostRecent)
        .expect("approximating");
    assert_eq!(x(&recent), 5.0);
    let images = esgm.get_entity_trajectory_structure("images").expect("loaded");
    assert_eq!(images.get_at(1_300).expect("at").structure, image(3), "images exact");
    // Loaded as primitive trajectories (a computed one is loaded as what it produced).
    let kinds: Vec<TrajectoryKind> = esgm.trajectories().unwrap().iter().map(|t| t.kind).collect();
    assert_eq!(kinds, [TrajectoryKind::Primitive, TrajectoryKind::Primitive]);
}

#[test]
fn the_recorded_policy_applies_with_its_cache_and_its_delay_on_a_simulated_clock() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .cache(CacheConstraint::Elements(4))
        .delay(DelayConstraint::Max(80))
        .reorder(false);
    write(&path, 10, policy.clone(), robot_type());
    let rec = Recording::open(&path).expect("open");
    let (esgm, clock) = sim_esgm();
    let report = load(&esgm, &rec, &LoadOptions::new().sim_clock(clock)).expect("load");
    let t = report.trajectories.iter().find(|t| t.name == "robot_state").expect("loaded");
    assert_eq!(t.policy, policy);
    assert_eq!(
        (t.added, t.evicted, t.stored),
        (10, 6, 4),
        "the recorded cache bound applies and is reported"
    );
    assert!(t.dropped.is_empty(), "added 50 after valid time, within the delay of 80: {t:?}");
    let loaded = esgm.get_entity_trajectory_structure("robot_state").expect("loaded");
    assert_eq!(loaded.policy().expect("policy"), policy, "the recorded policy is the trajectory's");
    assert_eq!(loaded.get_between(0, i64::MAX).expect("between").len(), 4);

    // A delay the recorded adds exceed drops them, counted by cause.
    let strict = dir.path().join("strict.mcap");
    write(&strict, 10, FluentStreamPolicy::default().delay(DelayConstraint::Max(20)), robot_type());
    let (esgm, clock) = sim_esgm();
    let report =
        load(&esgm, &Recording::open(&strict).expect("open"), &LoadOptions::new().sim_clock(clock))
            .expect("load");
    let t = report.trajectories.iter().find(|t| t.name == "robot_state").expect("loaded");
    assert_eq!((t.added, t.dropped.get("delay").copied()), (0, Some(10)), "{t:?}");
}

#[test]
fn a_real_clock_relaxes_the_delay_and_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    write(&path, 10, FluentStreamPolicy::default().delay(DelayConstraint::Max(80)), robot_type());
    let esgm = InProcessEsgm::default();
    let report =
        load(&esgm, &Recording::open(&path).expect("open"), &LoadOptions::new()).expect("load");
    let t = report.trajectories.iter().find(|t| t.name == "robot_state").expect("loaded");
    assert_eq!(t.relaxed, [Relaxation::Delay { recorded: DelayConstraint::Max(80) }]);
    assert_eq!(t.policy.delay, DelayConstraint::Any);
    assert_eq!((t.added, t.stored), (10, 10), "{t:?}");
    assert!(report.types_registered.is_empty(), "the library's types are equal: {report:?}");
}

#[test]
fn a_type_conflict_is_refused_before_anything_is_created() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let mut other = RobotState::entity_structure_type();
    other.attributes[2] = Attr::new("dir", ValueSort::Long);
    write(&path, 3, FluentStreamPolicy::default(), EntityStructureTypeArg(other));
    let rec = Recording::open(&path).expect("open");
    // The ESGM knows the library's RobotState (dir: Double), not the recording's, and
    // has no Image type.
    let mut types = TypeRegistry::new();
    types
        .create_entity_structure_type("RobotState", RobotState::entity_structure_type())
        .expect("type");
    let esgm = InProcessEsgm::builder().types(types).create();
    let e = load(&esgm, &rec, &LoadOptions::default()).expect_err("conflict");
    let LoadError::TypeConflict { difference, .. } = &e else { panic!("{e}") };
    assert_eq!(
        (difference.type_name.as_str(), difference.attribute.as_deref()),
        ("RobotState", Some("dir"))
    );
    assert!(e.to_string().contains("RobotState") && e.to_string().contains("dir"), "{e}");
    assert!(esgm.trajectories().unwrap().is_empty(), "no trajectory created");
    assert!(esgm.get_entity_structure_type("Image").is_err(), "no type registered");
}

#[test]
fn an_existing_trajectory_is_refused_by_name_unless_replaced() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    write(&path, 3, FluentStreamPolicy::default(), robot_type());
    let rec = Recording::open(&path).expect("open");
    let esgm = InProcessEsgm::default();
    esgm.create_primitive_entity_trajectory_structure("images", "Image").expect("create");
    let e = load(&esgm, &rec, &LoadOptions::default()).expect_err("exists");
    assert!(matches!(&e, LoadError::TrajectoryExists { name } if name == "images"), "{e}");
    assert_eq!(esgm.trajectories().unwrap().len(), 1, "robot_state was not created either");
    let report = load(&esgm, &rec, &LoadOptions::new().replace(true)).expect("replace");
    assert!(report.trajectories.iter().any(|t| t.name == "images" && t.replaced && t.stored == 3));
    let only = load(&InProcessEsgm::default(), &rec, &LoadOptions::new().only(["robot_state"]))
        .expect("only");
    assert_eq!(only.trajectories.len(), 1);
}
