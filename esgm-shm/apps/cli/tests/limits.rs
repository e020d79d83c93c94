//! P6 from the command line: a reader or process past a domain's limits is refused with
//! one line naming the limit and its setting, while `esgm push`, `latest`, `ps`,
//! `stats`, `traj list` and `down` keep working on the full domain.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{ESGM, PATIENCE, StopOnDrop, esgm, ok};

/// A long-lived reader: `esgm echo TRAJ` that has printed the trajectory's latest
/// sample (so it is subscribed). Killed when dropped.
struct Echo(Child);

impl Echo {
    fn start(domain: &str, trajectory: &str) -> Echo {
        let mut child = Command::new(ESGM)
            .args(["--domain", domain, "echo", trajectory, "--last", "1", "--seconds", "300"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run esgm echo");
        let stdout = child.stdout.take().expect("piped");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut lines = BufReader::new(stdout);
            let mut first = String::new();
            let read = lines.read_line(&mut first);
            let _ = tx.send(read.map(|_| first));
            // Drained while it runs: a reader whose stdout closed would leave.
            let mut rest = String::new();
            while lines.read_line(&mut rest).is_ok_and(|n| n > 0) {
                rest.clear();
            }
        });
        match rx.recv_timeout(PATIENCE) {
            Ok(Ok(line)) if !line.is_empty() => Echo(child),
            other => {
                child.kill().expect("kill esgm echo");
                let out = child.wait_with_output().expect("reap esgm echo");
                panic!(
                    "`esgm echo {trajectory}` printed nothing ({other:?}): {}",
                    String::from_utf8_lossy(&out.stderr)
                );
            }
        }
    }
}

impl Drop for Echo {
    fn drop(&mut self) {
        if let Err(e) = self.0.kill() {
            eprintln!("esgm echo had left: {e}");
        }
        if let Err(e) = self.0.wait() {
            eprintln!("cannot reap esgm echo: {e}");
        }
    }
}

/// `esgm echo TRAJ` must be refused at once, naming `limit` and `setting`.
fn refused(domain: &str, trajectory: &str, limit: &str, setting: &str) {
    let o = esgm(&["--domain", domain, "echo", trajectory, "--seconds", "30"], PATIENCE);
    assert_eq!(o.code, Some(1), "refused: {}\n{}", o.stdout, o.stderr);
    let line = o.stderr.trim();
    assert!(line.contains(limit), "names the limit `{limit}`: {line}");
    assert!(line.contains(setting), "names the setting `{setting}`: {line}");
    assert!(!line.contains("Exceeds") && !line.contains("Error::"), "no iceoryx2 words: {line}");
    assert_eq!(line.lines().count(), 1, "one line: {line}");
}

/// `esgm push` then `esgm latest` on `trajectory` work.
fn served(domain: &str, trajectory: &str, x: &str) {
    ok(&["--domain", domain, "push", trajectory, &format!("x={x}"), "y=0", "dir=0"]);
    let latest = ok(&["--domain", domain, "--json", "latest", trajectory]);
    assert!(latest.contains(&format!("\"x\":{x}")), "latest shows the push: {latest}");
}

#[test]
fn readers_and_processes_past_their_limits_are_refused_and_the_domain_serves_on() {
    let d = esgm_shm::unique_domain("cli-limits");
    let state = tempfile::tempdir().expect("state dir");
    let dir = state.path().to_str().expect("utf-8 path");
    ok(&[
        "--domain",
        &d,
        "up",
        "--detach",
        "--max-processes",
        "6",
        "--readers",
        "2",
        "--state-dir",
        dir,
    ]);
    let _stop = StopOnDrop(d.clone());
    ok(&["--domain", &d, "traj", "create", "tf", "--primitive", "RobotState", "--cache", "10"]);
    served(&d, "tf", "1.5");

    // `tf` admits 2 readers (the domain's default): a third is refused.
    let readers: Vec<Echo> = (0..2).map(|_| Echo::start(&d, "tf")).collect();
    refused(&d, "tf", "readers = 2", "--readers N");
    served(&d, "tf", "2.5");

    // The domain admits 6 processes: its own location and the 2 readers are 3.
    ok(&["--domain", &d, "traj", "create", "odom", "--primitive", "RobotState", "--readers", "6"]);
    served(&d, "odom", "3.5");
    let more: Vec<Echo> = (0..3).map(|_| Echo::start(&d, "odom")).collect();
    refused(&d, "odom", "max-processes = 6", "--max-processes N");
    served(&d, "odom", "4.5");
    served(&d, "tf", "5.5");
    // The operator is not locked out of the full domain: the short-lived commands look.
    let ps = ok(&["--domain", &d, "ps"]);
    assert!(ps.contains("process"), "{ps}");
    let stats = ok(&["--domain", &d, "stats"]);
    assert!(stats.contains("odom") && stats.contains("tf"), "{stats}");
    let traj = ok(&["--domain", &d, "traj", "list"]);
    assert!(traj.contains("odom"), "{traj}");

    // Processes leaving (killed: whoever needs their room cleans up after them) make
    // room for another.
    drop(more);
    let deadline = Instant::now() + PATIENCE;
    loop {
        let o = esgm(&["--domain", &d, "echo", "odom", "--last", "1", "--count", "1"], PATIENCE);
        if o.code == Some(0) {
            break;
        }
        assert!(Instant::now() < deadline, "no room after processes left: {}", o.stderr);
        std::thread::sleep(Duration::from_millis(500));
    }
    // Full again, `esgm down` still stops the domain.
    let full: Vec<Echo> = (0..3).map(|_| Echo::start(&d, "odom")).collect();
    refused(&d, "odom", "max-processes = 6", "--max-processes N");
    ok(&["--domain", &d, "down"]);
    let gone = esgm(&["--domain", &d, "ps"], PATIENCE);
    assert!(
        gone.code != Some(0) && gone.stderr.contains("no coordinator"),
        "the domain still answers after `esgm down`: {} {}",
        gone.stdout,
        gone.stderr
    );
    drop(full);
    drop(readers);
}
