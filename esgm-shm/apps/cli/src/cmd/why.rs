//! `esgm why TRAJ [--since T]`: why a trajectory has not produced, on one screen
//! (issue 42): the reasons first, then the evidence behind them — each input's latest
//! structure and its writer, the producer's last calls, a sync's wait, and each
//! cause's drops with the last structure dropped.

use std::fmt::Write as _;

use esgm_core::esgm::{CallOutcome, MissCause, Why};
use esgm_core::time::for_people as ago;
use esgm_core::{Clock, Esgm, SystemClock};

use crate::session::connect_tool as connect;
use crate::time_arg::{TimeArg, display};

/// A trajectory, and the time to explain from.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The trajectory.
    pub trajectory: String,
    /// Explain what happened since this time: nanoseconds, RFC 3339, or relative to
    /// now (-10s).
    #[arg(long, allow_hyphen_values = true, default_value = "-10s")]
    pub since: TimeArg,
}

/// `esgm why`.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let since = a.since.resolve(Some(SystemClock.now()))?;
    let why = esgm.why(&a.trajectory, since)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&why)?);
    } else {
        print!("{}", render(&why));
    }
    Ok(())
}

fn alive(a: Option<bool>) -> &'static str {
    match a {
        Some(true) => "writer runs",
        Some(false) => "writer gone",
        None => "",
    }
}

/// The answer as one screen of text.
pub fn render(why: &Why) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{} ({}) since {} ({} ago)",
        why.trajectory,
        why.kind.name(),
        display(why.since),
        ago(why.now - why.since)
    );
    for reason in &why.reasons {
        let _ = writeln!(out, "  - {reason}");
    }
    if !why.inputs.is_empty() {
        let _ = writeln!(out, "inputs:");
        let width = why.inputs.iter().map(|i| i.trajectory.len()).max().unwrap_or(0);
        for i in &why.inputs {
            let latest = match (i.latest_valid_time, i.age) {
                _ if !i.exists => "does not exist".to_owned(),
                (Some(vt), Some(age)) => {
                    format!("latest valid {}, entered {} ago", display(vt), ago(age))
                }
                _ => "holds nothing".to_owned(),
            };
            let _ = writeln!(out, "  {:width$}  {latest}  {}", i.trajectory, alive(i.writer_alive));
        }
    }
    if let Some(w) = &why.worker {
        let _ = writeln!(
            out,
            "producer: {} calls, {} outputs, {} no value, {} failed, {} panicked, {} wrong type, {} missed periods",
            w.calls,
            w.outputs,
            w.no_value,
            w.failures,
            w.panics,
            w.invalid_outputs,
            w.missed_periods
        );
    }
    if !why.recent_calls.is_empty() {
        let _ = writeln!(out, "last calls:");
        for c in why.recent_calls.iter().rev().take(5) {
            let what = match &c.outcome {
                CallOutcome::Produced => "produced".to_owned(),
                CallOutcome::Dropped(d) => format!("dropped by the policy: {d}"),
                CallOutcome::NoValue => "no value".to_owned(),
                CallOutcome::Failed(e) => format!("failed: {e}"),
                CallOutcome::Panicked(e) => format!("raised: {e}"),
                CallOutcome::InvalidOutput(e) => format!("wrong type: {e}"),
            };
            let _ = writeln!(out, "  {} ago  {what}", ago(why.now - c.at));
        }
    }
    for m in why.missed.iter().rev().take(5) {
        let cause = match m.cause {
            MissCause::SlowCall { took, period } => {
                format!("the call before took {} (period {})", ago(took), ago(period))
            }
            MissCause::LateWakeUp { late, period } => {
                format!("woke {} late (period {})", ago(late), ago(period))
            }
        };
        let _ = writeln!(
            out,
            "missed {} sample point(s) {} ago: {cause}",
            m.missed,
            ago(why.now - m.at)
        );
    }
    if let Some(s) = &why.sync {
        let _ = writeln!(
            out,
            "sync: waits for {}, {} behind (tolerance {}), {} discarded",
            s.waits_for.as_deref().unwrap_or("-"),
            s.gap.map_or("-".into(), ago),
            s.tolerance.map_or("none".into(), ago),
            s.discarded
        );
        for d in s.dropped.iter().filter(|d| d.drops.total() > 0) {
            let reasons: Vec<String> =
                d.drops.by_reason().iter().map(|(r, n)| format!("{n} {}", r.words())).collect();
            let last = d.drops.last.map(|(vt, _)| format!("; last valid {}", display(vt)));
            let _ =
                writeln!(out, "  {}: {}{}", d.input, reasons.join(", "), last.unwrap_or_default());
        }
    }
    for d in &why.drops {
        let last = d
            .last
            .as_ref()
            .map(|l| format!("; last: valid {}, {}", display(l.valid_time), l.detail))
            .unwrap_or_default();
        let _ =
            writeln!(out, "dropped ({:?}): {} since, {} in all{last}", d.cause, d.since, d.total);
    }
    if why.writer_alive == Some(false) {
        let _ = writeln!(out, "writer: gone");
    }
    out
}
