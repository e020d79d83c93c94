//! `esgm top`: the whole system on one screen, refreshed about once a second — every
//! trajectory's kind, type, rate, add delay, losses and violations by cause,
//! subscribers and the bytes its cache holds; every process's pid, CPU %, memory and
//! restarts.
//!
//! On a terminal it is a dashboard (`q` quits, `s` changes the sort key, `r` reverses,
//! `/` filters). With `--once`, or when stdout is not a terminal, it prints plain tables
//! instead (`--json`: one JSON object per refresh), so scripts and tests can read it.

use std::io::IsTerminal;
use std::time::Duration;

use crate::dashboard::table::{self, Shape, SortKey};
use crate::dashboard::{Sampler, tui};
use crate::session::connect;

/// `esgm top` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print one plain table and exit.
    #[arg(long)]
    pub once: bool,
    /// Seconds between refreshes.
    #[arg(long, default_value_t = 1.0, value_parser = crate::span_arg::seconds)]
    pub interval: f64,
    /// Plain output only: stop after this many refreshes.
    #[arg(long)]
    pub count: Option<usize>,
    /// The trajectory order.
    #[arg(long, value_enum, default_value_t = SortKey::Name)]
    pub sort: SortKey,
    /// Reverse the order.
    #[arg(long)]
    pub reverse: bool,
    /// Only rows whose name (or trajectory type or kind) contains this.
    #[arg(long, default_value = "")]
    pub filter: String,
}

/// How long `--once` waits between its two reads: CPU % is a difference.
const CPU_WINDOW: Duration = Duration::from_millis(500);

/// Shows the dashboard, or prints plain tables.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let interval = Duration::from_secs_f64(a.interval.max(0.1));
    let shape = Shape { sort: a.sort, reverse: a.reverse, filter: a.filter.clone() };
    let mut sampler = Sampler::new(connect(domain)?);
    let plain = a.once || json || !std::io::stdout().is_terminal();
    if !plain {
        return tui::run(domain, sampler, shape, interval);
    }
    let count = if a.once { Some(1) } else { a.count };
    // The first read opens every trajectory and starts the CPU meters.
    sampler.snapshot()?;
    std::thread::sleep(CPU_WINDOW.min(interval));
    let mut printed = 0;
    loop {
        let snapshot = sampler.snapshot()?;
        if json {
            println!("{}", serde_json::to_string(&snapshot)?);
        } else {
            if printed > 0 {
                println!();
            }
            print!("{}", table::plain(&snapshot, &shape));
        }
        printed += 1;
        if count.is_some_and(|c| printed >= c) {
            return Ok(());
        }
        std::thread::sleep(interval);
    }
}
