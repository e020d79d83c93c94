//! `esgm up --cpu-latency`: the coordinator holds the kernel's CPU latency request for
//! exactly as long as it runs, and a value that is not one is refused before anything
//! starts.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::time::{Duration, Instant};

use common::capability::{needs, root};
use common::{StopOnDrop, esgm, ok};
use esgm_shm::process::cpu_latency::current;

/// Waits up to 30 s for the kernel's CPU latency to read `want`.
fn reads(want: Duration, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let now = current();
        if now == Some(want) {
            return;
        }
        assert!(Instant::now() < deadline, "{what}: the CPU latency reads {now:?}, not {want:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_coordinator_holds_the_cpu_latency_while_it_runs_and_only_then() {
    if needs("root (for /dev/cpu_dma_latency)", root()).is_none() {
        return;
    }
    let before = current().expect("root reads /dev/cpu_dma_latency");
    assert!(before > Duration::from_micros(2), "another process holds it at {before:?}");
    let d = esgm_shm::unique_domain("cli-cpu-latency");
    let state = tempfile::tempdir().expect("state dir");
    let dir = state.path().to_str().expect("utf-8 path");
    let stop = StopOnDrop(d.clone());
    ok(&["--domain", &d, "up", "--detach", "--cpu-latency", "2", "--state-dir", dir]);
    reads(Duration::from_micros(2), "while the coordinator runs");
    ok(&["--domain", &d, "down"]);
    reads(before, "after `esgm down`");
    drop(stop);
}

#[test]
fn a_latency_that_is_not_whole_microseconds_is_refused() {
    let o = esgm(&["up", "--cpu-latency", "0.5"], Duration::from_secs(30));
    assert_eq!(o.code, Some(2), "{o:?}");
    assert!(o.stderr.contains("`0.5` is not a latency in whole microseconds"), "{}", o.stderr);
}
