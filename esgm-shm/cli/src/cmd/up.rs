//! `esgm up`: the coordinator of a domain.

use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::TypeRegistry;
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ControlClient, Coordinator, Registry, Request};

/// `esgm up` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Start in the background and return once it serves.
    #[arg(long)]
    pub detach: bool,
}

/// Runs (or starts) the coordinator of `domain`.
pub fn run(domain: &str, args: &Args) -> anyhow::Result<()> {
    if args.detach {
        let pid = spawn_detached(domain)?.id();
        println!("coordinator of `{domain}` serving (pid {pid}); stop it with `esgm down`");
        return Ok(());
    }
    let mut coordinator = Coordinator::create(domain, Registry::new(TypeRegistry::with_library()))?;
    eprintln!("coordinator of `{domain}` serving; stop it with `esgm down --domain {domain}`");
    coordinator.run(&AtomicBool::new(false), Duration::from_secs(1))?;
    let cleaned = cleanup_dead_nodes();
    tracing::info!(cleaned, "coordinator stopped");
    Ok(())
}

/// Starts `esgm up` for `domain` as a background process and waits until it answers.
pub fn spawn_detached(domain: &str) -> anyhow::Result<std::process::Child> {
    let exe = std::env::current_exe().context("cannot find the esgm executable")?;
    let mut child = Command::new(exe)
        .args(["up", "--domain", domain])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
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
