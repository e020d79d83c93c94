//! Replay into a running ESGM and deterministic reruns, in process.

#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // a failure is a failed test

use std::path::Path;

#[path = "common/fixtures.rs"]
mod fixtures;
use fixtures::primitive as info;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use esgm_core::esgm::TrajectoryKind;
use esgm_core::library::RobotState;
use esgm_core::{
    CompUnit, ComputeError, Entity, EntityStructure, EntityStructureType,
    EntityTrajectoryStructure, Esgm, InProcessEsgm, InputType, Sample, Time, TrajectorySpec,
    ValueSort,
};
use esgm_recording::replay::{ReplayOptions, replay};
use esgm_recording::{
    Pace, RecordOptions, Recording, RecordingWriter, ReplayError, RerunPlan, RerunUnit, TimeMode,
    TypeSchema, rerun,
};

fn pose_type(sort: ValueSort) -> EntityStructureType {
    EntityStructureType::new("Marker").attr("x", sort)
}

/// A recording of `robot_state` (10 structures) and `pose` (10), interleaved.
fn record(path: &Path) {
    record_with(path, |_, x| x);
}

/// [`record`], each pose's x passed through `pose_x(i, x)`.
fn record_with(path: &Path, pose_x: impl Fn(i64, f64) -> f64) {
    let mut w = RecordingWriter::create(path, RecordOptions::default()).unwrap();
    let r = w
        .add_trajectory(
            info("robot_state", "RobotState"),
            TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
        )
        .unwrap();
    let p = w
        .add_trajectory(
            info("pose", "Marker"),
            TypeSchema::collect(pose_type(ValueSort::Double), &|_| None),
        )
        .unwrap();
    for i in 0..10_i64 {
        let t = 1_000_000 + i * 1_000;
        let rs = RobotState { x: i as f64, y: 0.0, dir: 0.0 }.to_structure("robot", t, t);
        w.write(r, &rs, t + 10, t + 20).unwrap();
        let pose = EntityStructure::new("pose", t + 5, t + 5).with("x", pose_x(i, i as f64 * 2.0));
        w.write(p, &pose, t + 15, t + 25).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_replay_publishes_every_recorded_structure_in_add_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("in.mcap");
    record(&path);
    let rec = Recording::open(&path).unwrap();
    let esgm = InProcessEsgm::default();
    let position = std::sync::Arc::new(esgm_recording::ReplayPosition::default());
    assert_eq!(position.valid_time(), None);
    let options = ReplayOptions {
        pace: Pace::Max,
        times: TimeMode::Keep,
        position: Some(std::sync::Arc::clone(&position)),
        ..ReplayOptions::default()
    };
    let report = replay(&esgm, &rec, &options, &AtomicBool::new(false)).unwrap();
    assert_eq!(report.published["robot_state"].added, 10, "{report:?}");
    assert_eq!(report.published["pose"].added, 10, "{report:?}");
    // The position a progress display reads: all 20, the last one's recorded valid time.
    assert_eq!((position.published(), position.passes()), (20, 1));
    assert_eq!(position.valid_time(), Some(1_009_005));
    assert_eq!(report.created.len(), 2);
    let t = esgm.get_entity_trajectory_structure("pose").unwrap();
    let all = t.get_between(0, Time::MAX).unwrap();
    assert_eq!(all.len(), 10);
    assert_eq!(all[3].structure.get("x").and_then(|v| v.as_double()), Some(6.0));
    assert_eq!(all[3].structure.valid_time(), 1_003_005, "times kept");
}

#[test]
fn shifted_times_keep_their_spacing_and_start_now() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("in.mcap");
    record(&path);
    let rec = Recording::open(&path).unwrap();
    let esgm = InProcessEsgm::default();
    let options = ReplayOptions {
        pace: Pace::Max,
        only: Some(vec!["robot_state".into()]),
        ..ReplayOptions::default()
    };
    let before = esgm_core::Clock::now(&esgm_core::SystemClock);
    let report = replay(&esgm, &rec, &options, &AtomicBool::new(false)).unwrap();
    assert!(!report.published.contains_key("pose"), "--only");
    let all = esgm
        .get_entity_trajectory_structure("robot_state")
        .unwrap()
        .get_between(0, Time::MAX)
        .unwrap();
    assert_eq!(all.len(), 10);
    assert!(all[0].structure.valid_time() >= before, "shifted to now");
    assert_eq!(
        all[9].structure.valid_time() - all[0].structure.valid_time(),
        9_000,
        "spacing kept"
    );
}

#[test]
fn a_type_that_differs_is_refused_naming_the_attribute_before_anything_is_published() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("in.mcap");
    record(&path);
    let rec = Recording::open(&path).unwrap();
    let esgm = InProcessEsgm::default();
    esgm.create_entity_structure_type("Marker", pose_type(ValueSort::Long)).unwrap();
    let e = replay(
        &esgm,
        &rec,
        &ReplayOptions { pace: Pace::Max, ..ReplayOptions::default() },
        &AtomicBool::new(false),
    )
    .expect_err("a conflicting type");
    assert!(matches!(e, ReplayError::TypeMismatch { .. }), "{e}");
    assert!(e.to_string().contains("Marker") && e.to_string().contains("`x`"), "{e}");
    assert!(esgm.trajectories().unwrap().is_empty(), "nothing was created");
}

#[test]
fn a_computed_trajectory_in_the_domain_is_not_written_over() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("in.mcap");
    record(&path);
    let rec = Recording::open(&path).unwrap();
    let esgm = InProcessEsgm::default();
    esgm.create_entity_structure_type("Marker", pose_type(ValueSort::Double)).unwrap();
    esgm.add_comp_unit(
        "Double",
        "Marker",
        vec![InputType::Type("Marker".into())],
        Arc::new(Doubler),
    )
    .unwrap();
    esgm.create_trajectory(TrajectorySpec::primitive("source", "Marker")).unwrap();
    esgm.create_trajectory(TrajectorySpec::computed("pose", "Double", ["source"])).unwrap();
    let e = replay(
        &esgm,
        &rec,
        &ReplayOptions { pace: Pace::Max, ..ReplayOptions::default() },
        &AtomicBool::new(false),
    )
    .expect_err("pose is computed here");
    assert!(e.to_string().contains("`pose`") && e.to_string().contains("computed"), "{e}");
}

/// Doubles `x` of its input; the result is valid when its input is.
struct Doubler;

impl CompUnit for Doubler {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let x = inputs
            .first()
            .and_then(|s| s.get("x"))
            .and_then(|v| v.as_double())
            .ok_or(ComputeError::ValueNotAvailable)?;
        Ok(EntityStructure::new("doubled", inputs[0].valid_time(), qtime).with("x", x * 2.0))
    }
}

/// Adds the robot's x to the pose's x: two inputs, so the result depends on which
/// input's update came last.
struct Sum;

impl CompUnit for Sum {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let x = |s: &Sample| {
            s.get("x").and_then(|v| v.as_double()).ok_or(ComputeError::ValueNotAvailable)
        };
        let valid = inputs[0].valid_time().max(inputs[1].valid_time());
        Ok(EntityStructure::new("sum", valid, qtime).with("x", x(&inputs[0])? + x(&inputs[1])?))
    }
}

/// The pipeline the reruns run: `doubled` = `double`(pose), `sum` = Sum(robot_state,
/// doubled).
fn plan(double: Arc<dyn CompUnit>) -> RerunPlan {
    RerunPlan {
        types: vec![("Marker".into(), pose_type(ValueSort::Double))],
        units: vec![
            RerunUnit {
                name: "Double".into(),
                output_type: "Marker".into(),
                inputs: vec![InputType::Type("Marker".into())],
                unit: double,
            },
            RerunUnit {
                name: "Sum".into(),
                output_type: "Marker".into(),
                inputs: vec![
                    InputType::Type("RobotState".into()),
                    InputType::Type("Marker".into()),
                ],
                unit: Arc::new(Sum),
            },
        ],
        trajectories: vec![
            TrajectorySpec::primitive("robot_state", "RobotState"),
            TrajectorySpec::primitive("pose", "Marker"),
            TrajectorySpec::computed("doubled", "Double", ["pose"]),
            TrajectorySpec::computed("sum", "Sum", ["robot_state", "doubled"]),
        ],
    }
}

/// The valid time of the fourth pose (i = 3), where the runs below differ.
const POSE_3: Time = 1_003_005;

/// [`Doubler`], one off at [`POSE_3`]: a unit changed between two runs.
struct Skewed;

impl CompUnit for Skewed {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let mut out = Doubler.compute(inputs, qtime)?;
        if out.valid_time == POSE_3 {
            out = out.with("x", -1.0);
        }
        Ok(out)
    }
}

/// `compare` follows a differing output's lineage through both recordings to where
/// the difference comes from (X1): reruns of one pipeline, first on inputs that
/// differ in one pose (the origin is that recorded pose), then with `doubled`'s unit
/// changed (the origin is that unit: its inputs are the same in both).
#[test]
fn compare_follows_lineage_to_the_input_or_the_unit_a_difference_comes_from() {
    use esgm_recording::compare::{DifferenceOrigin, InputVerdict};
    use esgm_recording::{CompareOptions, compare};
    let dir = tempfile::tempdir().unwrap();
    let run = |input: &Path, double: Arc<dyn CompUnit>, out: &str| {
        let out = dir.path().join(out);
        let rec = Recording::open(input).unwrap();
        let writer = RecordingWriter::create(&out, RecordOptions::default()).unwrap();
        rerun(&rec, &plan(double), Some(writer)).unwrap();
        Recording::open(&out).unwrap()
    };
    let (same, other) = (dir.path().join("in.mcap"), dir.path().join("other.mcap"));
    record(&same);
    record_with(&other, |i, x| if i == 3 { x + 0.5 } else { x });
    let a = run(&same, Arc::new(Doubler), "a.mcap");
    let b = run(&other, Arc::new(Doubler), "b.mcap");
    let c = run(&same, Arc::new(Skewed), "c.mcap");
    let first = |report: &esgm_recording::CompareReport, name: &str| {
        let t = report.trajectories.iter().find(|t| t.name == name).unwrap();
        t.first_difference.clone().unwrap_or_else(|| panic!("`{name}` does not differ: {t:#?}"))
    };
    let pose_3 = DifferenceOrigin::Source { trajectory: "pose".into(), valid_time: POSE_3 };

    // Other inputs: `sum` differs first where it took the differing pose's double.
    let report = compare(&a, &b, &CompareOptions::default()).unwrap();
    let sum = first(&report, "sum");
    assert_eq!((sum.valid_time, sum.attribute.as_str()), (POSE_3, "x"), "{sum:#?}");
    assert_eq!(sum.origins, vec![pose_3.clone()], "{sum:#?}");
    let verdicts: Vec<(&str, bool)> = sum
        .inputs
        .iter()
        .map(|i| (i.trajectory.as_str(), i.verdict == InputVerdict::Same))
        .collect();
    assert_eq!(verdicts, [("robot_state", true), ("doubled", false)]);
    let doubled = &sum.inputs[1];
    assert!(doubled.produced && doubled.inputs.len() == 1, "{doubled:#?}");
    assert_eq!(doubled.inputs[0].trajectory, "pose");
    assert!(
        matches!(&doubled.inputs[0].verdict, InputVerdict::Differs { attribute, a, b }
            if attribute == "x" && a == "6" && b == "6.5"),
        "{doubled:#?}"
    );
    assert_eq!(first(&report, "doubled").origins, vec![pose_3]);

    // The same inputs, another unit: the origin is the unit of `doubled`.
    let report = compare(&a, &c, &CompareOptions::default()).unwrap();
    let unit = DifferenceOrigin::Producer { trajectory: "doubled".into(), valid_time: POSE_3 };
    assert_eq!(first(&report, "doubled").origins, vec![unit.clone()]);
    let sum = first(&report, "sum");
    assert_eq!(sum.origins, vec![unit], "{sum:#?}");
    assert_eq!(sum.inputs[1].inputs[0].verdict, InputVerdict::Same);
    // Identical runs: nothing differs, nothing to follow.
    let again = run(&same, Arc::new(Doubler), "again.mcap");
    assert!(!compare(&a, &again, &CompareOptions::default()).unwrap().differs());
}

#[test]
fn a_rerun_is_deterministic_and_runs_units_as_the_runtime_does() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("in.mcap");
    record(&path);
    let rec = Recording::open(&path).unwrap();
    let plan = plan(Arc::new(Doubler));
    let run = |out: &str| {
        let out = dir.path().join(out);
        let writer = RecordingWriter::create(
            &out,
            RecordOptions::default().flush_interval(std::time::Duration::MAX),
        )
        .unwrap();
        let report = rerun(&rec, &plan, Some(writer)).unwrap();
        (report, std::fs::read(&out).unwrap(), out)
    };
    let (report, first, out) = run("a.mcap");
    let (_, second, _) = run("b.mcap");
    assert!(first == second, "the same rerun wrote different bytes");
    assert_eq!(report.trajectories["doubled"].added, 10);
    // Add order: r0 p0 r1 p1 …; `sum` runs on every update once both inputs have one:
    // p0 (doubled 0) completes it, then r1, d1, r2, d2, … : 1 + 2 × 9 calls.
    assert_eq!(report.trajectories["sum"].calls, 19, "{report:?}");
    let rerun = Recording::open(&out).unwrap();
    let sums: Vec<f64> = rerun
        .samples()
        .unwrap()
        .map(Result::unwrap)
        .filter(|s| rerun.trajectories[s.trajectory].info.name == "sum")
        .map(|s| s.structure.get("x").and_then(|v| v.as_double()).unwrap())
        .collect();
    // After r_i: r_i + d_(i-1) = i + 4(i-1); after d_i: i + 4i.
    assert_eq!(&sums[..5], &[0.0, 1.0, 5.0, 6.0, 10.0], "{sums:?}");
    let doubled = rerun.trajectory("doubled").unwrap();
    assert_eq!(doubled.info.kind, TrajectoryKind::Computed);
    assert_eq!(doubled.info.inputs, vec!["pose".to_string()]);
}
