//! Issue 39's fault campaign in a debug build: `esgm chaos` runs a small robot while it
//! kills its processes (the coordinator too) with SIGKILL, and must find every
//! acknowledged structure still held or evicted by the policy, each loss with its
//! cause, memory and `/dev/shm` back within their bound, and nothing left after
//! `esgm down`. The 10-minute run at the default profile is in BENCHMARKS.md.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::time::Duration;

use common::esgm;

/// Six processes of a debug build on 2 cores, killed twice a second for 15 s, then
/// brought back and checked.
const LIMIT: Duration = Duration::from_secs(600);

#[test]
fn a_robot_whose_processes_are_killed_at_random_loses_nothing_acknowledged() {
    let out = std::env::temp_dir().join(format!("esgm-chaos-test-{}", std::process::id()));
    let dir = out.to_str().unwrap();
    let o = esgm(
        &[
            "chaos",
            "--trajectories",
            "16",
            "--processes",
            "6",
            "--seconds",
            "15",
            "--kill-every",
            "0.5",
            "--seed",
            "39",
            "--out",
            dir,
        ],
        LIMIT,
    );
    assert_eq!(o.code, Some(0), "esgm chaos failed:\n{}\n{}", o.stdout, o.stderr);
    assert!(o.stdout.contains("seed 39"), "the seed is printed:\n{}", o.stdout);
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("chaos.json")).unwrap()).unwrap();
    let kills = &r["kills"];
    let workers = ["writer_and_reader", "writer", "reader"]
        .iter()
        .map(|k| kills[k].as_u64().unwrap())
        .sum::<u64>();
    assert!(workers >= 5, "too few workers were killed: {kills}");
    let checked = &r["checked"];
    assert!(checked["checked"].as_u64().unwrap() > 0, "nothing checked: {checked}");
    assert!(checked["acknowledged"].as_u64().unwrap() > 1000, "too little written: {checked}");
    for failed in ["lost", "duplicated", "unacknowledged"] {
        assert!(checked[failed].as_array().unwrap().is_empty(), "{failed}: {checked}");
    }
    assert!(r["left_behind"].as_array().unwrap().is_empty(), "left: {}", r["left_behind"]);
    assert!(r["failures"].as_array().unwrap().is_empty(), "failures: {}", r["failures"]);
    std::fs::remove_dir_all(&out).unwrap();
}
