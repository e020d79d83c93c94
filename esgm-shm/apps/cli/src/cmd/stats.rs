//! `esgm stats`: every trajectory's statistics, as its readers see them (add delay is
//! the writer's valid → add time, carried in every sample), then the system's processes
//! with their restarts.

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind, WorkerStats};
use esgm_core::{EntityTrajectoryStructure, Esgm, TrajectoryStats};
use std::io::Write;

use serde_json::json;

use crate::session::{connect_tool as connect, trajectory};
use crate::show::{Line, TwoDecimals, ms};

/// Prints one line (or JSON object) per trajectory, then every drop by cause and
/// every unit or sensor whose calls failed.
///
/// The figures are the domain's (E7 through `connect`): each trajectory's writer's,
/// plus what its readers in every process lost on the way or rejected as malformed.
/// If some process does not answer, each trajectory's figures as this process reads
/// them instead.
pub fn run(domain: &str, json: bool) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    // Every listed trajectory with its figures: the domain's, or where some process
    // did not answer, this process's own reading of each.
    let (stats, unreported) = match esgm.domain_stats_listed() {
        Ok((stats, unreported)) => (stats.trajectories, unreported),
        Err(e) => {
            eprintln!("esgm: not every process answered ({e}); figures as this process reads them");
            (Default::default(), esgm.trajectories()?)
        }
    };
    let mut rows: Vec<(TrajectoryInfo, TrajectoryStats, Option<WorkerStats>)> = Vec::new();
    for info in unreported {
        let s = trajectory(&esgm, &info.name)?.stats()?;
        rows.push((info, s, None));
    }
    rows.extend(stats.into_values().map(|r| (r.info, r.stats, Some(r.worker))));
    rows.sort_by(|a, b| a.0.name.cmp(&b.0.name));
    // One write for the whole table, not one per line (a domain may hold thousands of
    // trajectories).
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    if !json {
        writeln!(
            out,
            "{:<20} {:<10} {:>7} {:>7} {:>7} {:>8} {:>11} {:>11}",
            "trajectory",
            "kind",
            "seen",
            "stored",
            "dropped",
            "rate Hz",
            "p50 lag ms",
            "p99 lag ms"
        )?;
    }
    let mut drops = Vec::new();
    let mut line = Line::default();
    for (info, s, worker) in &rows {
        if json {
            writeln!(
                out,
                "{}",
                json!({ "trajectory": info.name, "kind": info.kind.name(), "stats": s, "worker": worker })
            )?;
        } else {
            // Each line is made in one string and written at once: padding a cell
            // through the buffered writer costs a call per space, a millisecond over a
            // table of 1,000 trajectories.
            line.clear()
                .left(&info.name, 20)
                .left(info.kind.name(), 10)
                .right(s.added, 7)
                .right(s.stored, 7)
                .right(s.dropped_total, 7)
                .right(TwoDecimals(s.rate_hz), 8)
                .right(ms(s.add_delay_p50), 11)
                .right(ms(s.add_delay_p99), 11);
            writeln!(out, "{}", line.as_str())?;
            for (cause, n) in &s.dropped {
                drops.push(format!("{}: {n} dropped: {cause}", info.name));
            }
            if let Some(w) = worker.filter(|w| w.failures + w.panics + w.invalid_outputs > 0) {
                // A unit's or sensor's own failures lose no stored sample, but the
                // structures it did not make: say so, and where its tracebacks are.
                drops.push(format!(
                    "{}: {} of {} calls of {} `{}` failed ({} panicked, {} invalid outputs): esgm logs shows why",
                    info.name,
                    w.failures + w.panics,
                    w.calls,
                    if matches!(info.kind, TrajectoryKind::Sampled) { "sensor" } else { "unit" },
                    info.source.as_deref().unwrap_or("?"),
                    w.panics,
                    w.invalid_outputs
                ));
            }
        }
    }
    if !drops.is_empty() {
        writeln!(out)?;
        for line in drops {
            writeln!(out, "{line}")?;
        }
    }
    out.flush()?;
    drop(out);
    let processes = super::ps::listed(&esgm)?;
    if !processes.is_empty() && !json {
        println!();
    }
    super::ps::print(&processes, json)?;
    super::ps::warn_of_unsaved(&esgm, json)
}
