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
//!
//! The registry is kept in the domain's state directory (`--state-dir`, else
//! `$XDG_STATE_HOME/esgm/<domain>`; see `esgm_shm::control::StateDir` for why a file).
//! If the coordinator crashes, its workers keep running and exchanging data; the next
//! `esgm up` starts at once, restores the registry, takes over the control service,
//! and adopts the running workers (same pids, no restart).
//!
//! A domain's shared memory is its user's alone unless started with `--allow-group`
//! or `--allow-others` (see `esgm_shm::process::access` for why the files are widened
//! after iceoryx2 creates them): the coordinator keeps its files open, and every worker
//! it starts does the same with its own (`ESGM_SHM_ACCESS`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_cli::serve::Serve;
use esgm_shm::control::{ControlClient, Request, StateDir};
use esgm_shm::process::access::{ACCESS_ENV, ShmAccess};
use esgm_shm::process::cpu_latency::{self, CPU_LATENCY_ENV, CpuLatency};
use esgm_shm::{DEFAULT_MAX_PROCESSES, DEFAULT_READERS, DomainLimits};

use crate::config::{self, Plan};
pub use esgm_cli::serve::shutdown;

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
    /// Restart the coordinator if it crashes (it comes back with the registry and
    /// adopts the running workers); an orderly stop (`esgm down`) ends it.
    #[arg(long)]
    pub supervise: bool,
    /// Keep the registry and the processes' logs here (default:
    /// `$XDG_STATE_HOME/esgm/<domain>`, else `~/.local/state/esgm/<domain>`).
    #[arg(long, value_name = "DIR")]
    pub state_dir: Option<PathBuf>,
    /// Let the users of your group read and write the domain's shared memory (its
    /// files become 0660/0440); by default only you can.
    #[arg(long, conflicts_with = "allow_others")]
    pub allow_group: bool,
    /// Let every user of this host read and write the domain's shared memory (its
    /// files become 0666/0444): any local process can then publish into it. Their
    /// processes take part with `ESGM_SHM_ACCESS=others`.
    #[arg(long)]
    pub allow_others: bool,
    /// Processes the domain admits at once (each a connection: a worker, a unit, a
    /// command); one more is refused with an error naming this setting. Each costs
    /// about 4 KiB of shared memory in the domain's control and administration
    /// services (see ARCHITECTURE.md, "Limits").
    #[arg(long, value_name = "N", env = MAX_PROCESSES_ENV, default_value_t = DEFAULT_MAX_PROCESSES)]
    pub max_processes: usize,
    /// Reader processes a trajectory admits when its declaration names no `readers`
    /// of its own, at most --max-processes [default: 16, or --max-processes if fewer].
    #[arg(long, value_name = "N", env = READERS_ENV)]
    pub readers: Option<usize>,
    /// Keep every core's wake-up from idle within this many microseconds while the
    /// domain runs (0: idle cores poll instead of sleeping). A blocking hop between
    /// processes is mostly the woken core leaving its idle state: on a VM that halts idle
    /// cores, 40 µs instead of 4 µs (see `esgm_shm::process::cpu_latency`). It costs
    /// power, and a VM's host CPU; it needs root (`/dev/cpu_dma_latency`).
    #[arg(long, value_name = "MICROSECONDS", env = CPU_LATENCY_ENV, value_parser = cpu_latency::parse_micros)]
    pub cpu_latency: Option<Duration>,
}

/// How a coordinator that another command starts is set up ([`spawn_detached_with`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Setup {
    /// Restarted if it crashes (`--supervise`).
    pub supervise: bool,
    /// Who may use the domain's shared memory.
    pub access: ShmAccess,
    /// The domain's limits.
    pub limits: DomainLimits,
    /// The CPU latency it holds while it runs (`--cpu-latency`).
    pub cpu_latency: Option<Duration>,
}

/// The environment variables a coordinator started by another command reads its
/// limits from.
const MAX_PROCESSES_ENV: &str = "ESGM_MAX_PROCESSES";
const READERS_ENV: &str = "ESGM_READERS";

impl Args {
    /// The domain's limits, checked.
    pub fn limits(&self) -> anyhow::Result<DomainLimits> {
        let readers = self.readers.unwrap_or(DEFAULT_READERS.min(self.max_processes));
        let limits = DomainLimits { max_processes: self.max_processes, readers };
        limits.check().context("illegal limit")?;
        Ok(limits)
    }

    /// Who may use the domain's shared memory: the flags, else `ESGM_SHM_ACCESS`
    /// (a coordinator restarted by `--supervise` or a service manager), else its user.
    pub fn access(&self) -> anyhow::Result<ShmAccess> {
        Ok(match (self.allow_group, self.allow_others) {
            (true, _) => ShmAccess::Group,
            (_, true) => ShmAccess::Others,
            _ => ShmAccess::from_env()?,
        })
    }
}

/// The state directory of `domain`: `dir` if given, else the default.
pub fn state_dir(domain: &str, dir: Option<&Path>) -> anyhow::Result<StateDir> {
    match dir {
        Some(d) => Ok(StateDir::at(d)),
        None => StateDir::default_for(domain).context("cannot choose a state directory"),
    }
}

/// How long a detached coordinator may take to serve: taking over from a crashed one
/// connects every running worker's control client first.
const START_WITHIN: Duration = Duration::from_secs(30);

/// Runs (or starts) the coordinator of `domain`.
pub fn run(domain: &str, args: &Args) -> anyhow::Result<()> {
    // A configuration is checked before anything starts.
    let plan = args.config.as_deref().map(config::load).transpose()?;
    let state = state_dir(domain, args.state_dir.as_deref())?;
    let access = args.access()?;
    let limits = args.limits()?;
    if args.detach {
        if let Some(latency) = args.cpu_latency {
            // Refused before anything is made, the state directory included.
            drop(CpuLatency::request(latency)?);
        }
        state.create().context("cannot create the state directory")?;
        std::fs::create_dir_all(state.log_dir()).context("cannot create the log directory")?;
        let log_path = state.log_dir().join("coordinator.log");
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("cannot open {}", log_path.display()))?;
        let setup =
            Setup { supervise: args.supervise, access, limits, cpu_latency: args.cpu_latency };
        let pid =
            spawn_coordinator(domain, Some(state.path()), &setup, Stdio::from(log), true)?.id();
        println!("coordinator of `{domain}` serving (pid {pid}); stop it with `esgm down`");
        if access != ShmAccess::Private {
            println!("its shared memory is open to {access} (ESGM_SHM_ACCESS={access})");
        }
        if let Some(plan) = &plan {
            if let Err(e) = super::apply::apply_plan(domain, plan, false) {
                if let Err(stop) = shutdown(domain) {
                    tracing::warn!(error = %stop, "cannot stop the coordinator");
                }
                return Err(e.context("the configuration could not be applied; stopped"));
            }
        }
        return Ok(());
    }
    if args.supervise {
        return supervise_coordinator(domain, args, access, &state);
    }
    // Held from before serving until the coordinator ends: a domain asked to wake fast
    // that cannot does not start.
    let held = args.cpu_latency.map(CpuLatency::request).transpose()?;
    if let (Some(held), false) = (&held, args.quiet) {
        eprintln!("idle cores wake within {} µs while `{domain}` runs", held.latency().as_micros());
    }
    serve(domain, plan, args.quiet, access, limits, state)
}

/// `esgm up --supervise`: runs the coordinator as a child process and starts it again
/// (with backoff) whenever it ends other than by an orderly stop. The state directory
/// makes each new one the old one: registry restored, workers adopted.
fn supervise_coordinator(
    domain: &str,
    args: &Args,
    access: ShmAccess,
    state: &StateDir,
) -> anyhow::Result<()> {
    const FIRST_BACKOFF: Duration = Duration::from_millis(100);
    const MAX_BACKOFF: Duration = Duration::from_secs(5);
    /// A coordinator that ends this soon, this many times in a row, cannot start (a
    /// bad state file, another coordinator holding the domain): give up.
    const FAST_EXIT: Duration = Duration::from_secs(2);
    const FAST_EXITS: u32 = 5;
    let exe = std::env::current_exe().context("cannot find the esgm executable")?;
    let (mut backoff, mut fast_exits, mut first) = (FIRST_BACKOFF, 0, true);
    loop {
        let mut command = Command::new(&exe);
        command.args(["up", "--domain", domain]).arg("--state-dir").arg(state.path());
        command.env(ACCESS_ENV, access.as_str());
        command.env(MAX_PROCESSES_ENV, args.max_processes.to_string());
        if let Some(readers) = args.readers {
            command.env(READERS_ENV, readers.to_string());
        }
        if let Some(latency) = args.cpu_latency {
            command.env(CPU_LATENCY_ENV, latency.as_micros().to_string());
        }
        if args.quiet || !first {
            command.arg("--quiet");
        }
        if let (true, Some(config)) = (first, &args.config) {
            command.arg("--config").arg(config);
        }
        first = false;
        let started = Instant::now();
        let status = command
            .stdin(Stdio::null())
            .status()
            .context("cannot start the coordinator process")?;
        if status.success() {
            return Ok(());
        }
        // An orderly stop (`esgm down`) forgets the registry before the coordinator
        // leaves, and each coordinator saves it first thing: one that ran and left none
        // was stopped, whatever its exit status said (a worker slow to leave, say).
        if started.elapsed() >= FAST_EXIT && !state.registry_file().exists() {
            tracing::info!(domain, %status, "the coordinator was stopped; not restarting it");
            return Ok(());
        }
        if started.elapsed() < FAST_EXIT {
            fast_exits += 1;
            if fast_exits >= FAST_EXITS {
                bail!(
                    "the coordinator of `{domain}` cannot start ({status}, {fast_exits} times in a row)"
                );
            }
        } else {
            fast_exits = 0;
            backoff = FIRST_BACKOFF;
        }
        tracing::warn!(domain, %status, ?backoff, "the coordinator ended; restarting it");
        std::thread::sleep(backoff);
        backoff = (backoff * 2).min(MAX_BACKOFF);
    }
}

/// The foreground coordinator: serves until asked to stop.
fn serve(
    domain: &str,
    plan: Option<Plan>,
    quiet: bool,
    access: ShmAccess,
    limits: DomainLimits,
    state: StateDir,
) -> anyhow::Result<()> {
    let mut serve = Serve::new(domain, state).access(access).limits(limits).quiet(quiet);
    if let Some(plan) = plan {
        serve = serve.config(plan, |domain, plan| {
            super::apply::apply_plan(domain, plan, false).map_err(|e| {
                // Said at once, before the workers are waited for.
                eprintln!("esgm: {e:#}");
                anyhow::anyhow!("the configuration could not be applied; stopped")
            })
        });
    }
    serve.run()
}

/// Starts `esgm up` for `domain` as a background process (its log lines go to
/// `stderr`) and waits until it answers. An `outliving` coordinator gets a process
/// group of its own, so the signals of the terminal it was started from (Ctrl-C in a
/// later command, a hang-up) do not reach the system it now runs; the demo's stays in
/// the demo's group, so a Ctrl-C stops both.
pub fn spawn_detached(
    domain: &str,
    state_dir: Option<&Path>,
    supervise: bool,
    stderr: Stdio,
    outliving: bool,
) -> anyhow::Result<std::process::Child> {
    spawn_coordinator(
        domain,
        state_dir,
        &Setup { supervise, ..Setup::default() },
        stderr,
        outliving,
    )
}

/// [`spawn_detached`] (unsupervised unless `setup` says so) of a domain set up as
/// `setup` says.
pub fn spawn_detached_with(
    domain: &str,
    state_dir: Option<&Path>,
    setup: &Setup,
    stderr: Stdio,
    outliving: bool,
) -> anyhow::Result<std::process::Child> {
    spawn_coordinator(domain, state_dir, setup, stderr, outliving)
}

/// Starts `esgm up` set up as `setup` says, and waits until it answers.
fn spawn_coordinator(
    domain: &str,
    state_dir: Option<&Path>,
    setup: &Setup,
    stderr: Stdio,
    outliving: bool,
) -> anyhow::Result<std::process::Child> {
    if let Some(latency) = setup.cpu_latency {
        // Said here, not as a coordinator that "exited at once".
        drop(CpuLatency::request(latency)?);
    }
    let exe = std::env::current_exe().context("cannot find the esgm executable")?;
    let mut command = Command::new(exe);
    command.args(["up", "--quiet", "--domain", domain]).env(ACCESS_ENV, setup.access.as_str());
    command.env(MAX_PROCESSES_ENV, setup.limits.max_processes.to_string());
    command.env(READERS_ENV, setup.limits.readers.to_string());
    match setup.cpu_latency {
        Some(latency) => command.env(CPU_LATENCY_ENV, latency.as_micros().to_string()),
        // Not inherited from this command's environment unless asked for.
        None => command.env_remove(CPU_LATENCY_ENV),
    };
    if !matches!(std::env::var_os("NO_COLOR"), Some(v) if !v.is_empty()) {
        // Its log goes to a file (or the demo's terminal): plain text.
        command.env("NO_COLOR", "1");
    }
    if let Some(dir) = state_dir {
        command.arg("--state-dir").arg(dir);
    }
    if setup.supervise {
        command.arg("--supervise");
    }
    if outliving {
        std::os::unix::process::CommandExt::process_group(&mut command, 0);
    }
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .context("cannot start the coordinator process")?;
    let deadline = Instant::now() + START_WITHIN;
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
            if let Err(e) = child.kill() {
                tracing::warn!(error = %e, "cannot kill the coordinator that did not start");
            }
            bail!("the coordinator did not start serving within {START_WITHIN:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
