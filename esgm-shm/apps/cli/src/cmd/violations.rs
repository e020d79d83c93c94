//! `esgm violations`: a trajectory's policy violations as they happen (C7).

use std::time::Duration;

use esgm_core::EntityTrajectoryStructure;
use serde_json::json;

use crate::session::connect;
use esgm_cli::stop_args::StopArgs;

/// `esgm violations` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// When to stop (violations printed, or seconds).
    #[command(flatten)]
    pub stop: StopArgs,
}

/// Prints each violation as it is reported by the trajectory's writer.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = crate::session::trajectory(&esgm, &a.trajectory)?;
    let sub = t.subscribe_violations(1024)?;
    let mut stop = a.stop.start();
    while !stop.done() {
        if let Ok(v) = sub.recv_timeout(Duration::from_millis(200)) {
            if json {
                println!(
                    "{}",
                    json!({"trajectory": v.trajectory, "constraint": v.constraint.to_string(),
                           "valid_time": v.valid_time, "add_time": v.add_time, "detail": v.detail})
                );
            } else {
                println!(
                    "{}: {} violated at valid time {}: {}",
                    v.trajectory, v.constraint, v.valid_time, v.detail
                );
            }
            stop.seen_one();
        }
    }
    Ok(())
}
