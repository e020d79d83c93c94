//! `esgm stats`: every trajectory's statistics, as its readers see them (add delay is
//! the writer's valid → add time, carried in every sample), then the system's processes
//! with their restarts.

use esgm_core::{EntityTrajectoryStructure, Esgm};
use serde_json::json;

use crate::session::{connect, trajectory};
use crate::show::ms;

/// Prints one line (or JSON object) per trajectory.
pub fn run(domain: &str, json: bool) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let list = esgm.trajectories();
    if !json {
        println!(
            "{:<20} {:<10} {:>7} {:>7} {:>8} {:>11} {:>11}",
            "trajectory", "kind", "seen", "stored", "rate Hz", "p50 lag ms", "p99 lag ms"
        );
    }
    for info in list {
        let t = trajectory(&esgm, &info.name)?;
        let s = t.stats()?;
        if json {
            println!(
                "{}",
                json!({ "trajectory": info.name, "kind": info.kind.name(), "stats": s })
            );
        } else {
            println!(
                "{:<20} {:<10} {:>7} {:>7} {:>8.2} {:>11} {:>11}",
                info.name,
                info.kind.name(),
                s.added,
                s.stored,
                s.rate_hz,
                ms(s.add_delay_p50),
                ms(s.add_delay_p99)
            );
        }
    }
    let processes = super::ps::processes(domain)?;
    if !processes.is_empty() && !json {
        println!();
    }
    super::ps::print(&processes, json)
}
