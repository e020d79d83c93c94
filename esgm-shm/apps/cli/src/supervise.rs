//! Keeping a system's processes alive (run by `esgm up`): the processes declared to
//! the coordinator are started; one that exits unexpectedly is restarted with
//! exponential backoff, and the restart is logged and counted; one whose declaration
//! changes is restarted with the new one; one no longer declared is stopped.
//!
//! After a coordinator crash, the next `esgm up` *adopts* the workers that still run
//! (their pids are in the recovered process table, and each is checked to be that
//! worker of that domain by its environment): they keep their pid and restart count
//! and are not restarted. An adopted process is not this process's child, so it is
//! watched through `/proc` and stopped with signals.
//!
//! Each process's output goes to `<log dir>/<process>.log` (appended), which
//! `esgm logs` shows.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use esgm_shm::control::STATE_DIR_ENV;
use esgm_shm::control::{ProcessRecord, ProcessSpec, ProcessStatus, StateDir};
use esgm_shm::process::access::{ACCESS_ENV, ShmAccess};
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
    /// A process a former coordinator started, adopted by pid.
    adopted: Option<u32>,
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
    /// The domain's state directory (passed to each process; its logs go there).
    state: Option<StateDir>,
    /// Who may use the domain's shared memory.
    access: ShmAccess,
    processes: BTreeMap<String, Supervised>,
}

impl Supervisor {
    /// A supervisor of the processes of `domain` (passed to each as `ESGM_DOMAIN`),
    /// with the domain's state directory `state` (passed as `ESGM_STATE_DIR`; each
    /// process's output goes to its `logs/`).
    pub fn new(domain: &str, state: Option<StateDir>) -> Self {
        Self {
            domain: domain.to_owned(),
            state,
            access: ShmAccess::Private,
            processes: BTreeMap::new(),
        }
    }

    /// Starts every process with the domain's shared memory open to `access` (passed
    /// as `ESGM_SHM_ACCESS`; each process widens its own files, which only it can).
    pub fn sharing(mut self, access: ShmAccess) -> Self {
        self.access = access;
        self
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
        // Workers a crashed coordinator started whose pid it had not saved yet (a
        // restart just before the crash): found by their environment, adopted rather
        // than started a second time (two writers of one trajectory).
        let mut unrecorded = None;
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
                        adopted: None,
                        started: Instant::now(),
                        // Restarts survive a restart of the supervisor's own bookkeeping.
                        status: ProcessStatus { restarts: d.status.restarts, ..Default::default() },
                        backoff: FIRST_BACKOFF,
                        restart_at: None,
                        reported: None,
                    };
                    let recorded =
                        d.status.pid.filter(|pid| is_worker_of(*pid, &self.domain, &d.spec.name));
                    let running = recorded.or_else(|| {
                        unrecorded
                            .get_or_insert_with(|| workers_of(&self.domain))
                            .get(&d.spec.name)
                            .copied()
                    });
                    match running {
                        Some(pid) => {
                            tracing::info!(worker = %d.spec.name, pid, "adopted a running worker");
                            p.adopted = Some(pid);
                            // The saved status may predate the start of `pid` (the crash
                            // came between a restart and its save): it names `pid` now.
                            p.status = ProcessStatus { pid: Some(pid), ..d.status.clone() };
                        }
                        None => self.start(&mut p, false),
                    }
                    self.processes.insert(d.spec.name.clone(), p);
                }
            }
        }
    }

    fn start(&self, p: &mut Supervised, restart: bool) {
        // A crashed coordinator's last start may show up only now (it had forked but
        // not yet executed the worker when this one scanned `/proc`): adopt it rather
        // than start a second writer of its trajectories, which could never register.
        if restart && let Some(pid) = workers_of(&self.domain).get(&p.spec.name).copied() {
            tracing::warn!(worker = %p.spec.name, pid, "found the worker running; adopted it");
            p.adopted = Some(pid);
            p.status.pid = Some(pid);
            p.restart_at = None;
            return;
        }
        match spawn(&p.spec, &self.domain, self.access, self.state.as_ref()) {
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
            if let Some(pid) = p.adopted.filter(|pid| !alive(*pid)) {
                tracing::warn!(worker = %p.spec.name, pid, backoff = ?p.backoff,
                    "adopted worker exited; restarting");
                p.adopted = None;
                p.status.pid = None;
                p.status.last_exit = Some("exited (adopted; exit status unknown)".to_owned());
                p.restart_at = Some(Instant::now() + p.backoff);
                p.backoff = (p.backoff * 2).min(MAX_BACKOFF);
            }
            if let Some(child) = &mut p.child {
                let exited = match child.try_wait() {
                    Ok(exited) => exited,
                    Err(e) => {
                        tracing::warn!(worker = %p.spec.name, error = %e,
                            "cannot look at a worker; trying again");
                        None
                    }
                };
                if let Some(status) = exited {
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
            if p.child.is_none()
                && p.adopted.is_none()
                && p.restart_at.is_some_and(|t| Instant::now() >= t)
            {
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
            if let Some(pid) = p.adopted.take() {
                while alive(pid) && Instant::now() < deadline {
                    std::thread::sleep(Duration::from_millis(10));
                }
                if alive(pid) {
                    tracing::warn!(worker = %p.spec.name, pid, "worker did not leave; killing it");
                    signal(pid, libc::SIGKILL);
                }
            }
            let Some(child) = &mut p.child else { continue };
            loop {
                match child.try_wait() {
                    Ok(Some(_)) => break,
                    Ok(None) => {}
                    Err(e) => {
                        tracing::warn!(worker = %p.spec.name, error = %e, "cannot wait for a worker");
                        break;
                    }
                }
                if Instant::now() >= deadline {
                    tracing::warn!(worker = %p.spec.name, "worker did not leave; killing it");
                    kill_child(&p.spec.name, child);
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
        kill_child(&p.spec.name, child);
    }
    if let Some(pid) = p.adopted.take() {
        signal(pid, libc::SIGKILL);
    }
    p.child = None;
    p.status.pid = None;
}

/// Kills a child and reaps it; a failure is logged (it has exited already, say).
fn kill_child(name: &str, child: &mut Child) {
    if let Err(e) = child.kill() {
        tracing::debug!(worker = %name, error = %e, "cannot kill a worker (exited already?)");
    }
    if let Err(e) = child.wait() {
        tracing::warn!(worker = %name, error = %e, "cannot reap a worker");
    }
}

/// Sends `sig` to an adopted process.
fn signal(pid: u32, sig: libc::c_int) {
    let Ok(pid) = libc::pid_t::try_from(pid) else { return };
    // SAFETY: kill(2) takes plain integers; it touches no memory of this process.
    if unsafe { libc::kill(pid, sig) } != 0 {
        tracing::debug!(pid, sig, error = %std::io::Error::last_os_error(),
            "cannot signal a process (exited already?)");
    }
}

/// True while process `pid` runs (a zombie has stopped).
pub fn alive(pid: u32) -> bool {
    if pid == 0 {
        return false;
    }
    match std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat")) {
        // The state follows the command name in parentheses: `123 (esgm) S ...`.
        Ok(stat) => {
            stat.rsplit_once(')').is_some_and(|(_, rest)| !rest.trim_start().starts_with('Z'))
        }
        // No stat to read: the process is gone.
        Err(_) => false,
    }
}

/// True if process `pid` is the worker `name` of `domain` (its environment says so,
/// as the supervisor set it): a pid from a saved table may have been reused since.
pub fn is_worker_of(pid: u32, domain: &str, name: &str) -> bool {
    if !alive(pid) {
        return false;
    }
    let environ = match std::fs::read(Path::new("/proc").join(pid.to_string()).join("environ")) {
        Ok(e) => e,
        Err(e) => {
            tracing::debug!(pid, error = %e, "cannot read a process's environment");
            return false;
        }
    };
    let (want_domain, want_name) = (
        format!("{DOMAIN_ENV}={domain}").into_bytes(),
        format!("{WORKER_ENV}={name}").into_bytes(),
    );
    let vars: Vec<&[u8]> = environ.split(|b| *b == 0).collect();
    vars.contains(&want_domain.as_slice()) && vars.contains(&want_name.as_slice())
}

/// Every live worker of `domain` by name, found by its environment in `/proc` (one
/// scan, when a coordinator starts after a crash).
fn workers_of(domain: &str) -> BTreeMap<String, u32> {
    let mut found = BTreeMap::new();
    let Ok(entries) = std::fs::read_dir("/proc") else { return found };
    let want_domain = format!("{DOMAIN_ENV}={domain}").into_bytes();
    let prefix = format!("{WORKER_ENV}=").into_bytes();
    for entry in entries.flatten() {
        let Some(pid) = entry.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(environ) = std::fs::read(entry.path().join("environ")) else { continue };
        let vars: Vec<&[u8]> = environ.split(|b| *b == 0).collect();
        if !vars.contains(&want_domain.as_slice()) || !alive(pid) {
            continue;
        }
        let name = vars.iter().find_map(|v| v.strip_prefix(prefix.as_slice()));
        if let Some(name) = name.and_then(|n| std::str::from_utf8(n).ok()) {
            found.insert(name.to_owned(), pid);
        }
    }
    found
}

/// The log file of process `name` in `state`'s log directory.
pub fn log_file(state: &StateDir, name: &str) -> PathBuf {
    state.log_dir().join(format!("{name}.log"))
}

fn spawn(
    spec: &ProcessSpec,
    domain: &str,
    access: ShmAccess,
    state: Option<&StateDir>,
) -> std::io::Result<Child> {
    let mut command = Command::new(&spec.program);
    command
        .args(&spec.args)
        .envs(spec.env.iter().map(|(k, v)| (k.as_str(), v.as_str())))
        .env(DOMAIN_ENV, domain)
        .env(WORKER_ENV, &spec.name)
        .env(ACCESS_ENV, access.as_str())
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    if let Some(state) = state {
        // Plain text in the log file (tracing's formatter honours NO_COLOR).
        command.env(STATE_DIR_ENV, state.path()).env("NO_COLOR", "1");
        std::fs::create_dir_all(state.log_dir())?;
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log_file(state, &spec.name))?;
        command.stdout(log.try_clone()?).stderr(log);
    }
    command.spawn()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // a failure is a failed test

    use super::*;

    /// `sleep 60` as worker `name` of `domain`, as a former coordinator would have
    /// started it (not this supervisor's child).
    fn orphan(domain: &str, name: &str) -> Child {
        Command::new("sleep")
            .arg("60")
            .env(DOMAIN_ENV, domain)
            .env(WORKER_ENV, name)
            .spawn()
            .expect("sleep runs")
    }

    fn record(name: &str, pid: Option<u32>) -> ProcessRecord {
        ProcessRecord {
            spec: ProcessSpec {
                name: name.to_owned(),
                program: "sleep".to_owned(),
                args: vec!["60".to_owned()],
                env: Vec::new(),
            },
            status: ProcessStatus { pid, restarts: 2, last_exit: None },
        }
    }

    /// Waits until `pid`'s environment is the one `orphan` set (after its exec).
    fn wait_exec(pid: u32, domain: &str, name: &str) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !is_worker_of(pid, domain, name) {
            assert!(Instant::now() < deadline, "the orphan never ran");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    #[test]
    fn a_worker_started_after_the_last_save_is_adopted_with_its_pid() {
        let domain = format!("supervise-adopt-{}", std::process::id());
        let mut running = orphan(&domain, "w");
        wait_exec(running.id(), &domain, "w");
        let mut s = Supervisor::new(&domain, None);
        // The saved table says the worker had exited (no pid): the crash came before
        // the restart's save.
        s.reconcile(&[record("w", None)]);
        let changes = s.take_changes();
        let (_, status) = changes.iter().find(|(n, _)| n == "w").expect("reported");
        assert_eq!(status.pid, Some(running.id()), "the adopted pid is reported: {status:?}");
        assert_eq!(status.restarts, 2);
        assert_eq!(s.processes["w"].adopted, Some(running.id()));
        assert!(s.processes["w"].child.is_none(), "no second worker was started");
        s.processes.get_mut("w").unwrap().adopted = None; // not stopped by the drop
        running.kill().unwrap();
        running.wait().unwrap();
    }

    #[test]
    fn a_restart_adopts_a_worker_that_appeared_meanwhile() {
        let domain = format!("supervise-late-{}", std::process::id());
        let mut s = Supervisor::new(&domain, None);
        let mut p = Supervised {
            spec: record("w", None).spec,
            child: None,
            adopted: None,
            started: Instant::now(),
            status: ProcessStatus::default(),
            backoff: FIRST_BACKOFF,
            restart_at: Some(Instant::now()),
            reported: None,
        };
        // A former coordinator's last start, seen only after the scan at reconcile.
        let mut late = orphan(&domain, "w");
        wait_exec(late.id(), &domain, "w");
        s.start(&mut p, true);
        assert_eq!((p.adopted, p.status.pid), (Some(late.id()), Some(late.id())));
        assert!(p.child.is_none(), "no second worker was started");
        assert_eq!(p.status.restarts, 0, "an adoption is not a restart");
        late.kill().unwrap();
        late.wait().unwrap();
        s.processes.clear();
    }
}
