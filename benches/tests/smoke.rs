//! Runs the real `esgm-bench` binary on one small scenario and reads its JSON back.
//! No figure is asserted: speed is measured, not tested.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous for a debug build; only there so that a hang fails instead of blocking CI.
const WATCHDOG: Duration = Duration::from_secs(120);

#[test]
fn quick_hop_small_writes_the_json_report() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("report.json");
    let mut child = Command::new(env!("CARGO_BIN_EXE_esgm-bench"))
        .args(["--quick", "--only", "inproc-hop-small", "--samples", "200", "--json"])
        .arg(&json)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();

    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > WATCHDOG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("esgm-bench did not finish within {WATCHDOG:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let output = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(status.success(), "esgm-bench failed ({status}):\n{stdout}\n{stderr}");
    assert!(stdout.contains("inproc-hop-small"), "the table lacks the scenario:\n{stdout}");

    let text = std::fs::read_to_string(&json).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    let rows = report["scenarios"].as_array().expect("a `scenarios` array");
    let mut waits: Vec<&str> = Vec::new();
    for row in rows {
        assert_eq!(row["name"], "inproc-hop-small", "{row}");
        for field in ["payload_bytes", "n", "p50_ns", "p99_ns", "p999_ns", "max_ns"] {
            assert!(row[field].is_u64(), "{field} is not a count in {row}");
        }
        assert_eq!(row["n"], 200, "{row}");
        waits.push(row["wait"].as_str().expect("`wait` is a string"));
    }
    waits.sort_unstable();
    assert_eq!(waits, ["event", "spin"]);
}

#[test]
fn an_unknown_scenario_is_one_clear_error() {
    let output = Command::new(env!("CARGO_BIN_EXE_esgm-bench"))
        .args(["--only", "no-such-scenario"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("matches no scenario"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}
