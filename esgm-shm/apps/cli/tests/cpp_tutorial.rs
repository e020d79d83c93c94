//! The seed's tutorial with a C++ camera and a C++ unit (SPEC L3): the examples of
//! `esgm-shm/cpp/examples` are built with CMake against the esgm package of this
//! checkout (linked to the `libesgm_c.so` this test run built), put on PATH, and
//! `esgm demo --config esgm-shm/cpp/examples/tutorial_cpp.toml` runs the system they
//! are declared in: driving directions appear, the selected blob matches the scene's
//! ground truth (the C++ camera renders the Rust scene), and no process copied an
//! image (the C++ camera renders into loans of the trajectory's shared memory).
//!
//! CMake and a C++ compiler are needed (`.ci/run` installs them): in CI a missing one
//! fails the test; elsewhere it is skipped with a note.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{ESGM, capability};

/// As long as the plain demo's own test gives it (debug build, 2-core machine).
const DEMO_PATIENCE: Duration = Duration::from_secs(120);

fn checkout() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../..").canonicalize().unwrap()
}

/// The directory of the `libesgm_c.so` built with this test: `deps` beside the `esgm`
/// binary, where cargo builds it as this package's dev-dependency, every crate type
/// in the one compilation (the profile directory's copy is refreshed only by `cargo
/// build`, so it may be older).
fn library_dir() -> PathBuf {
    let deps = Path::new(ESGM).parent().unwrap().join("deps");
    assert!(deps.join("libesgm_c.so").is_file(), "no libesgm_c.so in {}", deps.display());
    deps
}

fn run_ok(command: &mut Command, what: &str) {
    let out = command.output().unwrap_or_else(|e| panic!("{what}: cannot run: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn tools() -> Result<(), String> {
    capability::runs("cmake", &["--version"])?;
    capability::runs("c++", &["--version"])
}

#[test]
fn the_tutorial_runs_with_a_cpp_camera_and_a_cpp_unit() {
    if capability::needs("cmake and a C++ compiler", tools()).is_none() {
        return;
    }
    let build = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cpp-tutorial");
    run_ok(
        Command::new("cmake")
            .arg("-S")
            .arg(checkout().join("esgm-shm/cpp/examples"))
            .arg("-B")
            .arg(&build)
            .arg(format!("-DESGM_LIBRARY_DIR={}", library_dir().display()))
            .arg("-DESGM_WERROR=ON"),
        "cmake configure",
    );
    run_ok(Command::new("cmake").arg("--build").arg(&build).arg("-j2"), "cmake --build");

    let path = format!("{}:{}", build.display(), std::env::var("PATH").unwrap_or_default());
    let file = checkout().join("esgm-shm/cpp/examples/tutorial_cpp.toml");
    let domain = esgm_shm::unique_domain("cli-cpp-tutorial");
    let child = Command::new(ESGM)
        .args(["--domain", &domain, "demo", "--config"])
        .arg(&file)
        .args(["--seconds", "4"])
        .env("PATH", path)
        // cargo runs tests with LD_LIBRARY_PATH naming the profile directory, whose
        // libesgm_c.so may be an older build, and it would win over the programs'
        // RUNPATH (the demo's workers inherit this environment).
        .env("LD_LIBRARY_PATH", library_dir())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let o = common::finish(child, DEMO_PATIENCE, "demo --config tutorial_cpp.toml");
    assert_eq!(o.code, Some(0), "demo failed:\n{}\n{}", o.stdout, o.stderr);
    for expected in [
        "started camera-camera",
        "started unit-DrivingDirection",
        "driving_direction as it changes",
        "image copies in all: 0\n",
        "consistent: the robot follows the largest blob",
    ] {
        assert!(
            o.stdout.contains(expected) || o.stderr.contains(expected),
            "missing `{expected}` in:\n{}\n{}",
            o.stdout,
            o.stderr
        );
    }
    // The C++ camera's frames crossed into the units' processes in shared memory.
    let images = o.stdout.lines().find(|l| l.trim_start().starts_with("camera-camera"));
    let sent = images.and_then(|l| l.split_whitespace().nth(2)).and_then(|n| n.parse::<u64>().ok());
    assert!(sent.is_some_and(|n| n > 0), "the C++ camera sent no image in place:\n{}", o.stdout);
    let after = o.stdout.split_once("driving_direction as it changes").unwrap().1;
    let rows = after
        .lines()
        .skip(2)
        .take_while(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
        .count();
    assert!(rows > 0, "no driving direction printed:\n{}", o.stdout);
}
