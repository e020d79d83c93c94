//! Runs the real `esgm-bench` binary on small scenarios — in-process, and across
//! processes (it starts itself as the peer) — and reads its JSON back. No figure is
//! asserted: speed is measured, not tested.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous for a debug build; only there so that a hang fails instead of blocking CI.
const WATCHDOG: Duration = Duration::from_secs(120);

/// Samples per row of [`run_quick`].
const SAMPLES: u64 = 200;

/// Runs `esgm-bench --quick --samples 200 --only <only> --json FILE` under the watchdog;
/// returns the printed table and the JSON report.
fn run_quick(only: &str) -> (String, serde_json::Value) {
    run_quick_with(only, SAMPLES)
}

/// [`run_quick`] with `samples` samples per row.
fn run_quick_with(only: &str, samples: u64) -> (String, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("report.json");
    let samples = samples.to_string();
    let mut child = Command::new(env!("CARGO_BIN_EXE_esgm-bench"))
        .args(["--quick", "--only", only, "--samples", &samples, "--json"])
        .arg(&json)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Read on threads: a full pipe must not block the child while we wait.
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let stdout = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let stderr = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });

    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > WATCHDOG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("esgm-bench --only {only} did not finish within {WATCHDOG:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stdout = stdout.join().unwrap();
    let stderr = stderr.join().unwrap();
    assert!(status.success(), "esgm-bench --only {only} failed ({status}):\n{stdout}\n{stderr}");

    let text = std::fs::read_to_string(&json).unwrap();
    (stdout, serde_json::from_str(&text).unwrap())
}

/// The `(name, wait)` of every row, sorted, after checking each row's counts.
fn rows(report: &serde_json::Value) -> Vec<(String, String)> {
    rows_with(report, SAMPLES)
}

/// [`rows`] of a run with `samples` samples per row.
fn rows_with(report: &serde_json::Value, samples: u64) -> Vec<(String, String)> {
    assert!(report.get("failed").is_none(), "rows failed: {report}");
    let rows = report["scenarios"].as_array().expect("a `scenarios` array");
    let mut keys: Vec<(String, String)> = rows
        .iter()
        .map(|row| {
            for field in ["payload_bytes", "n", "p50_ns", "p99_ns", "p999_ns", "max_ns"] {
                assert!(row[field].is_u64(), "{field} is not a count in {row}");
            }
            assert_eq!(row["n"], samples, "{row}");
            let name = row["name"].as_str().expect("`name` is a string").to_owned();
            let wait = row["wait"].as_str().expect("`wait` is a string").to_owned();
            (name, wait)
        })
        .collect();
    keys.sort_unstable();
    keys
}

fn key(name: &str, wait: &str) -> (String, String) {
    (name.to_owned(), wait.to_owned())
}

#[test]
fn quick_hop_small_writes_the_json_report() {
    let (stdout, report) = run_quick("inproc-hop-small");
    assert!(stdout.contains("inproc-hop-small"), "the table lacks the scenario:\n{stdout}");
    assert_eq!(rows(&report), [key("inproc-hop-small", "event"), key("inproc-hop-small", "spin")]);
}

#[test]
fn quick_floor_iceoryx2_runs_against_a_peer_process() {
    // `--only` takes every scenario whose name contains it: the floor on iceoryx2's plain
    // service type and on the thread-safe one esgm uses.
    let (stdout, report) = run_quick("floor-iceoryx2");
    assert!(stdout.contains("floor-iceoryx2"), "the table lacks the scenario:\n{stdout}");
    assert_eq!(
        rows(&report),
        [
            key("floor-iceoryx2", "event"),
            key("floor-iceoryx2", "spin"),
            key("floor-iceoryx2-threadsafe", "event"),
            key("floor-iceoryx2-threadsafe", "spin"),
        ]
    );
    for row in report["scenarios"].as_array().unwrap() {
        assert_eq!(row["payload_bytes"], 64, "{row}");
    }
}

#[test]
fn quick_esgm_small_reports_three_waits_idle_cpu_and_the_encode() {
    let (stdout, report) = run_quick("esgm-small");
    assert_eq!(
        rows(&report),
        [
            key("esgm-small", "event"),
            key("esgm-small", "spin"),
            key("esgm-small-default", "event"),
            key("esgm-small-publish", "spin"),
        ]
    );
    let strategies: Vec<&str> = report["scenarios"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row["wait_strategy"].as_str().expect("a wait_strategy"))
        .collect();
    assert_eq!(strategies, ["busy-spin", "block", "spin-then-block", "busy-spin"]);
    // The encode is outside the target rows' hops and reported beside them.
    assert!(stdout.contains("encoded into the loan before the hop"), "{stdout}");
    for row in &report["scenarios"].as_array().unwrap()[..3] {
        assert!(row["producer_write_p50_ns"].as_u64().is_some_and(|ns| ns > 0), "{row}");
    }
    assert!(stdout.contains("idle: a subscriber with this default wait used"), "{stdout}");
    // Its baselines did not run: the targets say so instead of failing.
    assert!(stdout.contains("esgm-small / floor-iceoryx2 (spin)"), "{stdout}");
    assert!(stdout.contains("(floor-iceoryx2 not run)"), "{stdout}");
}

#[test]
fn quick_connect_small_measures_the_api_both_ways() {
    // Back to back, paced as the image's hops (`connect-small-paced`), and on volatile
    // trajectories (what keeping the history costs).
    let (stdout, report) = run_quick("connect-small");
    assert_eq!(
        rows(&report),
        [
            key("connect-small", "event"),
            key("connect-small", "spin"),
            key("connect-small-paced", "event"),
            key("connect-small-paced", "spin"),
            key("connect-small-volatile", "event"),
            key("connect-small-volatile", "spin"),
        ]
    );
    for row in report["scenarios"].as_array().unwrap() {
        let baseline = match row["name"].as_str() {
            Some("connect-small") => "esgm-small",
            _ => "connect-small",
        };
        assert_eq!(row["baseline"], baseline, "{row}");
        assert!(row["p50_ns"].as_u64().is_some_and(|ns| ns > 0), "{row}");
    }
    assert!(stdout.contains("Subscription::recv_timeout"), "{stdout}");
    // Its baselines and the peers it is held against did not run.
    assert!(stdout.contains("connect-small / ros1-small (event)"), "{stdout}");
    assert!(stdout.contains("(zenoh-small not run)"), "{stdout}");
}

#[test]
fn quick_connect_image_reads_the_pixels_in_shared_memory() {
    // Few samples: a debug build writes a frame in tens of milliseconds.
    let (stdout, report) = run_quick_with("connect-image", 20);
    assert_eq!(
        rows_with(&report, 20),
        [
            key("connect-image", "event"),
            key("connect-image", "spin"),
            key("connect-image-volatile", "event"),
            key("connect-image-volatile", "spin"),
        ]
    );
    for row in report["scenarios"].as_array().unwrap() {
        assert!(row["payload_bytes"].as_u64().is_some_and(|b| b > 921_600), "{row}");
        // Compared with a small structure paced as the frames are; the volatile rows
        // with the kept ones.
        let baseline = match row["name"].as_str() {
            Some("connect-image") => "connect-small-paced",
            _ => "connect-image",
        };
        assert_eq!(row["baseline"], baseline, "{row}");
    }
    assert!(stdout.contains("20 of 20 replies' pixels read in place"), "{stdout}");
}

/// The C++ rows run whenever a C++ compiler is there (the program is built on first
/// use against this build's C ABI library), each at both waits, held to its `connect`
/// row; without one, they are reported as not run, saying so.
#[test]
fn cpp_rows_run_through_the_c_abi_when_a_compiler_is_there() {
    // Few samples: a debug build writes a frame in tens of milliseconds.
    let (stdout, report) = run_quick_with("cpp-", 20);
    let compiler = std::env::var_os("CXX").is_some()
        || std::env::var_os("PATH")
            .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("c++").is_file()));
    if !compiler {
        assert!(rows_with(&report, 20).is_empty(), "{report}");
        let skipped = report["skipped"].as_array().cloned().unwrap_or_default();
        assert_eq!(skipped.len(), 2, "{report}");
        return;
    }
    assert_eq!(
        rows_with(&report, 20),
        [
            key("cpp-image", "event"),
            key("cpp-image", "spin"),
            key("cpp-small", "event"),
            key("cpp-small", "spin"),
        ]
    );
    for row in report["scenarios"].as_array().unwrap() {
        let baseline = if row["name"] == "cpp-small" { "connect-small" } else { "connect-image" };
        assert_eq!(row["baseline"], baseline, "{row}");
        assert!(row["p50_ns"].as_u64().is_some_and(|ns| ns > 0), "{row}");
    }
    assert!(stdout.contains("esgm_subscription_recv"), "{stdout}");
    // The image's pixels were read where the C++ writer put them, in shared memory.
    assert!(stdout.contains("20 of 20 replies' pixels read in place"), "{stdout}");
    assert!(stdout.contains("cpp-small / connect-small (spin)"), "{stdout}");
}

/// Classic iceoryx's C peer is optional, as ROS 1 is: built (benches/iceoryx/build.sh)
/// with its packages, and as root (its RouDi runs in a mount namespace of its own),
/// both rows are measured at both waits; not built, both are reported as not run,
/// saying how to build it.
#[test]
fn iceoryx_rows_are_measured_when_built_and_say_how_when_not() {
    use esgm_benches::scenarios::iceoryx_c_peer;
    let (stdout, report) = run_quick("iceoryx-c-");
    let skipped = report["skipped"].as_array().cloned().unwrap_or_default();
    let roudi = std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("iox-roudi").is_file()));
    if iceoryx_c_peer::program().is_none() || !roudi {
        assert!(rows(&report).is_empty(), "{report}");
        assert_eq!(skipped.len(), 2, "{report}");
        for row in skipped {
            let reason = row["reason"].as_str().unwrap_or_default();
            assert!(reason.contains("benches/iceoryx/build.sh"), "{row}");
        }
        assert!(stdout.contains("benches/iceoryx/build.sh"), "{stdout}");
        return;
    }
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        // Built, but RouDi cannot have a namespace of its own: skipped with why.
        assert_eq!(skipped.len(), 4, "{report}");
        return;
    }
    assert!(skipped.is_empty(), "{report}");
    assert_eq!(
        rows(&report),
        [
            key("iceoryx-c-image", "event"),
            key("iceoryx-c-image", "spin"),
            key("iceoryx-c-small", "event"),
            key("iceoryx-c-small", "spin"),
        ]
    );
    for row in report["scenarios"].as_array().unwrap() {
        let baseline = if row["name"] == "iceoryx-c-small" { "cpp-small" } else { "cpp-image" };
        assert_eq!(row["baseline"], baseline, "{row}");
    }
}

/// Without the `ros2` feature (CI's build) the ROS 2 rows are reported as not run,
/// with the command that runs them, and their targets say so: nothing pretends to have
/// measured DDS.
#[cfg(not(feature = "ros2"))]
#[test]
fn ros2_rows_without_the_feature_are_reported_as_not_run() {
    let (stdout, report) = run_quick("ros2-");
    assert!(rows(&report).is_empty(), "{report}");
    let skipped = report["skipped"].as_array().expect("a `skipped` array");
    assert_eq!(skipped.len(), 6, "{report}");
    for row in skipped {
        assert!(row["reason"].as_str().is_some_and(|r| r.contains("--features ros2")), "{row}");
    }
    assert!(stdout.contains("(ros2-export-small not run) (ros2-raw-small not run)"), "{stdout}");
}

/// dora is optional, as ROS 1 is: built (benches/dora/build.sh), both rows are measured
/// at both waits; not built (CI), both are reported as not run, saying how to build it.
#[test]
fn dora_rows_are_measured_when_built_and_say_how_when_not() {
    use esgm_benches::scenarios::dora_peer;
    let (stdout, report) = run_quick("dora-");
    // The report leaves `skipped` out when nothing was.
    let skipped = report["skipped"].as_array().cloned().unwrap_or_default();
    if dora_peer::cli().is_some() && dora_peer::node().is_some() {
        assert!(skipped.is_empty(), "{report}");
        assert_eq!(
            rows(&report),
            [
                key("dora-image", "event"),
                key("dora-image", "spin"),
                key("dora-small", "event"),
                key("dora-small", "spin"),
            ]
        );
    } else {
        assert!(rows(&report).is_empty(), "{report}");
        assert_eq!(skipped.len(), 2, "{report}");
        for row in skipped {
            let reason = row["reason"].as_str().unwrap_or_default();
            assert!(reason.contains("benches/dora/build.sh"), "{row}");
        }
        assert!(stdout.contains("benches/dora/build.sh"), "{stdout}");
    }
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

#[test]
fn a_peer_role_for_no_scenario_is_one_clear_error() {
    let output = Command::new(env!("CARGO_BIN_EXE_esgm-bench"))
        .args(["--peer", "no-such-scenario", "--peer-wait", "spin", "--peer-domain", "x"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("names no scenario"), "{stderr}");
}

/// The reference system runs briefly on esgm in one process and one process per node,
/// and each reports its KPI rows (no figure is asserted: the rows exist and hold data).
#[test]
fn the_reference_system_runs_on_esgm_both_ways() {
    let (stdout, report) = run_quick("refsys");
    assert!(report.get("failed").is_none(), "rows failed: {report}");
    let rows = report["scenarios"].as_array().expect("a `scenarios` array");
    for system in ["refsys-esgm", "refsys-esgm-procs"] {
        for row in [system.to_owned(), format!("{system}-cpu"), format!("{system}-planner")] {
            let found = rows.iter().find(|r| r["name"] == row.as_str() && r["wait"] == "event");
            let found = found.unwrap_or_else(|| panic!("no row {row} in {report}"));
            assert!(found["n"].as_u64().is_some_and(|n| n > 0), "{found}");
        }
    }
    for note in ["front lidar:", "transforms missed", "behavior planner:", "% of a core"] {
        assert!(stdout.contains(note), "no `{note}` note:\n{stdout}");
    }
    assert!(
        stdout.contains("26 processes"),
        "a coordinator and 25 workers (24 nodes, the intersection as two units):\n{stdout}"
    );
}

/// The CLI rows run the `esgm` executable beside esgm-bench (the workspace's tests build
/// it), or say how to build it; no figure is asserted.
#[test]
fn cli_rows_run_the_esgm_executable_or_say_how_to_build_it() {
    let (stdout, report) = run_quick("cli");
    let skipped = report["skipped"].as_array().cloned().unwrap_or_default();
    let beside = Path::new(env!("CARGO_BIN_EXE_esgm-bench")).with_file_name("esgm").is_file();
    if beside {
        assert!(skipped.is_empty(), "{report}");
        // Whole processes: fewer samples than other rows (at most 3 under --quick).
        let measured: Vec<&serde_json::Value> =
            report["scenarios"].as_array().unwrap().iter().collect();
        for row in ["cli-version", "cli-latest-10", "cli-latest-1000", "cli-stats-1000"] {
            let found = measured.iter().find(|r| r["name"] == row && r["wait"] == "event");
            let found = found.unwrap_or_else(|| panic!("no {row} in {report}"));
            assert!(found["n"].as_u64().is_some_and(|n| n > 0), "{found}");
        }
        assert!(stdout.contains("cli-latest-1000 / cli-latest-10"), "the target: {stdout}");
    } else {
        assert!(report["scenarios"].as_array().is_none_or(Vec::is_empty), "{report}");
        let reason = skipped[0]["reason"].as_str().unwrap_or_default();
        assert!(reason.contains("cargo build --release -p esgm-cli"), "{report}");
    }
}
