//! A binary under test, watched: every wait has a watchdog that fails the test, a
//! process that exits early fails it with what it printed, and the process is killed
//! when the test ends, also when it fails.
//!
//! One copy for the end-to-end tests of both publishers: robot-publisher's include
//! this file by path.

// Each test binary uses part of it.
#![allow(dead_code)]

use std::io::Read;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Long enough for a debug build on a loaded 2-core machine; only a hang reaches it.
pub const WATCHDOG: Duration = Duration::from_secs(60);

/// A running binary; killed on drop unless it has already left.
#[derive(Debug)]
pub struct Watched {
    program: String,
    child: Child,
}

impl Watched {
    /// Starts `program args…` outside any supervised system (no `ESGM_*` variables),
    /// its output captured.
    pub fn start(program: &str, args: &[&str]) -> Self {
        let child = Command::new(program)
            .args(args)
            .env_remove(esgm_shm::WORKER_ENV)
            .env_remove(esgm_shm::DOMAIN_ENV)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
        let program = program.rsplit('/').next().unwrap_or(program).to_owned();
        Self { program, child }
    }

    /// Its exit status, if it has exited, with what it printed on stderr.
    fn exited(&mut self) -> Option<(ExitStatus, String)> {
        let status = self.child.try_wait().unwrap()?;
        Some((status, read(self.child.stderr.take())))
    }

    /// Polls `probe` until it gives a value; fails if the process exits or the watchdog
    /// expires first.
    pub fn wait_for<T>(&mut self, what: &str, mut probe: impl FnMut() -> Option<T>) -> T {
        let deadline = Instant::now() + WATCHDOG;
        loop {
            if let Some(t) = probe() {
                return t;
            }
            if let Some((status, stderr)) = self.exited() {
                panic!("{} exited ({status}) before {what}:\n{stderr}", self.program);
            }
            assert!(Instant::now() < deadline, "no {what} within {WATCHDOG:?}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the process to leave on its own: its status and stderr.
    pub fn wait_exit(&mut self, why: &str) -> (ExitStatus, String) {
        let deadline = Instant::now() + WATCHDOG;
        loop {
            if let Some(exit) = self.exited() {
                return exit;
            }
            assert!(Instant::now() < deadline, "{} did not exit ({why})", self.program);
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// What it printed on stdout (read to the end: call once it has exited).
    pub fn stdout(&mut self) -> String {
        read(self.child.stdout.take())
    }
}

fn read(pipe: Option<impl Read>) -> String {
    let mut text = String::new();
    if let Some(mut pipe) = pipe {
        pipe.read_to_string(&mut text).unwrap();
    }
    text
}

impl Drop for Watched {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            // Already exiting or gone if these fail; nothing else to clean.
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
