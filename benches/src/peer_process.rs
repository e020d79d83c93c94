//! A peer process: `esgm-bench` started again in a peer role, watched, and never left
//! behind.
//!
//! The measuring process starts one peer per measurement ([`PeerProcess::spawn`]),
//! tells it to stop through the scenario's own channel when done, and reaps it with
//! [`PeerProcess::finish`], which kills a peer that overstays. A peer that exits early
//! is noticed by [`crate::patience::Patience`] within one wait slice, and reported
//! with what it wrote on stderr. Dropping a `PeerProcess` that was not reaped (the
//! measurement failed) kills it, so no error path leaves a process running; after a
//! kill, the iceoryx2 resources the peer could not clean up are removed.

use std::io::Read;
use std::process::{Child, ChildStderr, ChildStdout, Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};

use crate::peer_role::PeerRole;
use crate::scenarios::ipc_node::remove_dead_nodes;

/// How long a peer may take to exit once told to stop.
pub const FINISH_TIMEOUT: Duration = Duration::from_secs(10);

/// A running peer process (see the module docs).
#[derive(Debug)]
pub struct PeerProcess {
    name: String,
    child: Child,
    stdout: Option<JoinHandle<String>>,
    stderr: Option<JoinHandle<String>>,
    reaped: bool,
}

impl PeerProcess {
    /// Starts this executable as the peer `role`.
    pub fn spawn(role: &PeerRole) -> anyhow::Result<Self> {
        let name = format!("{} peer process ({})", role.scenario, role.wait.arg());
        let exe = std::env::current_exe()
            .context("could not find the esgm-bench executable to start a peer process")?;
        let child = Command::new(&exe)
            .args(role.to_args())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("could not start the {name} ({})", exe.display()))?;
        let mut peer = Self { name, child, stdout: None, stderr: None, reaped: false };
        // Drained on threads so that a chatty peer can never block on a full pipe.
        peer.stdout = peer.child.stdout.take().map(drain::<ChildStdout>).transpose()?;
        peer.stderr = peer.child.stderr.take().map(drain::<ChildStderr>).transpose()?;
        Ok(peer)
    }

    /// The peer's process id (to read its memory use in `/proc`).
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// Fails if the peer has exited. A peer exits only when told to stop, so while a
    /// scenario still waits for it, an exit is a failure; the error carries its stderr.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        match self.child.try_wait() {
            Ok(None) => Ok(()),
            Ok(Some(status)) => {
                self.reaped = true;
                // It may have died without cleaning up.
                remove_dead_nodes();
                Err(self.exited(status, "exited before the measurement ended"))
            }
            Err(e) => Err(anyhow!(e).context(format!("could not check on the {}", self.name))),
        }
    }

    /// Waits for a peer that was told to stop, killing it after `timeout`; returns the
    /// lines it printed (its notes for the report).
    pub fn finish(mut self, timeout: Duration) -> anyhow::Result<Vec<String>> {
        let deadline = Instant::now() + timeout;
        loop {
            let status = self
                .child
                .try_wait()
                .with_context(|| format!("could not wait for the {}", self.name))?;
            if let Some(status) = status {
                self.reaped = true;
                if !status.success() {
                    return Err(self.exited(status, "failed"));
                }
                let out = self.stdout.take().and_then(|h| h.join().ok()).unwrap_or_default();
                return Ok(out.lines().map(str::to_owned).filter(|l| !l.is_empty()).collect());
            }
            if Instant::now() >= deadline {
                self.kill();
                bail!(
                    "the {} did not exit within {timeout:?} of being told to stop; killed it",
                    self.name
                );
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    fn exited(&mut self, status: ExitStatus, what: &str) -> anyhow::Error {
        let stderr = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        let message = stderr.trim();
        if message.is_empty() {
            anyhow!("the {} {what} ({status})", self.name)
        } else {
            anyhow!("the {} {what} ({status}): {message}", self.name)
        }
    }

    fn kill(&mut self) {
        // Errors mean it is gone already; there is nothing else to do.
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.reaped = true;
        remove_dead_nodes();
    }
}

impl Drop for PeerProcess {
    fn drop(&mut self) {
        if !self.reaped {
            // The measurement failed or was abandoned: never leave the peer running,
            // nor its shared-memory resources (see `kill`).
            self.kill();
        }
    }
}

fn drain<R: Read + Send + 'static>(mut pipe: R) -> anyhow::Result<JoinHandle<String>> {
    std::thread::Builder::new()
        .name("esgm-bench-peer-output".into())
        .spawn(move || {
            let mut bytes = Vec::new();
            // A read error only shortens what is reported.
            let _ = pipe.read_to_end(&mut bytes);
            String::from_utf8_lossy(&bytes).into_owned()
        })
        .context("could not start a thread to read the peer's output")
}
