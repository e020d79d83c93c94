//! `esgm replay`: a recording published into a running domain again, or rerun
//! deterministically in this process (`--in-process --config`).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use esgm_core::TrajectorySpec;
use esgm_recording::rerun::RerunUnit;
use esgm_recording::{
    ComputedMode, Pace, RecordOptions, Recording, RecordingWriter, ReplayOptions, ReplayPosition,
    RerunPlan, TimeMode,
};

use crate::cmd::worker::builtin_unit;
use crate::config;
use crate::session::connect;
use crate::time_arg::TimeArg;

/// `esgm replay` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The recording (`.mcap`).
    pub file: PathBuf,
    /// Speed factor against the recorded pace (2 = twice as fast).
    #[arg(long, default_value_t = 1.0, conflicts_with = "max", value_parser = crate::span_arg::rate)]
    pub rate: f64,
    /// As fast as the domain takes it.
    #[arg(long)]
    pub max: bool,
    /// Start again at the end, until Ctrl-C (valid times keep increasing).
    #[arg(long = "loop")]
    pub looped: bool,
    /// Replay only these trajectories.
    #[arg(long, num_args = 1..)]
    pub only: Vec<String>,
    /// Skip structures valid before this time: ns, RFC 3339, or `+5s` after the
    /// recording's first valid time.
    #[arg(long, allow_hyphen_values = true)]
    pub start: Option<TimeArg>,
    /// Skip structures valid after this time (as `--start`).
    #[arg(long, allow_hyphen_values = true)]
    pub end: Option<TimeArg>,
    /// Keep the recorded valid and create times (default: shifted so the first is now).
    #[arg(long)]
    pub keep_times: bool,
    /// Publish computed trajectories as recorded instead of letting the domain's units
    /// recompute them.
    #[arg(long)]
    pub as_recorded: bool,
    /// Run the configuration's units here on the recorded inputs, deterministically
    /// (simulated clock, recorded add order, as fast as possible); no domain needed.
    #[arg(long, requires = "config")]
    pub in_process: bool,
    /// The system configuration whose units `--in-process` runs.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// With `--in-process`: write every trajectory of the rerun into this file.
    #[arg(long, value_name = "FILE", requires = "in_process")]
    pub record: Option<PathBuf>,
}

/// Replays the file.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let rec =
        Recording::open(&a.file).with_context(|| format!("cannot read {}", a.file.display()))?;
    if let Some(d) = &rec.damage {
        eprintln!(
            "warning: {} is damaged at byte {} ({}); replaying what precedes it",
            a.file.display(),
            d.position,
            d.reason
        );
    }
    if a.in_process {
        return rerun(json, a, &rec);
    }
    let first = rec.valid_range().map(|r| r.0);
    let options = ReplayOptions {
        pace: if a.max { Pace::Max } else { Pace::Rate(a.rate) },
        looped: a.looped,
        only: (!a.only.is_empty()).then(|| a.only.clone()),
        start: a.start.as_ref().map(|t| t.resolve(first)).transpose()?,
        end: a.end.as_ref().map(|t| t.resolve(first)).transpose()?,
        times: if a.keep_times { TimeMode::Keep } else { TimeMode::ShiftToNow },
        computed: if a.as_recorded { ComputedMode::AsRecorded } else { ComputedMode::Recompute },
        position: Some(Arc::new(ReplayPosition::default())),
        ..ReplayOptions::default()
    };
    if !(a.max || a.rate > 0.0 && a.rate.is_finite()) {
        bail!("--rate must be a positive number (or use --max)");
    }
    let esgm = connect(domain)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Release))
        .context("cannot install the Ctrl-C handler")?;
    let span = rec
        .valid_range()
        .map(|(lo, hi)| (options.start.unwrap_or(lo).max(lo), options.end.unwrap_or(hi).min(hi)));
    let position = options.position.clone().unwrap_or_default();
    let progress = crate::progress::ReplayProgress::start(json, span, position);
    let report = esgm_recording::replay::replay(&esgm, &rec, &options, &stop);
    progress.finish();
    let report = report?;
    // Let the last structures reach their readers before the connection closes.
    std::thread::sleep(Duration::from_millis(200));
    if json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    for name in &report.created {
        println!("created `{name}`");
    }
    for (name, why) in &report.not_recomputed {
        println!("not recomputed: `{name}`: {why}");
    }
    println!(
        "{:<24} {:>9} {:>7} {:>8} {:>10}",
        "trajectory", "added", "held", "dropped", "in place"
    );
    for (name, c) in &report.published {
        println!(
            "{name:<24} {:>9} {:>7} {:>8} {:>10}",
            c.added, c.held, c.dropped, c.images_in_place
        );
    }
    if report.passes > 1 {
        println!("passes: {}", report.passes);
    }
    Ok(())
}

/// `--in-process`: the configuration's built-in units on the recorded inputs.
fn rerun(json: bool, a: &Args, rec: &Recording) -> anyhow::Result<()> {
    let Some(path) = &a.config else { bail!("--in-process needs --config") };
    let plan = config::load(path)?;
    let mut units = Vec::new();
    for u in &plan.units {
        let d = &u.what;
        if d.has_program() {
            bail!(
                "{}:{}: unit `{}` runs a program of its own; --in-process runs built-in units only",
                plan.file,
                u.line,
                d.name
            );
        }
        let builtin = d.builtin.as_deref().unwrap_or(&d.name);
        let (output_type, inputs, unit) =
            builtin_unit(builtin, d.type_name.as_deref(), d.window.unwrap_or(5))
                .with_context(|| format!("{}:{}: unit `{}`", plan.file, u.line, d.name))?;
        units.push(RerunUnit { name: d.name.clone(), output_type, inputs, unit });
    }
    let only = |s: &TrajectorySpec| a.only.is_empty() || a.only.contains(&s.name);
    let plan = RerunPlan {
        types: plan.types.iter().map(|t| t.what.clone()).collect(),
        units,
        trajectories: plan.trajectories.iter().map(|t| t.what.spec.clone()).filter(only).collect(),
    };
    let out = match &a.record {
        Some(p) => Some(
            // Chunks end by size only (no wall-clock flushes): the same rerun writes the
            // same bytes.
            RecordingWriter::create(
                p,
                RecordOptions::default()
                    .flush_interval(Duration::MAX)
                    .meta("rerun_of", a.file.display().to_string()),
            )
            .with_context(|| format!("cannot write {}", p.display()))?,
        ),
        None => None,
    };
    let report = esgm_recording::rerun(rec, &plan, out)?;
    if json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{:<24} {:>8} {:>8} {:>8} {:>7} {:>8} {:>9} {:>9}",
        "trajectory", "offered", "added", "dropped", "held", "calls", "no value", "failures"
    );
    for (name, c) in &report.trajectories {
        println!(
            "{name:<24} {:>8} {:>8} {:>8} {:>7} {:>8} {:>9} {:>9}",
            c.offered, c.added, c.dropped, c.held, c.calls, c.no_value, c.failures
        );
    }
    if let Some(w) = &report.written {
        for f in &w.files {
            println!("written: {}", f.display());
        }
    }
    Ok(())
}
