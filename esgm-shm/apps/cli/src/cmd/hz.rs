//! `esgm hz`: the rate of a trajectory and its add delay (valid → add), like
//! `ros2 topic hz`.

use std::time::{Duration, Instant};

use esgm_core::{EntityTrajectoryStructure, SubscribeOptions};
use serde_json::json;

use crate::session::connect;

/// `esgm hz` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// Seconds per report.
    #[arg(long, default_value_t = 1.0, value_parser = crate::span_arg::seconds)]
    pub window: f64,
    /// Stop after this many reports.
    #[arg(long)]
    pub count: Option<usize>,
}

fn percentile(sorted: &[i64], p: f64) -> Option<i64> {
    if sorted.is_empty() {
        return None;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted.get(i).copied()
}

/// Prints one report per window.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = crate::session::trajectory(&esgm, &a.trajectory)?;
    let sub = t.subscribe(SubscribeOptions::default().capacity(1 << 16))?;
    let window = Duration::from_secs_f64(a.window.max(0.05));
    let mut reports = 0;
    while a.count.is_none_or(|c| reports < c) {
        let start = Instant::now();
        let mut delays = Vec::new();
        let mut valid = Vec::new();
        while start.elapsed() < window {
            if let Ok(s) = sub.recv_timeout(window.saturating_sub(start.elapsed())) {
                delays.push(s.add_delay());
                valid.push(s.structure.valid_time());
            }
        }
        delays.sort_unstable();
        let rate = if valid.len() >= 2 {
            let span = (valid[valid.len() - 1] - valid[0]) as f64 / 1e9;
            if span > 0.0 { (valid.len() - 1) as f64 / span } else { 0.0 }
        } else {
            0.0
        };
        let (p50, p99) = (percentile(&delays, 0.5), percentile(&delays, 0.99));
        if json {
            println!(
                "{}",
                json!({"trajectory": a.trajectory, "samples": valid.len(), "rate_hz": rate,
                       "add_delay_p50_ns": p50, "add_delay_p99_ns": p99})
            );
        } else {
            println!(
                "{}: {:.2} Hz over {} samples; add delay p50 {} ms, p99 {} ms",
                a.trajectory,
                rate,
                valid.len(),
                crate::show::ms(p50),
                crate::show::ms(p99)
            );
        }
        reports += 1;
    }
    Ok(())
}
