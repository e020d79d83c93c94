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

/// Stops a test's system when the test ends, also when it fails (a detached
/// coordinator and its workers would otherwise outlive the test).
struct StopOnDrop(String);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        let _ = Command::new(ESGM)
            .args(["--domain", &self.0, "down"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// Nothing of the system is left in shared memory: no node of its domain, alive or
/// dead (crashed processes' resources were cleaned).
fn assert_nothing_left(domain: &str) {
    // A listing that fails fails the test: "none" is never assumed.
    let nodes = esgm_shm::nodes_of(domain).expect("cannot list iceoryx2 nodes");
    assert!(nodes.is_empty(), "nodes of `{domain}` left behind: {nodes:?}");
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
    // Images crossed processes in shared memory, and nobody copied one.
    let table = o
        .stdout
        .split_once("images in shared memory, per process")
        .and_then(|(_, rest)| rest.split_once("image copies in all:"))
        .unwrap_or_else(|| panic!("no table of image copies in:\n{}", o.stdout));
    // `process  read held  sent in place  copies`, after the header line.
    let rows: Vec<Vec<&str>> = table
        .0
        .lines()
        .skip(2)
        .map(|l| l.split_whitespace().collect())
        .filter(|r: &Vec<&str>| !r.is_empty())
        .collect();
    let column = |row: &[&str], i: usize| row[i].parse::<u64>().unwrap();
    let sent: u64 = rows.iter().map(|r| column(r, 2)).sum();
    let read: u64 = rows.iter().map(|r| column(r, 1)).sum();
    assert!(sent > 0 && read > 0, "no image was sent and read in shared memory:\n{}", o.stdout);
    for row in &rows {
        assert_eq!(column(row, 3), 0, "{} copied images:\n{}", row[0], o.stdout);
    }
    assert_eq!(table.1.lines().next().map(str::trim), Some("0"), "{}", o.stdout);
    assert!(coordinator_is_gone(&d));
    assert_nothing_left(&d);
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
        assert_eq!(robot.get_latest().unwrap().structure.valid_time(), t0 + 900_000_000);
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

/// `esgm trace` follows lineage across three processes: two pushed trajectories and a
/// unit in this process, a merge and a sync written by the system's own process, and
/// the CLI reading the trees, with every hop's writer and time.
#[test]
fn trace_follows_lineage_across_processes() {
    let _one = one_system();
    let d = domain("cli-trace");
    ok(&["--domain", &d, "up", "--detach"]);
    let _stop = StopOnDrop(d.clone());
    let system = esgm_shm::ShmEsgm::builder().domain(&d).host("pusher").connect().unwrap();
    let a = system.create_primitive_entity_trajectory_structure("a", "RobotState").unwrap();
    let b = system.create_primitive_entity_trajectory_structure("b", "RobotState").unwrap();
    ok(&["--domain", &d, "traj", "create", "pair", "--sync", "a,b", "--tolerance", "20ms"]);
    ok(&["--domain", &d, "traj", "create", "ab", "--merge", "a,b"]);
    let copy = |i: &[esgm_core::Sample], _: i64| Ok(i[0].structure.to_structure());
    let types = vec!["RobotState".into()];
    system.add_comp_unit("copy", "RobotState", types, std::sync::Arc::new(copy)).unwrap();
    system.create_computed_entity_trajectory_structure("out", "copy", &["ab"]).unwrap();
    let state =
        |t: i64| EntityStructure::new("r", t, t).with("x", 1.0).with("y", 2.0).with("dir", 0.0);
    let t0 = 1_700_000_000_000_000_000_i64;
    let out = system.get_entity_trajectory_structure("out").unwrap();
    let pair = system.get_entity_trajectory_structure("pair").unwrap();
    let merged = system.get_entity_trajectory_structure("ab").unwrap();
    // A merge stores its inputs in the order it takes them, and a and b are two
    // services: each add waits until the merge has taken the one before, so that b's
    // last is the merge's last.
    let mut added = 0;
    for k in 0..3 {
        let t = t0 + k * 100_000_000;
        for (input, time) in [(&a, t), (&b, t + 1_000_000)] {
            input.add(state(time)).unwrap();
            added += 1;
            let deadline = Instant::now() + Duration::from_secs(20);
            while merged.stats().map(|s| s.added).unwrap_or(0) < added {
                assert!(Instant::now() < deadline, "the merge never took sample {added}");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    let produced = || {
        out.stats().map(|s| s.added).unwrap_or(0) >= 6
            && pair.stats().map(|s| s.added).unwrap_or(0) >= 2
    };
    while !produced() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(produced(), "the pipeline never produced");
    let last = t0 + 200_000_000;

    // out <- ab <- b: a unit in this process, over a merge in the system's process.
    let json = ok(&["--domain", &d, "--json", "trace", "out", "--latest"]);
    let tree: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(
        (tree["trajectory"].as_str(), tree["writer"].as_str()),
        (Some("out"), Some("pusher")),
        "{json}"
    );
    assert_eq!(tree["complete"], false, "a unit's lineage says what it cannot know");
    let ab = &tree["inputs"][0];
    assert_eq!(
        (ab["trajectory"].as_str(), ab["found"].as_str()),
        (Some("ab"), Some("stored")),
        "{json}"
    );
    assert_ne!(ab["writer"], "pusher", "the merge is the system's: {json}");
    assert!(ab["hop_ns"].as_i64().is_some_and(|h| h >= 0), "{json}");
    let source = &ab["inputs"][0];
    assert_eq!(
        (source["trajectory"].as_str(), source["valid_time"].as_i64()),
        (Some("b"), Some(last + 1_000_000))
    );
    assert_eq!(source["add_time"], b.get_latest().unwrap().add_time, "as stored in b");

    // pair <- a, b: a sync's members.
    let json = ok(&["--domain", &d, "--json", "trace", "pair"]);
    let tree: serde_json::Value = serde_json::from_str(&json).unwrap();
    let members: Vec<_> = tree["inputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| (n["trajectory"].as_str().unwrap().to_owned(), n["valid_time"].as_i64().unwrap()))
        .collect();
    let vt = tree["inputs"][0]["valid_time"].as_i64().unwrap();
    assert_eq!(members, [("a".to_owned(), vt), ("b".to_owned(), vt + 1_000_000)], "{json}");
    assert_eq!(tree["complete"], true);

    let text = ok(&["--domain", &d, "trace", "out", "--at", &(last + 1_000_000).to_string()]);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("out (*)") && lines[0].contains("[pusher]"), "{text}");
    assert!(lines[1].starts_with("└─ ab") && lines[1].contains("hop"), "{text}");
    assert!(lines[2].starts_with("   └─ b") && lines[2].contains("source  [pusher]"), "{text}");
    assert!(lines[3].starts_with("end to end: "), "{text}");
    let o = esgm(&["--domain", &d, "trace", "nope"], Duration::from_secs(30));
    assert_eq!(o.code, Some(1));
    assert!(o.stderr.contains("no entity trajectory structure `nope`"), "{}", o.stderr);
    drop((a, b, out, pair, merged));
    drop(system);
}

/// `esgm why` across processes: the writer of a unit's trajectory answers with its
/// unit's calls, and a writer stopped with SIGSTOP is named as stopped, while the
/// trajectory computed from it names the input that went quiet.
#[test]
fn why_names_a_stopped_writer_and_the_input_that_went_quiet() {
    let _one = one_system();
    let d = domain("cli-why");
    ok(&["--domain", &d, "up", "--detach"]);
    let _stop = StopOnDrop(d.clone());
    let system = esgm_shm::ShmEsgm::builder().domain(&d).host("pusher").connect().unwrap();
    let steer =
        system.create_primitive_entity_trajectory_structure("steer", "DrivingDirection").unwrap();
    let now = esgm_core::Clock::now(&esgm_core::SystemClock);
    steer.add(EntityStructure::new("dd", now, now).with("dir", 0.0).with("speed", 0.0)).unwrap();
    let robot_args = [
        "--domain",
        &d,
        "worker",
        "robot",
        "--trajectory",
        "rs",
        "--follow",
        "steer",
        "--period",
        "20ms",
    ];
    let robot_process = || {
        let mut robot = Command::new(ESGM);
        robot.args(robot_args).stdout(Stdio::null()).stderr(Stdio::null());
        robot.spawn().unwrap()
    };
    let mut robot = robot_process();
    let deadline = Instant::now() + Duration::from_secs(30);
    while system.get_entity_trajectory_structure("rs").is_err() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let slow =
        |i: &[esgm_core::Sample], _: i64| -> Result<EntityStructure, esgm_core::ComputeError> {
            if i[0].get("x").and_then(|v| v.as_double()).is_some_and(|x| x >= 0.0) {
                Err(esgm_core::ComputeError::ValueNotAvailable)
            } else {
                Ok(i[0].structure.to_structure())
            }
        };
    let types = vec!["RobotState".into()];
    system.add_comp_unit("slow", "RobotState", types, std::sync::Arc::new(slow)).unwrap();
    system.create_computed_entity_trajectory_structure("c", "slow", &["rs"]).unwrap();
    std::thread::sleep(Duration::from_millis(300));

    // The unit's writer (this process) answers: no value, with its calls.
    let json = ok(&["--domain", &d, "--json", "why", "c", "--since", "-200ms"]);
    let why: serde_json::Value = serde_json::from_str(&json).unwrap();
    let reasons = why["reasons"].to_string();
    assert!(reasons.contains("call(s) returned no value"), "{json}");
    assert_eq!(why["writer_alive"], true);
    assert_eq!(why["inputs"][0]["trajectory"], "rs");
    assert_eq!(why["inputs"][0]["writer_alive"], true, "{json}");

    // The robot stops: its trajectory's writer is named stopped, and `c` names `rs`.
    let pid = robot.id().to_string();
    Command::new("kill").args(["-STOP", &pid]).status().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let text = ok(&["--domain", &d, "why", "rs", "--since", "-200ms"]);
    assert!(
        text.lines().nth(1).is_some_and(|l| l.contains("its writer process is stopped")),
        "{text}"
    );
    let text = ok(&["--domain", &d, "why", "c", "--since", "-200ms"]);
    assert!(text.contains("input `rs` has had nothing new since the time asked"), "{text}");
    Command::new("kill").args(["-CONT", &pid]).status().unwrap();
    // Killed (nobody supervises it here): gone, and `c`'s input names it.
    let _ = robot.kill();
    let _ = robot.wait();
    let json = ok(&["--domain", &d, "--json", "why", "rs", "--since", "-200ms"]);
    let why: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(why["writer_alive"], false, "{json}");
    assert!(
        why["reasons"][0].as_str().is_some_and(|r| r.contains("its writer process is gone")),
        "{json}"
    );
    let json = ok(&["--domain", &d, "--json", "why", "c"]);
    let why: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(why["inputs"][0]["writer_alive"], false, "{json}");
    // Run again, the robot writes `rs` anew: `why` names the restart, by both pids.
    let gone = robot.id();
    let mut robot = robot_process();
    let deadline = Instant::now() + Duration::from_secs(30);
    let restarted = loop {
        let json = ok(&["--domain", &d, "--json", "why", "rs"]);
        let why: serde_json::Value = serde_json::from_str(&json).unwrap();
        if why["writer_changed"]["to_pid"] == robot.id() || Instant::now() > deadline {
            break why;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let change = &restarted["writer_changed"];
    assert_eq!(change["how"], "restarted", "{restarted}");
    assert_eq!(
        (change["from_pid"].as_u64(), change["to_pid"].as_u64()),
        (Some(gone.into()), Some(robot.id().into()))
    );
    assert_eq!(restarted["writer_alive"], true, "{restarted}");
    assert!(
        restarted["reasons"][0].as_str().is_some_and(|r| r.contains("was restarted")),
        "{restarted}"
    );
    let _ = robot.kill();
    let _ = robot.wait();
    let o = esgm(&["--domain", &d, "why", "cc"], Duration::from_secs(30));
    assert_eq!(o.code, Some(1));
    assert!(
        o.stderr.contains("no entity trajectory structure `cc`; did you mean `c`?"),
        "{}",
        o.stderr
    );
    drop(steer);
    drop(system);
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
        if let Some(rest) = line.trim().strip_prefix("started unit-BlobDetection") {
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
    assert_nothing_left(&d);
}

/// Pids of the system's processes, as `esgm ps --json` reports them.
fn process_pids(d: &str) -> Vec<u32> {
    ok(&["--domain", d, "--json", "ps"])
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["status"]["pid"].as_u64())
        .filter_map(|p| u32::try_from(p).ok())
        .collect()
}

/// Polls `esgm latest traj` until it prints a sample, or fails after `limit`.
fn wait_for_sample(d: &str, traj: &str, limit: Duration) -> String {
    let deadline = Instant::now() + limit;
    loop {
        let o = esgm(&["--domain", d, "latest", traj], Duration::from_secs(30));
        if o.code == Some(0) && !o.stdout.trim().is_empty() {
            return o.stdout;
        }
        assert!(Instant::now() < deadline, "no sample in `{traj}` within {limit:?}: {}", o.stderr);
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn fails_with(args: &[&str], needles: &[&str]) {
    let o = esgm(args, Duration::from_secs(30));
    assert_eq!(
        o.code,
        Some(1),
        "`esgm {}` should fail:\n{}\n{}",
        args.join(" "),
        o.stdout,
        o.stderr
    );
    assert_eq!(o.stderr.trim().lines().count(), 1, "one line expected:\n{}", o.stderr);
    for n in needles {
        assert!(o.stderr.contains(n), "`{n}` missing in: {}", o.stderr);
    }
}

#[test]
fn a_system_from_a_config_file_with_built_in_generic_and_user_units() {
    let _one = one_system();
    let d = domain("cli-apply");
    let dir = tempfile::tempdir().unwrap();
    let user_unit =
        std::path::Path::new(ESGM).parent().unwrap().join("examples").join("large_blob_unit");
    assert!(
        user_unit.exists(),
        "{} is missing: `cargo test` builds the esgm-cli examples",
        user_unit.display()
    );
    let config = format!(
        r#"
[[type]]
name = "Waypoint"
attributes = ["x: Double", "y: Double"]

[[sensor]]
name = "camera"
camera = "synthetic"
seed = 3
blobs = 2
width = 320
height = 240

[[unit]]
name = "BlobDetection"

[[unit]]
name = "BlobSelection"

[[unit]]
name = "smooth"
builtin = "MovingAverage"
type = "Blob"
window = 3

[[unit]]
name = "LargeBlob"
exec = "{exe}"
args = ["--min-size", "1"]

[[trajectory]]
name = "poses"
primitive = "Waypoint"
policy = {{ cache = 10, order = "monotone" }}

[[trajectory]]
name = "images"
sampled = "camera"
period = "100ms"
policy = {{ cache = 3 }}

[[trajectory]]
name = "blobs"
computed = "BlobDetection"
inputs = ["images"]

[[trajectory]]
name = "smooth_blob"
computed = "smooth"
inputs = ["current_blob"]

[[trajectory]]
name = "current_blob"
computed = "BlobSelection"
inputs = ["blobs"]
policy = {{ cache = "5s", change = "any-update" }}

[[trajectory]]
name = "large_blob"
computed = "LargeBlob"
inputs = ["current_blob"]

[[trajectory]]
name = "any_blob"
merge = ["large_blob", "smooth_blob"]
"#,
        exe = user_unit.display()
    );
    let file = dir.path().join("system.toml");
    std::fs::write(&file, &config).unwrap();
    let file = file.to_str().unwrap();

    ok(&["--domain", &d, "up", "--detach"]);
    let _stop = StopOnDrop(d.clone());
    let applied = ok(&["--domain", &d, "apply", file]);
    for expected in [
        "type       Waypoint",
        "unit       LargeBlob            registered",
        "unit       smooth               registered",
        "trajectory any_blob             created",
    ] {
        assert!(applied.contains(expected), "`{expected}` missing in:\n{applied}");
    }
    // Inputs were created before the trajectories that read them (smooth_blob is
    // declared before current_blob).
    let pos = |s: &str| applied.find(s).unwrap();
    assert!(pos("trajectory current_blob") < pos("trajectory smooth_blob"), "{applied}");

    // Built-in, generic (moving average), user executable and merge all produce.
    for traj in ["blobs", "smooth_blob", "large_blob", "any_blob"] {
        wait_for_sample(&d, traj, Duration::from_secs(60));
    }
    let json = ok(&["--domain", &d, "--json", "traj", "show", "current_blob"]);
    assert!(json.contains("\"Duration\":5000000000") && json.contains("AnyUpdate"), "{json}");

    // Applying the same file again changes nothing.
    let again = ok(&["--domain", &d, "apply", file]);
    assert!(!again.contains("created"), "{again}");
    assert!(again.contains("trajectory large_blob           unchanged"), "{again}");

    // Files with errors: one line naming file and line; nothing running is disturbed.
    let pids = process_pids(&d);
    assert_eq!(pids.len(), 5, "{pids:?}");
    let bad = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_owned()
    };
    let unknown_field = bad(
        "a.toml",
        "[[trajectory]]\nname = \"x\"\nprimitive = \"Blob\"\npolicy = { cahce = 3 }\n",
    );
    fails_with(&["--domain", &d, "apply", &unknown_field], &["a.toml:4:", "cahce"]);
    let illegal = bad(
        "b.toml",
        "\n[[trajectory]]\nname = \"x\"\nprimitive = \"Blob\"\npolicy = { cache = -1 }\n",
    );
    fails_with(&["--domain", &d, "apply", &illegal], &["b.toml:2:", "cache"]);
    let unknown_unit = bad(
        "c.toml",
        "[[trajectory]]\nname = \"x\"\nprimitive = \"Blob\"\n\n[[trajectory]]\nname = \"y\"\ncomputed = \"LargBlob\"\ninputs = [\"x\"]\n",
    );
    fails_with(
        &["--domain", &d, "apply", &unknown_unit],
        &["c.toml:5:", "unknown unit `LargBlob`; did you mean `LargeBlob`?"],
    );
    let redefined = bad("d.toml", "[[trajectory]]\nname = \"images\"\nprimitive = \"Image\"\n");
    fails_with(
        &["--domain", &d, "apply", &redefined],
        &["d.toml:1:", "exists with another definition"],
    );
    let syntax = bad("e.toml", "[[trajectory]\nname = \"x\"\n");
    fails_with(&["--domain", &d, "apply", &syntax], &["e.toml:1:"]);
    // The file with an unknown unit declared `x` before failing: nothing was created.
    let list = ok(&["--domain", &d, "traj", "list"]);
    assert!(!list.lines().any(|l| l.starts_with("x ")), "{list}");
    assert_eq!(process_pids(&d), pids, "a bad file disturbed the processes");
    wait_for_sample(&d, "large_blob", Duration::from_secs(30));

    // The command-line faces of the same declarations.
    ok(&["--domain", &d, "type", "add", "Odometry", "dist:Double", "ticks:Long"]);
    assert!(ok(&["--domain", &d, "type", "show", "Odometry"]).contains("ticks"));
    fails_with(&["--domain", &d, "type", "add", "Bad", "x:Meters"], &["unknown sort `Meters`"]);
    let created = ok(&[
        "--domain",
        &d,
        "traj",
        "create",
        "odometry",
        "--primitive",
        "Odometry",
        "--cache",
        "10",
        "--order",
        "strict",
        "--delay",
        "50ms",
        "--reorder",
        "false",
    ]);
    assert!(created.contains("created primitive trajectory `odometry`"), "{created}");
    ok(&[
        "--domain",
        &d,
        "traj",
        "create",
        "blobs_again",
        "--computed",
        "BlobDetection",
        "--inputs",
        "images",
    ]);
    ok(&[
        "--domain",
        &d,
        "traj",
        "create",
        "pair",
        "--sync",
        "current_blob,large_blob",
        "--tolerance",
        "10ms",
    ]);
    fails_with(
        &["--domain", &d, "traj", "create", "y", "--sampled", "camra", "--period", "1s"],
        &["camra", "did you mean `camera`?"],
    );
    fails_with(
        &["--domain", &d, "traj", "create", "y", "--primitive", "Odometry", "--order", "sorted"],
        &["order"],
    );
    fails_with(&["--domain", &d, "traj", "create", "y"], &["needs a source"]);
    // Fluent generators (G4): one gives its values, several their state, every period.
    let args = ["traj", "create", "blob_10hz", "--generate", "current_blob", "--period", "100ms"];
    let created = ok(&[&["--domain", d.as_str()][..], &args[..]].concat());
    assert!(created.contains("sampled-generators trajectory `blob_10hz`"), "{created}");
    let args = ["traj", "create", "both", "--generate", "current_blob,images", "--period", "200ms"];
    ok(&[&["--domain", d.as_str()][..], &args[..]].concat());
    for (generator, needles) in [
        ("images:closest:avg", &["unknown merge `avg`", "average"][..]),
        ("images::median", &["unknown approximation ``"][..]),
        ("images:closest:median", &["image_data", "no median"][..]),
    ] {
        let args = ["traj", "create", "y", "--generate", generator, "--period", "1s"];
        fails_with(&[&["--domain", d.as_str()][..], &args[..]].concat(), needles);
    }
    wait_for_sample(&d, "blobs_again", Duration::from_secs(30));
    wait_for_sample(&d, "pair", Duration::from_secs(30));
    wait_for_sample(&d, "blob_10hz", Duration::from_secs(30));
    wait_for_sample(&d, "both", Duration::from_secs(30));

    // The dataflow with rates and delays: a single-input stage has its own delay.
    let graph = ok(&["--domain", &d, "graph"]);
    let stage = graph.lines().find(|l| l.contains("-> blobs_again")).unwrap_or_default();
    assert!(stage.contains(" Hz") && stage.contains("images: BlobDetection"), "{graph}");
    assert!(stage.contains(" ms"), "no stage delay: {graph}");
    let json = ok(&["--domain", &d, "--json", "graph"]);
    let blobs: serde_json::Value = json
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .find(|v| v["trajectory"] == "blobs_again")
        .unwrap();
    assert!(blobs["inputs"][0]["rate_hz"].as_f64().unwrap() > 0.0, "{blobs}");
    let png = dir.path().join("graph.png");
    ok(&["--domain", &d, "graph", "--png", png.to_str().unwrap()]);
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));

    // `esgm down` stops the coordinator and every process it started.
    ok(&["--domain", &d, "down"]);
    assert!(coordinator_is_gone(&d));
    for pid in pids {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        assert!(stat.is_empty() || stat.contains(") Z"), "worker {pid} still runs: {stat}");
    }
    assert_nothing_left(&d);
}
