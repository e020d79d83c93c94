//! esgm-view against an independent client on the protocol's spec name,
//! `foxglove.websocket.v1`: `@foxglove/ws-protocol`'s `FoxgloveClient` (the npm package
//! Lichtblick and older Foxglove Studio are built on) over `ws`, run by Node.js
//! (`tests/node/v1_client.mjs`). It subscribes to every channel and decodes an image
//! (protobuf, from the advertised schema) and a structure (JSON). Its packages are
//! installed here from the committed lock file (`npm ci`) into the test's target
//! directory. Without Node.js the test is skipped, and fails in CI (`CI` set).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::library::{Image, RobotState};
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, TypeRegistry};
use esgm_view::ViewServer;
use serde_json::Value;

/// The client's own deadline is 20 s; this one covers a slow start.
const DEADLINE: Duration = Duration::from_secs(60);

fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The client's directory with its packages installed, or `None` (skipped) without
/// Node.js outside CI.
fn client_dir() -> Option<PathBuf> {
    if !have("node") || !have("npm") {
        assert!(
            std::env::var_os("CI").is_none(),
            "Node.js and npm are needed for the Foxglove v1 client test (.ci/run installs them)"
        );
        eprintln!("skipped: no node or npm");
        return None;
    }
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/node");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("foxglove-v1-client");
    std::fs::create_dir_all(&dir).unwrap();
    let lock = std::fs::read(source.join("package-lock.json")).unwrap();
    let installed = dir.join("node_modules/.esgm-lock");
    if std::fs::read(&installed).ok().as_deref() != Some(&lock[..]) {
        for file in ["package.json", "package-lock.json"] {
            std::fs::copy(source.join(file), dir.join(file)).unwrap();
        }
        let status = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--loglevel=error"])
            .current_dir(&dir)
            .status()
            .expect("run npm ci");
        assert!(status.success(), "npm ci failed in {}", dir.display());
        std::fs::write(&installed, &lock).unwrap();
    }
    std::fs::copy(source.join("v1_client.mjs"), dir.join("v1_client.mjs")).unwrap();
    Some(dir)
}

#[test]
fn a_foxglove_websocket_v1_client_subscribes_and_decodes_an_image_and_a_structure() {
    let Some(client) = client_dir() else { return };
    let domain = esgm_shm::unique_domain("view-v1");
    let registry = esgm_shm::control::Registry::new(TypeRegistry::with_library());
    let _coordinator = esgm_shm::control::Coordinator::spawn(&domain, registry).unwrap();
    let writer = esgm_shm::ShmEsgm::builder().domain(&domain).connect().unwrap();
    let camera = writer.create_trajectory(TrajectorySpec::primitive("camera", "Image")).unwrap();
    let robot = writer.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    let server = ViewServer::builder(&domain).port(0).start().unwrap();

    // Both keep coming until the client has its messages: 4×2 rgb8 images whose first
    // pixel is (7, 20, 30), and robot states at x = 1.5.
    let t0 = 1_700_000_000_000_000_000_i64;
    let stop = Arc::new(AtomicBool::new(false));
    let adding = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let mut i = 0_i64;
            while !stop.load(Ordering::SeqCst) {
                let t = t0 + i * 1_000_000;
                let mut pixels = vec![0_u8; 4 * 2 * 3];
                pixels[..3].copy_from_slice(&[7, 20, 30]);
                let image = Image {
                    width: 4,
                    height: 2,
                    format: Image::FORMAT_RGB8,
                    image_data: pixels.into(),
                };
                camera.add(image.to_structure("cam", t, t)).unwrap();
                robot
                    .add(RobotState { x: 1.5, y: -2.0, dir: 90.0 }.to_structure("r1", t, t))
                    .unwrap();
                i += 1;
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };

    let url = format!("ws://127.0.0.1:{}", server.port());
    let mut node = Command::new("node")
        .arg(client.join("v1_client.mjs"))
        .args([url.as_str(), "/camera", "/robot"])
        .current_dir(&client)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start node");
    let deadline = Instant::now() + DEADLINE;
    while node.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            node.kill().unwrap();
            panic!("the v1 client did not finish within {DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    stop.store(true, Ordering::SeqCst);
    adding.join().unwrap();
    let out = node.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "the v1 client failed:\n{stdout}\n{stderr}");

    let lines: Vec<Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let line = |key: &str, value: &str| {
        lines
            .iter()
            .find(|l| l[key] == value)
            .unwrap_or_else(|| panic!("no line with {key} = {value}:\n{stdout}"))
    };
    line("protocol", "foxglove.websocket.v1");
    let image = line("topic", "/camera");
    assert_eq!(image["schemaName"], "foxglove.RawImage");
    assert_eq!(image["encoding"], "protobuf");
    let m = &image["message"];
    assert_eq!((m["width"].as_u64(), m["height"].as_u64()), (Some(4), Some(2)), "{m}");
    assert_eq!(m["encoding"], "rgb8");
    assert_eq!(m["data"], serde_json::json!([7, 20, 30]), "the first pixel");
    assert_eq!(m["dataLength"], 24);
    let structure = line("topic", "/robot");
    assert_eq!(structure["encoding"], "json");
    assert_eq!(structure["message"]["x"], 1.5);
    assert_eq!(structure["message"]["dir"], 90.0);
    let time: i64 = structure["timestamp"].as_str().unwrap().parse().unwrap();
    assert!(time >= t0, "log time is the valid time: {time}");
}
