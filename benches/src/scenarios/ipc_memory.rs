//! `memory`: resident memory of the coordinator and of the processes of a trajectory
//! after 10^6 small structures under a cache of 1,000 — it should stay flat — and the
//! shared memory a trajectory uses.
//!
//! Peers: a coordinator, a writer and a reader, each an `esgm-bench` peer connected
//! with [`esgm_shm::connect`]. The writer creates a primitive `RobotState` trajectory
//! with cache constraint `Elements(1000)` and adds 10^6 structures as fast as it can;
//! the reader follows it through its local replica (the way a unit in another process
//! reads). At 10^5 and at 10^6 structures each reports its own `VmRSS` from
//! `/proc/<pid>/status` (and how much of it is heap and how much mapped shared
//! memory); the writer reports the coordinator's too. The results go to the report's
//! `memory` section, not to the latency rows.
//!
//! Shared memory per trajectory: iceoryx2 0.10 keeps every segment of a service as a
//! file under `/dev/shm` (`iox2_…`; its static configs are small files under
//! `/tmp/iceoryx2`). The writer lists `/dev/shm` just before creating the trajectory
//! and again after adding to it; the files that appeared are the trajectory's data,
//! wake-up and violations services, its writer's and readers' ports and the
//! connections between them. Reported are their sizes (mapped) and the tmpfs blocks
//! in use (committed), for the small trajectory and for an image trajectory (640×480
//! RGB, cache 5) created after it.

use std::collections::HashMap;
use std::os::unix::fs::MetadataExt;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::{CacheConstraint, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, Time};
use esgm_shm::{ShmEsgm, unique_domain};

use super::inproc_echo::Payload;
use super::inproc_hop_image::Frames;
use super::ipc_payload::Kind;
use super::ipc_pipeline::{coordinator, shutdown, spawn_coordinator};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, MemoryRow};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "memory";
const SMALL: &str = "small";
const IMAGES: &str = "images";
const CACHE: usize = 1_000;
const IMAGE_CACHE: usize = 5;
const IMAGES_ADDED: u64 = 50;
/// How long any peer may take.
const PATIENCE: Duration = Duration::from_secs(300);
/// How long the reader's replica may stand still before it is reported as stalled.
const STALLED: Duration = Duration::from_secs(5);
/// How long the writer waits for the reader to see its last structure.
const READER_PATIENCE: Duration = Duration::from_secs(120);

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct Memory;

impl Scenario for Memory {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "resident memory of coordinator, writer and reader after 10^5 and 10^6 small \
         structures (cache 1,000), and /dev/shm use per trajectory (the memory section)"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        // A debug build (the CI smoke run) adds a tenth.
        let total: u64 = if ctx.is_quick() { 100_000 } else { 1_000_000 };
        let domain = unique_domain("esgm-bench-mem");
        let coord = spawn_coordinator(ctx, NAME, &domain)?;
        let writer = ctx.spawn_peer_process_as(
            NAME,
            WaitMode::SpinThenBlock,
            &domain,
            Some(&format!("writer:{}:{total}", coord.id())),
        )?;
        let reader = ctx.spawn_peer_process_as(
            NAME,
            WaitMode::SpinThenBlock,
            &domain,
            Some(&format!("reader:{total}")),
        )?;
        let written = writer.finish(PATIENCE);
        let read = reader.finish(PATIENCE);
        shutdown(&domain);
        let stopped = coord.finish(Duration::from_secs(15));
        for line in written?.into_iter().chain(read?) {
            if let Some(row) = parse(&line) {
                ctx.record_memory(row);
            }
        }
        stopped?;
        Ok(Vec::new())
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        let arg = role.arg.as_deref().unwrap_or_default();
        let parts: Vec<&str> = arg.split(':').collect();
        match parts.as_slice() {
            ["coordinator"] => coordinator(&role.domain),
            ["writer", pid, total] => write(&role.domain, pid.parse()?, total.parse()?),
            ["reader", total] => read(&role.domain, total.parse()?),
            _ => bail!("unknown memory peer {arg:?}"),
        }
    }
}

/// `mem <name> <after> <bytes> <mapped|-> <note…>` → a row.
fn parse(line: &str) -> Option<MemoryRow> {
    let mut w = line.splitn(6, ' ');
    if w.next()? != "mem" {
        return None;
    }
    let name = w.next()?.to_owned();
    let after_structures = w.next()?.parse().ok()?;
    let bytes = w.next()?.parse().ok()?;
    let mapped_bytes = w.next()?.parse().ok();
    let note = w.next().unwrap_or_default().to_owned();
    Some(MemoryRow { name, after_structures, bytes, mapped_bytes, note })
}

fn connect(domain: &str, host: &str) -> anyhow::Result<ShmEsgm> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    ShmEsgm::builder()
        .domain(domain)
        .host(host)
        .connect()
        .with_context(|| format!("{host}: cannot reach the coordinator"))
}

/// The points at which memory is reported: a tenth of the way, and the end.
fn checkpoints(total: u64) -> [u64; 2] {
    [total / 10, total]
}

fn write(domain: &str, coordinator: u32, total: u64) -> anyhow::Result<Vec<String>> {
    let esgm = connect(domain, "bench-writer")?;
    let mut lines = Vec::new();
    let before = shm_files()?;
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(CACHE));
    let small = esgm.create_trajectory(
        TrajectorySpec::primitive(SMALL, Kind::Small.type_name()).policy(policy),
    )?;
    // Give the reader a moment to attach, so it sees the whole stream.
    std::thread::sleep(Duration::from_millis(500));
    let started = Instant::now();
    let marks = checkpoints(total);
    for i in 1..=total {
        let mut es = Kind::Small.make(i);
        es.valid_time = i as Time;
        es.create_time = i as Time;
        small.add(es).with_context(|| format!("adding structure {i}"))?;
        if marks.contains(&i) {
            lines.push(rss_line("writer-rss", i, std::process::id())?);
            lines.push(rss_line("coordinator-rss", i, coordinator)?);
            lines.push(shm_line(&format!("shm-small-cache{CACHE}"), i, &before)?);
        }
        if started.elapsed() > PATIENCE {
            bail!("the writer added only {i} structures in {} s", PATIENCE.as_secs());
        }
    }
    lines.push(format!(
        "mem writer-rate {total} {} - structures added per second (through esgm_shm::connect)",
        (total as f64 / started.elapsed().as_secs_f64()) as u64
    ));

    let before = shm_files()?;
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(IMAGE_CACHE));
    let images = esgm
        .create_trajectory(TrajectorySpec::primitive(IMAGES, Frames::TYPE_NAME).policy(policy))?;
    let mut frames = Frames;
    for i in 1..=IMAGES_ADDED {
        let mut es = frames.make(i);
        es.valid_time = i as Time;
        images.add(es).with_context(|| format!("adding image {i}"))?;
    }
    lines.push(shm_line(&format!("shm-image-cache{IMAGE_CACHE}"), IMAGES_ADDED, &before)?);
    // Stay (and keep publishing) until the reader has seen the last structure: a
    // writer that leaves takes its unread samples with it.
    let done = reader_done(domain);
    let waiting = Instant::now();
    while !done.exists() && waiting.elapsed() < READER_PATIENCE {
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = std::fs::remove_file(&done);
    Ok(lines)
}

/// The file the reader creates once it has seen every structure.
fn reader_done(domain: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("{domain}.reader-done"))
}

fn read(domain: &str, total: u64) -> anyhow::Result<Vec<String>> {
    let esgm = connect(domain, "bench-reader")?;
    let started = Instant::now();
    let small = loop {
        if let Ok(t) = esgm.get_entity_trajectory_structure(SMALL) {
            break t;
        }
        if started.elapsed() > PATIENCE {
            bail!("the trajectory {SMALL} was never created");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut lines = Vec::new();
    let mut marks = checkpoints(total).into_iter().peekable();
    let (mut seen, mut changed) = (0i64, Instant::now());
    while let Some(&mark) = marks.peek() {
        // The replica is fed on a thread of the connection; ask it what it holds.
        let latest = small.get_latest().map(|s| s.structure.valid_time()).unwrap_or(0);
        if latest != seen {
            (seen, changed) = (latest, Instant::now());
        }
        if latest as u64 >= mark {
            lines.push(rss_line("reader-rss", mark, std::process::id())?);
            marks.next();
            continue;
        }
        // A replica that stopped short (it lost the last samples) is reported as far as
        // it got, and says so.
        if seen > 0 && changed.elapsed() > STALLED {
            let line = rss_line("reader-rss", latest as u64, std::process::id())?;
            lines.push(format!(
                "{line}; STALLED: the replica's latest structure stayed {latest} of {mark} for {} s",
                STALLED.as_secs()
            ));
            break;
        }
        if started.elapsed() > PATIENCE {
            bail!("the reader saw only up to {latest} of {total}");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let done = reader_done(domain);
    std::fs::write(&done, b"done").with_context(|| format!("writing {}", done.display()))?;
    Ok(lines)
}

/// `VmRSS` of `pid`, with its parts in the note.
fn rss_line(name: &str, after: u64, pid: u32) -> anyhow::Result<String> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .with_context(|| format!("reading /proc/{pid}/status"))?;
    let field = |key: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|kb| kb.parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    };
    let (rss, anon, shmem, file) =
        (field("VmRSS:"), field("RssAnon:"), field("RssShmem:"), field("RssFile:"));
    Ok(format!(
        "mem {name} {after} {rss} - VmRSS of pid {pid}: heap and stacks {:.1} MiB, shared \
         memory {:.1} MiB, files {:.1} MiB",
        mib(anon),
        mib(shmem),
        mib(file)
    ))
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// Every `/dev/shm` file: (size, bytes committed).
fn shm_files() -> anyhow::Result<HashMap<String, (u64, u64)>> {
    let mut files = HashMap::new();
    for entry in std::fs::read_dir("/dev/shm").context("listing /dev/shm")? {
        let Ok(entry) = entry else { continue };
        let Ok(meta) = entry.metadata() else { continue };
        files.insert(
            entry.file_name().to_string_lossy().into_owned(),
            (meta.size(), meta.blocks() * 512),
        );
    }
    Ok(files)
}

/// The `/dev/shm` files that appeared since `before`, summed.
fn shm_line(
    name: &str,
    after: u64,
    before: &HashMap<String, (u64, u64)>,
) -> anyhow::Result<String> {
    let now = shm_files()?;
    let new: Vec<_> = now.iter().filter(|(f, _)| !before.contains_key(*f)).collect();
    let mapped: u64 = new.iter().map(|(_, (size, _))| size).sum();
    let committed: u64 = new.iter().map(|(_, (_, used))| used).sum();
    let largest = new.iter().map(|(_, (size, _))| *size).max().unwrap_or(0);
    Ok(format!(
        "mem {name} {after} {committed} {mapped} {} new /dev/shm files: {:.1} MiB mapped, \
         {:.1} MiB committed (largest file {:.1} MiB)",
        new.len(),
        mib(mapped),
        mib(committed),
        mib(largest)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_parse_into_rows() {
        let row = parse("mem writer-rss 100 2048 - VmRSS of pid 7").unwrap();
        assert_eq!((row.name.as_str(), row.after_structures, row.bytes), ("writer-rss", 100, 2048));
        assert_eq!(row.mapped_bytes, None);
        assert_eq!(row.note, "VmRSS of pid 7");
        let shm = parse("mem shm-small 5 10 20 three files").unwrap();
        assert_eq!(shm.mapped_bytes, Some(20));
        assert!(parse("something else").is_none());
    }
}
