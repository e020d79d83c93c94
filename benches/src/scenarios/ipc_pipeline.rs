//! `pipeline-<stage>`: the seed's tutorial pipeline — camera → `images` → `blobs` →
//! `current_blob` → `driving_direction` — across processes, and the latency each stage
//! adds.
//!
//! Processes, all `esgm-bench` peers except the robot: a coordinator
//! ([`esgm_shm::control::Coordinator`]), a camera process serving a synthetic camera
//! ([`camera_publisher::CameraSensor`]) and one process per unit
//! ([`cu_workers::BlobDetectionUnit`], [`cu_workers::BlobSelectionUnit`],
//! [`cu_workers::DrivingDirectionUnit`]), each connected with [`esgm_shm::connect`] as
//! `esgm worker` does; this process creates the trajectories (so the coordinator
//! places each on the process that writes it, as in `esgm demo`), pushes the robot's
//! `RobotState` at 10 Hz ([`robot_publisher::RobotPublisher`]) and subscribes to every
//! trajectory of the pipeline.
//!
//! Every sample carries its structure's valid and create times and the add time its
//! writer's gate gave it, all on the host's system clock. Per stage:
//! - `pipeline-images`: add time − valid time of each image: the camera renders the
//!   frame for its sample time and writes it into shared memory;
//! - `pipeline-blobs`, `pipeline-current_blob`, `pipeline-driving_direction`: add time
//!   of the output − add time of the input sample that triggered it (the latest input
//!   added before the unit's call, whose time is the output's create time): the hop to
//!   the unit's process, the unit's computation and the publish;
//! - `pipeline-end-to-end`: for each blob, add time of the first driving direction
//!   computed from it − valid time of the image it came from (see `end_to_end` for why
//!   that includes the wait for the next robot state).
//!
//! Beside them, each unit's computation alone, timed in this process on the same
//! synthetic frames (`pipeline-<stage>-compute`): what the stage would cost with no
//! transport at all.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crate::domain_end::DomainEnd;
use anyhow::{Context as _, bail};
use camera_publisher::{CameraSensor, FrameSource, SyntheticScene};
use cu_workers::{
    BlobDetectionUnit, BlobDetector, BlobSelectionUnit, ComputeDirection, DrivingDirectionConfig,
    DrivingDirectionUnit, select_blob,
};
use esgm_core::esgm::{CompUnit, TrajectorySpec, TypedUnitAdapter};
use esgm_core::library::{Blob, RobotState};
use esgm_core::{
    Entity, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, Sample, SubscribeOptions, Time,
    TypeRegistry, millis,
};
use esgm_shm::ShmEsgm;
use esgm_shm::control::{ControlClient, Coordinator, Registry, Request};
use esgm_shm::unique_domain;
use robot_publisher::RobotPublisher;

use super::pipeline_woken::{Woken, note_for};
use crate::latency::Latency;
use crate::peer_process::PeerProcess;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "pipeline";
/// The stages, in data-flow order, and their inputs.
const STAGES: [(&str, &[&str]); 4] = [
    ("images", &[]),
    ("blobs", &["images"]),
    ("current_blob", &["blobs"]),
    ("driving_direction", &["robot_state", "current_blob"]),
];
const UNITS: [&str; 3] =
    [BlobDetectionUnit::NAME, BlobSelectionUnit::NAME, DrivingDirectionUnit::NAME];
/// Time between two camera images.
const IMAGE_PERIOD_MS: i64 = 50;
/// How long anything may take to come up.
const STARTUP: Duration = Duration::from_secs(30);

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct Pipeline;

impl Scenario for Pipeline {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "rows pipeline-<stage>: the tutorial's camera -> images -> blobs -> current_blob -> \
         driving_direction across six processes, latency added per stage; unit compute \
         time alone beside it"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let seconds = if ctx.is_quick() { 3 } else { 30 };
        let (collected, lines) = run_system(ctx, Duration::from_secs(seconds))?;
        let mut rows = stage_rows(&collected, &lines)?;
        rows.extend(compute_rows(ctx)?);
        Ok(rows)
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        match role.arg.as_deref() {
            Some("coordinator") => {
                iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
                let mut c =
                    Coordinator::create(&role.domain, Registry::new(TypeRegistry::with_library()))
                        .context("could not start the coordinator")?;
                c.run(&AtomicBool::new(false), Duration::from_secs(1))?;
                Ok(Vec::new())
            }
            Some(worker) => serve(&role.domain, worker),
            None => bail!("the pipeline peer needs --peer-arg"),
        }
    }
}

/// A coordinator process: serves `domain` until told to shut down.
pub fn coordinator(domain: &str) -> anyhow::Result<Vec<String>> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let mut c = Coordinator::create(domain, Registry::new(TypeRegistry::with_library()))
        .context("could not start the coordinator")?;
    c.run(&AtomicBool::new(false), Duration::from_secs(1))?;
    Ok(Vec::new())
}

/// Starts a coordinator peer of `scenario` for `domain` and waits until it answers.
pub fn spawn_coordinator(
    ctx: &Context,
    scenario: &str,
    domain: &str,
) -> anyhow::Result<PeerProcess> {
    let mut coordinator =
        ctx.spawn_peer_process_as(scenario, WaitMode::SpinThenBlock, domain, Some("coordinator"))?;
    let started = Instant::now();
    loop {
        if let Ok(c) = ControlClient::connect(domain, Duration::from_millis(200)) {
            if c.call(&Request::Ping).is_ok() {
                return Ok(coordinator);
            }
        }
        coordinator.check_running()?;
        if started.elapsed() > STARTUP {
            bail!("the coordinator did not answer within {STARTUP:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Asks the coordinator of `domain` to shut down (its workers notice and leave).
pub fn shutdown(domain: &str) {
    if let Ok(c) = ControlClient::connect(domain, Duration::from_secs(2)) {
        let _ = c.call(&Request::Shutdown);
    }
}

/// A camera or unit process: registers what it serves and stays until the
/// coordinator is gone.
fn serve(domain: &str, worker: &str) -> anyhow::Result<Vec<String>> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(format!("bench-{worker}"))
        .timeout(Duration::from_secs(2))
        .connect()
        .with_context(|| format!("{worker}: cannot reach the coordinator"))?;
    let mut woken = None;
    if worker == "camera" {
        let scene = SyntheticScene::builder().create()?;
        esgm.add_sensor_interface(
            "camera",
            CameraSensor::<SyntheticScene>::TYPE_NAME,
            Arc::new(CameraSensor::new(scene)),
        )?;
    } else {
        let (output, inputs, unit): (_, _, Arc<dyn CompUnit>) = match worker {
            BlobDetectionUnit::NAME => (
                BlobDetectionUnit::OUTPUT_TYPE,
                BlobDetectionUnit::input_types(),
                Arc::new(TypedUnitAdapter(BlobDetectionUnit::default())),
            ),
            BlobSelectionUnit::NAME => (
                BlobSelectionUnit::OUTPUT_TYPE,
                BlobSelectionUnit::input_types(),
                Arc::new(TypedUnitAdapter(BlobSelectionUnit)),
            ),
            DrivingDirectionUnit::NAME => (
                DrivingDirectionUnit::OUTPUT_TYPE,
                DrivingDirectionUnit::input_types(),
                Arc::new(TypedUnitAdapter(DrivingDirectionUnit::default())),
            ),
            other => bail!("unknown pipeline worker {other}"),
        };
        let timed = Arc::new(Woken::new(unit)?);
        esgm.add_comp_unit(worker, output, inputs, Arc::clone(&timed) as Arc<dyn CompUnit>)?;
        woken = Some(timed);
    }
    let started = Instant::now();
    let mut misses = 0;
    while misses < 2 {
        std::thread::sleep(Duration::from_millis(100));
        misses = if esgm.ping() { 0 } else { misses + 1 };
        if started.elapsed() > Duration::from_secs(600) {
            bail!("{worker}: still running after 10 minutes");
        }
    }
    let mut lines: Vec<String> = woken.map(|w| w.report(worker)).into_iter().collect();
    lines.extend(crate::hop_steps::lines(worker));
    Ok(lines)
}

/// What the measuring process saw of each trajectory.
type Collected = HashMap<&'static str, Vec<Sample>>;

/// What the measuring process saw, and the lines the workers printed when they left.
fn run_system(ctx: &Context, run_for: Duration) -> anyhow::Result<(Collected, Vec<String>)> {
    // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let domain = unique_domain("esgm-bench-pipe");
    // Dropped after every process of the domain: removes its futex words, which a
    // peer killed on a failure would leave in /dev/shm.
    let _end = DomainEnd::new(&domain);
    let coordinator = spawn_coordinator(ctx, NAME, &domain)?;
    let mut workers: Vec<PeerProcess> = Vec::new();
    for worker in std::iter::once("camera").chain(UNITS) {
        workers.push(ctx.spawn_peer_process_as(
            NAME,
            WaitMode::SpinThenBlock,
            &domain,
            Some(worker),
        )?);
    }
    let result = drive(&domain, run_for, &mut workers);

    // Stop: the coordinator leaves, the workers notice within two pings.
    shutdown(&domain);
    let mut failures = Vec::new();
    let mut lines = Vec::new();
    for peer in workers.into_iter().chain(std::iter::once(coordinator)) {
        match peer.finish(Duration::from_secs(15)) {
            Ok(printed) => lines.extend(printed),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    let collected = result?;
    if !failures.is_empty() {
        bail!("pipeline processes failed: {}", failures.join("; "));
    }
    Ok((collected, lines))
}

fn drive(
    domain: &str,
    run_for: Duration,
    workers: &mut [PeerProcess],
) -> anyhow::Result<Collected> {
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host("bench-robot")
        .connect()
        .context("cannot reach the pipeline's coordinator")?;
    let started = Instant::now();
    loop {
        let sensors = esgm.sensors()?;
        let units = esgm.comp_units()?;
        if sensors.iter().any(|(n, _)| n == "camera")
            && UNITS.iter().all(|u| units.iter().any(|(n, _, _)| n == u))
        {
            break;
        }
        for w in workers.iter_mut() {
            w.check_running()?;
        }
        if started.elapsed() > STARTUP {
            bail!("the camera and the units did not register within {STARTUP:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }

    let policy = FluentStreamPolicy::reasonable(millis(50), 600)?.reorder(false);
    let robot_state = esgm.create_trajectory(
        TrajectorySpec::primitive("robot_state", RobotState::TYPE_NAME).policy(policy),
    )?;
    let images = esgm.create_entity_trajectory_structure(
        "images",
        "camera",
        0,
        0,
        millis(IMAGE_PERIOD_MS),
        0,
        5,
    )?;
    let blobs = esgm.create_computed_entity_trajectory_structure(
        "blobs",
        BlobDetectionUnit::NAME,
        &["images"],
    )?;
    let current = esgm.create_computed_entity_trajectory_structure(
        "current_blob",
        BlobSelectionUnit::NAME,
        &["blobs"],
    )?;
    let directions = esgm.create_computed_entity_trajectory_structure(
        "driving_direction",
        DrivingDirectionUnit::NAME,
        &["robot_state", "current_blob"],
    )?;
    let options = SubscribeOptions::default;
    let subs = [
        ("robot_state", robot_state.subscribe(options())?),
        ("images", images.subscribe(options())?),
        ("blobs", blobs.subscribe(options())?),
        ("current_blob", current.subscribe(options())?),
        ("driving_direction", directions.subscribe(options())?),
    ];
    let clock = esgm.local().clock().clone();
    let robot = RobotPublisher::builder(robot_state.clone(), clock)
        .period(millis(100))
        .follow(directions.clone())
        .create()?;

    let mut collected: Collected = HashMap::new();
    let started = Instant::now();
    let mut next_check = Instant::now();
    while started.elapsed() < run_for {
        let mut any = false;
        for (name, sub) in &subs {
            while let Some(s) = sub.try_recv() {
                collected.entry(name).or_default().push(s);
                any = true;
            }
        }
        if Instant::now() >= next_check {
            for w in workers.iter_mut() {
                w.check_running()?;
            }
            next_check = Instant::now() + Duration::from_millis(200);
        }
        if !any {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    drop(robot);
    Ok(collected)
}

/// The latency rows, from the samples' times.
fn stage_rows(c: &Collected, lines: &[String]) -> anyhow::Result<Vec<Measurement>> {
    let empty = Vec::new();
    let of = |name: &str| c.get(name).unwrap_or(&empty);
    let mut rows = Vec::new();
    for (stage, inputs) in STAGES {
        let mut latency = Latency::new()?;
        let outputs = of(stage);
        let mut untriggered = 0u64;
        for out in outputs {
            if inputs.is_empty() {
                latency.record_ns(
                    u64::try_from(out.add_time - out.structure.valid_time()).unwrap_or(0),
                );
                continue;
            }
            match trigger(c, inputs, out.structure.create_time()) {
                Some((_, input)) => {
                    latency.record_ns(u64::try_from(out.add_time - input.add_time).unwrap_or(0));
                }
                None => untriggered += 1,
            }
        }
        let mut row = latency
            .measurement(&format!("pipeline-{stage}"), Wait::Event)
            .payload_bytes(payload_of(outputs))
            .method(Method::SystemClock)
            .wait_strategy("esgm runtime default (spin, then block)");
        row = row.note(if inputs.is_empty() {
            "valid time -> added by the camera process (render + write into shared memory)".to_owned()
        } else {
            format!("added here - added to its input ({}): hop to the unit's process + compute + publish", inputs.join(" or "))
        });
        row = row.if_empty(format!(
            "{} {stage} samples reached the measuring process, {untriggered} with no input added \
             before them",
            outputs.len()
        ));
        if untriggered > 0 {
            row = row.note(format!(
                "{untriggered} samples with no input added before them were left out"
            ));
        }
        if stage == "images" {
            row = row.note(format!("{} images at one per {IMAGE_PERIOD_MS} ms", outputs.len()));
        }
        if let Some(note) = unit_of(stage).and_then(|unit| note_for(unit, lines)) {
            row = row.note(note);
        }
        if let Some(note) = unit_of(stage).and_then(|unit| {
            crate::hop_steps::note(writer_of(inputs.last().copied()?)?, unit, lines)
        }) {
            row = row.note(note);
        }
        rows.push(row);
    }
    rows.push(end_to_end(c)?);
    Ok(rows)
}

/// The process that writes trajectory `stage`: the camera, or the unit computing it.
fn writer_of(stage: &str) -> Option<&'static str> {
    match stage {
        "images" => Some("camera"),
        other => unit_of(other),
    }
}

/// The unit that computes `stage`.
fn unit_of(stage: &str) -> Option<&'static str> {
    STAGES.iter().skip(1).zip(UNITS).find(|((s, _), _)| *s == stage).map(|(_, unit)| unit)
}

/// `pipeline-end-to-end`: for each blob, its image's valid time → the first driving
/// direction computed from it.
///
/// The driving direction unit follows the seed's synchronization rule
/// ([`cu_workers::inputs_synchronized`]): it computes only when the robot state is at
/// least as new as the blob, and otherwise has no value. So a new blob is usually
/// steered by at the next robot state (10 Hz, at a phase of its own), not when the blob
/// arrives: only a robot state valid between the image's sample time and the blob's
/// arrival lets a direction be computed at once. Counting only directions *triggered*
/// by a blob (as this row once did) kept that coincidence, a matter of the phase
/// between the robot's and the camera's clocks in each run: a few per cent of the blobs,
/// or none (n = 0 in a full `--pin` run).
fn end_to_end(c: &Collected) -> anyhow::Result<Measurement> {
    let empty = Vec::new();
    let of = |name: &str| c.get(name).unwrap_or(&empty);
    let blobs = of("current_blob");
    let directions = of("driving_direction");
    let mut e2e = Latency::new()?;
    let (mut at_once, mut counted) = (0u64, None);
    for out in directions {
        let Some(i) = blob_of(blobs, out) else { continue };
        if counted.is_some_and(|last| last >= i) {
            // Not the first direction from this blob.
            continue;
        }
        counted = Some(i);
        let blob = &blobs[i];
        e2e.record_ns(u64::try_from(out.add_time - blob.structure.valid_time()).unwrap_or(0));
        let inputs = ["robot_state", "current_blob"];
        if matches!(trigger(c, &inputs, out.structure.create_time()), Some(("current_blob", _))) {
            at_once += 1;
        }
    }
    Ok(e2e
        .measurement("pipeline-end-to-end", Wait::Event)
        .method(Method::SystemClock)
        .wait_strategy("esgm runtime default (spin, then block)")
        .note(
            "image valid time -> the first driving direction computed from its blob added; \
             includes the wait for a robot state as new as the blob (the seed's rule: up to \
             one robot period, 100 ms)",
        )
        .note(format!(
            "{} of {} blobs reached a direction, {at_once} of them at once (a robot state as new \
             was already there), the others at the next robot state; {} directions in all",
            e2e.len(),
            blobs.len(),
            directions.len()
        ))
        .if_empty(format!(
            "no driving direction was computed from any of the {} blobs ({} directions, {} \
             robot states)",
            blobs.len(),
            directions.len(),
            of("robot_state").len()
        )))
}

/// The index in `blobs` of the blob `direction` was computed from: the latest one added
/// by its create time (the unit's query time) that is not newer than its robot state
/// (its valid time): a newer one would have given no value (see [`end_to_end`]), so it
/// had not reached the unit yet.
fn blob_of(blobs: &[Sample], direction: &Sample) -> Option<usize> {
    // Samples arrive in add order.
    let added = blobs.partition_point(|b| b.add_time <= direction.structure.create_time());
    blobs[..added]
        .iter()
        .rposition(|b| b.structure.valid_time() <= direction.structure.valid_time())
}

/// The input sample added last at or before `at` among `inputs`.
fn trigger<'a>(
    c: &'a Collected,
    inputs: &[&'static str],
    at: Time,
) -> Option<(&'static str, &'a Sample)> {
    inputs
        .iter()
        .filter_map(|name| {
            let samples = c.get(name)?;
            // Samples arrive in add order.
            let i = samples.partition_point(|s| s.add_time <= at);
            samples.get(i.checked_sub(1)?).map(|s| (*name, s))
        })
        .max_by_key(|(_, s)| s.add_time)
}

fn payload_of(samples: &[Sample]) -> u64 {
    samples.first().and_then(|s| s.structure.to_codec_bytes().ok()).map_or(0, |b| b.len() as u64)
}

/// What lineage adds to one hop of a two-input stage (driving_direction's), as the
/// runtime does it: the writer names its inputs (`Lineage::of`, the names cloned) and
/// encodes them after the sample's archive; one reader decodes them. Beside the
/// `current_blob` stage's hop in the same run, the ratio is lineage's share of a hop.
fn lineage_work(n: u64) -> anyhow::Result<Measurement> {
    use esgm_core::codec::{decode_lineage, encode_lineage_into, lineage_len};
    use esgm_core::{InputRef, Lineage};
    let names = ["robot_state".to_owned(), "current_blob".to_owned()];
    let mut latency = Latency::new()?;
    let mut trailer = vec![0_u8; 256];
    for i in 0..n.max(1_000) {
        let t = i as Time * millis(IMAGE_PERIOD_MS);
        let start = Instant::now();
        let inputs = names
            .iter()
            .map(|trajectory| InputRef {
                trajectory: trajectory.clone(),
                generation: 7,
                valid_time: t,
                add_time: t + 1_000,
            })
            .collect();
        let lineage = std::sync::Arc::new(Lineage::of(inputs).with_unrecorded_reads());
        let len = lineage_len(&lineage);
        let written = encode_lineage_into(&lineage, &mut trailer[..len])?;
        let read = std::sync::Arc::new(decode_lineage(&trailer[..written])?);
        latency.record(start.elapsed());
        std::hint::black_box((lineage, read));
    }
    Ok(latency
        .measurement("pipeline-lineage", Wait::Event)
        .baseline("pipeline-current_blob")
        .method(Method::Call)
        .wait_strategy("none (in process)")
        .note("a two-input output's lineage: named, encoded after the archive, decoded by one reader; the ratio is its share of the current_blob stage's hop"))
}

/// Each unit's computation alone, in this process, on the camera's frames.
fn compute_rows(ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
    let frames = ctx.samples(1_000, 50).min(10_000);
    let scene = SyntheticScene::builder().create()?;
    let mut detector = BlobDetector::default();
    let direction = ComputeDirection::new(DrivingDirectionConfig::default())?;
    let robot = RobotState { x: 1.0, y: 2.0, dir: 3.0 };
    let (mut detect, mut select, mut steer) = (Latency::new()?, Latency::new()?, Latency::new()?);
    let mut last_blob = Blob { x: 320, y: 240, size: 100 };
    for i in 0..frames {
        let image = scene.frame(i as Time * millis(IMAGE_PERIOD_MS));
        let start = Instant::now();
        let blobs = detector.detect(&image).context("detecting blobs")?;
        detect.record(start.elapsed());
        let start = Instant::now();
        let blob = select_blob(&blobs);
        select.record(start.elapsed());
        if let Some(b) = blob {
            last_blob = b;
        }
        let start = Instant::now();
        std::hint::black_box(direction.compute(&robot, &last_blob));
        steer.record(start.elapsed());
    }
    let bytes = (scene.frame_len()) as u64;
    let lineage = lineage_work(frames)?;
    Ok(vec![
        lineage,
        detect
            .measurement("pipeline-blobs-compute", Wait::Spin)
            .payload_bytes(bytes)
            .method(Method::Call)
            .wait_strategy("none (in process)")
            .note("BlobDetector::detect on a 640x480 RGB frame of the synthetic scene"),
        select
            .measurement("pipeline-current_blob-compute", Wait::Spin)
            .method(Method::Call)
            .wait_strategy("none (in process)")
            .note("select_blob on the detected blobs"),
        steer
            .measurement("pipeline-driving_direction-compute", Wait::Spin)
            .method(Method::Call)
            .wait_strategy("none (in process)")
            .note("ComputeDirection::compute"),
    ])
}
