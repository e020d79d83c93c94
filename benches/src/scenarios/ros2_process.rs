//! A process of a `ros2-*` row (feature `ros2`): the `esgm-ros2` bridge, or a DDS end
//! (`esgm-bench` in a peer role), run inside the row's network namespace and talked to
//! by lines: written to its stdin, read from its stdout.
//!
//! Every wait for a line has a deadline and notices the process exiting (its stderr is
//! in the error). A process that was not seen to exit is killed and reaped when
//! dropped, so no error path leaves one running, and the iceoryx2 resources a killed
//! bridge could not clean up are removed ([`remove_dead_nodes`]).

use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};

use super::ipc_node::remove_dead_nodes;
use crate::patience::SLICE;

/// A running process of a row (see the module docs).
#[derive(Debug)]
pub struct LinkedProcess {
    name: String,
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<String>,
    stderr: Option<JoinHandle<String>>,
    reaped: bool,
}

impl LinkedProcess {
    /// Starts `command` (its stdin, stdout and stderr piped); `name` says which process
    /// it is in errors.
    pub fn spawn(name: impl Into<String>, mut command: Command) -> anyhow::Result<Self> {
        let name = name.into();
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start the {name}"))?;
        let stdin = child.stdin.take();
        let (stdout, stderr) = (child.stdout.take(), child.stderr.take());
        // Built before the checks below, so that a failure kills the child (Drop).
        let (tx, lines) = mpsc::channel();
        let mut process = Self { name, child, stdin, lines, stderr: None, reaped: false };
        let stdout = stdout.context("no stdout pipe")?;
        let stderr = stderr.context("no stderr pipe")?;
        std::thread::Builder::new()
            .name("esgm-bench-ros2-out".into())
            .spawn(move || {
                for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                    if tx.send(line).is_err() {
                        return;
                    }
                }
            })
            .context("starting a thread to read a process's output")?;
        process.stderr = Some(
            std::thread::Builder::new()
                .name("esgm-bench-ros2-err".into())
                .spawn(move || {
                    let mut text = String::new();
                    // A read error only shortens what an error message shows.
                    let _shortened = BufReader::new(stderr).read_to_string(&mut text);
                    text
                })
                .context("starting a thread to read a process's errors")?,
        );
        Ok(process)
    }

    /// Writes `line` to its stdin.
    pub fn send(&mut self, line: &str) -> anyhow::Result<()> {
        let stdin = self.stdin.as_mut().with_context(|| format!("{}: stdin closed", self.name))?;
        writeln!(stdin, "{line}")
            .and_then(|()| stdin.flush())
            .with_context(|| format!("writing to the {}", self.name))
    }

    /// Closes its stdin: the DDS ends stop at its end.
    pub fn close_stdin(&mut self) {
        self.stdin = None;
    }

    /// The next line `accept` takes, skipping others; fails if none came within
    /// `within` or the process exited.
    pub fn line(
        &mut self,
        what: &str,
        within: Duration,
        accept: impl Fn(&str) -> bool,
    ) -> anyhow::Result<String> {
        let deadline = Instant::now() + within;
        loop {
            if let Some(line) = self.line_within(SLICE, &accept)? {
                return Ok(line);
            }
            if Instant::now() >= deadline {
                bail!("the {} gave no {what} within {within:?}", self.name);
            }
        }
    }

    /// The next line `accept` takes within `slice`, if one comes; fails if the process
    /// exited.
    pub fn line_within(
        &mut self,
        slice: Duration,
        accept: impl Fn(&str) -> bool,
    ) -> anyhow::Result<Option<String>> {
        let deadline = Instant::now() + slice;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if accept(&line) => return Ok(Some(line)),
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => {
                    self.check_running()?;
                    return Ok(None);
                }
                Err(RecvTimeoutError::Disconnected) => {
                    // Its stdout closed: it is exiting.
                    let status = self.child.wait().context("waiting for an exiting process")?;
                    self.reaped = true;
                    return Err(self.failure(&format!("ended ({status})")));
                }
            }
        }
    }

    /// Lines it printed and nobody took yet.
    pub fn drain(&mut self) -> Vec<String> {
        self.lines.try_iter().collect()
    }

    /// Asks it to stop with SIGTERM (what `esgm-ros2` stops on, reporting its counters).
    pub fn terminate(&mut self) -> anyhow::Result<()> {
        let status = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .context("running kill")?;
        if !status.success() {
            bail!("kill -TERM {} failed ({status})", self.child.id());
        }
        Ok(())
    }

    /// Waits, at most `within`, for a process told to stop to exit successfully, and
    /// returns the lines it printed that nobody took; kills it when it overstays.
    pub fn finish(mut self, within: Duration) -> anyhow::Result<Vec<String>> {
        self.close_stdin();
        let deadline = Instant::now() + within;
        loop {
            if let Some(status) = self.child.try_wait().context("waiting for a process")? {
                self.reaped = true;
                if !status.success() {
                    return Err(self.failure(&format!("failed ({status})")));
                }
                // Its stdout is closed: the reader ends once it has sent every line.
                let mut lines = Vec::new();
                while let Ok(line) = self.lines.recv_timeout(within) {
                    lines.push(line);
                }
                return Ok(lines);
            }
            if Instant::now() >= deadline {
                bail!("the {} did not exit within {within:?} of being told to stop", self.name);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    fn check_running(&mut self) -> anyhow::Result<()> {
        match self.child.try_wait() {
            Ok(None) => Ok(()),
            Ok(Some(status)) => {
                self.reaped = true;
                Err(self.failure(&format!("exited ({status})")))
            }
            Err(e) => Err(anyhow!(e).context(format!("cannot check on the {}", self.name))),
        }
    }

    fn failure(&mut self, what: &str) -> anyhow::Error {
        let stderr = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        // The end of its stderr says why; a chatty process's whole log would not.
        let tail: Vec<&str> = stderr.lines().rev().take(12).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        if tail.is_empty() {
            anyhow!("the {} {what}, saying nothing on stderr", self.name)
        } else {
            anyhow!("the {} {what}: {}", self.name, tail.join("\n"))
        }
    }
}

impl Drop for LinkedProcess {
    fn drop(&mut self) {
        if !self.reaped {
            // Errors mean it is gone already.
            let _killed = self.child.kill();
            let _reaped = self.child.wait();
            // A killed bridge leaves its iceoryx2 node behind.
            remove_dead_nodes();
        }
    }
}
