//! `esgm demo --config FILE` end to end: the tutorial as a file declares it (here with
//! its DrivingDirection unit as a program of the user's own, at a path relative to the
//! file, as a C++ unit would be) runs through the demo's printing and checks; a file
//! that is not the tutorial is refused before anything starts. Real processes, unique
//! domains, a watchdog on every command.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::os::unix::fs::PermissionsExt;
use std::time::Duration;

use common::{ESGM, esgm};

/// The tutorial `esgm demo` runs by itself.
const TUTORIAL: &str = include_str!("../tutorial.toml");

/// As long as the plain demo's own test gives it (debug build, 2-core machine).
const DEMO_PATIENCE: Duration = Duration::from_secs(90);

#[test]
fn the_demo_runs_the_system_a_file_declares() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("bin")).unwrap();
    let unit = dir.path().join("bin/driving_direction");
    std::fs::write(
        &unit,
        format!("#!/bin/sh\nexec '{ESGM}' worker unit \"$ESGM_NAME\" --builtin DrivingDirection\n"),
    )
    .unwrap();
    std::fs::set_permissions(&unit, std::fs::Permissions::from_mode(0o755)).unwrap();
    let declared = "[[unit]]\nname = \"DrivingDirection\"\n";
    assert!(TUTORIAL.contains(declared), "tutorial.toml declares DrivingDirection otherwise");
    let text =
        TUTORIAL.replace(declared, &format!("{declared}program = \"bin/driving_direction\"\n"));
    let file = dir.path().join("tutorial.toml");
    std::fs::write(&file, text).unwrap();
    let file = file.to_str().unwrap();

    let d = esgm_shm::unique_domain("cli-demo-config");
    let o = esgm(&["--domain", &d, "demo", "--config", file, "--seconds", "3"], DEMO_PATIENCE);
    assert_eq!(o.code, Some(0), "demo failed:\n{}\n{}", o.stdout, o.stderr);
    for expected in [
        &format!("esgm demo: the tutorial of {file} as separate processes"),
        "started unit-DrivingDirection",
        "driving_direction as it changes",
        "latency of each stage",
        "image copies in all: 0\n",
        "consistent: the robot follows the largest blob",
        "stopped: coordinator and 5 workers",
    ] {
        assert!(o.stdout.contains(expected), "missing `{expected}` in:\n{}", o.stdout);
    }
    // At least one direction was printed: `t [s]` rows start with a number.
    let after = o.stdout.split_once("driving_direction as it changes").unwrap().1;
    let rows = after
        .lines()
        .skip(2)
        .take_while(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
        .count();
    assert!(rows > 0, "no driving direction printed:\n{}", o.stdout);
}

#[test]
fn a_file_without_the_tutorials_driving_direction_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let last = "[[trajectory]]\nname = \"driving_direction\"";
    let cut = TUTORIAL.find(last).expect("tutorial.toml declares driving_direction last");
    let file = dir.path().join("no_direction.toml");
    std::fs::write(&file, &TUTORIAL[..cut]).unwrap();
    let file = file.to_str().unwrap();

    let d = esgm_shm::unique_domain("cli-demo-config-refused");
    let o = esgm(&["--domain", &d, "demo", "--config", file, "--seconds", "3"], DEMO_PATIENCE);
    assert_eq!(o.code, Some(1), "should be refused:\n{}\n{}", o.stdout, o.stderr);
    let line = o.stderr.trim();
    assert_eq!(line.lines().count(), 1, "one line: {line}");
    assert!(line.starts_with(&format!("esgm: {file}: ")), "{line}");
    assert!(line.contains("declares no trajectory `driving_direction`"), "{line}");
    assert!(!line.contains("`blobs`"), "names only what is missing: {line}");
    assert!(o.stdout.is_empty(), "nothing started:\n{}", o.stdout);
}
