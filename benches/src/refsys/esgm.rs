//! The reference system on esgm, both ways from one declaration: its system file
//! ([`super::system_file`], `benches/refsys/refsys.toml`), read by esgm's own loader.
//! How each node kind maps to esgm is said there (and in [`super::served`]).
//! - `refsys-esgm`: every node in one process, on the in-process runtime (as upstream
//!   requires: "all nodes must run on a single process"). The file's type and
//!   trajectories are applied to an `InProcessEsgm`, and its sensors and units are
//!   registered in it by the node program's own code instead of started as processes.
//! - `refsys-esgm-procs`: one process per sensor and unit, through `connect`. A
//!   coordinator's process serves a fresh domain as `esgm up --config` does
//!   ([`esgm_cli::serve`]): it applies the file, its supervisor starts `esgm-refsys-node`
//!   for each sensor and unit ([`super::node_program`]), and it relays the run's
//!   window to them ([`super::run_dir`]). All of its processes are measured.

use std::path::Path;
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_cli::config::{Plan, Serves};
use esgm_cli::serve::{Serve, shutdown};
use esgm_shm::control::{ControlClient, Request, Response, StateDir};
use esgm_shm::prelude::*;

use super::processes::{NodeSide, sleep_until};
use super::report::NodeReport;
use super::run_dir::{CRUNCH_ENV, RUN_ENV, RunDir, Stage, Worker};
use super::served::{Part, Served, serve};
use super::system_file::{PATH, PROGRAM, TEXT};
use super::window::Window;

pub use super::window::DRAIN;

/// The peer argument of the in-process system's process.
const INPROC: &str = "esgm-inproc";
/// The peer argument of the coordinator's process.
const COORDINATOR: &str = "esgm-coordinator";

/// How long the coordinator's process waits for the file to be applied and every
/// worker to be ready (within the runner's 90 s for its `ready`).
const SETUP: Duration = Duration::from_secs(75);
/// How long after UNTIL and the drain the workers may take to report.
const REPORT: Duration = Duration::from_secs(20);

/// `refsys-esgm`: every node in one process, on the in-process runtime.
#[derive(Debug, Clone, Copy)]
pub struct EsgmInProcess;

/// `refsys-esgm-procs`: one process per sensor and unit through `connect`, started by a
/// coordinator (a documented deviation from upstream's single process: esgm's own
/// deployment).
#[derive(Debug, Clone, Copy)]
pub struct EsgmProcesses;

fn peer_command(domain: &str, arg: String) -> anyhow::Result<std::process::Command> {
    let role = crate::peer_role::PeerRole {
        scenario: crate::scenarios::refsys::NAME.to_owned(),
        wait: crate::wait_mode::WaitMode::Block,
        domain: domain.to_owned(),
        core: None,
        arg: Some(arg),
    };
    let exe = std::env::current_exe().context("cannot find the esgm-bench executable")?;
    let mut c = std::process::Command::new(exe);
    c.args(role.to_args());
    Ok(c)
}

impl super::system::System for EsgmInProcess {
    fn name(&self) -> &'static str {
        "esgm"
    }

    fn summary(&self) -> &'static str {
        "esgm's in-process runtime, every node in one process"
    }

    fn run(&self, s: &super::system::RunSettings) -> anyhow::Result<super::system::SystemRun> {
        let domain = esgm_shm::unique_domain("refsys-inproc");
        let arg = format!("{INPROC}|{}|{}", s.crunch, s.dir.display());
        let (reports, usage, notes) =
            super::processes::run(vec![("esgm".into(), peer_command(&domain, arg)?)], &[], s)?;
        Ok(super::system::SystemRun { reports, processes: usage.processes, usage, notes })
    }
}

impl super::system::System for EsgmProcesses {
    fn name(&self) -> &'static str {
        "esgm-procs"
    }

    fn summary(&self) -> &'static str {
        "esgm through connect, a process per sensor and unit, started by a coordinator"
    }

    fn run(&self, s: &super::system::RunSettings) -> anyhow::Result<super::system::SystemRun> {
        let domain = esgm_shm::unique_domain("refsys");
        let _end = crate::domain_end::DomainEnd::new(&domain);
        // This build serves the nodes: itself, by the node program's name, first on the
        // PATH the file's programs are found on.
        let bin = s.dir.join("bin");
        std::fs::create_dir_all(&bin).with_context(|| format!("cannot make {}", bin.display()))?;
        let exe = std::env::current_exe().context("cannot find the esgm-bench executable")?;
        std::os::unix::fs::symlink(&exe, bin.join(PROGRAM))
            .with_context(|| format!("cannot link {} as {PROGRAM}", exe.display()))?;
        let path = std::env::var_os("PATH").unwrap_or_default();
        let path =
            std::env::join_paths(std::iter::once(bin.clone()).chain(std::env::split_paths(&path)))
                .context("a PATH with the node program")?;
        let arg = format!("{COORDINATOR}|{}|{}", s.crunch, s.dir.display());
        let mut c = peer_command(&domain, arg)?;
        // Inherited by the workers the coordinator starts.
        c.env("PATH", path).env(RUN_ENV, &s.dir).env(CRUNCH_ENV, s.crunch.to_string());
        let (reports, usage, notes) =
            super::processes::run(vec![("coordinator".into(), c)], &[], s)?;
        Ok(super::system::SystemRun { reports, processes: usage.processes, usage, notes })
    }
}

/// Runs this process as one of the esgm systems' processes (`arg`: `KIND|CRUNCH|DIR`),
/// in `domain`. `None` if `arg` is not one of theirs.
pub fn peer_main(domain: &str, arg: &str) -> Option<anyhow::Result<()>> {
    let mut parts = arg.splitn(3, '|');
    let (Some(kind), Some(crunch), Some(dir)) = (parts.next(), parts.next(), parts.next()) else {
        return None;
    };
    if ![INPROC, COORDINATOR].contains(&kind) {
        return None;
    }
    let dir = std::path::PathBuf::from(dir);
    Some((|| -> anyhow::Result<()> {
        match kind {
            INPROC => in_process(crunch.parse().context("the crunch limit")?, &dir),
            _ => coordinator(domain, &dir),
        }
    })())
}

/// The file's system in one process: its sensors and units served here, its
/// trajectories on this process's runtime.
struct InProcessSystem {
    served: Vec<Served>,
    /// Handles that keep the trajectories (and their workers).
    _trajectories: Vec<InProcessTrajectory>,
}

impl InProcessSystem {
    /// Applies `plan` to `esgm`: its types, then every sensor and unit it declares
    /// served here (instead of by the process it names), then its trajectories, inputs
    /// first, aligned ones on multiples of their periods.
    fn apply(
        plan: &Plan,
        esgm: &InProcessEsgm,
        crunch: u64,
        window: &Arc<Window>,
    ) -> anyhow::Result<Self> {
        for t in &plan.types {
            esgm.create_type(t.what.1.clone()).map_err(|e| plan.error(t.line, e))?;
        }
        let mut served = Vec::new();
        for w in &plan.workers {
            let (sensor, name) = match &w.what.serves {
                Serves::Sensor(n) => (true, n),
                Serves::Unit(n) => (false, n),
                other => {
                    bail!(plan.error(w.line, format!("not the reference system's: {other:?}")))
                }
            };
            if matches!(Part::of(name), Some(Part::Sensor(_))) != sensor {
                bail!(plan.error(w.line, format!("`{name}` is declared as the wrong kind")));
            }
            served.push(
                serve(esgm, name, crunch, window)
                    .map_err(|e| plan.error(w.line, format!("{e:#}")))?,
            );
        }
        let now = SystemClock.now();
        let mut trajectories = Vec::new();
        for i in plan.creation_order()? {
            let t = &plan.trajectories[i];
            let created = esgm.create_trajectory(t.what.spec_at(now)).map_err(|e| {
                plan.error(t.line, format!("trajectory `{}`: {e}", t.what.spec.name))
            })?;
            trajectories.push(created);
        }
        Ok(Self { served, _trajectories: trajectories })
    }

    /// Every node's report.
    fn reports(&self) -> Vec<NodeReport> {
        NodeReport::by_node(self.served.iter().map(Served::report))
    }
}

/// `refsys-esgm`'s process: the file applied here, one window, the reports.
fn in_process(crunch: u64, dir: &Path) -> anyhow::Result<()> {
    // Its programs are not looked for: this process serves what they would.
    let plan = esgm_cli::config::parse(PATH, TEXT, Path::new("."))?;
    let esgm = InProcessEsgm::default();
    let window = Arc::new(Window::default());
    let system = InProcessSystem::apply(&plan, &esgm, crunch, &window)?;
    let (side, start, until) = NodeSide::ready()?;
    let as_time = |ns: u64| Time::try_from(ns).unwrap_or(Time::MAX);
    window.set(as_time(start), as_time(until));
    sleep_until(until.saturating_add(drain_ns()));
    side.done(&system.reports(), dir)
}

fn drain_ns() -> u64 {
    u64::try_from(DRAIN.as_nanos()).unwrap_or(0)
}

/// `refsys-esgm-procs`'s coordinator: serves the file in `domain` as `esgm up --config`
/// does, relays the window to the workers, and stops the domain at the end.
fn coordinator(domain: &str, dir: &Path) -> anyhow::Result<()> {
    init_logging();
    let run = RunDir::new(dir);
    let file = dir.join("refsys.toml");
    std::fs::write(&file, TEXT).with_context(|| format!("cannot write {}", file.display()))?;
    // Its programs are found on the PATH the runner gave: this build, by their name.
    let plan = esgm_cli::config::load(&file)?;
    let workers: Vec<Worker> = plan
        .workers
        .iter()
        .filter_map(|w| match &w.what.serves {
            Serves::Sensor(n) | Serves::Unit(n) => {
                Some(Worker { serves: n.clone(), process: w.what.spec.name.clone() })
            }
            _ => None,
        })
        .collect();
    let trajectories: Vec<String> =
        plan.trajectories.iter().map(|t| t.what.spec.name.clone()).collect();
    let (applied_tx, applied) = mpsc::channel();
    let serving = {
        let domain = domain.to_owned();
        let serve = Serve::new(&domain, StateDir::at(run.state())).quiet(true).config(
            plan,
            move |domain, plan| {
                let result = esgm_cli::config::apply::apply(domain, plan, &mut |_| {});
                let _waiter_gone = applied_tx.send(result.is_ok());
                result
            },
        );
        std::thread::Builder::new()
            .name("coordinator".into())
            .spawn(move || serve.run())
            .context("cannot start the coordinator's thread")?
    };
    let relayed = relay(domain, &run, &workers, &trajectories, &applied, &serving);
    // However the relay ended, the domain stops and its workers leave.
    let stopped = shutdown(domain);
    let served = serving.join().map_err(|_| anyhow::anyhow!("the coordinator panicked"))?;
    served.with_context(|| format!("serving {PATH}"))?;
    relayed?;
    stopped
}

/// The run's protocol, between the runner and the workers (see [`super::run_dir`]).
fn relay(
    domain: &str,
    run: &RunDir,
    workers: &[Worker],
    trajectories: &[String],
    applied: &mpsc::Receiver<bool>,
    serving: &std::thread::JoinHandle<anyhow::Result<()>>,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + SETUP;
    let mut given_up = || serving.is_finished().then(|| "the coordinator stopped".to_owned());
    // Applied: every sensor and unit registered, every trajectory created.
    loop {
        match applied.recv_timeout(Duration::from_millis(100)) {
            Ok(true) => break,
            Ok(false) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                bail!("{PATH} could not be applied")
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Some(why) = given_up() {
                    bail!("{PATH} was not applied: {why}");
                }
                if Instant::now() >= deadline {
                    bail!("{PATH} was not applied within {SETUP:?}");
                }
            }
        }
    }
    let pids = run.wait_for(Stage::Ready, workers, deadline, &mut given_up)?;
    wait_until_written(domain, trajectories, deadline)?;
    for pid in pids {
        println!("pid {pid}");
    }
    let (side, start, until) = NodeSide::ready()?;
    run.go(start, until)?;
    sleep_until(until.saturating_add(drain_ns()));
    run.wait_for(Stage::Done, workers, Instant::now() + REPORT, &mut given_up)?;
    side.done(&[], run.dir())
}

/// Waits until every trajectory of `names` has its writer's port, so every worker
/// writes (and has opened the inputs of) what the file placed on it.
fn wait_until_written(domain: &str, names: &[String], deadline: Instant) -> anyhow::Result<()> {
    let control = ControlClient::connect(domain, Duration::from_secs(2))
        .with_context(|| format!("cannot reach the coordinator of `{domain}`"))?;
    loop {
        let placed = match control.call(&Request::ListPlacements)? {
            Response::Placements(p) => p,
            other => bail!("unexpected answer to a placement listing: {other:?}"),
        };
        let waiting: Vec<&str> = names
            .iter()
            .filter(|n| !placed.iter().any(|p| p.name == **n && p.port.is_some()))
            .map(String::as_str)
            .collect();
        if waiting.is_empty() {
            return Ok(());
        }
        if Instant::now() >= deadline {
            bail!("trajectories not written by their workers in time: {}", waiting.join(", "));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
