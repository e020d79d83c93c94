//! `esgm down`: stop the coordinator and everything it started. The workers leave
//! when the coordinator is gone and its registry forgotten, and `esgm up` waits for
//! them, so this returns once the coordinator's process and every worker's are gone.
//!
//! If the coordinator crashed (its workers still run and its registry is kept in the
//! state directory), `esgm down` stops the system without it: it forgets the registry
//! (so the workers leave) and waits for the workers the registry names.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_shm::cleanup_dead_nodes;
use esgm_shm::control::{
    ControlClient, ControlClientError, ProcessRecord, Request, Response, StateDir,
};

use crate::supervise::{alive, is_worker_of};

/// How long the system may take to wind down.
const WITHIN: Duration = Duration::from_secs(20);

/// Stops the coordinator of `domain` and waits until its processes are gone.
pub fn run(domain: &str) -> anyhow::Result<()> {
    let client = match ControlClient::connect(domain, Duration::from_secs(3)) {
        Ok(c) => c,
        Err(e) => return stop_without_coordinator(domain, e),
    };
    let mut pids = Vec::new();
    match client.call(&Request::Ping) {
        Ok(Response::Pong { pid, .. }) => pids.push(pid),
        Ok(other) => tracing::warn!(answer = ?other, "unexpected answer to a ping"),
        // The service is there (its workers hold it) but nobody serves it.
        Err(e @ ControlClientError::NotServing { .. }) => {
            drop(client);
            return stop_without_coordinator(domain, e);
        }
        Err(e) => tracing::warn!(error = %e, "the coordinator did not answer a ping"),
    }
    match client.call(&Request::ListProcesses) {
        Ok(Response::Processes(list)) => pids.extend(list.iter().filter_map(|p| p.status.pid)),
        Ok(other) => tracing::warn!(answer = ?other, "unexpected answer to a process listing"),
        Err(e) => tracing::warn!(error = %e, "cannot list the processes to wait for"),
    }
    let answer = client.call(&Request::Shutdown);
    drop(client);
    // No answer but gone is stopped too (the answer may be lost as the server leaves).
    if let Err(e) = answer {
        if ControlClient::connect(domain, Duration::from_millis(200)).is_ok() {
            return Err(anyhow::Error::new(e).context(format!("cannot stop `{domain}`")));
        }
    }
    let deadline = Instant::now() + WITHIN;
    // A coordinator still serves, or a process of the system still runs. (The control
    // service itself may outlive them: a killed process's port holds it until the
    // cleanup below.)
    let serving = || {
        ControlClient::connect(domain, Duration::from_millis(200))
            .is_ok_and(|c| c.call(&Request::Ping).is_ok())
    };
    while serving() || pids.iter().any(|p| alive(*p)) {
        if Instant::now() > deadline {
            let left: Vec<String> =
                pids.iter().filter(|p| alive(**p)).map(u32::to_string).collect();
            bail!(
                "`{domain}` acknowledged the stop but is still running (pids {})",
                left.join(", ")
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    finish(domain)
}

/// How long the processes still attached once the system stopped have to leave after
/// a SIGTERM.
const LEAVE_WITHIN: Duration = Duration::from_secs(5);

/// Cleans up after dead processes, then stops every process still attached to the
/// domain (tools such as `esgm echo` or `esgm view`, and programs esgm did not start),
/// and names those it could not stop: after `esgm down`, nothing maps the domain.
fn finish(domain: &str) -> anyhow::Result<()> {
    cleanup_dead_nodes()
        .context("cannot list nodes to clean up after dead processes")?
        .log(esgm_shm::CleanupReporter::Owner);
    let stopped = stop_attached(domain);
    // What those it stopped left (a process ended by a signal leaves its node).
    cleanup_dead_nodes()
        .context("cannot list nodes to clean up after the processes it stopped")?
        .log(esgm_shm::CleanupReporter::Owner);
    stopped?;
    esgm_shm::process::remove_domain_files(domain);
    println!("stopped `{domain}`");
    Ok(())
}

/// SIGTERM to every other process attached to `domain`; an error naming each one that
/// is still attached after [`LEAVE_WITHIN`] (another user's, say, which this one may
/// not signal).
fn stop_attached(domain: &str) -> anyhow::Result<()> {
    let me = std::process::id();
    let attached = esgm_shm::processes_of(domain).context("cannot list the domain's nodes")?;
    let others: Vec<(u32, Vec<String>)> = attached.into_iter().filter(|(p, _)| *p != me).collect();
    if others.is_empty() {
        return Ok(());
    }
    let mut refused = Vec::new();
    for (pid, nodes) in &others {
        eprintln!(
            "esgm: stopping process {pid}, still attached to `{domain}` ({})",
            nodes.join(", ")
        );
        let Ok(target) = libc::pid_t::try_from(*pid) else { continue };
        // SAFETY: kill(2) with a pid read from the domain's live nodes; it only sends a
        // signal.
        if unsafe { libc::kill(target, libc::SIGTERM) } != 0 {
            refused.push((*pid, std::io::Error::last_os_error()));
        }
    }
    let deadline = Instant::now() + LEAVE_WITHIN;
    while others.iter().any(|(pid, _)| alive(*pid)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let left: Vec<String> = others
        .iter()
        .filter(|(pid, _)| alive(*pid))
        .map(|(pid, nodes)| {
            let why = refused
                .iter()
                .find(|(p, _)| p == pid)
                .map_or_else(|| "it ignored SIGTERM".to_owned(), |(_, e)| e.to_string());
            format!("process {pid} ({}): {why}", nodes.join(", "))
        })
        .collect();
    if !left.is_empty() {
        bail!(
            "`{domain}` stopped, but these processes are still attached to it: {}",
            left.join("; ")
        );
    }
    Ok(())
}

/// No coordinator answers: if one crashed and left its registry, stop its workers.
fn stop_without_coordinator(domain: &str, unreachable: ControlClientError) -> anyhow::Result<()> {
    let state = StateDir::from_env(domain).context("cannot choose a state directory")?;
    let Some(snapshot) = state.load().context("cannot read the saved registry")? else {
        // Nothing runs: what its killed processes left of the domain's futex words
        // goes all the same, unless a process is still attached to it.
        if esgm_shm::processes_of(domain).is_ok_and(|p| p.is_empty()) {
            esgm_shm::process::remove_domain_files(domain);
        }
        return Err(anyhow::Error::new(unreachable).context(format!("cannot stop `{domain}`")));
    };
    let workers: Vec<(String, u32)> = snapshot
        .processes
        .iter()
        .filter_map(|p: &ProcessRecord| Some((p.spec.name.clone(), p.status.pid?)))
        .filter(|(name, pid)| is_worker_of(*pid, domain, name))
        .collect();
    eprintln!(
        "esgm: no coordinator serves `{domain}` (it crashed); stopping its {} workers",
        workers.len()
    );
    // Without a kept registry, workers that find no coordinator leave by themselves.
    state.remove_registry().context("cannot forget the registry")?;
    let deadline = Instant::now() + WITHIN;
    while workers.iter().any(|(_, pid)| alive(*pid)) {
        if Instant::now() > deadline {
            let left: Vec<String> = workers
                .iter()
                .filter(|(_, pid)| alive(*pid))
                .map(|(name, pid)| format!("{name} ({pid})"))
                .collect();
            bail!("the workers of `{domain}` did not leave: {}", left.join(", "));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    finish(domain)
}
