//! `esgm compare` and `esgm load` end to end: the real binary, exit codes, and a
//! recording loaded into a live domain that still answers after `esgm load` exits.
//! Every command runs under a watchdog.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::time::Duration;

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::RobotState;
use esgm_core::{DelayConstraint, Entity, EntityStructure, FluentStreamPolicy, OrderConstraint};
use esgm_recording::{RecordOptions, RecordingWriter, TypeSchema};

mod common;

use common::{StopOnDrop, esgm, ok};

const T0: i64 = 1_700_000_000_000_000_000;

fn robot(i: i64, y: f64) -> EntityStructure {
    let vt = T0 + i * 100_000_000;
    RobotState { x: i as f64, y, dir: 0.0 }.to_structure("robot", vt, vt)
}

/// Ten robot states 100 ms apart, added 5 ms after their valid times; state 4's `y`
/// is `y4`.
fn write(path: &Path, y4: f64) {
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .delay(DelayConstraint::Max(50_000_000))
        .reorder(false);
    let info =
        TrajectoryInfo::new("robot_state", TrajectoryKind::Primitive, "RobotState").policy(policy);
    let mut w = RecordingWriter::create(path, RecordOptions::default()).unwrap();
    let t = w
        .add_trajectory(info, TypeSchema::collect(RobotState::entity_structure_type(), &|_| None))
        .unwrap();
    for i in 0..10 {
        let es = robot(i, if i == 4 { y4 } else { 0.0 });
        let add = es.valid_time + 5_000_000;
        w.write(t, &es, add, add + 1_000).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn compare_exits_0_when_recordings_match_and_1_when_they_differ() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) =
        (dir.path().join("a.mcap"), dir.path().join("b.mcap"), dir.path().join("c.mcap"));
    write(&a, 0.0);
    write(&b, 0.0);
    write(&c, 2.5);
    let (a, b, c) = (a.to_str().unwrap(), b.to_str().unwrap(), c.to_str().unwrap());

    let same = ok(&["compare", a, b]);
    assert!(same.contains("the recordings match"), "{same}");

    let o = esgm(&["compare", a, c], Duration::from_secs(60));
    assert_eq!(o.code, Some(1), "{}\n{}", o.stdout, o.stderr);
    assert!(o.stderr.trim().is_empty(), "a difference is not an error: {}", o.stderr);
    let vt = (T0 + 400_000_000).to_string();
    assert!(o.stdout.contains("DIFFER") && o.stdout.contains(&vt), "{}", o.stdout);
    assert!(o.stdout.contains("y = 0 in A, 2.5 in B"), "{}", o.stdout);

    let o = esgm(&["--json", "compare", a, c], Duration::from_secs(60));
    assert_eq!(o.code, Some(1));
    let v: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(v["trajectories"][0]["first_difference"]["attribute"], "y");
    assert_eq!(v["trajectories"][0]["largest_deviation"]["deviation"], 2.5);

    // Within a numeric tolerance they match; nearest alignment needs a duration.
    ok(&["compare", a, c, "--tolerance", "3"]);
    ok(&["compare", a, c, "--approx", "nearest", "--tolerance", "1ms", "--tolerance", "3"]);
    let o = esgm(&["compare", a, c, "--approx", "nearest"], Duration::from_secs(60));
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr.starts_with("esgm: ") && o.stderr.contains("duration --tolerance"),
        "{}",
        o.stderr
    );
    let o = esgm(&["compare", a, "/nonexistent.mcap"], Duration::from_secs(60));
    assert_eq!(o.code, Some(1));
    assert!(o.stderr.contains("/nonexistent.mcap"), "{}", o.stderr);
}

#[test]
fn a_loaded_recording_answers_queries_after_esgm_load_exits() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write(&path, 2.5);
    let file = path.to_str().unwrap();
    let d = esgm_shm::unique_domain("cli-load");
    ok(&["--domain", &d, "up", "--detach"]);
    let _stop = StopOnDrop(d.clone());

    let out = ok(&["--domain", &d, "load", file]);
    assert!(out.contains("robot_state") && out.contains("relaxed to any"), "{out}");
    // `esgm load` has exited: the system's own process writes what it loaded.
    let latest = ok(&["--domain", &d, "--json", "latest", "robot_state"]);
    let v: serde_json::Value = serde_json::from_str(latest.trim()).unwrap();
    assert_eq!(v["valid_time"], T0 + 900_000_000);
    assert_eq!(v["attributes"]["x"], 9.0);
    let from = (T0 + 300_000_000).to_string();
    let to = (T0 + 500_000_000).to_string();
    let between = ok(&["--domain", &d, "--json", "between", "robot_state", &from, &to]);
    assert_eq!(between.lines().count(), 3, "{between}");
    assert!(between.contains("\"y\":2.5"), "{between}");
    let at = ok(&[
        "--domain",
        &d,
        "--json",
        "approx",
        "robot_state",
        &(T0 + 450_000_000).to_string(),
        "--method",
        "linear",
    ]);
    assert!(at.contains("\"x\":4.5"), "{at}");

    // Loading again is refused by name, before anything changes.
    let o = esgm(&["--domain", &d, "load", file], Duration::from_secs(60));
    assert_eq!(o.code, Some(1));
    assert!(o.stderr.contains("robot_state") && o.stderr.contains("exists"), "{}", o.stderr);
    let json = ok(&["--domain", &d, "--json", "load", file, "--replace"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["trajectories"][0]["added"], 10);
    assert_eq!(v["trajectories"][0]["replaced"], true);
}
