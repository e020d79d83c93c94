//! `esgm`: start a system, drive it, look inside it — and run the seed's tutorial as
//! separate processes (`esgm demo`).
//!
//! Every command that talks to a running system connects to the coordinator of its
//! domain (`--domain`, or `ESGM_DOMAIN`, default `esgm`). User errors print one line
//! naming what was wrong and exit 1; usage errors exit 2.

mod cmd;
mod dashboard;
mod progress;
mod series;
mod session;
mod show;

// The library's modules keep their paths in the binary (`crate::config`).
use esgm_cli::{config, external, span_arg, supervise, time_arg};

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// esgm — knowledge processing for robots over zero-copy shared memory.
#[derive(Debug, Parser)]
#[command(name = "esgm", version, about, propagate_version = true)]
struct Cli {
    /// The system to talk to (one coordinator per domain).
    #[arg(long, global = true, env = "ESGM_DOMAIN", default_value = esgm_shm::SYSTEM_DOMAIN)]
    domain: String,
    /// Print data as JSON (one object per line for streams).
    #[arg(long, global = true)]
    json: bool,
    /// Answer latest, nth, between, at and closest from the domain's bridge on another
    /// host, at this Zenoh endpoint (e.g. `tcp/10.0.0.2:7447`; runs `esgm-bridge`).
    #[arg(long, global = true, value_name = "ENDPOINT")]
    remote: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Start the coordinator of a domain (foreground unless --detach).
    Up(cmd::up::Args),
    /// Stop the coordinator and every process it started.
    Down,
    /// Declare types, sensors, units and trajectories from a configuration file.
    Apply(cmd::apply::Args),
    /// The processes the system keeps running, with restarts.
    Ps,
    /// What the system's processes logged (`esgm up` keeps a log per process).
    Logs(cmd::logs::Args),
    /// The seed's tutorial as separate processes: coordinator, camera, robot, units
    /// (--config FILE: as that file declares them).
    Demo(cmd::demo::Args),
    /// The tutorial run hard for minutes (camera 30 Hz, robot 1 kHz), watched for
    /// memory growth and losses; writes soak.json and soak.png.
    Soak(cmd::soak::Args),
    /// A synthetic robot (by default 300 trajectories in 60 processes) in a fresh
    /// domain: memory, CPU, connect and first-add times, latency and losses against
    /// the scale targets; writes scale.json and scale.png.
    Scale(cmd::scale::Args),
    /// One process of `esgm scale`'s synthetic robot (started by `esgm scale`).
    #[command(hide = true)]
    ScaleWorker(cmd::scale::WorkerArgs),
    /// `esgm scale`'s robot while random processes (the coordinator too) are killed
    /// with SIGKILL and restarted: checks that nothing acknowledged was lost, that
    /// every loss has a cause and that memory and /dev/shm come back; writes
    /// chaos.json.
    Chaos(cmd::chaos::Args),
    /// One process of `esgm chaos`'s robot (declared by `esgm chaos`).
    #[command(hide = true)]
    ChaosWorker(cmd::chaos::WorkerArgs),
    /// Entity structure types.
    #[command(subcommand)]
    Type(cmd::types::TypeCommand),
    /// Trajectories.
    #[command(subcommand)]
    Traj(cmd::traj::TrajCommand),
    /// Sensors.
    #[command(subcommand)]
    Sensor(cmd::registry::ListOnly),
    /// Computational units.
    #[command(subcommand)]
    Unit(cmd::registry::ListOnly),
    /// The latest sample of a trajectory.
    Latest(cmd::query::One),
    /// The n-th latest sample (0 = latest).
    Nth(cmd::query::Nth),
    /// Samples valid between two times.
    Between(cmd::query::Between),
    /// The sample valid exactly at a time.
    At(cmd::query::At),
    /// The closest sample at or before a time.
    Closest(cmd::query::At),
    /// The value at a time, approximated.
    Approx(cmd::query::Approx),
    /// Print samples as they arrive.
    Echo(cmd::echo::Args),
    /// The input structures behind one structure, back to its sources, with the
    /// time each hop took (its lineage).
    Trace(cmd::trace::Args),
    /// Why a trajectory has not produced: its inputs, its producer's last calls, a
    /// sync's wait, the constraints' drops, its writer.
    Why(cmd::why::Args),
    /// Rate and add-delay percentiles of a trajectory.
    Hz(cmd::hz::Args),
    /// Statistics of every trajectory.
    Stats,
    /// Empty a trajectory (or all) in its writer and every reader.
    Reset(cmd::reset::Args),
    /// Change the log level of the running processes (or of one).
    LogLevel(cmd::log_level::Args),
    /// Add one structure by hand: `esgm push TRAJ attr=value … [--valid-time T]`.
    Push(cmd::push::Args),
    /// The whole system on one screen, refreshed every second (a dashboard).
    Top(cmd::top::Args),
    /// Attributes of a trajectory over valid time, as a PNG chart.
    Plot(cmd::plot::Args),
    /// The domain live in Foxglove: a WebSocket server (runs `esgm-view`).
    #[command(disable_help_flag = true)]
    View(cmd::view::Args),
    /// The dataflow: sensors, units and trajectories.
    Graph(cmd::graph::Args),
    /// Policy violations of a trajectory as they happen.
    Violations(cmd::violations::Args),
    /// Record trajectories into an MCAP file (Foxglove opens it).
    Record(cmd::record::Args),
    /// What a recording holds: duration, trajectories, counts, rates, losses.
    Info(cmd::info::Args),
    /// Publish a recording into the domain again, or rerun it deterministically here.
    Replay(cmd::replay::Args),
    /// Compare two recordings by valid time; exits 1 when they differ.
    Compare(cmd::compare::Args),
    /// Make a recording's trajectories queryable in the domain.
    Load(cmd::load::Args),
    /// Carry trajectories to and from other hosts over Zenoh (runs `esgm-bridge`).
    #[command(disable_help_flag = true)]
    Bridge(cmd::bridge::Args),
    /// ROS 2 topics in as trajectories, trajectories out as ROS 2 topics, over DDS
    /// without a ROS installation (runs `esgm-ros2`).
    #[command(disable_help_flag = true)]
    Ros2(cmd::ros2::Args),
    /// Run one of the system's processes (started by `esgm demo`; also by hand).
    #[command(subcommand, hide = true)]
    Worker(cmd::worker::Role),
    /// Print the shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(cmd::docs::CompletionArgs),
    /// Print the manual page, or write one per subcommand into a directory (--out).
    Man(cmd::docs::ManArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Generated from the command's own definition; no system, no logging.
    let generated = match &cli.command {
        Command::Completions(a) => {
            Some(cmd::docs::completions(<Cli as clap::CommandFactory>::command(), a))
        }
        Command::Man(a) => Some(cmd::docs::man(<Cli as clap::CommandFactory>::command(), a)),
        _ => None,
    };
    match generated {
        Some(Ok(())) => return ExitCode::SUCCESS,
        Some(Err(e)) => {
            eprintln!("esgm: {}", esgm_shm::process::one_line(e.chain()));
            return ExitCode::FAILURE;
        }
        None => {}
    }
    esgm_shm::process::init_logging();
    let process = cmd::process_name(&cli.command);
    let span = tracing::info_span!("esgm", process = %process);
    let _entered = span.enter();

    // A domain started to allow others: this process opens its own files of the domain
    // too (`ESGM_SHM_ACCESS`; a worker gets it from the coordinator). `up` opens the
    // domain as its flags say.
    let _sharing = match &cli.command {
        Command::Up(_) => None,
        _ => match esgm_shm::process::share_domain(&cli.domain) {
            Ok(widener) => widener,
            Err(e) => {
                eprintln!("esgm: {}", esgm_shm::process::one_line(error_chain(&e)));
                return ExitCode::FAILURE;
            }
        },
    };

    // `esgm echo x | head`: a closed stdout ends the command quietly (println! panics
    // on a broken pipe; the panic unwinds, so every connection is closed properly).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !is_broken_pipe(info.payload()) {
            default_hook(info);
        }
    }));
    let result = match std::panic::catch_unwind(|| cmd::run(&cli)) {
        Ok(result) => result,
        Err(payload) if is_broken_pipe(payload.as_ref()) => return ExitCode::SUCCESS,
        Err(payload) => std::panic::resume_unwind(payload),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // `esgm compare` found differences: its report said so, no error line.
        Err(e) if e.is::<cmd::compare::Differ>() => ExitCode::FAILURE,
        // A buffered table written into a closed pipe (`esgm stats | head`): as quiet
        // as println!'s panic above.
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            // One line: the error and its causes, never a backtrace.
            eprintln!("esgm: {}", esgm_shm::process::one_line(e.chain()));
            ExitCode::FAILURE
        }
    }
}

/// An error and its sources, outermost first.
fn error_chain<'a>(
    e: &'a (dyn std::error::Error + 'static),
) -> impl Iterator<Item = &'a (dyn std::error::Error + 'static)> {
    std::iter::successors(Some(e), |e| e.source())
}

/// True for the panic `println!` raises when stdout's reader has gone.
fn is_broken_pipe(payload: &(dyn std::any::Any + Send)) -> bool {
    let message = payload
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| payload.downcast_ref::<&str>().copied())
        .unwrap_or_default();
    message.contains("Broken pipe")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use std::path::Path;

    use super::*;

    /// A duration or rate that would panic once the system runs is refused by the parser,
    /// before anything starts (`esgm demo --seconds inf` started a whole system, then
    /// panicked and left it running).
    #[test]
    fn unusable_seconds_and_rates_are_refused_before_anything_starts() {
        use clap::Parser;

        for args in [
            &["esgm", "demo", "--seconds", "inf"][..],
            &["esgm", "echo", "x", "--seconds", "NaN"],
            &["esgm", "violations", "x", "--seconds=-1"],
            &["esgm", "top", "--interval", "1e300"],
            &["esgm", "hz", "x", "--window", "inf"],
            &["esgm", "replay", "f.mcap", "--rate", "0"],
        ] {
            let e = Cli::try_parse_from(args).err().unwrap_or_else(|| panic!("{args:?} parsed"));
            assert_eq!(e.kind(), clap::error::ErrorKind::ValueValidation, "{args:?}: {e}");
        }
        assert!(Cli::try_parse_from(["esgm", "demo", "--seconds", "2.5"]).is_ok());
    }

    /// What a plan starts is what `esgm worker` (the publishers' own arguments) takes.
    #[test]
    fn planned_workers_parse_as_esgm_worker() {
        use clap::Parser;

        use crate::cmd::worker::Role;
        use crate::config::parse;

        let base = tempfile::tempdir().unwrap();
        std::fs::create_dir(base.path().join("frames")).unwrap();
        let text = "[[sensor]]\nname = \"cam\"\ncamera = \"frames\"\nframe_period = \"250000000\"\n\
                    [[robot]]\ntrajectory = \"rs\"\nfollow = \"dd\"\nperiod = \"1.5s\"\n";
        let mut plan = parse("f.toml", text, base.path()).unwrap();
        plan.workers.extend(
            parse("tutorial.toml", include_str!("../tutorial.toml"), Path::new("."))
                .unwrap()
                .workers,
        );
        for worker in &plan.workers {
            let args = &worker.what.spec.args;
            let cli =
                Cli::try_parse_from(std::iter::once("esgm").chain(args.iter().map(String::as_str)))
                    .unwrap_or_else(|e| panic!("{args:?}: {e}"));
            let Command::Worker(role) = cli.command else { panic!("{args:?}") };
            match (worker.what.spec.name.as_str(), role) {
                ("camera-cam", Role::Camera(camera)) => {
                    assert_eq!(camera.dir, Some(base.path().join("frames")));
                    assert_eq!(camera.frame_period, std::time::Duration::from_millis(250));
                }
                ("robot-rs", Role::Robot(robot)) => {
                    assert_eq!((robot.trajectory.as_str(), robot.follow.as_str()), ("rs", "dd"));
                    assert_eq!(robot.period, std::time::Duration::from_millis(1500));
                }
                ("robot-robot_state", Role::Robot(robot)) => {
                    assert_eq!(robot.period, std::time::Duration::from_millis(100));
                }
                ("camera-camera", Role::Camera(camera)) => assert_eq!(camera.dir, None),
                (_, Role::Unit { .. }) => {}
                (name, role) => panic!("{name} runs {role:?}"),
            }
        }
    }
}
