//! `esgm down`: stop the coordinator and everything it started. The workers leave
//! when the coordinator is gone and `esgm up` waits for them, so this returns once
//! the coordinator's process and every worker's are gone.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ControlClient, Request, Response};

/// How long the system may take to wind down.
const WITHIN: Duration = Duration::from_secs(20);

/// Stops the coordinator of `domain` and waits until its processes are gone.
pub fn run(domain: &str) -> anyhow::Result<()> {
    let client = ControlClient::connect(domain, Duration::from_secs(3))
        .with_context(|| format!("cannot stop `{domain}`"))?;
    let mut pids = Vec::new();
    if let Ok(Response::Pong { pid, .. }) = client.call(&Request::Ping) {
        pids.push(pid);
    }
    if let Ok(Response::Processes(list)) = client.call(&Request::ListProcesses) {
        pids.extend(list.iter().filter_map(|p| p.status.pid));
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
    while ControlClient::connect(domain, Duration::from_millis(200)).is_ok()
        || pids.iter().any(alive)
    {
        if Instant::now() > deadline {
            let left: Vec<String> = pids.iter().filter(|p| alive(p)).map(u32::to_string).collect();
            bail!(
                "`{domain}` acknowledged the stop but is still running (pids {})",
                left.join(", ")
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    cleanup_dead_nodes();
    println!("stopped `{domain}`");
    // Programs esgm did not start (a user's own) may still hold the domain's services.
    let others: Vec<String> = esgm_shm::nodes_of(domain).into_iter().map(|(n, _)| n).collect();
    if !others.is_empty() {
        eprintln!(
            "esgm: note: processes esgm did not start are still connected to `{domain}`: {}",
            others.join(", ")
        );
    }
    Ok(())
}

/// True while process `pid` runs (an exited process its parent has not reaped yet —
/// a zombie — has stopped).
fn alive(pid: &u32) -> bool {
    if *pid == 0 {
        return false;
    }
    match std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat")) {
        // The state follows the command name in parentheses: `123 (esgm) S ...`.
        Ok(stat) => {
            stat.rsplit_once(')').is_some_and(|(_, rest)| !rest.trim_start().starts_with('Z'))
        }
        Err(_) => false,
    }
}
