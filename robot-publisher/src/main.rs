//! `robot-publisher`: the robot process of an esgm system. It connects to the
//! coordinator of `--domain`, creates its `RobotState` trajectory and pushes a state
//! every `--period`, steering by the latest `DrivingDirection` of `--follow`, until the
//! coordinator is gone — the same code as `esgm worker robot`
//! ([`robot_publisher::serve`]).
//!
//! Exit codes: 0 done, 1 an error (one line on stderr), 2 a usage error.

use std::process::ExitCode;

use clap::Parser;
use robot_publisher::serve::{self, RobotArgs};

/// A simulated robot pushing `RobotState`s into an esgm system.
#[derive(Debug, Parser)]
#[command(name = "robot-publisher", version, about)]
struct Cli {
    /// The system to publish into (one coordinator per domain).
    #[arg(long, env = esgm_shm::DOMAIN_ENV, default_value = "esgm")]
    domain: String,
    #[command(flatten)]
    robot: RobotArgs,
}

fn main() -> ExitCode {
    // Usage errors and --help are clap's: printed in full, exit 2 or 0.
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    match serve::run(&cli.domain, &cli.robot) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("robot-publisher: {}", one_line(&err));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, leaving out a cause the line already says
/// (some errors repeat their source in their own message).
fn one_line(err: &anyhow::Error) -> String {
    err.chain().map(ToString::to_string).fold(String::new(), |line, cause| match line.as_str() {
        "" => cause,
        _ if line.contains(&cause) => line,
        _ => format!("{line}: {cause}"),
    })
}
