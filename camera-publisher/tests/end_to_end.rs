//! The `camera-publisher` binary end to end: a coordinator in this process, the real
//! binary serving its camera to it, and this process sampling the camera through
//! shared memory. Every wait has a watchdog that fails the test, and the camera is
//! killed when a test ends, also when it fails.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Read;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use camera_publisher::{FrameSource, SyntheticScene};
use esgm_core::library::Image;
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, Time, TypeRegistry, millis};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

const CAMERA: &str = env!("CARGO_BIN_EXE_camera-publisher");

/// Long enough for a debug build on a loaded 2-core machine; only a hang reaches it.
const WATCHDOG: Duration = Duration::from_secs(60);

/// The camera process; killed on drop unless it has already left.
struct Camera(Child);

impl Camera {
    fn start(args: &[&str]) -> Self {
        let child = Command::new(CAMERA)
            .args(args)
            .env_remove(esgm_shm::WORKER_ENV)
            .env_remove(esgm_shm::DOMAIN_ENV)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start camera-publisher");
        Self(child)
    }

    /// Its exit status, if it has exited, with what it printed on stderr.
    fn exited(&mut self) -> Option<(ExitStatus, String)> {
        let status = self.0.try_wait().unwrap()?;
        let mut stderr = String::new();
        if let Some(mut pipe) = self.0.stderr.take() {
            pipe.read_to_string(&mut stderr).unwrap();
        }
        Some((status, stderr))
    }

    /// Polls `probe` until it gives a value; fails if the camera exits or the watchdog
    /// expires first.
    fn wait_for<T>(&mut self, what: &str, mut probe: impl FnMut() -> Option<T>) -> T {
        let deadline = Instant::now() + WATCHDOG;
        loop {
            if let Some(t) = probe() {
                return t;
            }
            if let Some((status, stderr)) = self.exited() {
                panic!("camera-publisher exited ({status}) before {what}:\n{stderr}");
            }
            assert!(Instant::now() < deadline, "no {what} within {WATCHDOG:?}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the camera to leave on its own.
    fn wait_exit(&mut self, why: &str) -> (ExitStatus, String) {
        let deadline = Instant::now() + WATCHDOG;
        loop {
            if let Some(exit) = self.exited() {
                return exit;
            }
            assert!(Instant::now() < deadline, "camera-publisher did not exit ({why})");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Camera {
    fn drop(&mut self) {
        if self.0.try_wait().ok().flatten().is_none() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

#[test]
fn serves_the_scene_to_a_sampled_trajectory_and_leaves_with_the_coordinator() {
    let domain = unique_domain("camera-e2e");
    let coordinator =
        Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library())).unwrap();
    let mut camera = Camera::start(&[
        "--domain", &domain, "--name", "cam", "--seed", "7", "--blobs", "2", "--width", "64",
        "--height", "48",
    ]);
    let esgm = ShmEsgm::builder().domain(&domain).connect().unwrap();
    camera.wait_for("the sensor `cam`", || {
        esgm.sensors().contains(&("cam".to_owned(), Image::TYPE_NAME.to_owned())).then_some(())
    });

    let images = esgm.create_entity_trajectory_structure("images", "cam", 0, 0, millis(100), 0, 5);
    let images = images.unwrap();
    let samples = camera.wait_for("three images", || {
        images.get_between(0, Time::MAX).ok().filter(|s| s.len() >= 3)
    });
    // Each image is the scene's frame at its valid time, rendered in the camera process.
    let scene = SyntheticScene::builder().width(64).height(48).blobs(2).seed(7).create().unwrap();
    for sample in &samples {
        assert_eq!(sample.name, "image");
        let image = Image::from_structure(sample).unwrap();
        assert_eq!((image.width, image.height, image.format), (64, 48, Image::FORMAT_RGB8));
        assert_eq!(image.image_data.len(), scene.frame_len());
        assert!(image == scene.frame(sample.valid_time), "not the frame at {}", sample.valid_time);
    }
    assert!(samples.windows(2).all(|w| w[0].valid_time < w[1].valid_time));

    drop((images, esgm, coordinator));
    let (status, stderr) = camera.wait_exit("after the coordinator was gone");
    assert!(status.success(), "camera-publisher failed ({status}):\n{stderr}");
}

#[test]
fn without_a_coordinator_it_fails_with_one_line() {
    let domain = unique_domain("camera-e2e-none");
    let (status, stderr) = Camera::start(&["--domain", &domain]).wait_exit("without a system");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!("camera-publisher: cannot reach the system `{domain}`")),
        "{stderr}"
    );
}

#[test]
fn bad_settings_fail_before_connecting() {
    let (status, stderr) = Camera::start(&["--width", "0", "--domain", &unique_domain("cam")])
        .wait_exit("with a zero width");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(stderr.starts_with("camera-publisher: cannot build the synthetic scene"), "{stderr}");

    let (status, stderr) = Camera::start(&["--dir", "frames", "--seed", "1"]).wait_exit("misused");
    assert_eq!(status.code(), Some(2), "a usage error: {stderr}");
}

#[test]
fn renders_one_frame_offline() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("frame.ppm");
    let mut camera = Camera::start(&[
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
    ]);
    let (status, stderr) = camera.wait_exit("after one frame");
    assert!(status.success(), "{stderr}");
    let mut stdout = String::new();
    camera.0.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    assert!(stdout.contains("32x24 RGB8 frame at t=1000000000 ns"), "{stdout}");
    assert!(stdout.contains("blob at"), "{stdout}");

    let scene = SyntheticScene::builder().width(32).height(24).blobs(1).create().unwrap();
    let mut expected = b"P6\n32 24\n255\n".to_vec();
    expected.extend_from_slice(&scene.frame(1_000_000_000).image_data);
    assert!(std::fs::read(&out).unwrap() == expected, "the PPM is not the frame");
}
