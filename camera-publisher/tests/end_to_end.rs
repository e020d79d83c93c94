//! The `camera-publisher` binary end to end: a coordinator in this process, the real
//! binary serving its camera to it, and this process sampling the camera through
//! shared memory. Every wait has a watchdog that fails the test, and the camera is
//! killed when a test ends, also when it fails ([`Watched`]).

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use camera_publisher::{FrameSource, SyntheticScene};
use esgm_core::library::Image;
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, Time, TypeRegistry, millis};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};
use support::watched::Watched;

const CAMERA: &str = env!("CARGO_BIN_EXE_camera-publisher");

#[test]
fn serves_the_scene_to_a_sampled_trajectory_and_leaves_with_the_coordinator() {
    let domain = unique_domain("camera-e2e");
    let coordinator =
        Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library())).unwrap();
    let mut camera = Watched::start(
        CAMERA,
        &[
            "--domain", &domain, "--name", "cam", "--seed", "7", "--blobs", "2", "--width", "64",
            "--height", "48",
        ],
    );
    let esgm = ShmEsgm::builder().domain(&domain).connect().unwrap();
    camera.wait_for("the sensor `cam`", || {
        esgm.sensors()
            .unwrap()
            .contains(&("cam".to_owned(), Image::TYPE_NAME.to_owned()))
            .then_some(())
    });

    let images = esgm.create_entity_trajectory_structure("images", "cam", 0, 0, millis(100), 0, 5);
    let images = images.unwrap();
    let samples = camera.wait_for("three images", || {
        images.get_between(0, Time::MAX).ok().filter(|s| s.len() >= 3)
    });
    // Each image is the scene's frame at its valid time, rendered in the camera process.
    let scene = SyntheticScene::builder().width(64).height(48).blobs(2).seed(7).create().unwrap();
    for sample in &samples {
        assert_eq!(sample.name(), "image");
        let image = Image::from_shared(sample).unwrap();
        assert_eq!((image.width, image.height, image.format), (64, 48, Image::FORMAT_RGB8));
        assert_eq!(image.image_data.len(), scene.frame_len());
        assert!(
            image == scene.frame(sample.valid_time()),
            "not the frame at {}",
            sample.valid_time()
        );
    }
    assert!(samples.windows(2).all(|w| w[0].valid_time() < w[1].valid_time()));

    drop((images, esgm, coordinator));
    let (status, stderr) = camera.wait_exit("after the coordinator was gone");
    assert!(status.success(), "camera-publisher failed ({status}):\n{stderr}");
}

#[test]
fn without_a_coordinator_it_fails_with_one_line() {
    let domain = unique_domain("camera-e2e-none");
    let (status, stderr) =
        Watched::start(CAMERA, &["--domain", &domain]).wait_exit("without a system");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!("camera-publisher: cannot reach the system `{domain}`")),
        "{stderr}"
    );
}

#[test]
fn bad_settings_fail_before_connecting() {
    let (status, stderr) =
        Watched::start(CAMERA, &["--width", "0", "--domain", &unique_domain("cam")])
            .wait_exit("with a zero width");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(stderr.starts_with("camera-publisher: cannot build the synthetic scene"), "{stderr}");

    let (status, stderr) =
        Watched::start(CAMERA, &["--dir", "frames", "--seed", "1"]).wait_exit("misused");
    assert_eq!(status.code(), Some(2), "a usage error: {stderr}");
}

#[test]
fn renders_one_frame_offline() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("frame.ppm");
    let mut camera = Watched::start(
        CAMERA,
        &[
            "--render-once",
            "--width",
            "32",
            "--height",
            "24",
            "--blobs",
            "1",
            "--time",
            "1000000000",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let (status, stderr) = camera.wait_exit("after one frame");
    assert!(status.success(), "{stderr}");
    let stdout = camera.stdout();
    assert!(stdout.contains("32x24 RGB8 frame at t=1000000000 ns"), "{stdout}");
    assert!(stdout.contains("blob at"), "{stdout}");

    let scene = SyntheticScene::builder().width(32).height(24).blobs(1).create().unwrap();
    let mut expected = b"P6\n32 24\n255\n".to_vec();
    expected.extend_from_slice(&scene.frame(1_000_000_000).image_data);
    assert!(std::fs::read(&out).unwrap() == expected, "the PPM is not the frame");
}
