//! `esgm info`: what a recording holds (like `ros2 bag info`), with no system running.

use std::path::PathBuf;

use anyhow::Context;
use esgm_recording::Recording;

use esgm_core::time::Time;

/// `esgm info` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The recording (`.mcap`).
    pub file: PathBuf,
}

/// Prints the recording's summary; a damaged file is summarised up to the damage.
pub fn run(json: bool, a: &Args) -> anyhow::Result<()> {
    let rec =
        Recording::open(&a.file).with_context(|| format!("cannot read {}", a.file.display()))?;
    let info = rec.info();
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    println!(
        "file:        {} ({:.2} MiB)",
        info.file.display(),
        info.bytes as f64 / (1 << 20) as f64
    );
    match &info.damage {
        None if info.complete => println!("state:       complete"),
        None => println!("state:       complete data, no summary"),
        Some(d) => println!(
            "state:       DAMAGED at byte {}: {}; recovered {} of {} bytes ({:.1} %)",
            d.position,
            d.reason,
            info.recovered_bytes,
            info.bytes,
            100.0 * info.recovered_bytes as f64 / info.bytes.max(1) as f64
        ),
    }
    println!("duration:    {:.3} s of valid time", info.duration_s);
    println!("start:       {}", when(info.start_valid_time));
    println!("end:         {}", when(info.end_valid_time));
    println!("structures:  {}", info.structures);
    println!(
        "{:<22} {:<10} {:<18} {:>8} {:>9} {:>10} {:>7} {:>10}",
        "trajectory", "kind", "type", "count", "rate Hz", "MiB", "lost", "violations"
    );
    for t in &info.trajectories {
        let lost: u64 = t.losses.values().fold(0, |a, &n| a.saturating_add(n));
        println!(
            "{:<22} {:<10} {:<18} {:>8} {:>9.2} {:>10.2} {:>7} {:>10}",
            t.name,
            t.kind,
            t.type_name,
            t.count,
            t.rate_hz,
            t.bytes as f64 / (1 << 20) as f64,
            lost,
            t.violations
        );
        for (cause, n) in &t.losses {
            println!("{:<22}   lost {n} ({cause})", "");
        }
    }
    if !info.foreign_topics.is_empty() {
        println!("other topics (not esgm's, not read): {}", info.foreign_topics.join(", "));
    }
    Ok(())
}

/// A valid time for people: RFC 3339 when it is after 1970, and the nanoseconds.
fn when(t: Option<Time>) -> String {
    match t {
        None => "-".into(),
        Some(ns) => match u64::try_from(ns) {
            Ok(u) => {
                let at = std::time::UNIX_EPOCH + std::time::Duration::from_nanos(u);
                format!("{} ({ns} ns)", humantime::format_rfc3339_nanos(at))
            }
            // Before 1970: no calendar date to show, the nanoseconds alone.
            Err(_) => format!("{ns} ns"),
        },
    }
}
