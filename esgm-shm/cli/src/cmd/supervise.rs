//! Keeping the system's worker processes alive: a worker that exits unexpectedly is
//! restarted with exponential backoff, and the restart is logged and counted.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;

/// One supervised process.
#[derive(Debug)]
pub struct Supervised {
    /// Its name in logs.
    pub name: String,
    args: Vec<String>,
    child: Option<Child>,
    /// Restarts so far.
    pub restarts: u32,
    backoff: Duration,
    restart_at: Option<Instant>,
}

/// The supervisor of a system's workers.
#[derive(Debug, Default)]
pub struct Supervisor {
    /// The workers.
    pub workers: Vec<Supervised>,
}

const FIRST_BACKOFF: Duration = Duration::from_millis(100);
const MAX_BACKOFF: Duration = Duration::from_secs(5);

impl Supervisor {
    /// Starts `esgm <args>` as a supervised worker called `name`.
    pub fn start(&mut self, name: &str, args: &[&str]) -> anyhow::Result<()> {
        let args: Vec<String> = args.iter().map(|s| (*s).to_owned()).collect();
        let child = spawn(&args).with_context(|| format!("cannot start {name}"))?;
        self.workers.push(Supervised {
            name: name.to_owned(),
            args,
            child: Some(child),
            restarts: 0,
            backoff: FIRST_BACKOFF,
            restart_at: None,
        });
        Ok(())
    }

    /// Restarts workers that died (after their backoff); call it periodically.
    pub fn poll(&mut self) {
        for w in &mut self.workers {
            if let Some(child) = &mut w.child {
                if let Ok(Some(status)) = child.try_wait() {
                    tracing::warn!(worker = %w.name, %status, backoff = ?w.backoff,
                        "worker exited; restarting");
                    w.child = None;
                    w.restart_at = Some(Instant::now() + w.backoff);
                    w.backoff = (w.backoff * 2).min(MAX_BACKOFF);
                }
            }
            if w.child.is_none() && w.restart_at.is_some_and(|t| Instant::now() >= t) {
                match spawn(&w.args) {
                    Ok(child) => {
                        w.restarts += 1;
                        w.child = Some(child);
                        w.restart_at = None;
                        tracing::warn!(worker = %w.name, restarts = w.restarts, "worker restarted");
                    }
                    Err(e) => {
                        tracing::error!(worker = %w.name, error = %e, "cannot restart worker");
                        w.restart_at = Some(Instant::now() + w.backoff);
                    }
                }
            }
        }
    }

    /// Process ids of the running workers, by name.
    pub fn pids(&self) -> Vec<(String, u32)> {
        self.workers
            .iter()
            .filter_map(|w| w.child.as_ref().map(|c| (w.name.clone(), c.id())))
            .collect()
    }

    /// Waits up to `grace` for every worker to leave on its own (they leave when the
    /// coordinator is gone), then kills the rest.
    pub fn wait_all(&mut self, grace: Duration) {
        let deadline = Instant::now() + grace;
        for w in &mut self.workers {
            let Some(child) = &mut w.child else { continue };
            loop {
                if matches!(child.try_wait(), Ok(Some(_)) | Err(_)) {
                    break;
                }
                if Instant::now() >= deadline {
                    tracing::warn!(worker = %w.name, "worker did not leave; killing it");
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            w.child = None;
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        for w in &mut self.workers {
            if let Some(child) = &mut w.child {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

fn spawn(args: &[String]) -> std::io::Result<Child> {
    let exe = std::env::current_exe()?;
    Command::new(exe).args(args).stdin(Stdio::null()).stdout(Stdio::null()).spawn()
}
