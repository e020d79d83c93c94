//! `esgm push`, `esgm reset` and `esgm log-level` against a running system with a
//! robot program in this test process: what the commands do is seen by the program
//! (its trajectory, its log level), in another process than the command's.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::time::{Duration, Instant};

use common::{PATIENCE, StopOnDrop, esgm, ok};
use esgm_core::esgm::LogLevel;
use esgm_core::prelude::*;
use esgm_core::{OrderConstraint, QueryError};

fn wait_for(mut cond: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    false
}

#[test]
fn push_reset_and_log_level_reach_the_running_program() {
    let d = esgm_shm::unique_domain("cli-admin");
    ok(&["--domain", &d, "up", "--detach"]);
    let _stop = StopOnDrop(d.clone());
    let program = esgm_shm::ShmEsgm::builder().domain(&d).host("robot-program").connect().unwrap();
    let policy = FluentStreamPolicy::default().order(OrderConstraint::Monotone);
    let robot = program
        .create_trajectory(TrajectorySpec::primitive("robot", "RobotState").policy(policy))
        .unwrap();

    // push: typed by the trajectory's type, added through the program's gate.
    let out =
        ok(&["--domain", &d, "push", "robot", "x=1.5", "y=2", "dir=0", "--valid-time", "1000"]);
    assert!(out.contains("added"), "{out}");
    assert!(wait_for(|| robot.get_latest().is_ok()), "the push never reached the program");
    let s = robot.get_latest().unwrap();
    assert_eq!((s.valid_time(), s.get("x").and_then(|v| v.as_double())), (1000, Some(1.5)));
    // The gate's violation comes back, and fails the command.
    let late = esgm(
        &["--domain", &d, "push", "robot", "x=0", "y=0", "dir=0", "--valid-time", "500"],
        PATIENCE,
    );
    assert_eq!(late.code, Some(1), "{}{}", late.stdout, late.stderr);
    assert!(late.stderr.contains("order"), "{}", late.stderr);
    // Checked against the type before anything is sent.
    for (args, says) in [
        (["x=1", "y=2", "z=3"], "has no attribute `z`"),
        (["x=one", "y=2", "dir=0"], "is not a number"),
    ] {
        let mut cmd = vec!["--domain", &d, "push", "robot"];
        cmd.extend(args);
        let o = esgm(&cmd, PATIENCE);
        assert_eq!(o.code, Some(1), "{}{}", o.stdout, o.stderr);
        assert!(o.stderr.contains(says), "{}", o.stderr);
    }
    assert_eq!(robot.stats().unwrap().added, 1);

    // log-level: one process by name, then all; an unknown level is refused.
    let out = ok(&["--domain", &d, "log-level", "debug", "--process", "robot-program"]);
    assert!(out.contains("robot-program"), "{out}");
    assert_eq!(program.log_level(), LogLevel::Debug);
    let o = esgm(&["--domain", &d, "log-level", "debug", "--process", "nobody"], PATIENCE);
    assert_eq!(o.code, Some(1), "{}{}", o.stdout, o.stderr);
    ok(&["--domain", &d, "log-level", "warn"]);
    assert_eq!(program.log_level(), LogLevel::Warn);
    let o = esgm(&["--domain", &d, "log-level", "loud"], PATIENCE);
    assert_eq!(o.code, Some(1));
    assert!(o.stderr.contains("not a log level"), "{}", o.stderr);

    // reset: the program's trajectory is empty when the command returns.
    ok(&["--domain", &d, "reset", "robot"]);
    assert!(matches!(robot.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    let out = ok(&["--domain", &d, "push", "robot", "x=3", "y=0", "dir=0", "--valid-time", "2000"]);
    assert!(out.contains("added"), "{out}");
    assert!(wait_for(|| robot.get_latest().is_ok()));
    ok(&["--domain", &d, "reset"]);
    assert!(robot.get_latest().is_err(), "a reset of the system empties it too");
}
