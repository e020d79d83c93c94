//! `esgm echo`: print a trajectory's samples as they arrive.

use std::time::{Duration, Instant};

use esgm_core::{EntityTrajectoryStructure, Esgm, SubscribeOptions};

use crate::session::connect;
use crate::show::print_sample;

/// `esgm echo` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// Print the last N stored samples first.
    #[arg(long, default_value_t = 0)]
    pub last: usize,
    /// Stop after this many samples.
    #[arg(long)]
    pub count: Option<usize>,
    /// Stop after this many seconds.
    #[arg(long, value_parser = crate::span_arg::seconds)]
    pub seconds: Option<f64>,
}

/// Subscribes and prints until a limit is reached (or forever).
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = crate::session::trajectory(&esgm, &a.trajectory)?;
    let sub = t.subscribe(SubscribeOptions::default().last(a.last))?;
    let until = a.seconds.map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut printed = 0;
    while a.count.is_none_or(|c| printed < c) {
        if until.is_some_and(|u| Instant::now() >= u) {
            break;
        }
        if let Ok(s) = sub.recv_timeout(Duration::from_millis(200)) {
            print_sample(json, &a.trajectory, &s);
            printed += 1;
        } else if !esgm.ping() {
            anyhow::bail!("the system `{domain}` stopped");
        }
    }
    Ok(())
}
