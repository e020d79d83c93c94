//! `esgm echo`: print a trajectory's samples as they arrive.

use std::time::Duration;

use esgm_core::{EntityTrajectoryStructure, Esgm, SubscribeOptions};

use crate::session::connect;
use crate::show::print_sample;
use esgm_cli::stop_args::StopArgs;

/// `esgm echo` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// Print the last N stored samples first.
    #[arg(long, default_value_t = 0)]
    pub last: usize,
    /// When to stop (samples printed, or seconds).
    #[command(flatten)]
    pub stop: StopArgs,
}

/// Subscribes and prints until a limit is reached (or forever).
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = crate::session::trajectory(&esgm, &a.trajectory)?;
    let sub = t.subscribe(SubscribeOptions::default().last(a.last))?;
    let mut stop = a.stop.start();
    while !stop.done() {
        if let Ok(s) = sub.recv_timeout(Duration::from_millis(200)) {
            print_sample(json, &a.trajectory, &s);
            stop.seen_one();
        } else if !esgm.ping() {
            anyhow::bail!("the system `{domain}` stopped");
        }
    }
    Ok(())
}
