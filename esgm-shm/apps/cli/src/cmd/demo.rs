//! `esgm demo`: the seed's tutorial (chapters 8–10) as separate processes — a
//! coordinator, a camera, a robot and three unit workers, supervised — driven from
//! this process as the seed's main program drives its ESGM.
//!
//! `--config FILE` runs the tutorial as another file declares it (a camera or units
//! of the user's own, in C++ say) through the same checks: the file must declare the
//! tutorial's five trajectories, whoever computes them, so that its result can be
//! held to the same ground truth and the same zero image copies.

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use camera_publisher::{CameraArgs, SyntheticScene};
use clap::Parser as _;
use esgm_core::esgm::TrajectorySource;
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::{
    Entity, EntityTrajectoryStructure, Esgm, InProcessTrajectory, Sample, SubscribeOptions, Time,
    ValueApproximation, millis,
};
use esgm_shm::cleanup_dead_nodes;
use esgm_shm::control::{ProcessRecord, StateDir};
use esgm_shm::control::{Request, Response};
use esgm_shm::{ShmEsgm, unique_domain};

use crate::config::{self, Plan, Serves};
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
    #[arg(long, default_value_t = 250, conflicts_with = "config")]
    pub image_period_ms: u32,
    /// Run the system this file declares instead of the built-in tutorial.toml
    /// (relative paths in it are taken from its directory, as `esgm apply` takes
    /// them). It must declare the tutorial's trajectories robot_state, images, blobs,
    /// current_blob and driving_direction; its camera and periods are its own, and
    /// --seed/--blobs name the scene the result is checked against.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Keep idle cores' wake-up within this many microseconds while the demo runs, as
    /// `esgm up --cpu-latency` does (needs root).
    #[arg(long, value_name = "MICROSECONDS", value_parser = esgm_shm::process::cpu_latency::parse_micros)]
    pub cpu_latency: Option<std::time::Duration>,
}

/// The tutorial's trajectories in data-flow order.
const PIPELINE: [&str; 5] = ["robot_state", "images", "blobs", "current_blob", "driving_direction"];

/// The system, as a configuration file (also shipped as an example of the format).
const TUTORIAL: &str = include_str!("../../tutorial.toml");

/// The types the demo reads from the tutorial's trajectories (the others it only
/// counts): a file naming them must give them these types.
const READ_AS: [(&str, &str); 3] = [
    ("robot_state", "RobotState"),
    ("current_blob", "Blob"),
    ("driving_direction", "DrivingDirection"),
];

/// A system file `esgm demo --config` cannot run as the tutorial: what to change.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NotTheTutorial {
    /// The file lacks trajectories the demo reads or times: declare them.
    #[error(
        "{file}: declares no trajectory {}; esgm demo --config runs the tutorial's {}",
        missing.iter().map(|m| format!("`{m}`")).collect::<Vec<_>>().join(", "),
        PIPELINE.join(", ")
    )]
    MissingTrajectories {
        /// The file, as given.
        file: String,
        /// The trajectories it does not declare.
        missing: Vec<&'static str>,
    },
    /// The file's built-in camera draws another scene than the one the result is
    /// checked against: give the file's seed and blobs on the command line.
    #[error(
        "{file}:{line}: sensor `{sensor}` draws {drawn}, but esgm demo checks the result \
         against {checked}; {hint}"
    )]
    OtherScene {
        /// The file, as given.
        file: String,
        /// The line of the sensor's declaration.
        line: usize,
        /// The sensor sampled by `images`.
        sensor: String,
        /// What the file's camera draws.
        drawn: String,
        /// What the check expects.
        checked: String,
        /// What to do.
        hint: String,
    },
    /// A trajectory the demo reads has another type: compute the tutorial's type.
    #[error("trajectory `{trajectory}` is of type `{found}`; esgm demo reads `{expected}` from it")]
    WrongType {
        /// The trajectory.
        trajectory: String,
        /// Its type in the running system.
        found: String,
        /// The type the demo reads.
        expected: &'static str,
    },
}

/// Runs the demo; an inconsistent result, or an image a process copied, is an error
/// (exit 1).
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    if a.seconds.is_nan() || a.seconds <= 0.0 {
        bail!("--seconds must be positive, got {}", a.seconds);
    }
    if a.image_period_ms == 0 {
        bail!("--image-period-ms must be positive");
    }
    let plan = match &a.config {
        Some(file) => plan_of_file(a, file)?,
        None => plan(a)?,
    };
    // A fresh system unless the user named one.
    let domain = if domain == "esgm" { unique_domain("demo") } else { domain.to_owned() };
    let system = match &a.config {
        Some(file) => format!("the tutorial of {}", file.display()),
        None => "the seed's tutorial".to_owned(),
    };
    println!("esgm demo: {system} as separate processes, domain `{domain}`");
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
    esgm_shm::process::remove_domain_files(domain);
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

/// The system a file declares, loaded as `esgm apply` loads it (its programs found),
/// if it is the tutorial's: its five trajectories, and a built-in camera (if it has
/// one) drawing the scene the result is checked against.
fn plan_of_file(a: &Args, file: &Path) -> anyhow::Result<Plan> {
    let plan = config::load(file)?;
    let declared = |name: &str| plan.trajectories.iter().find(|t| t.what.spec.name == name);
    let missing: Vec<&'static str> =
        PIPELINE.into_iter().filter(|name| declared(name).is_none()).collect();
    if !missing.is_empty() {
        bail!(NotTheTutorial::MissingTrajectories { file: plan.file.clone(), missing });
    }
    same_scene(a, &plan)?;
    Ok(plan)
}

/// If `images` is sampled from a built-in camera of the plan, it must draw the scene
/// `--seed`/`--blobs` name (at the size the built-in demo draws): a camera of the
/// user's own is trusted to, and a mismatch shows in the check at the end.
fn same_scene(a: &Args, plan: &Plan) -> anyhow::Result<()> {
    let sensor = plan.trajectories.iter().find_map(|t| match &t.what.spec.source {
        TrajectorySource::Sampled { sensor, .. } if t.what.spec.name == "images" => {
            Some(sensor.clone())
        }
        _ => None,
    });
    let Some(sensor) = sensor else { return Ok(()) };
    let camera = plan.workers.iter().find(|w| {
        w.what.serves == Serves::Sensor(sensor.clone())
            && w.what.program.is_none()
            && w.what.spec.args.starts_with(&["worker".to_owned(), "camera".to_owned()])
    });
    let Some(camera) = camera else { return Ok(()) };
    let words = |args: &[String]| std::iter::once("camera".to_owned()).chain(args.to_vec());
    let drawn = CameraArgs::try_parse_from(words(&camera.what.spec.args[2..]))
        .context("the file's camera takes arguments `esgm worker camera` does not")?;
    let checked = CameraArgs::try_parse_from(words(&[
        "--seed".to_owned(),
        a.seed.to_string(),
        "--blobs".to_owned(),
        a.blobs.to_string(),
    ]))
    .context("--seed and --blobs")?;
    let scene = |c: &CameraArgs| match &c.dir {
        Some(dir) => format!("the frames of {}", dir.display()),
        None => format!("seed {}, {} blobs at {}x{}", c.seed, c.blobs, c.width, c.height),
    };
    if scene(&drawn) == scene(&checked) {
        return Ok(());
    }
    // Only the seed and the number of blobs are the demo's to choose.
    let hint =
        if drawn.dir.is_none() && (drawn.width, drawn.height) == (checked.width, checked.height) {
            format!("run it with --seed {} --blobs {}", drawn.seed, drawn.blobs)
        } else {
            "the demo checks a synthetic camera of the default size, as tutorial.toml declares it"
                .to_owned()
        };
    bail!(NotTheTutorial::OtherScene {
        file: plan.file.clone(),
        line: camera.line,
        sensor,
        drawn: scene(&drawn),
        checked: scene(&checked),
        hint,
    })
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
    let trajectories = esgm.trajectories()?;
    for (name, expected) in READ_AS {
        if let Some(t) = trajectories.iter().find(|t| t.name == name && t.type_name != expected) {
            bail!(NotTheTutorial::WrongType {
                trajectory: name.to_owned(),
                found: t.type_name.clone(),
                expected,
            });
        }
    }
    println!("\n  {:<18} {:<10} {:<17} source", "trajectory", "kind", "type");
    for name in PIPELINE {
        if let Some(i) = trajectories.iter().find(|i| i.name == name) {
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
        let t0 = *t0.get_or_insert(s.structure.valid_time());
        print_direction(&s, t0, &robot_state);
    }
    drop(sub);

    let latest = directions.get_latest().context("no driving direction was computed")?;
    let t0 = t0.unwrap_or(latest.structure.valid_time());
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
    let Ok(d) = DrivingDirection::from_shared(&s.structure) else { return };
    let heading = robot_state
        .get_closest_at_or_before(s.structure.valid_time())
        // No robot state yet (or not a `RobotState`): the heading prints as NaN.
        .ok()
        .and_then(|r| RobotState::from_shared(&r.structure).ok())
        .map_or(f64::NAN, |r| r.dir);
    println!(
        "  {:>7.3}  {:>11.2}  {:>9.2}  {:>8.2}  {:>8.2}",
        since(t0, s.structure.valid_time()),
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
    let show = |s: &Sample| match DrivingDirection::from_shared(&s.structure) {
        Ok(d) => format!(
            "t={:.3} s  dir {:>7.2} deg  speed {:.2}",
            since(t0, s.structure.valid_time()),
            d.dir,
            d.speed
        ),
        Err(e) => format!("unreadable: {e}"),
    };
    println!("\nqueries on driving_direction (seed 10.2)");
    println!("  {:<52} {}", "get_latest", show(latest));
    let vt = latest.structure.valid_time();
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
    let blob_sample = current_blob.get_closest_at_or_before(latest.structure.valid_time())?;
    let blob = Blob::from_shared(&blob_sample.structure)?;
    let truth = scene.truth(blob_sample.structure.valid_time());
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use clap::Parser as _;

    use super::*;

    /// `esgm demo ARGS…`'s options.
    fn args(words: &[&str]) -> Args {
        let cli = crate::Cli::try_parse_from(["esgm", "demo"].iter().chain(words)).unwrap();
        match cli.command {
            crate::Command::Demo(a) => a,
            _ => unreachable!("parsed as esgm demo"),
        }
    }

    fn refusal(text: &str, words: &[&str]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("system.toml");
        std::fs::write(&file, text).unwrap();
        let mut words = words.to_vec();
        let path = file.to_str().unwrap().to_owned();
        words.extend(["--config", &path]);
        let e = plan_of_file(&args(&words), &file).unwrap_err();
        e.to_string().replace(&path, "system.toml")
    }

    #[test]
    fn the_tutorial_as_a_file_is_the_demos_system() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("tutorial.toml");
        std::fs::write(&file, TUTORIAL).unwrap();
        let plan = plan_of_file(&args(&["--config", file.to_str().unwrap()]), &file).unwrap();
        assert_eq!(plan.trajectories.len(), PIPELINE.len());
    }

    #[test]
    fn a_file_is_refused_naming_every_trajectory_it_lacks() {
        let e =
            refusal("[[trajectory]]\nname = \"robot_state\"\nprimitive = \"RobotState\"\n", &[]);
        assert_eq!(
            e,
            "system.toml: declares no trajectory `images`, `blobs`, `current_blob`, \
             `driving_direction`; esgm demo --config runs the tutorial's robot_state, images, \
             blobs, current_blob, driving_direction"
        );
    }

    #[test]
    fn a_built_in_camera_must_draw_the_scene_the_result_is_checked_against() {
        let seven = TUTORIAL.replace("seed = 0", "seed = 7");
        let e = refusal(&seven, &[]);
        assert!(e.starts_with("system.toml:33: sensor `camera` draws seed 7, 3 blobs"), "{e}");
        assert!(e.ends_with("run it with --seed 7 --blobs 3"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("seven.toml");
        std::fs::write(&file, &seven).unwrap();
        let path = file.to_str().unwrap();
        assert!(plan_of_file(&args(&["--seed", "7", "--config", path]), &file).is_ok());

        let small = TUTORIAL.replace("# width = 640", "width = 320");
        let e = refusal(&small, &[]);
        assert!(e.contains("at 320x480") && e.ends_with("as tutorial.toml declares it"), "{e}");
    }

    #[test]
    fn the_image_period_is_the_files_own() {
        let e = crate::Cli::try_parse_from([
            "esgm",
            "demo",
            "--config",
            "f.toml",
            "--image-period-ms",
            "100",
        ])
        .unwrap_err();
        assert_eq!(e.kind(), clap::error::ErrorKind::ArgumentConflict);
    }
}
