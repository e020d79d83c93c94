//! `esgm up`: the coordinator of a domain, and the process that keeps the system's
//! workers running.
//!
//! One process holds three things: the coordinator (the registry, on its own thread),
//! the system's own location ([`SYSTEM_HOST`]: it writes the primitive, sync and merge
//! trajectories created from the command line, which does not stay to write them),
//! and the supervisor of every process declared to the coordinator (`esgm apply`).
//! `esgm down` asks the coordinator to stop; the workers notice and leave, the
//! supervisor waits for them (killing stragglers) and dead processes' shared memory
//! is cleaned.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::TypeRegistry;
use esgm_shm::ShmEsgm;
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ControlClient, Coordinator, Registry, Request, Response};

use super::supervise::Supervisor;
use crate::config::apply::SYSTEM_HOST;
use crate::config::{self, Plan};

/// `esgm up` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Start in the background and return once it serves.
    #[arg(long)]
    pub detach: bool,
    /// Apply this configuration once serving (see `esgm apply`).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print nothing but warnings (for a coordinator another command started).
    #[arg(long, hide = true)]
    pub quiet: bool,
}

/// How often the supervisor looks at the declared processes.
const SUPERVISE_EVERY: Duration = Duration::from_millis(100);

/// Runs (or starts) the coordinator of `domain`.
pub fn run(domain: &str, args: &Args) -> anyhow::Result<()> {
    // A configuration is checked before anything starts.
    let plan = args.config.as_deref().map(config::load).transpose()?;
    if args.detach {
        let pid = spawn_detached(domain, Stdio::null())?.id();
        println!("coordinator of `{domain}` serving (pid {pid}); stop it with `esgm down`");
        if let Some(plan) = &plan {
            if let Err(e) = super::apply::apply_plan(domain, plan, false) {
                shutdown(domain);
                return Err(e.context("the configuration could not be applied; stopped"));
            }
        }
        return Ok(());
    }
    serve(domain, plan, args.quiet)
}

/// The foreground coordinator: serves until asked to stop.
fn serve(domain: &str, plan: Option<Plan>, quiet: bool) -> anyhow::Result<()> {
    let coordinator = Coordinator::spawn(domain, Registry::new(TypeRegistry::with_library()))
        .with_context(|| {
            format!("cannot serve `{domain}`; is a coordinator already running for it?")
        })?;
    let system = ShmEsgm::builder()
        .domain(domain)
        .host(SYSTEM_HOST)
        .connect()
        .context("cannot start the system's own location")?;
    system.serve_assignments();
    if !quiet {
        eprintln!("coordinator of `{domain}` serving; stop it with `esgm down --domain {domain}`");
    }

    let applying = plan.map(|plan| {
        let d = domain.to_owned();
        std::thread::spawn(move || {
            let result = super::apply::apply_plan(&d, &plan, false);
            if let Err(e) = &result {
                eprintln!("esgm: {e:#}");
                shutdown(&d);
            }
            result.is_ok()
        })
    });

    let mut supervisor = Supervisor::new(domain);
    while !coordinator.is_finished() {
        if let Ok(Response::Processes(declared)) = system.control(Request::ListProcesses) {
            supervisor.reconcile(&declared);
        }
        supervisor.poll();
        for (name, status) in supervisor.take_changes() {
            let _ = system.control(Request::ReportProcess { name, status });
        }
        std::thread::sleep(SUPERVISE_EVERY);
    }
    drop(system);
    supervisor.wait_all(Duration::from_secs(10));
    drop(supervisor);
    drop(coordinator);
    let cleaned = cleanup_dead_nodes();
    tracing::info!(cleaned, "coordinator stopped");
    match applying.map(std::thread::JoinHandle::join) {
        Some(Ok(false)) => bail!("the configuration could not be applied; stopped"),
        _ => Ok(()),
    }
}

/// Asks the coordinator of `domain` to stop (best effort).
pub fn shutdown(domain: &str) {
    if let Ok(c) = ControlClient::connect(domain, Duration::from_secs(2)) {
        let _ = c.call(&Request::Shutdown);
    }
}

/// Starts `esgm up` for `domain` as a background process (its log lines go to
/// `stderr`) and waits until it answers.
pub fn spawn_detached(domain: &str, stderr: Stdio) -> anyhow::Result<std::process::Child> {
    let exe = std::env::current_exe().context("cannot find the esgm executable")?;
    let mut child = Command::new(exe)
        .args(["up", "--quiet", "--domain", domain])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .context("cannot start the coordinator process")?;
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Ok(c) = ControlClient::connect(domain, Duration::from_millis(500)) {
            if c.call(&Request::Ping).is_ok() {
                return Ok(child);
            }
        }
        if let Some(status) = child.try_wait()? {
            bail!(
                "the coordinator exited at once ({status}); is one already running for `{domain}`?"
            );
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            bail!("the coordinator did not start serving within 10 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
