//! An image another process wrote, read in place through `connect`, stays valid and
//! unchanged for as long as a value reads it — whatever happens to the trajectory,
//! the connection or esgm's threads meanwhile — and its pixels are in the writer's
//! shared-memory segment, not a copy.
//!
//! Each test keeps one image sample in the reading location, then lets the writer
//! publish many more images (which would reuse any chunk given back too early) and
//! checks every pixel of the kept one.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{TIMEOUT, coordinator};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::value::Octets;
use esgm_core::{
    CacheConstraint, EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy,
    InProcessTrajectory, Sample, SubscribeOptions, Time,
};
use esgm_shm::ShmEsgm;
use esgm_shm::control::CoordinatorThread;

const SIDE: usize = 256;

fn location(c: &CoordinatorThread, host: &str) -> ShmEsgm {
    ShmEsgm::builder().domain(c.domain()).host(host).connect().unwrap()
}

fn image(vt: Time, frame: u64) -> EntityStructure {
    let mut pixels = vec![0u8; SIDE * SIDE];
    common::fill(&mut pixels, frame);
    EntityStructure::new("cam", vt, vt)
        .with("width", SIDE as i64)
        .with("height", SIDE as i64)
        .with("format", 0i64)
        .with("image_data", Octets::from(pixels))
}

fn pixels(s: &Sample) -> Octets {
    s.structure.get("image_data").and_then(|v| v.as_octets()).unwrap()
}

fn assert_frame(s: &Sample, frame: u64, when: &str) {
    let px = pixels(s);
    assert!(px.is_held(), "{when}: the image is no longer read in shared memory");
    let wrong = px.iter().enumerate().filter(|(i, p)| **p != common::pixel(frame, *i)).count();
    assert_eq!(wrong, 0, "{when}: {wrong} pixels of frame {frame} changed under their reader");
}

/// A camera location writing `frames` (cache 3) and a reader location holding one
/// received image, frame 1.
struct Setup {
    _c: common::TestDomain,
    camera: ShmEsgm,
    frames: InProcessTrajectory,
    reader: ShmEsgm,
    kept: Sample,
}

fn setup(prefix: &str) -> Setup {
    let c = coordinator(prefix);
    let camera = location(&c, "camera");
    let reader = location(&c, "reader");
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(3));
    let frames = camera
        .create_trajectory(TrajectorySpec::primitive("frames", "Image").policy(policy))
        .unwrap();
    let there = reader.get_entity_trajectory_structure("frames").unwrap();
    let sub = there.subscribe(SubscribeOptions::default()).unwrap();
    frames.add(image(10, 1)).unwrap();
    let kept = sub.recv_timeout(TIMEOUT).unwrap();
    assert_frame(&kept, 1, "at first");
    Setup { _c: c, camera, frames, reader, kept }
}

/// The writer publishes `n` more frames, each different from frame 1, into whatever
/// trajectory `frames` now is.
fn publish_more(frames: &InProcessTrajectory, from: u64, n: u64) {
    for f in from..from + n {
        frames.add(image(f as Time * 10, f)).unwrap();
    }
}

#[test]
fn a_kept_image_survives_the_destruction_of_its_trajectory() {
    let s = setup("life-destroy");
    // Destroyed by its reader, then by the system: both ends drop their ports.
    s.reader.destroy_entity_trajectory_structure("frames").unwrap();
    assert_frame(&s.kept, 1, "after destroy");
    // A new trajectory of the same name and services, written on: new chunks, never
    // the kept one.
    let frames = s.camera.create_trajectory(TrajectorySpec::primitive("frames", "Image")).unwrap();
    let again = s.reader.get_entity_trajectory_structure("frames").unwrap();
    let sub = again.subscribe(SubscribeOptions::default()).unwrap();
    publish_more(&frames, 100, 40);
    assert!(sub.recv_timeout(TIMEOUT).is_ok(), "the new trajectory is read");
    assert_frame(&s.kept, 1, "after the name was re-created and written");
    drop(s.frames);
}

#[test]
fn a_kept_image_survives_its_connection() {
    let s = setup("life-disconnect");
    let Setup { _c, camera, frames, reader, kept } = s;
    drop(reader);
    publish_more(&frames, 2, 40);
    assert_frame(&kept, 1, "after the reader's connection was dropped");
    drop(camera);
    assert_frame(&kept, 1, "after the writer's connection was dropped");
}

#[test]
fn a_kept_image_survives_panics_of_esgm_threads() {
    let s = setup("life-panic");
    s.reader.inject_thread_panics_for_tests();
    s.camera.inject_thread_panics_for_tests();
    // The panicked threads are gone (the reader no longer receives); the writer's
    // adds still publish from the adding thread.
    std::thread::sleep(std::time::Duration::from_millis(200));
    publish_more(&s.frames, 2, 40);
    assert_frame(&s.kept, 1, "after the location and receiver threads panicked");
    let Setup { _c, camera, frames, reader, kept } = s;
    drop((reader, frames, camera));
    assert_frame(&kept, 1, "after the connections with panicked threads were dropped");
}

#[test]
fn a_readers_pixels_live_in_the_kept_history_mapped_read_only() {
    let s = setup("life-segment");
    let px = pixels(&s.kept);
    let (start, end) = (px.as_ptr() as usize, px.as_ptr() as usize + px.len());
    let maps = std::fs::read_to_string("/proc/self/maps").unwrap();
    let mapping = maps
        .lines()
        .find(|line| {
            let Some((range, _)) = line.split_once(' ') else { return false };
            let Some((lo, hi)) = range.split_once('-') else { return false };
            let lo = usize::from_str_radix(lo, 16).unwrap_or(usize::MAX);
            let hi = usize::from_str_radix(hi, 16).unwrap_or(0);
            lo <= start && end <= hi
        })
        .unwrap_or_else(|| panic!("no mapping holds the pixels at {start:#x}"));
    // A kept trajectory's image lies in its kept history, where the camera wrote it
    // (written once, P7), and the reader maps that file read-only.
    assert!(
        mapping.contains("/dev/shm/esgm_keep@"),
        "the pixels are not in the trajectory's kept history: {mapping}"
    );
    let permissions = mapping.split_whitespace().nth(1).unwrap_or_default();
    assert_eq!(permissions, "r--s", "the reader maps the kept history read-only: {mapping}");
    assert!(px.is_held());
    drop(s.frames);
}

/// A camera that renders each frame into the buffer its trajectory hands it.
struct LoanedCamera;

impl esgm_core::SensorInterface for LoanedCamera {
    fn get_current_value(&self, _qtime: Time) -> Result<EntityStructure, esgm_core::SensorError> {
        Err(esgm_core::SensorError::Failed { reason: "renders only into a buffer".into() })
    }

    fn get_current_value_with(
        &self,
        qtime: Time,
        images: &dyn esgm_core::OctetsAllocator,
    ) -> Result<EntityStructure, esgm_core::SensorError> {
        let side = SIDE as i64;
        let format = esgm_core::library::Image::FORMAT_MONO8;
        let mut buffer = images
            .image(side, side, format)
            .ok_or_else(|| esgm_core::SensorError::Failed { reason: "no buffer".into() })?;
        common::fill(buffer.pixels_mut(), qtime as u64);
        Ok(EntityStructure::new("cam", qtime, qtime)
            .with("width", side)
            .with("height", side)
            .with("format", format)
            .with("image_data", buffer.into_octets()))
    }
}

#[test]
fn a_camera_behind_connect_writes_each_frame_once_in_shared_memory() {
    let c = coordinator("life-camera");
    let camera = location(&c, "camera");
    let reader = location(&c, "reader");
    camera.add_sensor_interface("cam", "Image", std::sync::Arc::new(LoanedCamera)).unwrap();
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(3));
    let spec =
        TrajectorySpec::sampled("frames", "cam", esgm_core::millis(20)).unwrap().policy(policy);
    let frames = reader.create_trajectory(spec).unwrap();
    let sub = frames.subscribe(SubscribeOptions::default()).unwrap();
    for _ in 0..10 {
        let s = sub.recv_timeout(TIMEOUT).unwrap();
        assert_frame(&s, s.structure.valid_time() as u64, "a frame read in another process");
    }
    // The camera's own process reads its frames through the sample it sent, too.
    let own = camera.get_entity_trajectory_structure("frames").unwrap();
    let latest = own.get_latest().unwrap();
    assert_frame(&latest, latest.structure.valid_time() as u64, "the writer's own cache");
    let sent = camera.holding_stats().unwrap();
    assert!(sent.sent_in_place >= 10, "{sent:?}");
    assert_eq!(sent.copies(), 0, "no image copied by the camera's process: {sent:?}");
    assert_eq!(reader.holding_stats().unwrap().copies(), 0, "nor by the reader's");
}
