//! The seed's tutorial (chapters 8–10, `esgm_tutorial.cc`) on the in-process runtime,
//! with real computations: a synthetic camera, blob detection, selection of the largest
//! blob, a driving direction toward it, and a simulated robot that follows it.
//!
//! ```text
//! cargo run --release --example tutorial -- [--seconds N] [--seed S] [--blobs N]
//!                                           [--image-period-ms MS]
//! ```
//!
//! The steps follow the seed's main program: types (predefined in esgm's library),
//! the pushed `robot_state` trajectory, the pulled `camera` sensor and the `images`
//! trajectory sampled from it, the three units and their computed trajectories, a
//! subscription printing each new driving direction, then the seed's queries. The
//! camera is fixed above the scene, not mounted on the robot, so the robot keeps
//! turning by the bearing of the blob: the check at the end compares the last
//! direction with the scene's ground truth, not with where the robot ends up.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::{CameraSensor, FrameSource, SyntheticScene};
use cu_workers::{DrivingDirectionUnit, register_tutorial_units};
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::prelude::*;
use esgm_core::{SharedClock, TIMEUNITS_PER_MILLI_SECOND, TIMEUNITS_PER_SECOND};
use robot_publisher::RobotPublisher;

const USAGE: &str =
    "usage: tutorial [--seconds N] [--seed S] [--blobs N] [--image-period-ms MS] [--shm]";

/// The robot's states may arrive this late (the seed's "small delay"): far more than an
/// in-process push takes, far less than the 100 ms between states.
const ROBOT_STATE_DELAY: Time = millis(50);
/// Robot states kept: a minute at 10 Hz.
const ROBOT_STATE_CACHE: i64 = 600;

/// The validated command line.
#[derive(Debug)]
struct Config {
    run_for: Duration,
    seed: u64,
    blobs: usize,
    image_period: Time,
    /// Run against shared memory (a coordinator and `esgm_shm::connect`) instead of
    /// the in-process runtime: the same code, the other runtime.
    shm: bool,
}

/// Parses `--flag value` pairs; `Ok(None)` means help was asked for.
fn parse_args(args: impl IntoIterator<Item = String>) -> anyhow::Result<Option<Config>> {
    let mut config = Config {
        run_for: Duration::from_secs(6),
        seed: 0,
        blobs: 3,
        image_period: TIMEUNITS_PER_SECOND,
        shm: false,
    };
    let mut args = args.into_iter();
    while let Some(flag) = args.next() {
        if flag == "-h" || flag == "--help" {
            return Ok(None);
        }
        if flag == "--shm" {
            config.shm = true;
            continue;
        }
        let value = args.next().with_context(|| format!("{flag} needs a value"))?;
        let number = || format!("{flag} takes a number, got `{value}`");
        match flag.as_str() {
            "--seconds" => {
                let seconds: f64 = value.parse().with_context(number)?;
                config.run_for = Duration::try_from_secs_f64(seconds)
                    .ok()
                    .filter(|d| !d.is_zero())
                    .with_context(|| format!("--seconds must be positive, got `{value}`"))?;
            }
            "--seed" => config.seed = value.parse().with_context(number)?,
            "--blobs" => config.blobs = value.parse().with_context(number)?,
            "--image-period-ms" => {
                let ms: u32 = value.parse().with_context(number)?;
                if ms == 0 {
                    bail!("--image-period-ms must be positive");
                }
                config.image_period = Time::from(ms) * TIMEUNITS_PER_MILLI_SECOND;
            }
            _ => bail!("unknown option `{flag}`"),
        }
    }
    Ok(Some(config))
}

/// Seconds from `t0` to `t`, for display.
fn since(t0: Time, t: Time) -> f64 {
    (t - t0) as f64 / TIMEUNITS_PER_SECOND as f64
}

/// The signed turn from heading `from` to heading `to` the short way, in (-180, 180]
/// degrees, counter-clockwise positive.
fn turn(from: f64, to: f64) -> f64 {
    let d = (to - from).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

fn side(degrees: f64) -> &'static str {
    if degrees > 0.0 {
        "left"
    } else if degrees < 0.0 {
        "right"
    } else {
        "straight"
    }
}

/// Runs the tutorial on the runtime `config` names.
fn run(config: &Config) -> anyhow::Result<bool> {
    if config.shm {
        let domain = esgm_shm::unique_domain("tutorial");
        let registry = esgm_shm::control::Registry::new(esgm_core::TypeRegistry::with_library());
        let _coordinator = esgm_shm::control::Coordinator::spawn(&domain, registry)?;
        let esgm = esgm_shm::connect(&domain)?;
        let clock = esgm.local().clock().clone();
        run_on(&esgm, &clock, config, "over shared memory")
    } else {
        let esgm = InProcessEsgm::default();
        let clock = esgm.clock().clone();
        let ok = run_on(&esgm, &clock, config, "in process");
        esgm.shutdown();
        ok
    }
}

/// The tutorial itself, on any runtime.
fn run_on<E: Esgm>(
    esgm: &E,
    clock: &SharedClock,
    config: &Config,
    where_: &str,
) -> anyhow::Result<bool>
where
    E::Trajectory: 'static,
{
    let t0 = clock.now();
    let image_period_s = config.image_period as f64 / TIMEUNITS_PER_SECOND as f64;
    println!(
        "esgm tutorial (seed chapters 8-10): {where_}, {:.1} s on the system clock",
        config.run_for.as_secs_f64()
    );

    // Chapter 7: the tutorial's types are esgm's predefined library types.
    let types = esgm.entity_structure_type_names()?;
    println!("  types       {}", types.join(", "));

    // 8.1: the robot pushes its states into a primitive trajectory. The seed's
    // "reasonable set of constraints": monotone order, a small delay and a bounded
    // cache. The one producer pushes in order, so states are not held for reordering
    // (which would only add the delay to the control loop).
    let policy =
        FluentStreamPolicy::reasonable(ROBOT_STATE_DELAY, ROBOT_STATE_CACHE)?.reorder(false);
    let robot_state = esgm
        .create_trajectory(TrajectorySpec::primitive("robot_state", "RobotState").policy(policy))?;

    // 8.2: the camera is pulled: register it, then sample it into `images` every
    // second forever with any delay, keeping the last 5 (the seed's arguments).
    let scene = SyntheticScene::builder()
        .blobs(config.blobs)
        .seed(config.seed)
        .create()
        .context("building the synthetic scene")?;
    let camera = CameraSensor::new(scene.clone());
    esgm.add_sensor_interface(
        "camera",
        CameraSensor::<SyntheticScene>::TYPE_NAME,
        Arc::new(camera),
    )?;
    let _images = esgm.create_entity_trajectory_structure(
        "images",
        "camera",
        0,
        0,
        config.image_period,
        0,
        5,
    )?;

    // Chapter 9: the units, and the trajectories computed by them.
    register_tutorial_units(esgm)?;
    let _blobs =
        esgm.create_computed_entity_trajectory_structure("blobs", "BlobDetection", &["images"])?;
    let current_blob = esgm.create_computed_entity_trajectory_structure(
        "current_blob",
        "BlobSelection",
        &["blobs"],
    )?;
    let _driving_direction = esgm.create_computed_entity_trajectory_structure(
        "driving_direction",
        "DrivingDirection",
        &["robot_state", "current_blob"],
    )?;

    println!(
        "  scene       {}x{}, {} blobs, seed {}; images every {image_period_s} s",
        scene.width(),
        scene.height(),
        config.blobs,
        config.seed
    );
    println!("\n  {:<18} {:<10} {:<17} source", "trajectory", "kind", "type");
    for name in PIPELINE {
        let Some(info) = esgm.trajectories()?.into_iter().find(|i| i.name == name) else {
            continue;
        };
        let source = match (&info.source, info.inputs.as_slice()) {
            (Some(s), []) => s.clone(),
            (Some(s), inputs) => format!("{s}({})", inputs.join(", ")),
            (None, _) => "pushed".to_owned(),
        };
        println!("  {:<18} {:<10} {:<17} {source}", info.name, info.kind.name(), info.type_name);
    }

    // The seed's robot thread, here a simulated robot steering by the directions.
    let driving_dir = esgm.get_entity_trajectory_structure("driving_direction")?;
    let robot = RobotPublisher::builder(robot_state.clone(), clock.clone())
        .follow(driving_dir.clone())
        .create()?;

    // 10.3: a subscription whose callback prints every new driving direction.
    println!(
        "\nsubscribed to driving_direction (times since start)\n  {:>7}  {:>11}  {:>9}  {:>12}  {:>5}  {:>8}",
        "t [s]", "robot [deg]", "dir [deg]", "turn [deg]", "speed", "lag [ms]"
    );
    let states = robot_state.clone();
    // The valid time of the last direction printed, to let the last one through.
    let printed = Arc::new(AtomicI64::new(Time::MIN));
    let printed_by_callback = Arc::clone(&printed);
    let callback =
        driving_dir.subscribe(SubscribeOptions::default())?.spawn_callback(move |s| {
            printed_by_callback.store(s.valid_time(), Ordering::Relaxed);
            let Ok(direction) = DrivingDirection::from_shared(&s) else { return };
            let heading = states
                .get_at(s.valid_time())
                .ok()
                .and_then(|r| RobotState::from_shared(&r).ok())
                .map_or(f64::NAN, |r| r.dir);
            let t = turn(heading, direction.dir);
            println!(
                "  {:>7.3}  {:>11.2}  {:>9.2}  {:>6.2} {:<5}  {:>5.2}  {:>8.2}",
                since(t0, s.valid_time()),
                heading,
                direction.dir,
                t,
                side(t),
                direction.speed,
                s.add_delay() as f64 / TIMEUNITS_PER_MILLI_SECOND as f64,
            );
        })?;

    std::thread::sleep(config.run_for);

    // Stop the robot, let the direction for its last state be computed and printed,
    // then stop printing.
    robot.stop();
    let settle = Instant::now() + Duration::from_secs(1);
    while Instant::now() < settle {
        let (Ok(last_state), Ok(last_dir)) = (robot_state.get_latest(), driving_dir.get_latest())
        else {
            break;
        };
        if last_dir.valid_time() >= last_state.valid_time()
            && printed.load(Ordering::Relaxed) >= last_dir.valid_time()
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    drop(callback);

    // 10.2: the seed's queries.
    let show = |s: &esgm_core::Sample| -> String {
        match DrivingDirection::from_shared(s) {
            Ok(d) => format!(
                "t={:.3} s  dir {:>6.2} deg  speed {:.2}",
                since(t0, s.valid_time()),
                d.dir,
                d.speed
            ),
            Err(e) => format!("unreadable: {e}"),
        }
    };
    println!("\nqueries on driving_direction (seed 10.2)");
    let latest = match driving_dir.get_latest() {
        Ok(latest) => latest,
        Err(e) => {
            println!("  get_latest: {e}");
            print_stats(esgm)?;
            if config.blobs == 0 {
                println!(
                    "\nas expected: without blobs, BlobSelection has no value, so nothing follows"
                );
                return Ok(true);
            }
            println!("\nno direction was computed, though the scene has blobs");
            return Ok(false);
        }
    };
    println!("  {:<52} {}", "get_latest", show(&latest));
    let (t1, t2) = (
        latest.valid_time() - 5 * TIMEUNITS_PER_SECOND,
        latest.valid_time() - TIMEUNITS_PER_SECOND,
    );
    let label = "get_between(latest - 5 s, latest - 1 s)";
    match driving_dir.get_between(t1, t2) {
        Ok(interval) if !interval.is_empty() => {
            println!("  {label:<52} {} samples", interval.len());
            if let (Some(first), Some(last)) = (interval.first(), interval.last()) {
                println!("  {:<52} {}", "  first", show(first));
                println!("  {:<52} {}", "  last", show(last));
            }
        }
        Ok(_) => println!("  {label:<52} no samples (run longer than 1 s)"),
        Err(e) => println!("  {label:<52} {e}"),
    }
    let t = latest.valid_time() - 100 * TIMEUNITS_PER_MILLI_SECOND;
    let label = "get_at_approximating(latest - 100 ms, most recent)";
    match driving_dir.get_at_approximating(t, &ValueApproximation::MostRecent) {
        Ok(at_t) => println!("  {label:<52} {}", show(&at_t)),
        Err(e) => println!("  {label:<52} {e}"),
    }

    print_stats(esgm)?;

    check(&scene, t0, &latest, &robot_state, &current_blob)
}

/// The tutorial's trajectories in data-flow order.
const PIPELINE: [&str; 5] = ["robot_state", "images", "blobs", "current_blob", "driving_direction"];

/// The per-trajectory statistics (E7) as a table.
fn print_stats(esgm: &impl Esgm) -> anyhow::Result<()> {
    let ms = |t: Option<Time>| {
        t.map_or_else(
            || "-".to_owned(),
            |t| format!("{:.2}", t as f64 / TIMEUNITS_PER_MILLI_SECOND as f64),
        )
    };
    let stats = esgm.stats()?;
    println!(
        "\nstatistics\n  {:<18} {:>6} {:>8} {:>7} {:>11} {:>11} {:>6} {:>9} {:>7}",
        "trajectory",
        "added",
        "dropped",
        "stored",
        "p50 lag ms",
        "p99 lag ms",
        "calls",
        "no value",
        "failed"
    );
    for name in PIPELINE {
        let Some(report) = stats.get(name) else {
            continue;
        };
        let (info, s, w) = (&report.info, &report.stats, &report.worker);
        let worker = |n: u64| if info.source.is_some() { n.to_string() } else { "-".to_owned() };
        println!(
            "  {:<18} {:>6} {:>8} {:>7} {:>11} {:>11} {:>6} {:>9} {:>7}",
            info.name,
            s.added,
            s.dropped_total,
            s.stored,
            ms(s.add_delay_p50),
            ms(s.add_delay_p99),
            worker(w.calls),
            worker(w.no_value),
            worker(w.failures + w.panics + w.invalid_outputs),
        );
    }
    Ok(())
}

/// Compares the last direction with the scene's ground truth: the largest disc in the
/// image the direction was computed from must lie on the side the robot is told to
/// turn to, at the bearing its centre gives.
fn check(
    scene: &SyntheticScene,
    t0: Time,
    latest: &esgm_core::Sample,
    robot_state: &impl EntityTrajectoryStructure,
    current_blob: &impl EntityTrajectoryStructure,
) -> anyhow::Result<bool> {
    let direction = DrivingDirection::from_shared(latest)?;
    let state = robot_state.get_at(latest.valid_time())?;
    let robot = RobotState::from_shared(&state)?;
    // The blob the unit used: the newest not newer than the robot state.
    let blob_sample = current_blob.get_closest_at_or_before(latest.valid_time())?;
    let blob = Blob::from_shared(&blob_sample)?;
    let truth = scene.truth(blob_sample.valid_time());
    let Some(largest) = truth.iter().max_by_key(|b| b.size).copied() else {
        bail!("the scene has no blobs, yet a direction was computed");
    };
    let unit = DrivingDirectionUnit::default();
    let bearing = |b: &Blob| unit.computation().bearing(b.x);
    let actual = turn(robot.dir, direction.dir);
    // A centroid off by a few pixels moves the bearing by a few tenths of a degree.
    let points_at = |b: &Blob| {
        let expected = bearing(b);
        actual.signum() == expected.signum() && (actual - expected).abs() < 0.5
    };
    // Detected sizes are within about 10% of the truth, so discs closer in size than
    // that are all "the largest" as far as the detector can tell.
    let target = truth.iter().filter(|b| b.size * 10 >= largest.size * 9).find(|b| points_at(b));

    println!("\ncheck against the scene's ground truth");
    println!(
        "  last direction     t={:.3} s: robot heading {:.2} deg, told {:.2} deg: turn {:.2} deg {}",
        since(t0, latest.valid_time()),
        robot.dir,
        direction.dir,
        actual,
        side(actual)
    );
    println!(
        "  selected blob      image t={:.3} s: centre ({}, {}), {} px",
        since(t0, blob_sample.valid_time()),
        blob.x,
        blob.y,
        blob.size
    );
    println!(
        "  largest disc       centre ({}, {}), {} px: bearing {:.2} deg {}",
        largest.x,
        largest.y,
        largest.size,
        bearing(&largest),
        side(bearing(&largest))
    );
    match target {
        Some(b) if *b == largest => {
            println!("  consistent: the robot is told to turn toward the largest blob");
        }
        Some(b) => println!(
            "  consistent: the robot is told to turn toward the disc at ({}, {}), {} px, \
             within 10% of the largest in size (too close for the detector to tell apart)",
            b.x, b.y, b.size
        ),
        None => println!("  MISMATCH: the direction does not point at the largest blob"),
    }
    Ok(target.is_some())
}

fn main() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();

    let config = match parse_args(std::env::args().skip(1)) {
        Ok(Some(config)) => config,
        Ok(None) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(err) => {
            eprintln!("tutorial: {err:#}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(&config) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(err) => {
            eprintln!("tutorial: {err:#}");
            ExitCode::FAILURE
        }
    }
}
