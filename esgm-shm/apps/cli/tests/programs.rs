//! `program = "NAME_OR_PATH"` end to end: a sensor and a unit of the user's own, named
//! by a bare name `esgm apply` finds on its PATH, run by the supervisor with the
//! worker's environment, arguments and extra environment; and a program that is not
//! there refused at apply, naming the file's line, before anything changes. Real
//! processes, unique domains, a watchdog on every command and wait.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::ffi::OsString;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{ESGM, Output, PATIENCE, StopOnDrop, esgm, finish, ok};

/// Writes an executable shell script `name` into `dir`.
fn script(dir: &Path, name: &str, body: &str) {
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// `bin` first, then this process's PATH.
fn path_with(bin: &Path) -> OsString {
    let inherited = std::env::var_os("PATH").unwrap_or_default();
    std::env::join_paths(
        std::iter::once(bin.to_path_buf()).chain(std::env::split_paths(&inherited)),
    )
    .unwrap()
}

/// Runs `esgm args…` with `PATH=path`, killing it after [`PATIENCE`].
fn esgm_on(path: &OsString, args: &[&str]) -> Output {
    let child = Command::new(ESGM)
        .args(args)
        .env("PATH", path)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run esgm");
    finish(child, PATIENCE, &args.join(" "))
}

/// Polls `esgm latest traj` until it prints a sample, or fails after `limit`.
fn wait_for_sample(d: &str, traj: &str, limit: Duration) {
    let deadline = Instant::now() + limit;
    loop {
        let o = esgm(&["--domain", d, "latest", traj], PATIENCE);
        if o.code == Some(0) && !o.stdout.trim().is_empty() {
            return;
        }
        assert!(Instant::now() < deadline, "no sample in `{traj}` within {limit:?}: {}", o.stderr);
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Waits for `path` to exist and returns what it holds, or fails after `limit`.
fn wait_for_file(path: &Path, limit: Duration) -> String {
    let deadline = Instant::now() + limit;
    loop {
        if let Ok(text) = std::fs::read_to_string(path) {
            if text.ends_with('\n') {
                return text;
            }
        }
        assert!(Instant::now() < deadline, "{} was not written within {limit:?}", path.display());
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn programs_named_by_a_bare_name_are_found_on_path_and_run_as_workers() {
    let d = esgm_shm::unique_domain("cli-program");
    let state = tempfile::tempdir().unwrap();
    let bin = tempfile::tempdir().unwrap();
    let marks = tempfile::tempdir().unwrap();
    // Programs of the user's own, standing in for a C++ camera and unit: each notes how
    // it was started, then serves what esgm's own workers serve under the declared name.
    let note = format!(
        "printf '%s\\n' \"ESGM_NAME=$ESGM_NAME\" \"ESGM_WORKER=$ESGM_WORKER\" \
         \"ESGM_DOMAIN=$ESGM_DOMAIN\" \"LENS=$LENS\" \"ARGS=$*\" > {}/\"$ESGM_NAME\".tmp\n\
         mv {0}/\"$ESGM_NAME\".tmp {0}/\"$ESGM_NAME\".started\n",
        marks.path().display()
    );
    script(
        bin.path(),
        "esgm_test_camera",
        &format!("{note}exec '{ESGM}' worker camera --name \"$ESGM_NAME\" \"$@\"\n"),
    );
    script(
        bin.path(),
        "esgm_test_blob_unit",
        &format!("{note}exec '{ESGM}' worker unit \"$ESGM_NAME\" --builtin BlobDetection\n"),
    );
    let config = tempfile::tempdir().unwrap();
    let file = config.path().join("system.toml");
    std::fs::write(
        &file,
        r#"[[sensor]]
name = "lens"
program = "esgm_test_camera"
args = ["--blobs", "2", "--width", "160", "--height", "120"]
env = { LENS = "wide" }

[[unit]]
name = "Finder"
program = "esgm_test_blob_unit"

[[trajectory]]
name = "images"
sampled = "lens"
period = "100ms"
policy = { cache = 3 }

[[trajectory]]
name = "blobs"
computed = "Finder"
inputs = ["images"]
"#,
    )
    .unwrap();
    let file = file.to_str().unwrap();

    // `esgm up` runs without the programs' directory on its PATH: the supervisor runs
    // the path `esgm apply` found, so what was checked is what runs.
    ok(&["--domain", &d, "up", "--detach", "--state-dir", state.path().to_str().unwrap()]);
    let _stop = StopOnDrop(d.clone());
    let applied = esgm_on(&path_with(bin.path()), &["--domain", &d, "apply", file]);
    assert_eq!(applied.code, Some(0), "apply failed:\n{}\n{}", applied.stdout, applied.stderr);
    for (kind, name) in [("sensor", "lens"), ("unit", "Finder")] {
        assert!(
            applied.stdout.lines().any(|l| l.starts_with(kind)
                && l.split_whitespace().nth(1) == Some(name)
                && l.contains("registered")),
            "{kind} `{name}` not registered:\n{}",
            applied.stdout
        );
    }

    // Started as any worker: the domain, its process name and the declared name in its
    // environment, with the declaration's arguments and environment.
    let camera = wait_for_file(&marks.path().join("lens.started"), PATIENCE);
    for expected in [
        "ESGM_NAME=lens\n",
        "ESGM_WORKER=camera-lens\n",
        &format!("ESGM_DOMAIN={d}\n"),
        "LENS=wide\n",
        "ARGS=--blobs 2 --width 160 --height 120\n",
    ] {
        assert!(camera.contains(expected), "`{expected}` missing in:\n{camera}");
    }
    let unit = wait_for_file(&marks.path().join("Finder.started"), PATIENCE);
    assert!(unit.contains("ESGM_WORKER=unit-Finder\n") && unit.contains("ARGS=\n"), "{unit}");

    // `esgm ps` lists them running, as the programs found on PATH.
    let ps = ok(&["--domain", &d, "--json", "ps"]);
    let processes: Vec<serde_json::Value> =
        ps.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    for (process, program) in
        [("camera-lens", "esgm_test_camera"), ("unit-Finder", "esgm_test_blob_unit")]
    {
        let p = processes
            .iter()
            .find(|p| p["spec"]["name"] == process)
            .unwrap_or_else(|| panic!("no process `{process}` in:\n{ps}"));
        assert_eq!(p["spec"]["program"], bin.path().join(program).to_str().unwrap(), "{ps}");
        assert!(p["status"]["pid"].is_u64(), "`{process}` is not running:\n{ps}");
    }
    // And their data flows: the unit computes blobs from the camera's images.
    wait_for_sample(&d, "blobs", Duration::from_secs(60));
    ok(&["--domain", &d, "down"]);
}

#[test]
fn a_program_that_is_not_there_is_refused_at_apply_and_nothing_changes() {
    let d = esgm_shm::unique_domain("cli-no-program");
    let state = tempfile::tempdir().unwrap();
    let bin = tempfile::tempdir().unwrap();
    let config = tempfile::tempdir().unwrap();
    let file = config.path().join("system.toml");
    // Line 9 declares the unit whose program was never built.
    std::fs::write(
        &file,
        r#"[[type]]
name = "Waypoint"
attributes = ["x: Double", "y: Double"]

[[trajectory]]
name = "waypoints"
primitive = "Waypoint"

[[unit]]
name = "DrivingDirection"
program = "driving_direction_unit"

[[trajectory]]
name = "steering"
computed = "DrivingDirection"
inputs = ["waypoints"]
"#,
    )
    .unwrap();
    let file = file.to_str().unwrap();
    ok(&["--domain", &d, "up", "--detach", "--state-dir", state.path().to_str().unwrap()]);
    let _stop = StopOnDrop(d.clone());

    let path = path_with(bin.path());
    for args in
        [vec!["--domain", &d, "apply", file], vec!["--domain", &d, "apply", "--dry-run", file]]
    {
        let o = esgm_on(&path, &args);
        assert_eq!(
            o.code,
            Some(1),
            "`esgm {}` should fail:\n{}\n{}",
            args.join(" "),
            o.stdout,
            o.stderr
        );
        let line = o.stderr.trim();
        let expected = format!(
            "esgm: {file}:9: unit `DrivingDirection`: program `driving_direction_unit` is not on \
             PATH (PATH={})",
            path.to_str().unwrap()
        );
        assert_eq!(line, expected, "one line naming the file, line, unit and program");
        assert!(o.stdout.is_empty(), "nothing was reported as applied:\n{}", o.stdout);
    }

    // Nothing of the file was applied: no type, trajectory or process.
    let types = ok(&["--domain", &d, "type", "list"]);
    assert!(!types.contains("Waypoint"), "{types}");
    let trajectories = ok(&["--domain", &d, "traj", "list"]);
    assert!(!trajectories.contains("waypoints"), "{trajectories}");
    let ps = ok(&["--domain", &d, "--json", "ps"]);
    assert!(!ps.contains("DrivingDirection"), "{ps}");
    ok(&["--domain", &d, "down"]);
}
