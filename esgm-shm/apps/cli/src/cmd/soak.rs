//! `esgm soak`: the tutorial run hard for minutes, watched for leaks and losses.
//!
//! It starts the tutorial (`tutorial.toml`, as `esgm demo` does) in a fresh domain of
//! its own with the camera at 30 Hz and robot_state at 1 kHz (`--camera-hz`,
//! `--robot-hz`; the file is not edited: its periods are overridden in the plan), and
//! once a second it samples:
//! - the resident memory of the coordinator and of every supervised worker
//!   (`/proc/<pid>/status`: `VmRSS`, and `RssAnon` for private memory alone);
//! - the domain's shared memory: the `/dev/shm` files the domain's processes map,
//!   counted by allocated bytes (`st_blocks × 512`), not by apparent size (see
//!   [`probe`] for why mapping is what ties a file to a domain), and every iceoryx2 file
//!   on the host for context;
//! - every trajectory's added count and losses by cause, as `esgm stats` reports them.
//!
//! # Caches
//! The tutorial lets blobs, current_blob and driving_direction keep every sample (no
//! cache constraint: the seed's default). At 1 kHz that is retention, not a leak:
//! driving_direction alone grows its writer and the robot's replica by about 25 MB a
//! minute (measured), and no memory can stay flat. A soak looks for leaks, so by
//! default those trajectories keep the last 10 s of valid time instead (`--cache`,
//! overridden in the plan like the periods); `--cache all` runs the file's policy and
//! shows the retention. Trajectories the file bounds keep their bound.
//!
//! At the end it stops the system as `esgm demo` does, checks that no process, node or
//! shared-memory file of the domain is left, prints a verdict, and writes `soak.json`
//! (every sample and the verdict) and `soak.png` (memory over time, losses) into
//! `--out`. The targets: after the warm-up (the first minute: caches and queues fill),
//! no process's resident memory and not the shared memory grows by 1 % or more, no
//! process restarts, data keeps flowing, and no loss is unexplained (see [`sample`]
//! for which are). A missed target exits 1 unless `--no-check`; something left behind
//! always does. Ctrl-C (or SIGTERM) ends the run early: the system is stopped and the
//! report written as after a full run, and the command exits 1 (the run was short).

mod chart;
pub(super) mod probe;
pub(super) mod sample;
mod verdict;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_shm::control::{Request, Response, StateDir};
use esgm_shm::{ShmEsgm, nodes_of, unique_domain};

use crate::config::{self, Plan};
use sample::{Counts, ProcessSample, Sample};
use verdict::Verdict;

/// `esgm soak` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// How long to run, in minutes [default: 10].
    #[arg(long, conflicts_with = "seconds", value_parser = crate::span_arg::minutes)]
    pub minutes: Option<f64>,
    /// How long to run, in seconds (for short runs).
    #[arg(long, value_parser = crate::span_arg::seconds)]
    pub seconds: Option<f64>,
    /// Directory for `soak.json`, `soak.png` and the processes' logs (created).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
    /// Camera images per second.
    #[arg(long, default_value_t = 30.0, value_parser = crate::span_arg::rate)]
    pub camera_hz: f64,
    /// robot_state samples per second.
    #[arg(long, default_value_t = 1000.0, value_parser = crate::span_arg::rate)]
    pub robot_hz: f64,
    /// What the trajectories the file lets keep every sample keep during the soak: a
    /// duration of valid time (`10s`), a count (`1000`), or `all` for the file's policy.
    #[arg(long, default_value = "10s")]
    pub cache: String,
    /// Seconds before the baseline memory is taken (at most half the run).
    #[arg(long, default_value_t = 60.0, value_parser = crate::span_arg::seconds)]
    pub warmup: f64,
    /// Most memory growth after the warm-up that passes, in percent.
    #[arg(long, default_value_t = 1.0)]
    pub max_growth: f64,
    /// Only report: exit 0 even when a target is missed.
    #[arg(long)]
    pub no_check: bool,
}

/// The arguments, checked.
#[derive(Debug, Clone, PartialEq)]
struct Settings {
    run_for: Duration,
    out: PathBuf,
    camera_hz: f64,
    robot_hz: f64,
    /// The cache of unbounded trajectories; `None`: the file's (keep all).
    cache: Option<String>,
    /// The warm-up, capped at half the run so a short run still compares two halves.
    warmup: f64,
    max_growth: f64,
    check: bool,
}

impl Settings {
    fn new(a: &Args) -> anyhow::Result<Self> {
        let seconds = match (a.minutes, a.seconds) {
            (Some(m), _) => positive("--minutes", m)? * 60.0,
            (None, Some(s)) => positive("--seconds", s)?,
            (None, None) => 600.0,
        };
        let warmup = a.warmup;
        if !warmup.is_finite() || warmup < 0.0 {
            bail!("--warmup must be zero or more seconds, got {warmup}");
        }
        Ok(Settings {
            run_for: Duration::try_from_secs_f64(seconds).context("the run is too long")?,
            out: a.out.clone(),
            camera_hz: positive("--camera-hz", a.camera_hz)?,
            robot_hz: positive("--robot-hz", a.robot_hz)?,
            cache: (a.cache != "all").then(|| a.cache.clone()),
            warmup: warmup.min(seconds / 2.0),
            max_growth: positive("--max-growth", a.max_growth)?,
            check: !a.no_check,
        })
    }
}

fn positive(flag: &str, v: f64) -> anyhow::Result<f64> {
    if v.is_finite() && v > 0.0 { Ok(v) } else { bail!("{flag} must be positive, got {v}") }
}

/// What `soak.json` holds.
#[derive(Debug, serde::Serialize)]
struct Report<'a> {
    domain: &'a str,
    camera_hz: f64,
    robot_hz: f64,
    /// The cache the trajectories in `bounded` kept instead of every sample.
    cache: Option<&'a str>,
    bounded: &'a [String],
    planned_seconds: f64,
    interrupted: bool,
    /// How the domain's shared memory is told from other files.
    shm_attribution: &'static str,
    samples: &'a [Sample],
    verdict: &'a Verdict,
    /// Processes, nodes and files of the domain still there after the stop.
    left_behind: &'a [String],
}

/// The tutorial's configuration file.
const TUTORIAL: &str = include_str!("../../tutorial.toml");

/// Runs the soak; a missed target or anything left behind is an error (exit 1).
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    let settings = Settings::new(a)?;
    let (plan, bounded) = plan(&settings)?;
    std::fs::create_dir_all(&settings.out)
        .with_context(|| format!("cannot create {}", settings.out.display()))?;
    let stop = Arc::new(AtomicBool::new(false));
    // A fresh system unless the user named one.
    let domain = if domain == "esgm" { unique_domain("soak") } else { domain.to_owned() };
    println!(
        "esgm soak: the tutorial with the camera at {} Hz and robot_state at {} Hz for {:.0} s, domain `{domain}`",
        settings.camera_hz,
        settings.robot_hz,
        settings.run_for.as_secs_f64()
    );
    if let Some(cache) = &settings.cache {
        println!("  keeping {cache} (not every sample) of {}", bounded.join(", "));
    }

    let mut system = System::start(&domain)?;
    let run = system.soak(&plan, &settings, &stop);
    let logs = settings.out.join("logs");
    if let Err(e) = copy_dir(&system.state.log_dir(), &logs) {
        eprintln!("esgm: cannot keep the processes' logs in {}: {e:#}", logs.display());
    }
    let stopped = system.stop();
    let (samples, seen) = run?;
    stopped?;
    let left_behind = left_behind(&domain, &seen, &samples);

    let v = verdict::judge(&samples, settings.warmup, settings.max_growth);
    let interrupted = stop.load(Ordering::Acquire);
    print(&v, &samples, &left_behind);
    let report = Report {
        domain: &domain,
        camera_hz: settings.camera_hz,
        robot_hz: settings.robot_hz,
        cache: settings.cache.as_deref(),
        bounded: &bounded,
        planned_seconds: settings.run_for.as_secs_f64(),
        interrupted,
        shm_attribution: "the /dev/shm files mapped by the domain's processes (coordinator, \
                          workers, the soak's own connection), by st_blocks x 512",
        samples: &samples,
        verdict: &v,
        left_behind: &left_behind,
    };
    let json = settings.out.join("soak.json");
    std::fs::write(&json, serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let png = settings.out.join("soak.png");
    let title = format!(
        "esgm soak: camera {} Hz, robot_state {} Hz, {:.0} s",
        settings.camera_hz, settings.robot_hz, v.end_t
    );
    chart::draw(&samples, v.baseline_t, &title, &png)?;
    println!("\nwrote {} and {}", json.display(), png.display());

    if !left_behind.is_empty() {
        bail!("the soak left {} things of `{domain}` behind", left_behind.len());
    }
    if interrupted {
        bail!("interrupted after {:.0} s", v.end_t);
    }
    if settings.check && !v.passed() {
        bail!("{} targets missed", v.missed.len());
    }
    Ok(())
}

/// The tutorial at the soak's settings, overridden in the parsed file: the images
/// trajectory's period, the robot's, and the cache of every trajectory that keeps all
/// (returned by name).
fn plan(settings: &Settings) -> anyhow::Result<(Plan, Vec<String>)> {
    let mut doc: toml::Table = toml::from_str(TUTORIAL).context("tutorial.toml")?;
    let camera = period_of(settings.camera_hz)?;
    set(&mut doc, "trajectory", ("name", "images"), "period", camera)?;
    let robot = period_of(settings.robot_hz)?;
    set(&mut doc, "robot", ("trajectory", "robot_state"), "period", robot)?;
    let bounded = match &settings.cache {
        Some(cache) => bound_caches(&mut doc, cache),
        None => Vec::new(),
    };
    let text = toml::to_string(&doc).context("tutorial.toml")?;
    let plan = config::parse("tutorial.toml (soak settings)", &text, Path::new("."))?;
    Ok((plan, bounded))
}

/// Gives every `[[trajectory]]` without a cache constraint (or with `all` or `0`) the
/// cache `cache`; returns their names.
fn bound_caches(doc: &mut toml::Table, cache: &str) -> Vec<String> {
    let mut bounded = Vec::new();
    let list = doc.get_mut("trajectory").and_then(toml::Value::as_array_mut);
    for t in list.into_iter().flatten().filter_map(toml::Value::as_table_mut) {
        let name = t.get("name").and_then(toml::Value::as_str).unwrap_or_default().to_owned();
        let policy = t
            .entry("policy")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut();
        let Some(policy) = policy else { continue }; // not a table: parse() says so
        let keeps_all = match policy.get("cache") {
            None => true,
            Some(toml::Value::String(s)) => s == "all" || s == "0",
            Some(toml::Value::Integer(n)) => *n == 0,
            Some(_) => false,
        };
        if keeps_all {
            policy.insert("cache".to_owned(), toml::Value::String(cache.to_owned()));
            bounded.push(name);
        }
    }
    bounded
}

/// A rate as a configuration file's period: integer nanoseconds.
fn period_of(hz: f64) -> anyhow::Result<toml::Value> {
    let ns = (1e9 / hz).round();
    if ns < 1.0 {
        bail!("{hz} Hz is faster than one sample a nanosecond");
    }
    Ok(toml::Value::String(format!("{ns:.0}")))
}

/// Sets `setting` of the `[[key]]` table whose `field` is `value`.
fn set(
    doc: &mut toml::Table,
    key: &str,
    (field, value): (&str, &str),
    setting: &str,
    to: toml::Value,
) -> anyhow::Result<()> {
    let table = doc
        .get_mut(key)
        .and_then(toml::Value::as_array_mut)
        .and_then(|list| {
            list.iter_mut().find(|t| t.get(field).and_then(toml::Value::as_str) == Some(value))
        })
        .and_then(toml::Value::as_table_mut)
        .with_context(|| format!("tutorial.toml has no {key} with {field} = `{value}`"))?;
    table.insert(setting.to_owned(), to);
    Ok(())
}

/// The system under test: its coordinator (a child of this process) and state
/// directory. Dropping it stops the system, so no exit path leaves it running.
struct System {
    domain: String,
    coordinator: Child,
    state: StateDir,
    stopped: bool,
}

impl System {
    fn start(domain: &str) -> anyhow::Result<Self> {
        // A state directory of its own, removed at the stop.
        let state = StateDir::at(std::env::temp_dir().join(format!("esgm-{domain}")));
        // Its own process group: a Ctrl-C reaches this process alone, which then stops
        // the system in order (and Drop does if this process unwinds).
        let coordinator =
            super::up::spawn_detached(domain, Some(state.path()), false, Stdio::inherit(), true)?;
        Ok(System { domain: domain.to_owned(), coordinator, state, stopped: false })
    }

    /// Applies the plan and samples once a second for the run's length (or until
    /// `stop`): the samples, and every shared-memory file seen mapped.
    fn soak(
        &mut self,
        plan: &Plan,
        settings: &Settings,
        stop: &Arc<AtomicBool>,
    ) -> anyhow::Result<(Vec<Sample>, BTreeSet<PathBuf>)> {
        config::apply::apply(&self.domain, plan, &mut |_| {})?;
        let esgm = crate::session::connect(&self.domain)?;
        // After the connection: iceoryx2 takes SIGINT and SIGTERM for itself when this
        // process's first node is made, and would swallow a Ctrl-C.
        let flag = Arc::clone(stop);
        ctrlc::set_handler(move || flag.store(true, Ordering::Release))
            .context("cannot catch Ctrl-C")?;
        let mut probe = Probe { esgm, coordinator: self.coordinator.id(), seen: BTreeSet::new() };
        let start = Instant::now();
        let mut samples = Vec::new();
        let ticks = settings.run_for.as_secs();
        for tick in 0..=ticks {
            // Sleep to the tick in small steps, so a Ctrl-C is seen at once.
            let due = start + Duration::from_secs(tick);
            while Instant::now() < due && !stop.load(Ordering::Acquire) {
                std::thread::sleep(due.saturating_duration_since(Instant::now()).min(STEP));
            }
            if stop.load(Ordering::Acquire) {
                break;
            }
            if Instant::now() > due + Duration::from_secs(1) {
                continue; // the last sample took more than a second: skip to the next
            }
            let s = probe.sample(start.elapsed().as_secs_f64());
            if tick % 60 == 0 || tick == ticks {
                progress(&s);
            }
            samples.push(s);
        }
        Ok((samples, probe.seen))
    }

    /// Stops the system (as `esgm demo` does), once.
    fn stop(&mut self) -> anyhow::Result<()> {
        if std::mem::replace(&mut self.stopped, true) {
            return Ok(());
        }
        super::demo::stop(&self.domain, &mut self.coordinator, &self.state)
    }
}

impl Drop for System {
    fn drop(&mut self) {
        if let Err(e) = self.stop() {
            eprintln!("esgm: cannot stop `{}`: {e:#}", self.domain);
        }
    }
}

/// How often a waiting soak looks for Ctrl-C.
const STEP: Duration = Duration::from_millis(100);

/// Takes the samples.
struct Probe {
    esgm: ShmEsgm,
    coordinator: u32,
    /// Every `/dev/shm` file a process of the domain was seen to map.
    seen: BTreeSet<PathBuf>,
}

impl Probe {
    fn sample(&mut self, t: f64) -> Sample {
        let mut s = Sample { t, ..Sample::default() };
        let mut gap = |what: &str, e: &dyn std::fmt::Display| s.gaps.push(format!("{what}: {e}"));
        let load = probe::load_average().map_err(|e| gap("load average", &format!("{e:#}")));

        let mut pids = vec![("coordinator".to_owned(), self.coordinator, 0)];
        match self.esgm.control(Request::ListProcesses) {
            Ok(Response::Processes(list)) => {
                for p in list {
                    match p.status.pid {
                        Some(pid) => pids.push((p.spec.name, pid, p.status.restarts)),
                        None => gap(&p.spec.name, &"not running"),
                    }
                }
            }
            Ok(other) => gap("processes", &format!("unexpected answer {other:?}")),
            Err(e) => gap("processes", &e),
        }
        let mut files = BTreeSet::new();
        // The soak's own connection is a process of the domain too.
        match probe::mapped_shm(std::process::id()) {
            Ok(f) => files.extend(f),
            Err(e) => gap("this process's mappings", &format!("{e:#}")),
        }
        let mut processes = std::collections::BTreeMap::new();
        for (name, pid, restarts) in pids {
            let memory = probe::resident(pid).and_then(|m| Ok((m, probe::mapped_shm(pid)?)));
            match memory {
                Ok((m, mapped)) => {
                    files.extend(mapped);
                    let p = ProcessSample { pid, rss: m.rss, anon: m.anon, restarts };
                    processes.insert(name, p);
                }
                Err(e) => gap(&name, &format!("{e:#}")),
            }
        }
        let shm = probe::usage(&files).map_err(|e| gap("shared memory", &format!("{e:#}")));
        let host = probe::host_iceoryx2().map_err(|e| gap("/dev/shm", &format!("{e:#}")));
        let stats = self.esgm.domain_stats().map_err(|e| gap("trajectory counters", &e));
        // Each failure is in `gaps` (`gap` above). The load and the host's files are
        // context the verdict never judges; a failed shared-memory figure is marked.
        s.load = load.unwrap_or_default();
        s.processes = processes;
        s.shm_failed = shm.is_err();
        // Zero only with `shm_failed` set: the verdict counts it as a failed check.
        s.shm = shm.unwrap_or_default();
        // Context only; its failure is in `gaps`.
        s.host_iceoryx2 = host.unwrap_or_default();
        if let Ok(stats) = stats {
            s.trajectories =
                stats.trajectories.iter().map(|(n, r)| (n.clone(), Counts::of(r))).collect();
        }
        self.seen.extend(files);
        s
    }
}

/// One line a minute while the run goes on.
fn progress(s: &Sample) {
    let rss: u64 = s.processes.values().map(|p| p.rss).sum();
    let added: u64 = s.trajectories.values().map(|c| c.added).sum();
    let lost: u64 = s.trajectories.values().flat_map(|c| &c.losses).map(|l| l.count).sum();
    println!(
        "  {:>5.0} s  rss {:>7.1} MiB in {} processes  shm {:>7.1} MiB in {} files  added {added}  lost {lost}  load {:.2}{}",
        s.t,
        mib(rss),
        s.processes.len(),
        mib(s.shm.allocated),
        s.shm.files,
        s.load[0],
        if s.gaps.is_empty() { String::new() } else { format!("  ({} gaps)", s.gaps.len()) }
    );
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// What of the domain is still there after the stop: processes that were sampled and
/// still run, iceoryx2 nodes of the domain, and shared-memory files its processes
/// mapped. A failure to look counts as something left (never assume "none").
fn left_behind(domain: &str, seen: &BTreeSet<PathBuf>, samples: &[Sample]) -> Vec<String> {
    let pids: BTreeSet<(String, u32)> =
        samples.iter().flat_map(|s| s.processes.iter().map(|(n, p)| (n.clone(), p.pid))).collect();
    left_behind_of(domain, seen, pids)
}

/// What of `domain` is still there: which of the named `pids` still run, its iceoryx2
/// nodes, and which of the `seen` shared-memory files exist (`esgm scale` checks the
/// same).
pub(super) fn left_behind_of(
    domain: &str,
    seen: &BTreeSet<PathBuf>,
    pids: BTreeSet<(String, u32)>,
) -> Vec<String> {
    let mut left = Vec::new();
    for (name, pid) in pids {
        if crate::supervise::alive(pid) {
            left.push(format!("process {name} (pid {pid})"));
        }
    }
    match nodes_of(domain) {
        Ok(nodes) => left.extend(nodes.into_iter().map(|(n, _)| format!("iceoryx2 node {n}"))),
        Err(e) => left.push(format!("iceoryx2 nodes (cannot list them: {e})")),
    }
    left.extend(probe::still_present(seen).into_iter().map(|p| format!("file {}", p.display())));
    left
}

/// Copies the files of `from` into `to` (created).
pub(super) fn copy_dir(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("cannot create {}", to.display()))?;
    for entry in
        std::fs::read_dir(from).with_context(|| format!("cannot list {}", from.display()))?
    {
        let path = entry?.path();
        if let Some(name) = path.file_name() {
            std::fs::copy(&path, to.join(name))
                .with_context(|| format!("cannot copy {}", path.display()))?;
        }
    }
    Ok(())
}

/// Prints the verdict.
fn print(v: &Verdict, samples: &[Sample], left_behind: &[String]) {
    let load = samples.last().map_or([0.0; 3], |s| s.load);
    println!(
        "\nmemory from {:.0} s to {:.0} s (target: growth under {} %), load average {:.2} {:.2} {:.2}",
        v.baseline_t, v.end_t, v.target_percent, load[0], load[1], load[2]
    );
    println!(
        "  {:<28} {:>12} {:>12} {:>12} {:>9}   (private memory alone)",
        "", "baseline MiB", "end MiB", "peak MiB", "growth"
    );
    for g in v.rss.iter().chain(&v.shm) {
        let private = v.anon.iter().find(|a| a.what == g.what);
        println!(
            "  {:<28} {:>12.2} {:>12.2} {:>12.2} {:>8.2}% {:<6} {}",
            g.what,
            mib(g.baseline),
            mib(g.end),
            mib(g.peak),
            g.percent,
            if g.within { "ok" } else { "MISSED" },
            private.map_or(String::new(), |a| format!(
                "({:.2} MiB, {:+.2} %)",
                mib(a.end),
                a.percent
            ))
        );
    }
    println!("\n  {:<28} {:>12} {:>10} {:>10}", "trajectory", "added", "rate Hz", "stored");
    for f in &v.trajectories {
        println!("  {:<28} {:>12} {:>10.1} {:>10}", f.trajectory, f.added, f.rate_hz, f.stored);
    }
    if v.losses.is_empty() {
        println!("\nlosses: none");
    } else {
        println!("\nlosses by cause");
        for l in &v.losses {
            let kind = if l.loss.explained { "explained" } else { "UNEXPLAINED" };
            println!("  {:<20} {:<24} {:>10}  {kind}", l.trajectory, l.loss.cause, l.loss.count);
        }
    }
    let gaps: usize = samples.iter().map(|s| s.gaps.len()).sum();
    if gaps > 0 {
        let first = samples.iter().flat_map(|s| &s.gaps).next();
        println!("\n{gaps} measurements failed (first: {})", first.map_or("", String::as_str));
    }
    for thing in left_behind {
        println!("LEFT BEHIND: {thing}");
    }
    if v.passed() {
        println!("\nverdict: every target met ({} unexplained losses)", v.unexplained);
    } else {
        println!("\nverdict: {} targets missed", v.missed.len());
        for m in &v.missed {
            println!("  - {m}");
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use clap::Parser;
    use esgm_core::CacheConstraint;

    use super::*;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn settings(argv: &[&str]) -> anyhow::Result<Settings> {
        let cli = Cli::try_parse_from(std::iter::once("soak").chain(argv.iter().copied()))?;
        Settings::new(&cli.args)
    }

    #[test]
    fn arguments_become_settings() {
        let s = settings(&[]).unwrap();
        assert_eq!((s.run_for, s.warmup, s.check), (Duration::from_secs(600), 60.0, true));
        let s = settings(&["--seconds", "5", "--no-check"]).unwrap();
        assert_eq!((s.run_for, s.warmup, s.check), (Duration::from_secs(5), 2.5, false));
        assert_eq!(settings(&["--minutes", "2"]).unwrap().run_for, Duration::from_secs(120));
        assert!(settings(&["--minutes", "2", "--seconds", "3"]).is_err());
        assert!(settings(&["--seconds", "0"]).is_err());
        assert!(settings(&["--camera-hz", "nan"]).is_err());
    }

    #[test]
    fn the_plan_runs_the_tutorial_at_the_soak_settings() {
        let (plan, bounded) = plan(&settings(&[]).unwrap()).unwrap();
        let robot = plan.workers.iter().find(|w| w.what.spec.name.contains("robot")).unwrap();
        let period = robot.what.spec.args.iter().skip_while(|a| *a != "--period").nth(1);
        assert_eq!(period.map(String::as_str), Some("1ms"));
        let images = plan.trajectories.iter().find(|t| t.what.spec.name == "images").unwrap();
        let esgm_core::esgm::TrajectorySource::Sampled { sample_period, .. } =
            images.what.spec.source
        else {
            panic!("images is not sampled: {:?}", images.what.spec.source);
        };
        assert_eq!(sample_period, 33_333_333);
        // The trajectories that keep every sample keep 10 s; the others their bound.
        assert_eq!(bounded, ["blobs", "current_blob", "driving_direction"]);
        let cache = |name: &str| {
            plan.trajectories
                .iter()
                .find(|t| t.what.spec.name == name)
                .unwrap()
                .what
                .spec
                .policy
                .cache
        };
        assert_eq!(cache("driving_direction"), CacheConstraint::Duration(10_000_000_000));
        assert_eq!(cache("robot_state"), CacheConstraint::Elements(600));
        let (file, bounded) = super::plan(&settings(&["--cache", "all"]).unwrap()).unwrap();
        assert!(bounded.is_empty());
        let all = file.trajectories.iter().find(|t| t.what.spec.name == "blobs").unwrap();
        assert_eq!(all.what.spec.policy.cache, CacheConstraint::All);
    }
}
