//! Issue 23 in a debug build: a domain of 200 trajectories in 40 processes, where every
//! process writes some and reads others, holds up. `esgm scale` runs it as a user would;
//! this test checks what a debug build on a shared machine can promise (every worker
//! set up and error-free, every class of trajectory delivered to its readers, every
//! loss explained, nothing left in shared memory), not the timing targets, which the
//! release build's `esgm scale` and `esgm-bench` measure.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::time::Duration;

use common::esgm;

/// A debug build of 40 processes on 2 cores: connects, creations and subscriptions at
/// once take a minute or two; the run itself takes about 10 s.
const LIMIT: Duration = Duration::from_secs(600);

#[test]
fn a_domain_of_200_trajectories_and_40_processes_holds_up() {
    let out = std::env::temp_dir().join(format!("esgm-scale-test-{}", std::process::id()));
    let dir = out.to_str().unwrap();
    let o = esgm(
        &[
            "scale",
            "--trajectories",
            "200",
            "--processes",
            "40",
            "--settle-seconds",
            "1",
            "--idle-seconds",
            "2",
            "--seconds",
            "4",
            "--out",
            dir,
            // Timing targets are for the release build: the checks below are this
            // test's.
            "--no-check",
        ],
        LIMIT,
    );
    assert_eq!(o.code, Some(0), "esgm scale failed:\n{}\n{}", o.stdout, o.stderr);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scale.json")).unwrap()).unwrap();
    let m = &report["measured"];

    assert_eq!(m["trajectories"], 200);
    assert_eq!(m["processes"], 40);
    assert_eq!(m["errors"].as_array().unwrap().len(), 0, "worker errors: {}", m["errors"]);
    let left = m["left_behind"].as_array().unwrap();
    assert!(left.is_empty(), "left in shared memory: {left:?}");

    // Every process writes and reads.
    let workers = m["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 40);
    for (i, w) in workers.iter().enumerate() {
        assert!(w["writes"].as_u64().unwrap() > 0, "worker {i} writes nothing: {w}");
        assert!(w["reads"].as_u64().unwrap() > 0, "worker {i} reads nothing: {w}");
    }

    // Every class reached its readers, and every trajectory was written.
    for class in ["tf", "image", "small"] {
        let received = m["latency"][class]["received"].as_u64().unwrap_or(0);
        assert!(received > 0, "no `{class}` structure reached a reader: {}", m["latency"]);
    }
    let counts = m["trajectory_counts"].as_object().unwrap();
    assert_eq!(counts.len(), 200, "counters of {} trajectories", counts.len());
    for (name, c) in counts {
        assert!(c["added"].as_u64().unwrap() > 0, "`{name}` was never written: {c}");
    }

    // The verdict's own accounting: no worker error, no loss without a cause.
    let checks = report["verdict"]["checks"].as_array().unwrap();
    for c in checks {
        let target = c["target"].as_str().unwrap();
        if target.starts_with("no ") || target.ends_with(" delivered") {
            assert_eq!(c["met"], true, "{target}: {}", c["measured"]);
        }
    }
    assert!(
        checks.iter().any(|c| c["target"].as_str().unwrap().starts_with("no loss")),
        "the verdict lost its loss check: {checks:?}"
    );
    std::fs::remove_dir_all(&out).unwrap();
}
