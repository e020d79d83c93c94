//! `esgm soak` end to end: a short run of the real binaries writes a report whose
//! series have samples, whose processes have memory and whose counts grow, draws its
//! chart, and leaves nothing of its domain behind.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::{ESGM, StopOnDrop, finish};
use serde_json::Value;

#[test]
fn a_short_soak_reports_every_series_and_leaves_nothing() {
    let d = esgm_shm::unique_domain("cli-soak");
    let _stop = StopOnDrop(d.clone());
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().to_str().unwrap();
    // The coordinator's and workers' log lines go to a file, not a pipe nobody reads
    // until the end.
    let log = std::fs::File::create(out.path().join("stderr.log")).unwrap();
    let child = Command::new(ESGM)
        .args(["--domain", &d, "soak", "--seconds", "5", "--no-check", "--out", dir])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log)
        .spawn()
        .unwrap();
    let o = finish(child, Duration::from_secs(180), "soak --seconds 5");
    let stderr = std::fs::read_to_string(out.path().join("stderr.log")).unwrap();
    assert_eq!(o.code, Some(0), "soak failed:\n{}\n{stderr}", o.stdout);
    assert!(o.stdout.contains("verdict:"), "no verdict:\n{}", o.stdout);

    let report: Value =
        serde_json::from_slice(&std::fs::read(out.path().join("soak.json")).unwrap()).unwrap();
    assert_eq!(report["domain"], d.as_str());
    let samples = report["samples"].as_array().unwrap();
    assert!(samples.len() >= 3, "{} samples", samples.len());

    // Every process of the tutorial, in every sample, with resident memory.
    let processes = [
        "coordinator",
        "camera-camera",
        "robot-robot_state",
        "unit-BlobDetection",
        "unit-BlobSelection",
        "unit-DrivingDirection",
    ];
    for name in processes {
        let rss: Vec<u64> =
            samples.iter().filter_map(|s| s["processes"][name]["rss"].as_u64()).collect();
        assert!(rss.len() >= 3, "{name}: {} samples", rss.len());
        assert!(rss.iter().all(|b| *b > 0), "{name} has no resident memory: {rss:?}");
    }
    // The domain's shared memory is measured, by allocated bytes.
    let shm: Vec<u64> = samples.iter().filter_map(|s| s["shm"]["allocated"].as_u64()).collect();
    assert!(shm.len() >= 3 && shm.iter().all(|b| *b > 0), "shared memory: {shm:?}");

    // Every trajectory is counted in at least three samples, and its count grows.
    for trajectory in ["robot_state", "images", "blobs", "current_blob", "driving_direction"] {
        let added: Vec<u64> = samples
            .iter()
            .filter_map(|s| s["trajectories"][trajectory]["added"].as_u64())
            .collect();
        assert!(added.len() >= 3, "{trajectory}: {} samples", added.len());
        assert!(added.windows(2).all(|w| w[0] <= w[1]), "{trajectory} went back: {added:?}");
        assert!(added.last() > added.first(), "{trajectory} did not grow: {added:?}");
    }

    // The verdict and the picture.
    assert!(report["verdict"]["rss"].as_array().unwrap().len() == processes.len());
    assert_eq!(report["left_behind"], Value::Array(Vec::new()));
    let png = std::fs::read(out.path().join("soak.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "soak.png is not a PNG");

    // Nothing of the domain is left: no coordinator, no node.
    let nodes = esgm_shm::nodes_of(&d).expect("cannot list iceoryx2 nodes");
    assert!(nodes.is_empty(), "nodes of `{d}` left behind: {nodes:?}");
    assert!(esgm_shm::control::ControlClient::connect(&d, Duration::from_millis(200)).is_err());
}
