//! Keeping a system's processes alive (run by `esgm up`): the processes declared to
//! the coordinator are started; one that exits unexpectedly is restarted with
//! exponential backoff, and the restart is logged and counted; one whose declaration
//! changes is restarted with the new one; one no longer declared is stopped.

use std::collections::BTreeMap;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use esgm_shm::control::{ProcessRecord, ProcessSpec, ProcessStatus};
use esgm_shm::{DOMAIN_ENV, WORKER_ENV};

const FIRST_BACKOFF: Duration = Duration::from_millis(100);
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A process that ran this long before exiting starts its backoff afresh.
const STABLE_AFTER: Duration = Duration::from_secs(30);

/// One supervised process.
#[derive(Debug)]
struct Supervised {
    spec: ProcessSpec,
    child: Option<Child>,
    started: Instant,
    status: ProcessStatus,
    backoff: Duration,
    restart_at: Option<Instant>,
    /// The status as last reported to the coordinator.
    reported: Option<ProcessStatus>,
}

/// The supervisor of a system's processes.
#[derive(Debug)]
pub struct Supervisor {
    domain: String,
    processes: BTreeMap<String, Supervised>,
}

impl Supervisor {
    /// A supervisor of the processes of `domain` (passed to each as `ESGM_DOMAIN`).
    pub fn new(domain: &str) -> Self {
        Self { domain: domain.to_owned(), processes: BTreeMap::new() }
    }

    /// Makes the supervised set what the coordinator declares.
    pub fn reconcile(&mut self, declared: &[ProcessRecord]) {
        self.processes.retain(|name, p| {
            let keep = declared.iter().any(|d| d.spec.name == *name);
            if !keep {
                tracing::info!(process = %name, "no longer declared; stopping it");
                stop(p);
            }
            keep
        });
        for d in declared {
            match self.processes.get_mut(&d.spec.name) {
                Some(p) if p.spec == d.spec => {}
                Some(p) => {
                    tracing::info!(process = %d.spec.name, "declaration changed; restarting it");
                    stop(p);
                    p.spec = d.spec.clone();
                    p.restart_at = Some(Instant::now());
                }
                None => {
                    let mut p = Supervised {
                        spec: d.spec.clone(),
                        child: None,
                        started: Instant::now(),
                        // Restarts survive a restart of the supervisor's own bookkeeping.
                        status: ProcessStatus { restarts: d.status.restarts, ..Default::default() },
                        backoff: FIRST_BACKOFF,
                        restart_at: None,
                        reported: None,
                    };
                    self.start(&mut p, false);
                    self.processes.insert(d.spec.name.clone(), p);
                }
            }
        }
    }

    fn start(&self, p: &mut Supervised, restart: bool) {
        match spawn(&p.spec, &self.domain) {
            Ok(child) => {
                p.status.pid = Some(child.id());
                p.child = Some(child);
                p.started = Instant::now();
                p.restart_at = None;
                if restart {
                    p.status.restarts += 1;
                    tracing::warn!(worker = %p.spec.name, restarts = p.status.restarts,
                        "worker restarted");
                } else {
                    tracing::info!(worker = %p.spec.name, pid = child_id(p), "worker started");
                }
            }
            Err(e) => {
                tracing::error!(worker = %p.spec.name, program = %p.spec.program, error = %e,
                    "cannot start worker");
                p.status.pid = None;
                p.status.last_exit = Some(format!("cannot start `{}`: {e}", p.spec.program));
                p.restart_at = Some(Instant::now() + p.backoff);
                p.backoff = (p.backoff * 2).min(MAX_BACKOFF);
            }
        }
    }

    /// Notices exits and restarts processes whose backoff is over; call it
    /// periodically.
    pub fn poll(&mut self) {
        let names: Vec<String> = self.processes.keys().cloned().collect();
        for name in names {
            let Some(mut p) = self.processes.remove(&name) else { continue };
            if let Some(child) = &mut p.child {
                if let Ok(Some(status)) = child.try_wait() {
                    if p.started.elapsed() > STABLE_AFTER {
                        p.backoff = FIRST_BACKOFF;
                    }
                    tracing::warn!(worker = %p.spec.name, %status, backoff = ?p.backoff,
                        "worker exited; restarting");
                    p.child = None;
                    p.status.pid = None;
                    p.status.last_exit = Some(status.to_string());
                    p.restart_at = Some(Instant::now() + p.backoff);
                    p.backoff = (p.backoff * 2).min(MAX_BACKOFF);
                }
            }
            if p.child.is_none() && p.restart_at.is_some_and(|t| Instant::now() >= t) {
                self.start(&mut p, true);
            }
            self.processes.insert(name, p);
        }
    }

    /// Statuses that changed since they were last taken (to report to the coordinator).
    pub fn take_changes(&mut self) -> Vec<(String, ProcessStatus)> {
        let mut out = Vec::new();
        for (name, p) in &mut self.processes {
            if p.reported.as_ref() != Some(&p.status) {
                p.reported = Some(p.status.clone());
                out.push((name.clone(), p.status.clone()));
            }
        }
        out
    }

    /// Waits up to `grace` for every process to leave on its own (workers leave when
    /// the coordinator is gone), then kills the rest.
    pub fn wait_all(&mut self, grace: Duration) {
        let deadline = Instant::now() + grace;
        for p in self.processes.values_mut() {
            let Some(child) = &mut p.child else { continue };
            loop {
                if matches!(child.try_wait(), Ok(Some(_)) | Err(_)) {
                    break;
                }
                if Instant::now() >= deadline {
                    tracing::warn!(worker = %p.spec.name, "worker did not leave; killing it");
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            p.child = None;
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        for p in self.processes.values_mut() {
            stop(p);
        }
    }
}

fn child_id(p: &Supervised) -> u32 {
    p.child.as_ref().map_or(0, Child::id)
}

fn stop(p: &mut Supervised) {
    if let Some(child) = &mut p.child {
        let _ = child.kill();
        let _ = child.wait();
    }
    p.child = None;
    p.status.pid = None;
}

fn spawn(spec: &ProcessSpec, domain: &str) -> std::io::Result<Child> {
    Command::new(&spec.program)
        .args(&spec.args)
        .envs(spec.env.iter().map(|(k, v)| (k.as_str(), v.as_str())))
        .env(DOMAIN_ENV, domain)
        .env(WORKER_ENV, &spec.name)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
}
