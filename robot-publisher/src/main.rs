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
    esgm_shm::process::init_logging();
    match serve::run(&cli.domain, &cli.robot) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("robot-publisher: {}", esgm_shm::process::one_line(err.chain()));
            ExitCode::FAILURE
        }
    }
}
