//! `esgm demo`: the seed's tutorial (chapters 8–10) as separate processes — a
//! coordinator, a camera, a robot and three unit workers, supervised — driven from
//! this process as the seed's main program drives its ESGM.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::SyntheticScene;
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::{
    Entity, EntityTrajectoryStructure, Esgm, Sample, SubscribeOptions, Time, ValueApproximation,
    millis,
};
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ControlClient, Request};
use esgm_shm::{ShmEsgm, unique_domain};

use super::supervise::Supervisor;
use crate::session;
use crate::show::ms;

/// `esgm demo` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// How long the robot drives.
    #[arg(long, default_value_t = 6.0)]
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
}

/// The tutorial's trajectories in data-flow order.
const PIPELINE: [&str; 5] = ["robot_state", "images", "blobs", "current_blob", "driving_direction"];

const UNITS: [&str; 3] = ["BlobDetection", "BlobSelection", "DrivingDirection"];

/// Runs the demo; an inconsistent result is an error (exit 1).
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    if a.seconds.is_nan() || a.seconds <= 0.0 {
        bail!("--seconds must be positive, got {}", a.seconds);
    }
    if a.image_period_ms == 0 {
        bail!("--image-period-ms must be positive");
    }
    // A fresh system unless the user named one.
    let domain = if domain == "esgm" { unique_domain("demo") } else { domain.to_owned() };
    println!("esgm demo: the seed's tutorial as separate processes, domain `{domain}`");
    let mut coordinator = super::up::spawn_detached(&domain)?;
    let mut workers = Supervisor::default();
    let result = drive(&domain, a, &mut workers);

    // Shut down: the coordinator goes, the workers notice and leave, stale resources
    // of anything that died are cleaned.
    if let Ok(c) = ControlClient::connect(&domain, Duration::from_secs(2)) {
        let _ = c.call(&Request::Shutdown);
    }
    workers.wait_all(Duration::from_secs(10));
    let deadline = Instant::now() + Duration::from_secs(5);
    while coordinator.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    if coordinator.try_wait().ok().flatten().is_none() {
        let _ = coordinator.kill();
        let _ = coordinator.wait();
    }
    cleanup_dead_nodes();
    let restarts: u32 = workers.workers.iter().map(|w| w.restarts).sum();
    println!("\nstopped: coordinator and {} workers ({restarts} restarts)", workers.workers.len());
    result
}

fn drive(domain: &str, a: &Args, workers: &mut Supervisor) -> anyhow::Result<()> {
    let (seed, blobs) = (a.seed.to_string(), a.blobs.to_string());
    let d = ["--domain", domain];
    workers.start(
        "camera",
        &[&d[..], &["worker", "camera", "--seed", &seed, "--blobs", &blobs]].concat(),
    )?;
    for unit in UNITS {
        workers.start(unit, &[&d[..], &["worker", "unit", unit]].concat())?;
    }
    workers.start("robot", &[&d[..], &["worker", "robot"]].concat())?;
    for (name, pid) in workers.pids() {
        println!("  started {name:<17} pid {pid}");
    }

    let esgm = session::connect(domain)?;
    wait_until(workers, "the camera, the units and the robot", || {
        let sensors = esgm.sensors();
        let units = esgm.comp_units();
        sensors.iter().any(|(n, _)| n == "camera")
            && UNITS.iter().all(|u| units.iter().any(|(n, _, _)| n == u))
            && esgm.trajectories().iter().any(|t| t.name == "robot_state")
    })?;

    // The seed's main program: sample the camera, compute blobs, the current blob and
    // the driving direction. Each is written by the process that makes its data.
    let period = millis(i64::from(a.image_period_ms));
    esgm.create_entity_trajectory_structure("images", "camera", 0, 0, period, 0, 5)?;
    esgm.create_computed_entity_trajectory_structure("blobs", "BlobDetection", &["images"])?;
    let current_blob = esgm.create_computed_entity_trajectory_structure(
        "current_blob",
        "BlobSelection",
        &["blobs"],
    )?;
    let directions = esgm.create_computed_entity_trajectory_structure(
        "driving_direction",
        "DrivingDirection",
        &["robot_state", "current_blob"],
    )?;
    let robot_state = esgm.get_entity_trajectory_structure("robot_state")?;
    println!("\n  {:<18} {:<10} {:<17} source", "trajectory", "kind", "type");
    for name in PIPELINE {
        if let Some(i) = esgm.trajectories().into_iter().find(|i| i.name == name) {
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
        workers.poll();
        let Ok(s) = sub.recv_timeout(Duration::from_millis(50)) else { continue };
        let t0 = *t0.get_or_insert(s.structure.valid_time);
        print_direction(&s, t0, &robot_state);
    }
    drop(sub);

    let latest = directions.get_latest().context("no driving direction was computed")?;
    let t0 = t0.unwrap_or(latest.structure.valid_time);
    queries(&directions, &latest, t0)?;
    stage_latencies(&esgm)?;
    check(a, &latest, &current_blob)
}

fn wait_until(
    workers: &mut Supervisor,
    what: &str,
    mut ready: impl FnMut() -> bool,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(30);
    while !ready() {
        workers.poll();
        if Instant::now() > deadline {
            bail!("{what} did not come up within 30 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

fn since(t0: Time, t: Time) -> f64 {
    (t - t0) as f64 / 1e9
}

fn print_direction(s: &Sample, t0: Time, robot_state: &impl EntityTrajectoryStructure) {
    let Ok(d) = DrivingDirection::from_structure(&s.structure) else { return };
    let heading = robot_state
        .get_closest_at_or_before(s.structure.valid_time)
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
fn stage_latencies(esgm: &ShmEsgm) -> anyhow::Result<()> {
    println!(
        "\nlatency of each stage (valid time -> added by its writer)\n  {:<18} {:>7} {:>11} {:>11}",
        "trajectory", "samples", "p50 ms", "p99 ms"
    );
    for name in PIPELINE {
        let t = esgm.get_entity_trajectory_structure(name)?;
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
