//! `esgm violations`: a trajectory's policy violations as they happen (C7).

use std::time::{Duration, Instant};

use esgm_core::EntityTrajectoryStructure;
use serde_json::json;

use crate::session::connect;

/// `esgm violations` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// Stop after this many.
    #[arg(long)]
    pub count: Option<usize>,
    /// Stop after this many seconds.
    #[arg(long, value_parser = crate::span_arg::seconds)]
    pub seconds: Option<f64>,
}

/// Prints each violation as it is reported by the trajectory's writer.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = crate::session::trajectory(&esgm, &a.trajectory)?;
    let sub = t.subscribe_violations(1024)?;
    let until = a.seconds.map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut printed = 0;
    while a.count.is_none_or(|c| printed < c) {
        if until.is_some_and(|u| Instant::now() >= u) {
            break;
        }
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
            printed += 1;
        }
    }
    Ok(())
}
