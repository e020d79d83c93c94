//! Serving a domain from this process: its coordinator, the system's own location
//! ([`SYSTEM_HOST`]: it writes the primitive, sync and merge trajectories created from
//! the command line or a file) and the supervisor of every process declared to it
//! ([`crate::supervise`]) — what `esgm up` runs in the foreground.
//!
//! It is in the library so that a program that brings up a system of its own runs the
//! very code `esgm up --config` runs, not a copy: esgm-bench's reference system
//! (`benches/refsys/refsys.toml`) is served this way, its nodes started as workers.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::TypeRegistry;
use esgm_shm::DomainLimits;
use esgm_shm::ShmEsgm;
use esgm_shm::cleanup_dead_nodes;
use esgm_shm::control::log_cleanup;
use esgm_shm::control::{ControlClient, Coordinator, Request, Response, StateDir};
use esgm_shm::process::access::{ShmAccess, Widener, widen_domain};

use crate::config::Plan;
use crate::config::apply::SYSTEM_HOST;
use crate::supervise::Supervisor;

/// How often the supervisor looks whether a worker exited.
const SUPERVISE_EVERY: Duration = Duration::from_millis(250);

/// How often the supervisor asks the coordinator which processes are declared: a
/// round trip each, which ten times a second was half of an idle robot's coordinator.
const RECONCILE_EVERY: Duration = Duration::from_secs(1);

/// How a plan is applied once the domain serves: `esgm up` prints each outcome, a
/// program may only wait for it. Its error is what [`Serve::run`] returns.
type Applier = Box<dyn FnOnce(&str, &Plan) -> anyhow::Result<()> + Send>;

/// A domain served from this process until it is asked to stop ([`shutdown`], `esgm
/// down`): set it up, then [`Serve::run`].
pub struct Serve {
    domain: String,
    state: StateDir,
    access: ShmAccess,
    limits: DomainLimits,
    quiet: bool,
    config: Option<(Plan, Applier)>,
}

impl std::fmt::Debug for Serve {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Serve")
            .field("domain", &self.domain)
            .field("state", &self.state.path())
            .field("access", &self.access)
            .field("limits", &self.limits)
            .field("quiet", &self.quiet)
            .field("config", &self.config.as_ref().map(|(plan, _)| &plan.file))
            .finish()
    }
}

impl Serve {
    /// Serves `domain`, its registry and its processes' logs kept in `state`; its shared
    /// memory is its user's alone, with the default limits, until set otherwise.
    pub fn new(domain: &str, state: StateDir) -> Self {
        Self {
            domain: domain.to_owned(),
            state,
            access: ShmAccess::Private,
            limits: DomainLimits::default(),
            quiet: false,
            config: None,
        }
    }

    /// Who may use the domain's shared memory (`--allow-group`, `--allow-others`).
    #[must_use]
    pub fn access(mut self, access: ShmAccess) -> Self {
        self.access = access;
        self
    }

    /// The domain's limits (`--max-processes`, `--readers`).
    #[must_use]
    pub fn limits(mut self, limits: DomainLimits) -> Self {
        self.limits = limits;
        self
    }

    /// Says nothing on the terminal when it serves (`--quiet`).
    #[must_use]
    pub fn quiet(mut self, quiet: bool) -> Self {
        self.quiet = quiet;
        self
    }

    /// Applies `plan` with `apply` once the domain serves (`--config`), on a thread of
    /// its own, while the supervisor starts the processes it declares. A plan that
    /// cannot be applied stops the domain; [`Serve::run`] then returns `apply`'s error.
    #[must_use]
    pub fn config(
        mut self,
        plan: Plan,
        apply: impl FnOnce(&str, &Plan) -> anyhow::Result<()> + Send + 'static,
    ) -> Self {
        self.config = Some((plan, Box::new(apply)));
        self
    }

    /// Serves until the coordinator is asked to stop; then waits for the workers to
    /// leave (killing stragglers) and cleans up what dead processes left.
    pub fn run(self) -> anyhow::Result<()> {
        let Serve { domain, state, access, limits, quiet, config } = self;
        let domain = domain.as_str();
        let (coordinator, recovered) = Coordinator::spawn_recovering(
            domain,
            TypeRegistry::with_library(),
            state.clone(),
            limits,
        )
        .with_context(|| {
            format!("cannot serve `{domain}`; is a coordinator already running for it?")
        })?;
        if recovered > 0 {
            tracing::warn!(domain, recovered, state = %state.path().display(),
                "recovered the registry a stopped coordinator left");
        }
        let system = ShmEsgm::builder()
            .domain(domain)
            .host(SYSTEM_HOST)
            .connect()
            .context("cannot start the system's own location")?;
        system.serve_assignments();
        // Before anything is applied: a second user's process may come as soon as we
        // serve. The first pass here, so a domain that cannot be opened does not start.
        let cannot_open = || format!("cannot open the shared memory of `{domain}` to {access}");
        widen_domain(domain, access).with_context(cannot_open)?;
        let sharing = Widener::start(domain, access).with_context(cannot_open)?;
        if !quiet {
            eprintln!(
                "coordinator of `{domain}` serving; stop it with `esgm down --domain {domain}`"
            );
        }

        let applying = config.map(|(plan, apply)| {
            let d = domain.to_owned();
            std::thread::spawn(move || {
                let result = apply(&d, &plan);
                if result.is_err() {
                    if let Err(stop) = shutdown(&d) {
                        tracing::warn!(error = %stop, "cannot stop the coordinator");
                    }
                }
                result
            })
        });

        let mut supervisor = Supervisor::new(domain, Some(state)).sharing(access);
        // Failures to reach the own coordinator are logged once per streak.
        let mut failing = false;
        let mut next_reconcile = Instant::now();
        while !coordinator.is_finished() {
            let reconcile = Instant::now() >= next_reconcile;
            if reconcile {
                next_reconcile = Instant::now() + RECONCILE_EVERY;
            }
            match reconcile.then(|| system.control(Request::ListProcesses)).transpose() {
                Ok(None) => {}
                Ok(Some(Response::Processes(declared))) => {
                    failing = false;
                    supervisor.reconcile(&declared);
                }
                Ok(Some(other)) => {
                    tracing::warn!(answer = ?other, "unexpected answer to a process listing");
                }
                // Asked while the coordinator stopped: nothing is wrong.
                Err(_) if coordinator.is_finished() => break,
                Err(e) if !failing => {
                    failing = true;
                    tracing::warn!(error = %e, "cannot list the declared processes; retrying");
                }
                // Still failing: warned once when it started.
                Err(_) => {}
            }
            // Stopping: the workers leave once the coordinator is gone, and must not be
            // taken for crashed ones (restarted, and logged as such).
            if coordinator.is_finished() {
                break;
            }
            supervisor.poll();
            for (name, status) in supervisor.take_changes() {
                if let Err(e) =
                    system.control(Request::ReportProcess { name: name.clone(), status })
                {
                    tracing::warn!(process = %name, error = %e, "cannot report a process's status");
                }
            }
            std::thread::sleep(SUPERVISE_EVERY);
        }
        drop(sharing);
        drop(system);
        supervisor.wait_all(Duration::from_secs(10));
        drop(supervisor);
        drop(coordinator);
        log_cleanup(cleanup_dead_nodes(), esgm_shm::CleanupReporter::Owner);
        // Every worker is gone: the futex words its killed processes kept go too.
        esgm_shm::process::remove_domain_files(domain);
        tracing::info!("coordinator stopped");
        match applying.map(std::thread::JoinHandle::join) {
            Some(Ok(Err(e))) => Err(e),
            Some(Err(_)) => bail!("applying the configuration panicked; stopped"),
            _ => Ok(()),
        }
    }
}

/// Asks the coordinator of `domain` to stop (`esgm down`): its workers leave, and a
/// [`Serve::run`] serving it returns.
pub fn shutdown(domain: &str) -> anyhow::Result<()> {
    let c = ControlClient::connect(domain, Duration::from_secs(2))
        .with_context(|| format!("cannot reach the coordinator of `{domain}`"))?;
    c.call(&Request::Shutdown).with_context(|| format!("cannot stop `{domain}`"))?;
    Ok(())
}
