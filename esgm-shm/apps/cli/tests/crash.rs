//! Crashes end to end: the coordinator of a running tutorial system is killed with
//! `kill -9`; data keeps flowing between its workers, a new `esgm up` recovers the
//! registry and adopts them; the demo leaves nothing behind. Real processes, unique
//! domains and state directories, a watchdog on every command and wait.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::capability;
use esgm_shm::control::{ControlClient, Request, Response};

const ESGM: &str = env!("CARGO_BIN_EXE_esgm");
const TUTORIAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tutorial.toml");

/// One system at a time (each is six processes on a 2-core machine).
static ONE_SYSTEM: std::sync::Mutex<()> = std::sync::Mutex::new(());

struct Output {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// A test's system: its domain and state home, stopped when the test ends.
struct System {
    domain: String,
    state_home: PathBuf,
}

impl System {
    fn new(prefix: &str) -> Self {
        let domain = esgm_shm::unique_domain(prefix);
        let state_home = std::env::temp_dir().join(format!("esgm-test-state-{domain}"));
        Self { domain, state_home }
    }

    fn command(&self, args: &[&str]) -> Command {
        let mut c = Command::new(ESGM);
        c.args(["--domain", &self.domain])
            .args(args)
            .env("XDG_STATE_HOME", &self.state_home)
            .env_remove("ESGM_STATE_DIR")
            .stdin(Stdio::null());
        c
    }

    /// Runs `esgm --domain d args…`, killing it after `limit`.
    fn run(&self, args: &[&str], limit: Duration) -> Output {
        let mut child =
            self.command(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
        let deadline = Instant::now() + limit;
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if Instant::now() > deadline {
                child.kill().unwrap();
                child.wait().unwrap();
                panic!("`esgm {}` did not finish within {limit:?}", args.join(" "));
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let (mut stdout, mut stderr) = (String::new(), String::new());
        child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
        child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        Output { code: status.code(), stdout, stderr }
    }

    fn ok(&self, args: &[&str]) -> String {
        let o = self.run(args, Duration::from_secs(60));
        assert_eq!(
            o.code,
            Some(0),
            "`esgm {}` failed:\n{}\n{}",
            args.join(" "),
            o.stdout,
            o.stderr
        );
        o.stdout
    }

    fn state_dir(&self) -> PathBuf {
        self.state_home.join("esgm").join(&self.domain)
    }

    /// `(name, pid, restarts)` of every process, from `esgm ps --json`.
    fn processes(&self) -> Vec<(String, Option<u32>, u64)> {
        self.ok(&["--json", "ps"])
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .map(|v| {
                (
                    v["spec"]["name"].as_str().unwrap().to_owned(),
                    v["status"]["pid"].as_u64().map(|p| u32::try_from(p).unwrap()),
                    v["status"]["restarts"].as_u64().unwrap(),
                )
            })
            .collect()
    }

    /// Polls until every declared process has a pid, or fails after `limit`.
    fn wait_for_pids(&self, limit: Duration) -> Vec<(String, Option<u32>, u64)> {
        let deadline = Instant::now() + limit;
        loop {
            let p = self.processes();
            if !p.is_empty() && p.iter().all(|(_, pid, _)| pid.is_some()) {
                return p;
            }
            assert!(Instant::now() < deadline, "processes did not start: {p:?}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// `esgm echo traj` running, with its lines as they come, once it has received one.
    fn subscriber(&self, traj: &str) -> (Child, mpsc::Receiver<String>) {
        let mut echo = self
            .command(&["echo", traj])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let lines = lines_of(&mut echo);
        lines.recv_timeout(Duration::from_secs(30)).expect("the subscriber receives");
        (echo, lines)
    }

    /// `esgm up --detach` and the tutorial applied; every worker's `(name, pid,
    /// restarts)` once all run.
    fn tutorial(&self) -> Vec<(String, Option<u32>, u64)> {
        self.ok(&["up", "--detach"]);
        self.ok(&["apply", TUTORIAL]);
        self.wait_for_pids(Duration::from_secs(60))
    }

    /// The valid time of the latest sample of `traj`, polled until there is one.
    fn latest_valid_time(&self, traj: &str, limit: Duration) -> i64 {
        let deadline = Instant::now() + limit;
        loop {
            let o = self.run(&["--json", "latest", traj], Duration::from_secs(60));
            if o.code == Some(0) {
                if let Some(line) = o.stdout.lines().next() {
                    let v: serde_json::Value = serde_json::from_str(line).unwrap();
                    if let Some(t) = v["valid_time"].as_i64() {
                        return t;
                    }
                }
            }
            assert!(Instant::now() < deadline, "no sample in `{traj}`: {}{}", o.stdout, o.stderr);
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for System {
    fn drop(&mut self) {
        match self.command(&["down"]).stdout(Stdio::null()).stderr(Stdio::null()).status() {
            Ok(_) => {}
            Err(e) => eprintln!("cannot run `esgm down`: {e}"),
        }
        if let Err(e) = std::fs::remove_dir_all(&self.state_home) {
            if e.kind() != std::io::ErrorKind::NotFound {
                eprintln!("cannot remove {}: {e}", self.state_home.display());
            }
        }
    }
}

/// `kill -9 pid`.
fn kill9(pid: u32) {
    assert!(Command::new("kill").args(["-9", &pid.to_string()]).status().unwrap().success());
}

/// `kill -9 pid`, then waits (at most 10 s) until it is gone.
fn kill9_and_wait(pid: u32, what: &str) {
    kill9(pid);
    let killed_at = Instant::now();
    while alive(pid) {
        assert!(killed_at.elapsed() < Duration::from_secs(10), "{what} did not die");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Every one of `pids` has exited and the domain has no iceoryx2 node left (a listing
/// that fails, fails the test).
fn nothing_left<'a>(domain: &str, pids: impl IntoIterator<Item = (&'a str, u32)>) {
    for (name, pid) in pids {
        assert!(!alive(pid), "{name} still runs");
    }
    let nodes = esgm_shm::nodes_of(domain).expect("cannot list nodes");
    assert!(nodes.is_empty(), "nodes left behind: {nodes:?}");
}

fn alive(pid: u32) -> bool {
    std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat"))
        .is_ok_and(|s| s.rsplit_once(')').is_some_and(|(_, r)| !r.trim_start().starts_with('Z')))
}

fn coordinator_pid(domain: &str) -> u32 {
    let c = ControlClient::connect(domain, Duration::from_secs(10)).unwrap();
    match c.call(&Request::Ping).unwrap() {
        Response::Pong { pid, .. } => pid,
        other => panic!("{other:?}"),
    }
}

/// Lines of a child's stdout, as they come.
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
fn a_killed_coordinator_leaves_data_flowing_and_comes_back_whole() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let sys = System::new("crash-coord");
    let before = sys.tutorial();
    sys.latest_valid_time("driving_direction", Duration::from_secs(60));

    // A subscriber in the middle of the stream.
    let (mut echo, lines) = sys.subscriber("robot_state");

    let coordinator = coordinator_pid(&sys.domain);
    kill9_and_wait(coordinator, "the coordinator");

    // Data keeps flowing between the existing processes: the subscriber receives the
    // robot's states (the robot steers by the driving direction the units compute).
    while lines.try_recv().is_ok() {}
    let mut received = 0;
    let deadline = Instant::now() + Duration::from_secs(30);
    while received < 20 {
        assert!(Instant::now() < deadline, "the subscriber stopped after the crash ({received})");
        if lines.recv_timeout(Duration::from_secs(5)).is_ok() {
            received += 1;
        }
    }
    for (name, pid, _) in &before {
        assert!(alive(pid.unwrap()), "{name} exited when the coordinator died");
    }
    // The registry is kept for the next coordinator.
    assert!(sys.state_dir().join("registry.json").exists());
    // Each worker notices on its own (a ping overstays its deadline, the coordinator's
    // pid is gone) and says so in its log, before anyone starts a new coordinator: one
    // started earlier would answer the pending ping and the crash would go unseen.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let camera = sys.ok(&["logs", "camera-camera"]);
        if camera.contains("the coordinator is gone; serving on") {
            break;
        }
        assert!(Instant::now() < deadline, "the camera did not notice the crash:\n{camera}");
        std::thread::sleep(Duration::from_millis(250));
    }

    // A new coordinator starts while the old workers live, recovers the registry and
    // adopts them: same pids, no restart.
    sys.ok(&["up", "--detach"]);
    let after = sys.wait_for_pids(Duration::from_secs(30));
    assert_eq!(before.len(), after.len(), "{after:?}");
    for ((name, pid, _), (name2, pid2, restarts)) in before.iter().zip(&after) {
        assert_eq!((name, pid), (name2, pid2), "{name} was not adopted");
        assert_eq!(*restarts, 0, "{name} was restarted");
    }
    let traj = sys.ok(&["traj", "list"]);
    for t in ["images", "blobs", "current_blob", "driving_direction", "robot_state"] {
        assert!(traj.contains(t), "`{t}` not recovered:\n{traj}");
    }
    // New data after the recovery, answered through the new coordinator.
    let t0 = sys.latest_valid_time("driving_direction", Duration::from_secs(30));
    let deadline = Instant::now() + Duration::from_secs(30);
    while sys.latest_valid_time("driving_direction", Duration::from_secs(30)) <= t0 {
        assert!(Instant::now() < deadline, "driving_direction stopped after the recovery");
        std::thread::sleep(Duration::from_millis(200));
    }
    // The subscriber still receives.
    lines.recv_timeout(Duration::from_secs(10)).expect("the subscriber receives after recovery");
    echo.kill().unwrap();
    echo.wait().unwrap();

    // Each process logged to the domain's log directory.
    let logs = sys.ok(&["logs"]);
    for name in ["coordinator", "camera-camera", "robot-robot_state"] {
        assert!(logs.contains(name), "no log of {name}:\n{logs}");
    }

    sys.ok(&["down"]);
    assert!(!sys.state_dir().join("registry.json").exists(), "an orderly stop forgets");
    nothing_left(&sys.domain, after.iter().map(|(n, p, _)| (n.as_str(), p.unwrap())));
}

/// Issue 39's done criteria from the command line: structures `esgm push` acknowledged
/// stay queryable after `kill -9` of their writer, here the coordinator's own process
/// (it writes what the command line creates); the next coordinator writes the
/// trajectory again with that history, and an orderly `esgm down` leaves no kept
/// history in shared memory.
#[test]
fn pushed_structures_outlive_kill_9_of_their_writer_and_the_coordinator() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let sys = System::new("crash-kept");
    sys.ok(&["up", "--detach"]);
    sys.ok(&["traj", "create", "odo", "--primitive", "RobotState", "--cache", "2"]);
    for (vt, x) in [("1000", "1"), ("2000", "2"), ("3000", "3")] {
        sys.ok(&["push", "odo", &format!("x={x}"), "y=0", "dir=0", "--valid-time", vt]);
    }
    let xs = |sys: &System| -> Vec<f64> {
        sys.ok(&["--json", "between", "odo", "0", "10000"])
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .map(|v| v["attributes"]["x"].as_f64().unwrap())
            .collect()
    };
    assert_eq!(xs(&sys), [2.0, 3.0], "what cache 2 keeps");

    let coordinator = coordinator_pid(&sys.domain);
    kill9_and_wait(coordinator, "the coordinator");
    sys.ok(&["up", "--detach"]);
    assert_eq!(sys.latest_valid_time("odo", Duration::from_secs(30)), 3000);
    assert_eq!(xs(&sys), [2.0, 3.0], "the history the killed writer kept");
    sys.ok(&["push", "odo", "x=4", "y=0", "dir=0", "--valid-time", "4000"]);
    assert_eq!(xs(&sys), [3.0, 4.0], "continued by the new writer");

    sys.ok(&["down"]);
    let kept: Vec<String> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&format!("esgm_keep@{}.", sys.domain)))
        .collect();
    assert!(kept.is_empty(), "kept histories left after `esgm down`: {kept:?}");
}

/// `kill -9` of each worker kind in turn — the camera, each unit, the robot — and of a
/// CLI subscriber: the killed worker is restarted, its trajectory resumes, every other
/// process keeps its pid, the subscriber and a recorder keep running, and `esgm down`
/// leaves nothing behind.
#[test]
fn every_process_kind_survives_kill_9_of_any_other() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let sys = System::new("crash-each");
    let before = sys.tutorial();
    sys.latest_valid_time("driving_direction", Duration::from_secs(60));
    let recording = sys.state_home.join("run.mcap");
    let mut recorder = sys
        .command(&["record", "-o", recording.to_str().unwrap(), "robot_state", "images"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (mut echo, lines) = sys.subscriber("robot_state");

    let workers = [
        ("camera-camera", "images"),
        ("unit-BlobDetection", "blobs"),
        ("unit-BlobSelection", "current_blob"),
        ("unit-DrivingDirection", "driving_direction"),
        ("robot-robot_state", "robot_state"),
    ];
    let mut pids: std::collections::BTreeMap<String, u32> =
        before.iter().map(|(n, p, _)| (n.clone(), p.unwrap())).collect();
    for (process, trajectory) in workers {
        let old = pids[process];
        let t0 = sys.latest_valid_time(trajectory, Duration::from_secs(60));
        kill9(old);
        // Restarted by the supervisor, with a new pid; the others untouched.
        let deadline = Instant::now() + Duration::from_secs(60);
        let new = loop {
            let now = sys.processes();
            let me = now.iter().find(|(n, _, _)| n == process).unwrap();
            if let (Some(pid), restarts) = (me.1, me.2) {
                if pid != old && restarts >= 1 {
                    break pid;
                }
            }
            assert!(Instant::now() < deadline, "{process} was not restarted: {now:?}");
            std::thread::sleep(Duration::from_millis(100));
        };
        for (name, pid) in &pids {
            if name != process {
                assert!(alive(*pid), "{name} died when {process} was killed");
            }
        }
        pids.insert(process.to_owned(), new);
        // Its trajectory resumes.
        let deadline = Instant::now() + Duration::from_secs(60);
        while sys.latest_valid_time(trajectory, Duration::from_secs(30)) <= t0 {
            assert!(Instant::now() < deadline, "`{trajectory}` did not resume after {process}");
            std::thread::sleep(Duration::from_millis(200));
        }
        // The subscriber and the recorder live on.
        while lines.try_recv().is_ok() {}
        lines
            .recv_timeout(Duration::from_secs(30))
            .unwrap_or_else(|_| panic!("the subscriber stopped after {process} was killed"));
        assert!(recorder.try_wait().unwrap().is_none(), "the recorder ended with {process}");
    }

    // The subscriber itself: nobody else notices, and a new one receives.
    echo.kill().unwrap();
    echo.wait().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    for (name, pid) in &pids {
        assert!(alive(*pid), "{name} died with the subscriber");
    }
    let again = sys.ok(&["--json", "echo", "robot_state", "--count", "3"]);
    assert_eq!(again.lines().count(), 3, "{again}");

    // The recorder stops on Ctrl-C and its file holds structures from before and after.
    assert!(
        Command::new("kill").args(["-INT", &recorder.id().to_string()]).status().unwrap().success()
    );
    let deadline = Instant::now() + Duration::from_secs(60);
    while recorder.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "the recorder did not stop on Ctrl-C");
        std::thread::sleep(Duration::from_millis(100));
    }
    let info = sys.ok(&["--json", "info", recording.to_str().unwrap()]);
    assert!(info.contains("robot_state") && info.contains("images"), "{info}");

    sys.ok(&["down"]);
    nothing_left(&sys.domain, pids.iter().map(|(n, p)| (n.as_str(), *p)));
}

#[test]
fn down_stops_a_system_whose_coordinator_crashed() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let sys = System::new("crash-down");
    let workers = sys.tutorial();
    kill9(coordinator_pid(&sys.domain));
    let out = sys.run(&["down"], Duration::from_secs(60));
    assert_eq!(out.code, Some(0), "{}\n{}", out.stdout, out.stderr);
    assert!(out.stderr.contains("crashed"), "{}", out.stderr);
    nothing_left(&sys.domain, workers.iter().map(|(n, p, _)| (n.as_str(), p.unwrap())));
}

/// The demo in a private `/dev/shm` (segments, and iceoryx2's small files in
/// `/dev/shm/iceoryx2`) and `/tmp/iceoryx2` (iceoryx2's own default root), in a user
/// namespace; the rest of `/tmp` stays visible, where a checkout and its binaries may
/// live: afterwards only iceoryx2's own global counter file may remain, nothing of the
/// demo.
#[test]
fn the_demo_leaves_no_file_in_shared_memory() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // A private /dev/shm: a user and mount namespace.
    let namespaces = capability::runs("unshare", &["-rm", "true"]);
    if capability::needs("user namespaces (unshare -rm)", namespaces).is_none() {
        return;
    }
    let script = format!(
        "mkdir -p /tmp/iceoryx2 && mount -t tmpfs tmpfs /dev/shm && \
         mount -t tmpfs tmpfs /tmp/iceoryx2 && out=$(mktemp) && \
         {ESGM} demo --seconds 6 >$out 2>&1; rc=$?; \
         if [ $rc -ne 0 ]; then cat $out; rm -f $out; exit $rc; fi; rm -f $out; \
         echo LEFT; find /dev/shm /tmp/iceoryx2 -type f 2>/dev/null; true"
    );
    let mut child = Command::new("unshare")
        .args(["-rm", "sh", "-c", &script])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(180);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("the demo did not finish");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut out = String::new();
    child.stdout.take().unwrap().read_to_string(&mut out).unwrap();
    assert!(status.success(), "demo failed:\n{out}");
    let left: Vec<&str> = out
        .split_once("LEFT")
        .map(|(_, l)| l.lines().filter(|l| !l.trim().is_empty()).collect())
        .unwrap_or_default();
    let extra: Vec<&&str> = left.iter().filter(|f| !f.ends_with(".global_mgmt")).collect();
    assert!(extra.is_empty(), "the demo left files behind: {extra:?}");
}

#[test]
fn a_supervised_coordinator_comes_back_by_itself() {
    let _one = ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let sys = System::new("crash-super");
    let up = sys.ok(&["up", "--detach", "--supervise"]);
    let supervisor: u32 = up
        .split("(pid ")
        .nth(1)
        .and_then(|r| r.split(')').next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no pid in: {up}"));
    sys.ok(&["apply", TUTORIAL]);
    let before = sys.wait_for_pids(Duration::from_secs(60));
    let first = coordinator_pid(&sys.domain);
    kill9(first);
    // A new coordinator serves, by itself.
    let deadline = Instant::now() + Duration::from_secs(60);
    let second = loop {
        let answer = ControlClient::connect(&sys.domain, Duration::from_secs(2))
            .and_then(|c| c.call(&Request::Ping));
        if let Ok(Response::Pong { pid, .. }) = answer {
            if pid != first {
                break pid;
            }
        }
        assert!(Instant::now() < deadline, "no coordinator came back");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(alive(second));
    let after = sys.wait_for_pids(Duration::from_secs(30));
    for ((name, pid, _), (_, pid2, restarts)) in before.iter().zip(&after) {
        assert_eq!((pid, *restarts), (pid2, 0), "{name} was not adopted");
    }
    sys.ok(&["down"]);
    for (name, pid, _) in &after {
        assert!(!alive(pid.unwrap()), "{name} still runs after `esgm down`");
    }
    assert!(!alive(second), "the coordinator still runs after `esgm down`");
    // An orderly stop ends the supervisor too.
    let deadline = Instant::now() + Duration::from_secs(10);
    while alive(supervisor) {
        assert!(Instant::now() < deadline, "the supervisor still runs after `esgm down`");
        std::thread::sleep(Duration::from_millis(20));
    }
}
