//! `esgm record`: a running system's trajectories into an MCAP file.
//!
//! Stops after `--duration`, on Ctrl-C or SIGTERM, or when the system stops, and
//! prints a summary: per trajectory, what was recorded and what was missed, with the
//! cause. The file is flushed at least every `--flush` (default 1 s), so a recorder
//! killed outright loses at most that much.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::Esgm;
use esgm_core::clock::{Clock, SystemClock};
use esgm_recording::recorder::DEFAULT_BUFFER;
use esgm_recording::{Compression, RecordOptions, Recorder, RecorderStats, RecordingWriter};

use crate::session::connect;

/// `esgm record` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The file to write (`.mcap`); with --ros2, the bag's directory (new, or empty).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Trajectories to record, by name; `*` and `?` match any characters.
    #[arg(value_name = "TRAJECTORY")]
    pub trajectories: Vec<String>,
    /// Record every trajectory of the system.
    #[arg(long, conflicts_with = "trajectories")]
    pub all: bool,
    /// Chunk compression: zstd, lz4 or none.
    #[arg(long, default_value = "zstd")]
    pub compression: Compression,
    /// Stop after this long (`30s`, `5m`); default: until Ctrl-C.
    #[arg(long, value_parser = humantime::parse_duration)]
    pub duration: Option<Duration>,
    /// Start a new file when the current one reaches this many MiB.
    #[arg(long, value_name = "MIB")]
    pub split_size: Option<u64>,
    /// Start a new file after this long (`10m`).
    #[arg(long, value_parser = humantime::parse_duration)]
    pub split_duration: Option<Duration>,
    /// Flush at least this often: what a killed recorder can lose at most.
    #[arg(long, default_value = "1s", value_parser = humantime::parse_duration)]
    pub flush: Duration,
    /// Chunk size in KiB.
    #[arg(long, default_value_t = 4096)]
    pub chunk_kib: u64,
    /// Do not write the JSON views of structured trajectories (Foxglove then shows
    /// only images; the file is smaller).
    #[arg(long)]
    pub no_views: bool,
    /// Write a rosbag2 directory: `OUTPUT/OUTPUT_0.mcap` with only ROS 2 profile
    /// channels (`ros2msg` schemas, CDR messages, topics `/<trajectory>`) and the
    /// `metadata.yaml` rosbag2 writes, so `ros2 bag`, rosbags and Foxglove read it as
    /// theirs; images as `sensor_msgs/msg/Image`, other types as their `esgm_msgs`
    /// messages (`esgm ros2 msg TYPE`).
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: also keep esgm's lossless recording (every structure exactly, the
    /// events) beside the bag's files, in `OUTPUT/lossless/`, which rosbag2 ignores and
    /// esgm's info, replay, load and compare prefer.
    #[arg(long, requires = "ros2")]
    pub lossless: bool,
    /// Wait for the named trajectories to exist (a replay or a system starting up)
    /// instead of refusing names that do not exist yet, and record what each holds
    /// already (the structures written before the recorder subscribed, up to
    /// --buffer of them), then everything after.
    #[arg(long)]
    pub wait: bool,
    /// Structures buffered per trajectory before the recorder drops (and counts) one.
    #[arg(long, default_value_t = DEFAULT_BUFFER)]
    pub buffer: usize,
}

/// Records until a stop condition, then prints the summary.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let existing = || -> anyhow::Result<Vec<String>> {
        Ok(esgm.trajectories()?.into_iter().map(|t| t.name).collect())
    };
    if a.wait {
        let give_up = a.duration.map(|d| Instant::now() + d);
        // Names with patterns wait for one match each; --all for any trajectory.
        while select(&existing()?, a).is_err() {
            if give_up.is_some_and(|g| Instant::now() >= g) {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    let names = select(&existing()?, a)?;
    let options = RecordOptions::default()
        .compression(a.compression)
        .chunk_size(a.chunk_kib.saturating_mul(1024))
        .flush_interval(a.flush)
        .split_bytes(a.split_size.map(|m| m.saturating_mul(1 << 20)))
        .split_duration(a.split_duration)
        .views(!a.no_views)
        .bag(a.ros2)
        .meta("domain", domain)
        .meta("started_unix_ns", SystemClock.now().to_string());
    let start = |path: &std::path::Path, options: RecordOptions| -> anyhow::Result<Recorder> {
        let writer = RecordingWriter::create(path, options)
            .with_context(|| format!("cannot record into {}", path.display()))?;
        // Waited for: what was written between a trajectory's creation and this
        // subscription is in its cache, and belongs to the recording.
        Ok(if a.wait {
            Recorder::start_with_held(&esgm, &names, writer, a.buffer)?
        } else {
            Recorder::start(&esgm, &names, writer, a.buffer)?
        })
    };
    let recorder = start(&a.output, options.clone())?;
    // The lossless recording beside the bag: a recorder of its own, reading the same
    // structures (images in place, not copied).
    let lossless = if a.lossless {
        let dir = a.output.join(esgm_recording::rosbag2::LOSSLESS_DIR);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let name = a
            .output
            .file_name()
            .map_or_else(|| "recording".into(), |n| n.to_string_lossy().into_owned());
        Some(start(&dir.join(format!("{name}.mcap")), options.bag(false).ros2(false))?)
    } else {
        None
    };
    if !json {
        eprintln!(
            "recording {} trajector{} of `{domain}` into {} (Ctrl-C stops)",
            names.len(),
            if names.len() == 1 { "y" } else { "ies" },
            a.output.display()
        );
    }

    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&interrupted);
    ctrlc::set_handler(move || flag.store(true, Ordering::Release))
        .context("cannot install the Ctrl-C handler")?;
    let started = Instant::now();
    let until = a.duration.map(|d| started + d);
    let mut last_ping = Instant::now();
    let mut progress = crate::progress::RecordProgress::start(json, &a.output);
    let why = loop {
        std::thread::sleep(Duration::from_millis(50));
        progress.tick(|| recorder.stats());
        if interrupted.load(Ordering::Acquire) {
            break "interrupted";
        }
        if until.is_some_and(|u| Instant::now() >= u) {
            break "duration reached";
        }
        if recorder.failed() || lossless.as_ref().is_some_and(Recorder::failed) {
            break "writing failed";
        }
        if last_ping.elapsed() > Duration::from_secs(1) {
            last_ping = Instant::now();
            if !esgm.ping() {
                break "the system stopped";
            }
        }
    };
    progress.finish();
    let (summary, stats) = recorder.stop()?;
    let lossless = lossless.map(Recorder::stop).transpose()?;
    for name in &summary.left_out {
        eprintln!(
            "esgm: `{name}` is not in the bag: its type has no ROS 2 message{}",
            if lossless.is_some() { " (it is in the lossless recording)" } else { "" }
        );
    }
    let seconds = started.elapsed().as_secs_f64();
    if json {
        println!(
            "{}",
            serde_json::json!({ "stopped": why, "seconds": seconds, "files": summary.files,
                "trajectories": stats.trajectories, "view_bytes": summary.view_bytes,
                "lossless_bytes": summary.lossless_bytes, "left_out": summary.left_out,
                "lossless_files": lossless.as_ref().map(|(s, _)| &s.files) })
        );
    } else {
        print_summary(why, seconds, &summary.files, &stats, &summary);
        if let Some((s, _)) = &lossless {
            for f in &s.files {
                println!("lossless: {}", f.display());
            }
        }
    }
    Ok(())
}

/// The trajectories the arguments name (patterns expanded), each checked to exist.
fn select(all: &[String], a: &Args) -> anyhow::Result<Vec<String>> {
    if a.all {
        if all.is_empty() {
            bail!("the system has no trajectories to record");
        }
        return Ok(all.to_vec());
    }
    if a.trajectories.is_empty() {
        bail!("name the trajectories to record, or give --all");
    }
    let mut out: Vec<String> = Vec::new();
    for pattern in &a.trajectories {
        let matched: Vec<&String> = all.iter().filter(|n| glob_match(pattern, n)).collect();
        if matched.is_empty() {
            let hint =
                esgm_core::type_registry::closest_name(pattern, all.iter().map(String::as_str))
                    .map(|c| format!("; did you mean `{c}`?"))
                    .unwrap_or_default();
            bail!("no trajectory matches `{pattern}`{hint}");
        }
        for m in matched {
            if !out.contains(m) {
                out.push(m.clone());
            }
        }
    }
    Ok(out)
}

/// `*` matches any run of characters, `?` any one; everything else itself.
fn glob_match(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    let (mut pi, mut ni, mut star, mut mark) = (0, 0, None, 0);
    while ni < n.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == n[ni]) {
            pi += 1;
            ni += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ni;
            pi += 1;
        } else if let Some(s) = star {
            pi = s + 1;
            mark += 1;
            ni = mark;
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|c| *c == '*')
}

fn print_summary(
    why: &str,
    seconds: f64,
    files: &[PathBuf],
    stats: &RecorderStats,
    summary: &esgm_recording::WriteSummary,
) {
    println!("stopped: {why} after {seconds:.1} s");
    for f in files {
        println!("file: {}", f.display());
    }
    println!(
        "{:<24} {:>10} {:>10} {:>10} {:>10} {:>12}",
        "trajectory", "recorded", "overflow", "lost", "violations", "MiB"
    );
    for (name, c) in &stats.trajectories {
        let bytes = summary.lossless_bytes.get(name).copied().unwrap_or(0)
            + summary.view_bytes.get(name).copied().unwrap_or(0);
        println!(
            "{name:<24} {:>10} {:>10} {:>10} {:>10} {:>12.2}",
            c.recorded,
            c.recorder_overflow,
            c.lost,
            c.violations,
            bytes as f64 / (1 << 20) as f64
        );
    }
    let missed = stats.missed();
    if missed > 0 {
        println!(
            "MISSED {missed} structures (see the causes above; they are in the file's esgm-events channel)"
        );
    } else {
        println!("nothing missed");
    }
}

#[cfg(test)]
mod tests {
    use super::glob_match;

    #[test]
    fn globs() {
        assert!(glob_match("*", "images"));
        assert!(glob_match("im*", "images"));
        assert!(glob_match("*blob*", "current_blob"));
        assert!(glob_match("blob?", "blobs"));
        assert!(!glob_match("blob?", "blob"));
        assert!(!glob_match("robot", "robot_state"));
        assert!(glob_match("robot_state", "robot_state"));
    }
}
