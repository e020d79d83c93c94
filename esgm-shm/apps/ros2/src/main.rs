//! `esgm-ros2`: esgm beside ROS 2 (see the crate docs of `esgm_ros2`). Usually run as
//! `esgm ros2 …`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use clap::Parser;
use esgm_ros2::export::{self, ExportSpec};
use esgm_ros2::import::{self, ImportSpec};
use esgm_ros2::node::{self, TopicQos};
use esgm_ros2::stats::Stats;
use esgm_ros2::watch::Watch;
use esgm_shm::{CoordinatorWatch, ShmEsgm};
use interfaces::{Types, print_msg, write_package};

mod interfaces;

/// esgm-ros2 — ROS 2 topics in as trajectories, trajectories out as ROS 2 topics.
#[derive(Debug, Parser)]
#[command(name = "esgm-ros2", version, about)]
struct Cli {
    /// The local esgm system (one coordinator per domain).
    #[arg(long, env = "ESGM_DOMAIN", default_value = "esgm")]
    domain: String,
    /// The ROS 2 domain to join, as ROS 2 takes it.
    #[arg(long, env = "ROS_DOMAIN_ID", default_value_t = 0)]
    ros_domain_id: u16,
    /// The node's name on the ROS 2 graph (`/esgm/<name>`; default `esgm_<domain>`).
    #[arg(long)]
    node_name: Option<String>,
    /// Import a ROS 2 topic: `TOPIC:TYPE[=TRAJECTORY]`, e.g.
    /// `/camera/image_raw:sensor_msgs/msg/Image`; repeatable.
    #[arg(long, value_name = "TOPIC:TYPE[=TRAJECTORY]")]
    import: Vec<String>,
    /// Export a trajectory as a ROS 2 topic: `TRAJECTORY[=TOPIC]` (default topic
    /// `/<trajectory>`); repeatable.
    #[arg(long, value_name = "TRAJECTORY[=TOPIC]")]
    export: Vec<String>,
    /// Read imported topics best effort (matches sensor drivers that publish best
    /// effort; a reliable reader, the default, does not).
    #[arg(long)]
    best_effort: bool,
    /// Keep-last depth of every topic.
    #[arg(long, default_value_t = 10)]
    depth: usize,
    /// Print every topic's counters as JSON lines this often (e.g. `1s`).
    #[arg(long, value_parser = humantime::parse_duration)]
    report_every: Option<Duration>,
    /// Check the settings and exit, joining nothing (`esgm apply` checks a `[[ros2]]`
    /// with it).
    #[arg(long)]
    check: bool,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Print the ROS 2 message definitions (`.msg`) a type is exported as: its own
    /// `esgm_msgs/msg/<Type>` and `esgm_msgs/msg/<T>Frame` for each type it nests as a
    /// frame, so a ROS workspace can build them (a type with a standard message says
    /// which). A library type needs no running system; a system file's with --config.
    Msg {
        /// The entity structure type.
        type_name: String,
        /// A system file whose `[[type]]`s are looked up before the domain's.
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
    },
    /// Write the ROS 2 interface package `esgm_msgs` (package.xml, CMakeLists.txt,
    /// msg/) into DIR, for the types named, or every type of the system file
    /// (--config), or of the running domain: a ROS 2 workspace builds it with colcon.
    Pkg {
        /// The directory to write `esgm_msgs/` into (a workspace's `src`).
        dir: PathBuf,
        /// The types; none: every type of --config, or of the domain.
        types: Vec<String>,
        /// A system file whose `[[type]]`s are looked up before the domain's.
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    // No ROS installation is needed, so ros2-client's check of ROS_DISTRO is not news.
    esgm_shm::process::init_logging_with("warn,ros2_client::distributions=error");
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("esgm-ros2: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: &Cli) -> anyhow::Result<()> {
    match &cli.command {
        Some(Command::Msg { type_name, config }) => {
            let mut types = Types::new(&cli.domain, config.as_deref())?;
            return print_msg(&mut types, type_name);
        }
        Some(Command::Pkg { dir, types: names, config }) => {
            let mut types = Types::new(&cli.domain, config.as_deref())?;
            let package = write_package(&mut types, dir, names)?;
            println!("wrote {}", package.display());
            return Ok(());
        }
        None => {}
    }
    let imports: Vec<ImportSpec> =
        cli.import.iter().map(|s| ImportSpec::parse(s)).collect::<Result<_, _>>()?;
    let exports: Vec<ExportSpec> =
        cli.export.iter().map(|s| ExportSpec::parse(s)).collect::<Result<_, _>>()?;
    anyhow::ensure!(
        !imports.is_empty() || !exports.is_empty(),
        "nothing to do: give at least one --import TOPIC:TYPE or --export TRAJECTORY"
    );
    anyhow::ensure!(cli.depth > 0, "--depth must be at least 1, not {}", cli.depth);
    if cli.check {
        return Ok(());
    }
    let domain = &cli.domain;
    // Run by the supervisor (`[[ros2]]`), it is the worker it was started as, so a
    // trajectory the file places there (`writer = "ros2"`) is written here, and taken
    // back after a restart.
    let host = std::env::var(esgm_shm::WORKER_ENV)
        .unwrap_or_else(|_| format!("esgm-ros2-{}", std::process::id()));
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(host)
        .connect()
        .with_context(|| format!("cannot reach the esgm system `{domain}`"))?;
    // It writes the trajectories it imports.
    esgm.serve_assignments();
    let name = cli.node_name.clone().unwrap_or_else(|| node::default_node_name(domain));
    let mut ros = node::join(cli.ros_domain_id, &name)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("installing the Ctrl-C/SIGTERM handler")?;
    }
    let stats = Stats::default();
    let qos = TopicQos { reliable: true, depth: cli.depth };
    let mut threads = Vec::new();
    let mut watch = Watch::default();
    for spec in &imports {
        let import_qos = TopicQos { reliable: !cli.best_effort, ..qos };
        let spawned = import::spawn(&mut ros.node, &esgm, spec, import_qos, &stats, &stop)?;
        threads.push(spawned.thread);
        watch.add(spawned.watched);
    }
    for spec in &exports {
        let spawned = export::spawn(&mut ros.node, &esgm, spec, qos, &stats, &stop)?;
        threads.push(spawned.thread);
        watch.add(spawned.watched);
    }
    let participant = ros.context().domain_participant();
    let mut watched = Instant::now();
    println!(
        "esgm-ros2: esgm domain `{domain}`, ROS 2 domain {} as /esgm/{name}: importing {:?}, exporting {:?}",
        cli.ros_domain_id,
        imports.iter().map(|s| format!("{} -> {}", s.topic, s.trajectory)).collect::<Vec<_>>(),
        exports.iter().map(|s| format!("{} -> {}", s.trajectory, s.topic)).collect::<Vec<_>>(),
    );
    let mut reported = Instant::now();
    // It leaves with its system: 3 s without the coordinator's answer.
    let mut coordinator = CoordinatorWatch::new(Duration::from_secs(3));
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        if coordinator.gone(&esgm) {
            stop.store(true, Ordering::Relaxed);
            eprintln!("esgm-ros2: the coordinator of `{domain}` is gone; stopping");
        }
        // A peer discovery finds that cannot match is named at once, not at the report.
        if watched.elapsed() >= Duration::from_millis(250) {
            watched = Instant::now();
            watch.check(&participant);
        }
        if cli.report_every.is_some_and(|every| reported.elapsed() >= every) {
            reported = Instant::now();
            report(&stats);
        }
    }
    for t in threads {
        if t.join().is_err() {
            tracing::error!("an esgm-ros2 thread panicked");
        }
    }
    report(&stats);
    Ok(())
}

/// Prints every topic's counters, a JSON line each.
fn report(stats: &Stats) {
    esgm_shm::process::print_json_lines(stats.snapshot());
}
