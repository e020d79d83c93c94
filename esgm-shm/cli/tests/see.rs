//! Seeing a running system: `esgm top --once` and `esgm plot`, end to end with the real
//! binary. Unique domains, a watchdog on every command (one that overstays is killed
//! and fails the test).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Esgm};

const ESGM: &str = env!("CARGO_BIN_EXE_esgm");

struct Output {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs `esgm args…`, killing it (and failing) after `limit`.
fn esgm(args: &[&str], limit: Duration) -> Output {
    let mut child = Command::new(ESGM)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run esgm");
    let deadline = Instant::now() + limit;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("`esgm {}` did not finish within {limit:?}", args.join(" "));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    Output {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into(),
        stderr: String::from_utf8_lossy(&out.stderr).into(),
    }
}

fn ok(args: &[&str]) -> String {
    let o = esgm(args, Duration::from_secs(60));
    assert_eq!(o.code, Some(0), "`esgm {}` failed:\n{}\n{}", args.join(" "), o.stdout, o.stderr);
    o.stdout
}

/// Stops a test's coordinator when the test ends, also when it fails.
struct Down(String);

impl Drop for Down {
    fn drop(&mut self) {
        let _ = esgm(&["--domain", &self.0, "down"], Duration::from_secs(30));
    }
}

#[test]
fn top_once_prints_every_trajectory_and_the_coordinator() {
    let d = esgm_shm::unique_domain("cli-top");
    ok(&["--domain", &d, "up", "--detach"]);
    let _down = Down(d.clone());

    let system = esgm_shm::ShmEsgm::builder().domain(&d).connect().unwrap();
    let robot = system.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    let t0 = 1_700_000_000_000_000_000_i64;
    for i in 0..20 {
        let t = t0 + i * 50_000_000;
        let es =
            EntityStructure::new("r1", t, t).with("x", i as f64).with("y", 0.0).with("dir", 0.0);
        robot.add(es).unwrap();
    }

    let out = ok(&["--domain", &d, "top", "--once"]);
    let mut lines = out.lines();
    let header = lines.next().unwrap_or_default();
    for column in ["trajectory", "kind", "type", "rate Hz", "p99 ms", "violations", "bytes"] {
        assert!(header.contains(column), "no `{column}` column:\n{out}");
    }
    let row = out.lines().find(|l| l.starts_with("robot ")).unwrap_or_else(|| panic!("{out}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(&cells[..3], ["robot", "primitive", "RobotState"], "{row}");
    // The replica this command opened received the 20 adds, 50 ms of valid time apart.
    assert_eq!(cells[4], "20", "added: {row}");
    assert!(cells[3].parse::<f64>().is_ok(), "rate: {row}");
    let coordinator =
        out.lines().find(|l| l.starts_with("coordinator")).unwrap_or_else(|| panic!("{out}"));
    let pid: u32 = coordinator.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(pid > 0, "{coordinator}");
    assert!(coordinator.contains("MiB") || coordinator.contains("KiB"), "rss: {coordinator}");

    // The filter and JSON.
    let filtered = ok(&["--domain", &d, "top", "--once", "--filter", "nothing-like-it"]);
    assert!(!filtered.contains("robot"), "{filtered}");
    let json = ok(&["--domain", &d, "--json", "top", "--once"]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["trajectories"][0]["name"], "robot");
    assert_eq!(v["trajectories"][0]["added"], 20);
    drop(robot);
    drop(system);
}
