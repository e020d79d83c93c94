//! CI's fuzzing: the real `esgm-fuzz` binary runs every target for a few seconds
//! and must report cases for each and no finding.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use esgm_fuzz::targets::NAMES;

#[test]
fn every_target_runs_briefly_without_findings() {
    let findings = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_esgm-fuzz"))
        // Two seconds per target (the nine of `NAMES`: recordings, the slowest, are
        // files written and read, a few hundred cases a second in a debug build).
        .args(["--seconds", &(2 * NAMES.len()).to_string(), "--seed", "16"])
        // A debug build on a loaded machine is slow: only a real hang may count.
        .args(["--hang-ms", "10000"])
        .arg("--findings")
        .arg(findings.path())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut report = String::new();
        out.read_to_string(&mut report).unwrap();
        report
    });
    // Watchdog: the run ends on its own well within this.
    let deadline = Instant::now() + Duration::from_secs(180);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("esgm-fuzz did not end");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let report = reader.join().unwrap();
    assert!(status.success(), "{status}:\n{report}");
    for name in NAMES {
        let row = report.lines().find(|l| l.split_whitespace().next() == Some(name));
        let row = row.unwrap_or_else(|| panic!("no row for {name}:\n{report}"));
        let columns: Vec<&str> = row.split_whitespace().collect();
        let cases: u64 = columns[1].parse().unwrap();
        // panics, hangs, aborts, broken promises
        let found: Vec<u64> = columns[4..8].iter().map(|c| c.parse().unwrap()).collect();
        assert!(cases > 0, "{name} ran no case:\n{report}");
        assert_eq!(found, [0, 0, 0, 0], "{name}:\n{report}");
    }
    assert_eq!(std::fs::read_dir(findings.path()).unwrap().count(), 0, "inputs were saved");
}
