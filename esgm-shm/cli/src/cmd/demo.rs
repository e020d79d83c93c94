//! `esgm demo`: the seed's tutorial (chapters 8–10) as separate processes — a
//! coordinator, a camera, a robot and three unit workers, supervised — driven from
//! this process as the seed's main program drives its ESGM.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::SyntheticScene;
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::{
    Entity, EntityTrajectoryStructure, Esgm, InProcessTrajectory, Sample, SubscribeOptions, Time,
    ValueApproximation, millis,
};
use esgm_shm::control::protocol::{Request, Response};
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ProcessRecord, StateDir};
use esgm_shm::{ShmEsgm, unique_domain};

use crate::config::{self, Plan};
use crate::session;
use crate::show::ms;

/// `esgm demo` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// How long the robot drives.
    #[arg(long, default_value_t = 6.0, value_parser = crate::span_arg::seconds)]
    pub seconds: f64,
    /// Scene seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Blobs in the scene.
    #[arg(long, default_value_t = 3)]
    pub blobs: usize,
    /// Milliseconds between camera images.
    #[arg(long, default_value_t = 250)]
    pub image_period_ms: u32,
    /// Keep idle cores' wake-up within this many microseconds while the demo runs, as
    /// `esgm up --cpu-latency` does (needs root).
    #[arg(long, value_name = "MICROSECONDS", value_parser = esgm_shm::process::cpu_latency::parse_micros)]
    pub cpu_latency: Option<std::time::Duration>,
}

/// The tutorial's trajectories in data-flow order.
const PIPELINE: [&str; 5] = ["robot_state", "images", "blobs", "current_blob", "driving_direction"];

/// The system, as a configuration file (also shipped as an example of the format).
const TUTORIAL: &str = include_str!("../../tutorial.toml");

/// Runs the demo; an inconsistent result, or an image a process copied, is an error
/// (exit 1).
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    if a.seconds.is_nan() || a.seconds <= 0.0 {
        bail!("--seconds must be positive, got {}", a.seconds);
    }
    if a.image_period_ms == 0 {
        bail!("--image-period-ms must be positive");
    }
    let plan = plan(a)?;
    // A fresh system unless the user named one.
    let domain = if domain == "esgm" { unique_domain("demo") } else { domain.to_owned() };
    println!("esgm demo: the seed's tutorial as separate processes, domain `{domain}`");
    // A state directory of its own, removed at the end: the demo leaves nothing.
    let state = StateDir::at(std::env::temp_dir().join(format!("esgm-{domain}")));
    // The coordinator's log (worker restarts among it) goes to this terminal.
    let setup = super::up::Setup { cpu_latency: a.cpu_latency, ..super::up::Setup::default() };
    let mut coordinator = super::up::spawn_detached_with(
        &domain,
        Some(state.path()),
        &setup,
        Stdio::inherit(),
        false,
    )?;
    if let Some(latency) = a.cpu_latency {
        println!("idle cores wake within {} µs while the demo runs", latency.as_micros());
    }
    let result = drive(&domain, a, &plan);
    let processes: Vec<ProcessRecord> = match super::ps::processes(&domain) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("esgm: cannot list the demo's processes: {e:#}");
            Vec::new()
        }
    };

    stop(&domain, &mut coordinator, &state)?;
    let restarts: u32 = processes.iter().map(|p| p.status.restarts).sum();
    println!("\nstopped: coordinator and {} workers ({restarts} restarts)", processes.len());
    result
}

/// Stops a system this process started (`coordinator`, from
/// [`super::up::spawn_detached`], with its own `state` directory) and leaves nothing
/// of it: the coordinator goes, the workers notice and leave, `esgm up` waits for them
/// and cleans up after anything that died; a coordinator that does not stop within
/// 20 s is killed, the nodes of dead processes are cleaned and `state` is removed.
/// Also used by `esgm soak`.
pub fn stop(
    domain: &str,
    coordinator: &mut std::process::Child,
    state: &StateDir,
) -> anyhow::Result<()> {
    if let Err(e) = super::up::shutdown(domain) {
        eprintln!("esgm: {e:#}");
    }
    let stopped = wait_for_exit(coordinator, Duration::from_secs(20))?;
    if !stopped {
        eprintln!("esgm: the coordinator of `{domain}` did not stop within 20 s; killing it");
        coordinator.kill().context("cannot kill the coordinator")?;
        coordinator.wait().context("cannot reap the coordinator")?;
    }
    let cleaned = cleanup_dead_nodes().context("cannot list nodes to clean up")?;
    if cleaned.removed > 0 {
        println!("cleaned up after {} processes that did not leave", cleaned.removed);
    }
    cleaned.log(esgm_shm::CleanupReporter::Owner);
    esgm_shm::wake_word::remove_domain(domain);
    if let Err(e) = std::fs::remove_dir_all(state.path()) {
        eprintln!("esgm: cannot remove {}: {e}", state.path().display());
    }
    Ok(())
}

/// Waits up to `limit` for `child` to exit; true if it did.
fn wait_for_exit(child: &mut std::process::Child, limit: Duration) -> anyhow::Result<bool> {
    let deadline = Instant::now() + limit;
    loop {
        if child.try_wait().context("cannot wait for the coordinator")?.is_some() {
            return Ok(true);
        }
        if Instant::now() >= deadline {
            return Ok(false);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The tutorial's configuration file with the demo's settings.
fn plan(a: &Args) -> anyhow::Result<Plan> {
    let mut doc: toml::Table = toml::from_str(TUTORIAL).context("tutorial.toml")?;
    let section = |doc: &mut toml::Table, key: &str, name: &str| -> anyhow::Result<toml::Table> {
        doc.get(key)
            .and_then(toml::Value::as_array)
            .and_then(|list| {
                list.iter().find(|t| t.get("name").and_then(toml::Value::as_str) == Some(name))
            })
            .and_then(toml::Value::as_table)
            .cloned()
            .with_context(|| format!("tutorial.toml has no {key} `{name}`"))
    };
    let mut camera = section(&mut doc, "sensor", "camera")?;
    camera.insert("seed".into(), toml::Value::Integer(i64::try_from(a.seed).context("--seed")?));
    camera.insert("blobs".into(), toml::Value::Integer(i64::try_from(a.blobs).context("--blobs")?));
    let mut images = section(&mut doc, "trajectory", "images")?;
    images.insert("period".into(), toml::Value::String(format!("{}ms", a.image_period_ms)));
    for (key, table) in [("sensor", camera), ("trajectory", images)] {
        if let Some(list) = doc.get_mut(key).and_then(toml::Value::as_array_mut) {
            for t in list.iter_mut() {
                if t.get("name") == table.get("name") {
                    *t = toml::Value::Table(table.clone());
                }
            }
        }
    }
    Ok(config::parse("tutorial.toml", &toml::to_string(&doc)?, Path::new("."))?)
}

fn drive(domain: &str, a: &Args, plan: &Plan) -> anyhow::Result<()> {
    // The seed's main program, declared: the camera, the units and the robot run in
    // processes `esgm up` keeps alive; each trajectory is written by the process that
    // makes its data.
    config::apply::apply(domain, plan, &mut |_| {})?;
    for p in super::ps::processes(domain)? {
        let pid = p.status.pid.map_or_else(|| "-".to_owned(), |p| p.to_string());
        println!("  started {:<24} pid {pid}", p.spec.name);
    }

    let esgm = session::connect(domain)?;
    // Read every stage from the start (replicas fill as the writers publish), for the
    // latency table at the end.
    let stages = PIPELINE
        .iter()
        .map(|name| esgm.get_entity_trajectory_structure(name))
        .collect::<Result<Vec<_>, _>>()?;
    let directions = esgm.get_entity_trajectory_structure("driving_direction")?;
    let current_blob = esgm.get_entity_trajectory_structure("current_blob")?;
    let robot_state = esgm.get_entity_trajectory_structure("robot_state")?;
    println!("\n  {:<18} {:<10} {:<17} source", "trajectory", "kind", "type");
    for name in PIPELINE {
        if let Some(i) = esgm.trajectories()?.into_iter().find(|i| i.name == name) {
            let source = match (&i.source, i.inputs.as_slice()) {
                (Some(s), []) => s.clone(),
                (Some(s), inputs) => format!("{s}({})", inputs.join(", ")),
                (None, _) => "pushed (robot process)".to_owned(),
            };
            println!("  {:<18} {:<10} {:<17} {source}", i.name, i.kind.name(), i.type_name);
        }
    }

    println!(
        "\ndriving_direction as it changes (subscribed from this process)\n  {:>7}  {:>11}  {:>9}  {:>8}  {:>8}",
        "t [s]", "robot [deg]", "dir [deg]", "speed", "lag [ms]"
    );
    let sub = directions.subscribe(SubscribeOptions::default())?;
    let start = Instant::now();
    let run_for = Duration::from_secs_f64(a.seconds);
    let mut t0 = None;
    while start.elapsed() < run_for {
        let Ok(s) = sub.recv_timeout(Duration::from_millis(50)) else { continue };
        let t0 = *t0.get_or_insert(s.structure.valid_time);
        print_direction(&s, t0, &robot_state);
    }
    drop(sub);

    let latest = directions.get_latest().context("no driving direction was computed")?;
    let t0 = t0.unwrap_or(latest.structure.valid_time);
    queries(&directions, &latest, t0)?;
    stage_latencies(&stages)?;
    let copies = image_copies(&esgm)?;
    check(a, &latest, &current_blob)?;
    if copies > 0 {
        bail!(
            "the processes copied {copies} images; every image must cross processes in \
             shared memory, uncopied (the table above names who copied)"
        );
    }
    Ok(())
}

/// Prints, per process, the images it read and sent in shared memory, and the copies it
/// made (its last report to the coordinator, at most a second old); returns the copies
/// of all.
fn image_copies(esgm: &ShmEsgm) -> anyhow::Result<u64> {
    let Response::Holdings(list) = esgm.control(Request::ListHoldings)? else {
        bail!("the coordinator did not list the processes' images");
    };
    println!(
        "
images in shared memory, per process
  {:<30} {:>10} {:>14} {:>7}",
        "process", "read held", "sent in place", "copies"
    );
    let mut copies = 0;
    for (host, s) in list {
        if s.held_total + s.sent_in_place + s.copies() == 0 {
            continue;
        }
        copies += s.copies();
        println!("  {:<30} {:>10} {:>14} {:>7}", host, s.held_total, s.sent_in_place, s.copies());
    }
    println!("  image copies in all: {copies}");
    Ok(copies)
}

fn since(t0: Time, t: Time) -> f64 {
    (t - t0) as f64 / 1e9
}

fn print_direction(s: &Sample, t0: Time, robot_state: &impl EntityTrajectoryStructure) {
    let Ok(d) = DrivingDirection::from_structure(&s.structure) else { return };
    let heading = robot_state
        .get_closest_at_or_before(s.structure.valid_time)
        // No robot state yet (or not a `RobotState`): the heading prints as NaN.
        .ok()
        .and_then(|r| RobotState::from_structure(&r.structure).ok())
        .map_or(f64::NAN, |r| r.dir);
    println!(
        "  {:>7.3}  {:>11.2}  {:>9.2}  {:>8.2}  {:>8.2}",
        since(t0, s.structure.valid_time),
        heading,
        d.dir,
        d.speed,
        s.add_delay() as f64 / 1e6
    );
}

/// The seed's queries (10.2) on the driving direction.
fn queries(
    directions: &impl EntityTrajectoryStructure,
    latest: &Sample,
    t0: Time,
) -> anyhow::Result<()> {
    let show = |s: &Sample| match DrivingDirection::from_structure(&s.structure) {
        Ok(d) => format!(
            "t={:.3} s  dir {:>7.2} deg  speed {:.2}",
            since(t0, s.structure.valid_time),
            d.dir,
            d.speed
        ),
        Err(e) => format!("unreadable: {e}"),
    };
    println!("\nqueries on driving_direction (seed 10.2)");
    println!("  {:<52} {}", "get_latest", show(latest));
    let vt = latest.structure.valid_time;
    let between = directions.get_between(vt - 5_000_000_000, vt - 1_000_000_000)?;
    println!("  {:<52} {} samples", "get_between(latest - 5 s, latest - 1 s)", between.len());
    if let (Some(first), Some(last)) = (between.first(), between.last()) {
        println!("  {:<52} {}", "  first", show(first));
        println!("  {:<52} {}", "  last", show(last));
    }
    let label = "get_at_approximating(latest - 100 ms, most recent)";
    match directions.get_at_approximating(vt - millis(100), &ValueApproximation::MostRecent) {
        Ok(s) => println!("  {label:<52} {}", show(&s)),
        Err(e) => println!("  {label:<52} {e}"),
    }
    Ok(())
}

/// Valid → add time per stage, as carried in every sample from its writer.
fn stage_latencies(stages: &[InProcessTrajectory]) -> anyhow::Result<()> {
    println!(
        "\nlatency of each stage (valid time -> added by its writer)\n  {:<18} {:>7} {:>11} {:>11}",
        "trajectory", "samples", "p50 ms", "p99 ms"
    );
    for (name, t) in PIPELINE.iter().zip(stages) {
        let s = t.stats()?;
        println!(
            "  {:<18} {:>7} {:>11} {:>11}",
            name,
            s.added,
            ms(s.add_delay_p50),
            ms(s.add_delay_p99)
        );
    }
    Ok(())
}

/// The blob the last direction was computed from must be (one of) the largest discs
/// of the synthetic scene at that image's time: the scene is a pure function of seed
/// and time, so this process can rebuild it.
fn check(
    a: &Args,
    latest: &Sample,
    current_blob: &impl EntityTrajectoryStructure,
) -> anyhow::Result<()> {
    println!("\ncheck against the scene's ground truth");
    if a.blobs == 0 {
        println!("  no blobs in the scene: nothing to follow");
        return Ok(());
    }
    let scene = SyntheticScene::builder().blobs(a.blobs).seed(a.seed).create()?;
    let blob_sample = current_blob.get_closest_at_or_before(latest.structure.valid_time)?;
    let blob = Blob::from_structure(&blob_sample.structure)?;
    let truth = scene.truth(blob_sample.structure.valid_time);
    let largest = truth.iter().map(|b| b.size).max().unwrap_or(0);
    let near = |b: &Blob| (b.x - blob.x).abs() <= 3 && (b.y - blob.y).abs() <= 3;
    let matched = truth.iter().filter(|b| b.size * 10 >= largest * 9).any(near);
    println!(
        "  selected blob centre ({}, {}), {} px; largest disc {} px",
        blob.x, blob.y, blob.size, largest
    );
    if matched {
        println!("  consistent: the robot follows the largest blob");
        Ok(())
    } else {
        bail!("MISMATCH: the selected blob is not the largest disc of the scene")
    }
}
