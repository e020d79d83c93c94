//! A ROS 2 node declared in a system's TOML file (`[[ros2]]`): `esgm apply` checks it
//! with the process's own parser (refused naming the line), has the supervisor run
//! `esgm-ros2`, and restarts it after `kill -9`; images a stand-in ROS 2 node publishes
//! (the `cyclonedds` package from PyPI) reach the trajectory, and the tutorial's blob
//! detection runs on them unchanged.
//!
//! DDS discovery is multicast: the whole system (`esgm up`, hence its workers) and the
//! stand-in run in a loopback-only network namespace this test makes.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

/// The venv with the independent implementations (`target/py-venv`).
#[path = "../../../../esgm-core/recording/tests/common/python.rs"]
mod python;

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::netns::Namespace;
use common::{ESGM, StopOnDrop, capability, esgm, ok};

const WAIT: Duration = Duration::from_secs(60);

fn peer_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../ros2/tests/python/ros2_peer.py")
}

/// The `ros2` worker's pid, as `esgm ps --json` shows it (a JSON line per process).
fn ros2_pid(domain: &str) -> Option<u64> {
    let o = esgm(&["--domain", domain, "--json", "ps"], WAIT);
    o.stdout
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|p| p["spec"]["name"] == "ros2")
        .and_then(|p| p["status"]["pid"].as_u64())
}

#[test]
fn a_ros2_node_declared_in_toml_imports_a_topic_and_comes_back_after_kill_9() {
    let ros2 = Path::new(ESGM).with_file_name("esgm-ros2");
    let built = capability::built(&ros2);
    if capability::needs("esgm-ros2 (cargo build -p esgm-ros2)", built).is_none() {
        return;
    }
    let Some(ns) = capability::needs("root and `ip netns`", Namespace::create("ros2cfg")) else {
        return;
    };
    let python = python::venv_python();
    let dir = tempfile::tempdir().unwrap();
    let domain = esgm_shm::unique_domain("cli-ros2");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "\n[[ros2]]\nimport = [\"/scan:sensor_msgs/msg/LaserScan\"]\n").unwrap();
    let good = dir.path().join("ros2.toml");
    // The tutorial's blob detection, unchanged, on the imported camera.
    std::fs::write(
        &good,
        "[[ros2]]\nimport = [\"/camera/image_raw:sensor_msgs/msg/Image=images\"]\n\n\
         [[unit]]\nname = \"BlobDetection\"\n\n\
         [[trajectory]]\nname = \"images\"\nprimitive = \"Image\"\nwriter = \"ros2\"\n\
         policy = { cache = 5 }\n\n\
         [[trajectory]]\nname = \"blobs\"\ncomputed = \"BlobDetection\"\ninputs = [\"images\"]\n",
    )
    .unwrap();

    let up = ns
        .command(ESGM)
        .args(["--domain", &domain, "up", "--detach"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert!(up.status.success(), "{}", String::from_utf8_lossy(&up.stderr));
    let _stop = StopOnDrop(domain.clone());

    // A type that does not map is refused naming the line and the types that do.
    let o = esgm(&["--domain", &domain, "apply", bad.to_str().unwrap()], WAIT);
    assert_eq!(o.code, Some(1), "{}", o.stdout);
    assert!(
        o.stderr.contains("bad.toml:2:") && o.stderr.contains("sensor_msgs/msg/Image (Image)"),
        "{}",
        o.stderr
    );

    ok(&["--domain", &domain, "apply", good.to_str().unwrap()]);
    let deadline = Instant::now() + WAIT;
    let first = loop {
        if let Some(pid) = ros2_pid(&domain) {
            break pid;
        }
        assert!(Instant::now() < deadline, "no ros2 worker: {}", ok(&["--domain", &domain, "ps"]));
        std::thread::sleep(Duration::from_millis(100));
    };
    // Killed, it comes back (a new pid), and then imports what a ROS 2 node publishes.
    assert!(
        std::process::Command::new("kill")
            .args(["-9", &first.to_string()])
            .status()
            .unwrap()
            .success()
    );
    let deadline = Instant::now() + WAIT;
    while ros2_pid(&domain).is_none_or(|p| p == first) {
        assert!(Instant::now() < deadline, "the ros2 worker did not come back");
        std::thread::sleep(Duration::from_millis(100));
    }
    let published = ns
        .command(python.to_str().unwrap())
        .arg(peer_script())
        .args(["publish-images", "/camera/image_raw", "3"])
        .output()
        .unwrap();
    assert!(published.status.success(), "{}", String::from_utf8_lossy(&published.stderr));
    let deadline = Instant::now() + WAIT;
    loop {
        let o = esgm(&["--domain", &domain, "--json", "latest", "images"], WAIT);
        if o.code == Some(0) {
            let v: serde_json::Value = serde_json::from_str(o.stdout.trim()).unwrap();
            // The third image: stamp 1000 s + 2 ms.
            if v["valid_time"].as_i64() == Some(1_000_002_000_000) {
                assert_eq!(v["attributes"]["width"].as_i64(), Some(4), "{v}");
                break;
            }
        }
        assert!(Instant::now() < deadline, "the images never arrived: {}", o.stderr);
        std::thread::sleep(Duration::from_millis(100));
    }
    // The blob detection ran on the third image too.
    let deadline = Instant::now() + WAIT;
    loop {
        let o = esgm(&["--domain", &domain, "--json", "latest", "blobs"], WAIT);
        if o.code == Some(0) && o.stdout.contains("1000002000000") {
            break;
        }
        assert!(Instant::now() < deadline, "no blobs of the third image: {}{}", o.stdout, o.stderr);
        std::thread::sleep(Duration::from_millis(100));
    }
}
