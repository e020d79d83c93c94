//! Running the `esgm` binary in tests: every command under a watchdog (a command that
//! overstays is killed and fails the test), and systems stopped when a test ends.

#![allow(dead_code)] // each test binary uses what it needs
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The binary under test.
pub const ESGM: &str = env!("CARGO_BIN_EXE_esgm");

/// How long a command may take by default (debug builds on a loaded 2-core machine).
pub const PATIENCE: Duration = Duration::from_secs(120);

/// What a finished command said.
#[derive(Debug)]
pub struct Output {
    /// Its exit code (`None`: killed by a signal).
    pub code: Option<i32>,
    /// Everything it printed.
    pub stdout: String,
    /// Everything it printed on stderr.
    pub stderr: String,
}

/// Runs `esgm args…`, killing it after `limit`.
pub fn esgm(args: &[&str], limit: Duration) -> Output {
    let child = Command::new(ESGM)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run esgm");
    finish(child, limit, &args.join(" "))
}

/// Waits for a started `esgm` (stdout and stderr piped), killing it after `limit`.
pub fn finish(mut child: Child, limit: Duration, what: &str) -> Output {
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("`esgm {what}` did not finish within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let (mut stdout, mut stderr) = (String::new(), String::new());
    if let Some(mut out) = child.stdout.take() {
        out.read_to_string(&mut stdout).unwrap();
    }
    if let Some(mut err) = child.stderr.take() {
        err.read_to_string(&mut stderr).unwrap();
    }
    Output { code: status.code(), stdout, stderr }
}

/// Runs `esgm args…` within [`PATIENCE`], failing the test unless it exits 0;
/// returns its stdout.
pub fn ok(args: &[&str]) -> String {
    ok_within(args, PATIENCE)
}

/// Runs `esgm args…` within `limit`, failing the test unless it exits 0; returns its
/// stdout.
pub fn ok_within(args: &[&str], limit: Duration) -> String {
    let o = esgm(args, limit);
    assert_eq!(o.code, Some(0), "`esgm {}` failed:\n{}\n{}", args.join(" "), o.stdout, o.stderr);
    o.stdout
}

/// Stops a domain's system when the test ends, also when it fails (a detached
/// coordinator and its workers would otherwise outlive the test).
pub struct StopOnDrop(pub String);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        let status = Command::new(ESGM)
            .args(["--domain", &self.0, "down"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
        if let Err(e) = status {
            eprintln!("cannot stop `{}`: {e}", self.0);
        }
    }
}

/// Tests that need root, namespaces or a binary beside `esgm`: skipped, or failed in CI.
pub mod capability;
pub mod netns;
