//! The independent reader: `tests/python/read_recording.py`, the `mcap` package from
//! PyPI in a venv, run on a recording. See that script for what it checks and prints.
//!
//! The venv lives in `<workspace>/target/py-venv` and is ready when its
//! `.esgm-requirements` file equals `tests/python/requirements.txt`. `.ci/run` makes it
//! before `cargo test`; when it is missing or stale (a run by hand, a changed
//! requirements file) the first test that needs it builds it. Parallel tests cannot
//! race: within a test binary one thread builds it (a `OnceLock`), and across binaries
//! each builder works in a directory of its own and renames it into place, so a reader
//! only ever sees a complete venv. A venv is movable this way because nothing here runs
//! its scripts, only `bin/python`, which finds its site-packages from where it is.

#![allow(dead_code)] // each test binary uses what it needs of `common`
#![allow(clippy::panic, clippy::expect_used)] // test setup: a failure is a failed test

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

const MARKER: &str = ".esgm-requirements";

/// The workspace root: the nearest directory above the testing crate whose
/// `Cargo.toml` declares the workspace (tests of other crates include this file too).
fn workspace_dir() -> PathBuf {
    let mut dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    loop {
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap_or_default();
        if manifest.contains("[workspace]") {
            return dir;
        }
        assert!(dir.pop(), "no workspace above {}", env!("CARGO_MANIFEST_DIR"));
    }
}

/// The recording crate, where the reader script lives.
fn crate_dir() -> PathBuf {
    workspace_dir().join("esgm-core/recording")
}

/// `<workspace>/target/py-venv`.
pub fn venv_dir() -> PathBuf {
    workspace_dir().join("target/py-venv")
}

fn requirements() -> PathBuf {
    crate_dir().join("tests/python/requirements.txt")
}

fn is_ready(venv: &Path, wanted: &str) -> bool {
    venv.join("bin/python").exists()
        && std::fs::read_to_string(venv.join(MARKER)).is_ok_and(|have| have == wanted)
}

fn run(what: &str, cmd: &mut Command) {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: cannot start {cmd:?}: {e}"));
    if !out.status.success() {
        panic!(
            "{what} failed ({}):\n{}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

fn build_venv(venv: &Path, wanted: &str) {
    let parent = venv.parent().expect("the venv has a parent");
    std::fs::create_dir_all(parent).expect("create target/");
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let tmp = parent.join(format!("py-venv.building.{}.{nanos}", std::process::id()));
    run("python3 -m venv", Command::new("python3").arg("-m").arg("venv").arg(&tmp));
    run(
        "pip install -r tests/python/requirements.txt",
        Command::new(tmp.join("bin/python"))
            .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r"])
            .arg(requirements()),
    );
    std::fs::write(tmp.join(MARKER), wanted).expect("write the venv's marker");

    // A stale venv is moved aside first: rename cannot replace a non-empty directory.
    if venv.exists() && !is_ready(venv, wanted) {
        let stale = parent.join(format!("py-venv.stale.{}.{nanos}", std::process::id()));
        if std::fs::rename(venv, &stale).is_ok() {
            std::fs::remove_dir_all(&stale).expect("remove the stale venv");
        }
    }
    if std::fs::rename(&tmp, venv).is_err() {
        // Another process put its venv there first; use it if it is the one wanted.
        std::fs::remove_dir_all(&tmp).expect("remove the spare venv");
        assert!(is_ready(venv, wanted), "{} exists but is not the venv wanted", venv.display());
    }
}

/// The venv's python, building the venv first if it is missing or stale.
pub fn venv_python() -> &'static Path {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let venv = venv_dir();
        let wanted = std::fs::read_to_string(requirements()).expect("read requirements.txt");
        if !is_ready(&venv, &wanted) {
            build_venv(&venv, &wanted);
        }
        venv.join("bin/python")
    })
}

/// Runs `tests/python/<script>` (called `what` in failures) with `args`, and returns
/// the JSON it printed. Panics with the script's stderr if it fails: a recording it
/// cannot read (or write) is a failed test.
fn run_script(what: &str, script: &str, args: &[&Path]) -> serde_json::Value {
    let script = crate_dir().join("tests/python").join(script);
    let out = Command::new(venv_python())
        .arg(&script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", script.display()));
    if !out.status.success() {
        panic!(
            "{what} failed on {:?} ({}):\n{}",
            args,
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!("{what} printed no JSON ({e}):\n{}", String::from_utf8_lossy(&out.stdout))
    })
}

/// Runs the independent reader (`read_recording.py`, the `mcap` package) on the
/// recording at `path` and returns what it printed.
pub fn independent_reader(path: &Path) -> serde_json::Value {
    run_script("the independent reader", "read_recording.py", &[path])
}

/// Runs the ROS 2 MCAP decoder (`read_ros2.py`, mcap-ros2-support) on the recording at
/// `path`: `{topic: {schema, count, first}}` for its `cdr` channels.
pub fn ros2_reader(path: &Path) -> serde_json::Value {
    run_script("the ROS 2 decoder", "read_ros2.py", &[path])
}

/// Writes a ROS 2 bag at `path` with mcap-ros2-support's writer (`write_ros2_bag.py`,
/// the ROS 2 MCAP profile rosbag2 writes) and returns what it wrote (see the script).
pub fn ros2_bag_writer(path: &Path) -> serde_json::Value {
    run_script("the ROS 2 bag writer", "write_ros2_bag.py", &[path])
}
