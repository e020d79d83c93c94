//! The `esgm` binary end to end: real processes, unique domains, a watchdog on every
//! command (a command that overstays is killed and fails the test).

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy};
use esgm_shm::control::ControlClient;

const ESGM: &str = env!("CARGO_BIN_EXE_esgm");

/// One system at a time: each starts six processes, and a 2-core CI machine running
/// them all at once (in debug builds) would measure the machine, not esgm.
static ONE_SYSTEM: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_system() -> std::sync::MutexGuard<'static, ()> {
    ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

struct Output {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs `esgm args…`, killing it after `limit`.
fn esgm(args: &[&str], limit: Duration) -> Output {
    let mut child = Command::new(ESGM)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run esgm");
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("`esgm {}` did not finish within {limit:?}", args.join(" "));
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let (mut stdout, mut stderr) = (String::new(), String::new());
    child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    Output { code: status.code(), stdout, stderr }
}

fn ok(args: &[&str]) -> String {
    let o = esgm(args, Duration::from_secs(30));
    assert_eq!(o.code, Some(0), "`esgm {}` failed:\n{}\n{}", args.join(" "), o.stdout, o.stderr);
    o.stdout
}

fn domain(prefix: &str) -> String {
    esgm_shm::unique_domain(prefix)
}

fn coordinator_is_gone(domain: &str) -> bool {
    ControlClient::connect(domain, Duration::from_millis(200)).is_err()
}

#[test]
fn demo_follows_the_largest_blob_and_leaves_nothing_behind() {
    let _one = one_system();
    let d = domain("cli-demo");
    let o = esgm(&["--domain", &d, "demo", "--seconds", "3"], Duration::from_secs(90));
    assert_eq!(o.code, Some(0), "demo failed:\n{}\n{}", o.stdout, o.stderr);
    for expected in [
        "driving_direction as it changes",
        "get_between(latest - 5 s, latest - 1 s)",
        "get_at_approximating(latest - 100 ms, most recent)",
        "latency of each stage",
        "consistent: the robot follows the largest blob",
        "stopped: coordinator and 5 workers",
    ] {
        assert!(o.stdout.contains(expected), "missing `{expected}` in:\n{}", o.stdout);
    }
    assert!(coordinator_is_gone(&d));
}

#[test]
fn every_query_command_against_a_running_system() {
    let _one = one_system();
    let d = domain("cli-queries");
    ok(&["--domain", &d, "up", "--detach"]);
    let result = std::panic::catch_unwind(|| {
        // A robot program: a primitive trajectory with a few states.
        let system = esgm_shm::ShmEsgm::builder().domain(&d).connect().unwrap();
        let policy = FluentStreamPolicy::default().order(esgm_core::OrderConstraint::Monotone);
        let robot = system
            .create_trajectory(TrajectorySpec::primitive("robot", "RobotState").policy(policy))
            .unwrap();
        let t0 = 1_700_000_000_000_000_000_i64;
        for i in 0..10 {
            let t = t0 + i * 100_000_000;
            robot
                .add(
                    EntityStructure::new("r1", t, t)
                        .with("x", i as f64)
                        .with("y", 0.0)
                        .with("dir", 0.0),
                )
                .unwrap();
        }

        assert!(ok(&["--domain", &d, "type", "list"]).contains("RobotState"));
        assert!(ok(&["--domain", &d, "type", "show", "Image"]).contains("image_data"));
        let list = ok(&["--domain", &d, "traj", "list"]);
        assert!(list.contains("robot") && list.contains("primitive"), "{list}");
        let json = ok(&["--domain", &d, "--json", "traj", "list"]);
        let v: serde_json::Value = serde_json::from_str(json.lines().next().unwrap()).unwrap();
        assert_eq!(v["name"], "robot");
        ok(&["--domain", &d, "sensor", "list"]);
        ok(&["--domain", &d, "unit", "list"]);

        let latest = ok(&["--domain", &d, "--json", "latest", "robot"]);
        let v: serde_json::Value = serde_json::from_str(latest.trim()).unwrap();
        assert_eq!(v["attributes"]["x"], 9.0);
        assert_eq!(v["valid_time"], t0 + 900_000_000);
        let nth = ok(&["--domain", &d, "--json", "nth", "robot", "2"]);
        assert!(nth.contains("\"x\":7.0"), "{nth}");
        let between = ok(&["--domain", &d, "--json", "between", "robot", "-500ms", "-200ms"]);
        assert_eq!(between.lines().count(), 4, "{between}");
        let at = ok(&["--domain", &d, "at", "robot", &(t0 + 300_000_000).to_string()]);
        assert!(at.contains("x=3.0"), "{at}");
        let closest = ok(&["--domain", &d, "--json", "closest", "robot", "-150ms"]);
        assert!(closest.contains("\"x\":7.0"), "{closest}");
        let linear =
            ok(&["--domain", &d, "--json", "approx", "robot", "-50ms", "--method", "linear"]);
        assert!(linear.contains("\"x\":8.5"), "{linear}");
        let rfc = ok(&["--domain", &d, "--json", "closest", "robot", "2023-11-14T22:13:20.25Z"]);
        assert!(rfc.contains("\"x\":2.0"), "{rfc}");
        let echo = ok(&["--domain", &d, "--json", "echo", "robot", "--last", "3", "--count", "3"]);
        assert_eq!(echo.lines().count(), 3, "{echo}");
        assert!(ok(&["--domain", &d, "stats"]).contains("robot"));
        assert!(ok(&["--domain", &d, "graph", "--dot"]).contains("digraph esgm"));
        ok(&["--domain", &d, "violations", "robot", "--seconds", "0.2"]);
        let hz = ok(&["--domain", &d, "--json", "hz", "robot", "--window", "0.2", "--count", "1"]);
        assert!(hz.contains("rate_hz"), "{hz}");

        // User errors: one line, the seed's error, a suggestion, exit 1.
        let o = esgm(&["--domain", &d, "latest", "robt"], Duration::from_secs(30));
        assert_eq!(o.code, Some(1));
        assert_eq!(o.stderr.trim().lines().count(), 1, "{}", o.stderr);
        assert!(
            o.stderr.contains("no entity trajectory structure `robt`; did you mean `robot`?"),
            "{}",
            o.stderr
        );
        let o = esgm(&["--domain", &d, "type", "show", "Imag"], Duration::from_secs(30));
        assert_eq!(o.code, Some(1));
        assert!(o.stderr.contains("did you mean `Image`?"), "{}", o.stderr);
        let o = esgm(&["--domain", &d, "at", "robot", "yesterday"], Duration::from_secs(30));
        assert_eq!(o.code, Some(2), "a malformed time is a usage error: {}", o.stderr);
        assert!(o.stderr.contains("`yesterday` is not a time"), "{}", o.stderr);
        let o = esgm(&["--domain", "no-such-system", "traj", "list"], Duration::from_secs(30));
        assert_eq!(o.code, Some(1));
        assert!(o.stderr.contains("no coordinator is running"), "{}", o.stderr);
        assert!(!o.stderr.contains("panicked"), "{}", o.stderr);

        // Nothing running was disturbed.
        assert_eq!(robot.get_latest().unwrap().structure.valid_time, t0 + 900_000_000);
        drop(robot);
        drop(system);
    });
    let down = esgm(&["--domain", &d, "down"], Duration::from_secs(30));
    if let Err(panic) = result {
        std::panic::resume_unwind(panic);
    }
    assert_eq!(down.code, Some(0), "{}", down.stderr);
    assert!(coordinator_is_gone(&d));
}

/// Reads the demo's output as it comes.
fn lines_of(child: &mut Child) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    let out = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

#[test]
fn a_killed_unit_worker_is_restarted_and_the_trajectory_resumes() {
    let _one = one_system();
    let d = domain("cli-kill");
    let mut demo = Command::new(ESGM)
        .args(["--domain", &d, "demo", "--seconds", "8"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lines = lines_of(&mut demo);
    let deadline = Instant::now() + Duration::from_secs(120);
    let mut output = Vec::new();
    let mut pid = None;
    // Find the BlobDetection worker, wait for directions to flow, kill it with -9.
    let mut directions = 0;
    while Instant::now() < deadline {
        let Ok(line) = lines.recv_timeout(Duration::from_millis(100)) else {
            if demo.try_wait().unwrap().is_some() {
                break;
            }
            continue;
        };
        if let Some(rest) = line.trim().strip_prefix("started BlobDetection") {
            pid = rest.split_whitespace().last().and_then(|p| p.parse::<u32>().ok());
        }
        if line.trim_start().starts_with(|c: char| c.is_ascii_digit()) && line.contains('.') {
            directions += 1;
            if directions == 10 {
                let pid = pid.expect("the demo printed the worker's pid");
                let killed = Command::new("kill").args(["-9", &pid.to_string()]).status().unwrap();
                assert!(killed.success());
            }
        }
        output.push(line);
    }
    let status = loop {
        if let Some(s) = demo.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = demo.kill();
            panic!("the demo did not finish:\n{}", output.join("\n"));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    while let Ok(line) = lines.recv_timeout(Duration::from_millis(200)) {
        output.push(line);
    }
    let mut stderr = String::new();
    demo.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    let text = output.join("\n");
    assert!(status.success(), "demo failed:\n{text}\n{stderr}");
    assert!(text.contains("(1 restarts)"), "no restart counted:\n{text}\n{stderr}");
    assert!(stderr.contains("worker restarted"), "restart not logged:\n{stderr}");
    // The blobs kept coming after the restart: the stage's sample count covers the run.
    let blobs: u64 = text
        .lines()
        .filter(|l| l.trim_start().starts_with("blobs "))
        .filter_map(|l| l.split_whitespace().nth(1))
        .next_back()
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(blobs >= 20, "blobs did not resume after the restart ({blobs}):\n{text}");
    assert!(coordinator_is_gone(&d));
}
