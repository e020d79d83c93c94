//! `cli-*` (issue 40): what an operator waits for a CLI query, as whole processes. The
//! `esgm` executable built beside esgm-bench is run again and again against a domain
//! whose coordinator and trajectories live in a peer process (so that the measuring
//! process, which spawns the queries, holds none of the domain's descriptors, as an
//! operator's shell holds none): every query verb (`latest`, `nth`, `between`, `at`, `closest`,
//! `approx`, `echo --last`, `traj list`, `stats`), each timed from spawn to exit, in a
//! domain of 10 trajectories and one of 1,000 (`cli-<verb>-10`, `cli-<verb>-1000`).
//! `cli-version` (`esgm --version`) is the floor: starting the executable.
//!
//! Targets, as ratios of the same run: each verb within ×1.5 between the two domains
//! (nothing an operator waits for grows with the domain). The issue's absolute goal, p50
//! ≤ 15 ms on an idle machine, is said in each row's note and in BENCHMARKS.md, since
//! targets here are ratios. Without the `esgm` executable the rows are reported as not
//! run, saying how to build it.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::library::RobotState;
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, TypeRegistry};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

use crate::latency::Latency;
use crate::peer_process::PeerProcess;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The scenario's name (and its rows' prefix).
pub const NAME: &str = "cli";
/// The floor: starting the executable.
const VERSION: &str = "cli-version";
/// The two domain sizes, in trajectories.
const SIZES: [usize; 2] = [10, 1_000];
/// How long the peer may take to write its domain, or to exit once told to.
const PEER_LIFETIME: Duration = Duration::from_secs(120);
/// Structures in each trajectory.
const HISTORY: i64 = 5;

/// The verbs measured: row name and the arguments after `esgm --domain D`, `{t}` the
/// trajectory queried.
const VERBS: [(&str, &[&str]); 9] = [
    ("latest", &["latest", "{t}"]),
    ("nth", &["nth", "{t}", "2"]),
    ("between", &["between", "{t}", "1000000000", "4000000000"]),
    ("at", &["at", "{t}", "3000000000"]),
    ("closest", &["closest", "{t}", "3500000000"]),
    ("approx", &["approx", "{t}", "3500000000"]),
    ("echo-last", &["echo", "{t}", "--last", "1", "--count", "1"]),
    ("traj-list", &["traj", "list"]),
    ("stats", &["stats"]),
];

/// The CLI's queries as whole processes (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct CliQuery;

fn row_name(verb: &str, size: usize) -> String {
    format!("cli-{verb}-{size}")
}

/// The `esgm` executable beside this one (cargo builds them into one directory).
fn esgm_executable() -> anyhow::Result<Option<PathBuf>> {
    let exe = std::env::current_exe().context("cannot find esgm-bench itself")?;
    let esgm = exe.with_file_name("esgm");
    Ok(esgm.is_file().then_some(esgm))
}

/// `samples` timed runs of `esgm args` after `warmup` untimed ones; each must succeed.
fn time_runs(
    esgm: &PathBuf,
    args: &[String],
    samples: u64,
    warmup: u64,
) -> anyhow::Result<Latency> {
    let mut latency = Latency::new()?;
    for i in 0..warmup + samples {
        let started = Instant::now();
        run_esgm(esgm, args)?;
        let took = started.elapsed();
        if i >= warmup {
            latency.record(took);
        }
    }
    Ok(latency)
}

/// Runs `esgm args` once; it must succeed.
fn run_esgm(esgm: &PathBuf, args: &[String]) -> anyhow::Result<()> {
    let out = Command::new(esgm)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .with_context(|| format!("cannot run {}", esgm.display()))?;
    if !out.status.success() {
        bail!("`esgm {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

/// Waits until the peer has written its last trajectory, asking as an operator would
/// (`esgm latest`), and fails if the peer exits or takes longer than [`PEER_LIFETIME`].
fn wait_until_written(
    esgm: &PathBuf,
    domain: &str,
    size: usize,
    peer: &mut PeerProcess,
) -> anyhow::Result<()> {
    let last = format!("t{}", size - 1);
    let args = ["--domain".to_owned(), domain.to_owned(), "latest".to_owned(), last];
    let deadline = Instant::now() + PEER_LIFETIME;
    loop {
        peer.check_running()?;
        if run_esgm(esgm, &args).is_ok() {
            return Ok(());
        }
        if Instant::now() >= deadline {
            bail!("the peer did not write {size} trajectories within {PEER_LIFETIME:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The peer's side: a coordinator and a writer of `size` trajectories in `domain`,
/// until `esgm down` stops the coordinator (or [`PEER_LIFETIME`] passes).
fn serve_domain(domain: &str, size: usize) -> anyhow::Result<Vec<String>> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let coordinator = Coordinator::spawn(domain, Registry::new(TypeRegistry::with_library()))
        .with_context(|| format!("could not start a coordinator for {domain}"))?;
    let writer = ShmEsgm::builder()
        .domain(domain)
        .host("cli-writer")
        .connect()
        .context("the writer's connection")?;
    let mut trajectories = Vec::with_capacity(size);
    for i in 0..size {
        let t = writer
            .create_trajectory(TrajectorySpec::primitive(format!("t{i}"), "RobotState"))
            .with_context(|| format!("trajectory t{i}"))?;
        for k in 1..=HISTORY {
            let vt = k * 1_000_000_000;
            t.add(RobotState { x: k as f64, y: 0.0, dir: 0.0 }.to_structure("r", vt, vt))?;
        }
        trajectories.push(t);
    }
    let deadline = Instant::now() + PEER_LIFETIME * 4;
    while !coordinator.is_finished() {
        if Instant::now() >= deadline {
            bail!("the cli peer was not told to stop (esgm down) within {:?}", PEER_LIFETIME * 4);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(trajectories);
    drop(writer);
    drop(coordinator);
    Ok(Vec::new())
}

impl Scenario for CliQuery {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "rows cli-<verb>-10 and -1000: every CLI query verb as a whole esgm process, spawn to exit, in a domain of 10 and of 1,000 trajectories; cli-version the floor"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let Some(esgm) = esgm_executable()? else {
            ctx.skip(
                NAME,
                "the esgm executable is not beside esgm-bench: build it with the same profile \
                 (cargo build --release -p esgm-cli)",
            );
            return Ok(Vec::new());
        };
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        // Whole processes are slow to sample: at most 20 a row, 3 under --quick, even
        // when a run asks for more (the CI smoke's --samples 100 on a debug build).
        let samples = ctx.samples(20, 3).min(if ctx.is_quick() { 3 } else { 20 });
        let warmup = if ctx.is_quick() { 1 } else { 2 };
        let mut rows = Vec::new();
        let version = time_runs(&esgm, &["--version".to_owned()], samples, warmup)?;
        rows.push(
            version
                .measurement(VERSION, Wait::Event)
                .method(Method::Call)
                .wait_strategy("process")
                .note("esgm --version: starting the executable, spawn to exit"),
        );
        for size in SIZES {
            let domain = unique_domain("esgm-bench-cli");
            let _end = crate::domain_end::DomainEnd::new(&domain);
            // The domain lives in a peer process: a process holding 1,000 trajectories
            // holds about 10,000 descriptors, and every child it spawns closes them all
            // in exec (`do_close_on_exec`, 3 ms), which an operator's shell does not.
            let mut peer =
                ctx.spawn_peer_process_as(NAME, WaitMode::Block, &domain, Some(&size.to_string()))?;
            let queried = format!("t{}", size / 2);
            wait_until_written(&esgm, &domain, size, &mut peer)?;
            for (verb, args) in VERBS {
                let mut full = vec!["--domain".to_owned(), domain.clone()];
                full.extend(args.iter().map(|a| a.replace("{t}", &queried)));
                let latency = time_runs(&esgm, &full, samples, warmup)
                    .with_context(|| format!("{verb} in a domain of {size}"))?;
                let mut row = latency
                    .measurement(&row_name(verb, size), Wait::Event)
                    .method(Method::Call)
                    .wait_strategy("process")
                    .baseline(VERSION)
                    .note(format!(
                        "esgm {}: spawn to exit, in a domain of {size} trajectories of \
                         {HISTORY} RobotStates each, written by a peer process that also \
                         runs the coordinator; the issue's goal is p50 <= 15 ms on an idle \
                         machine",
                        full[2..].join(" ")
                    ));
                if size == SIZES[0] {
                    row = row.note("compared with the same verb in a domain of 1,000");
                }
                rows.push(row);
                peer.check_running()?;
            }
            run_esgm(&esgm, &["--domain".to_owned(), domain.clone(), "down".to_owned()])
                .context("esgm down, to end the peer's domain")?;
            peer.finish(PEER_LIFETIME)?;
        }
        Ok(rows)
    }

    /// Nothing an operator waits for grows with the domain: each verb within ×1.5
    /// between 10 and 1,000 trajectories.
    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        let size: usize = role
            .arg
            .as_deref()
            .context("the cli peer needs its domain's size")?
            .parse()
            .context("the cli peer's size is not a number")?;
        serve_domain(&role.domain, size)
    }

    fn targets(&self) -> Vec<Target> {
        VERBS
            .iter()
            .map(|(verb, _)| {
                Target::at_most(
                    &row_name(verb, SIZES[1]),
                    &row_name(verb, SIZES[0]),
                    Wait::Event,
                    1.5,
                )
            })
            .collect()
    }
}
