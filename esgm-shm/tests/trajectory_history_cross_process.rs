//! A trajectory's writer and its readers in separate processes: this test binary
//! spawns itself as the writer (selected by an environment variable).
//!
//! Parent: a reader and a violations subscriber, then the child, then a late reader;
//! everything they see is compared with an in-process store fed the same script.
//! Child: the writer, gating the script, keeping its history for late readers until
//! the parent acknowledges. Every wait has a timeout; the parent kills a child that
//! overstays.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
mod history_support;

use std::thread;
use std::time::{Duration, Instant};

use common::{TIMEOUT, node};
use esgm_core::{EntityStructure, PolicyViolation, SimClock};
use esgm_shm::{
    ShmTrajectoryReader, ShmTrajectoryWriter, TrajectoryPublisher, TrajectoryQos,
    TrajectorySubscriber, ViolationSubscriber, unique_domain,
};
use history_support::*;

const ROLE: &str = "ESGM_SHM_HISTORY_TEST_ROLE";
const DOMAIN: &str = "ESGM_SHM_HISTORY_TEST_DOMAIN";

/// Both ends' settings: room for the whole script in a reader's queue.
fn qos() -> TrajectoryQos {
    TrajectoryQos { subscriber_buffer_size: 64, ..TrajectoryQos::default() }
}

fn reader(domain: &str, clock: std::sync::Arc<SimClock>) -> ShmTrajectoryReader {
    let (policy, _, _) = hold_and_reorder();
    ShmTrajectoryReader::builder(TRAJECTORY, checker())
        .domain(domain)
        .policy(policy)
        .qos(qos())
        .clock(clock)
        .create(&node())
        .unwrap()
}

/// Runs only inside the child process; a no-op in a normal test run.
#[test]
fn child_writer_role() {
    if std::env::var(ROLE).as_deref() != Ok("writer") {
        return;
    }
    let domain = std::env::var(DOMAIN).expect("domain from parent");
    let (policy, start, script) = hold_and_reorder();
    let expected = in_process(&policy, start, &script);
    let n = node();
    let clock = SimClock::shared(start);
    let mut writer = ShmTrajectoryWriter::builder(TRAJECTORY, checker())
        .domain(&domain)
        .policy(policy)
        .qos(qos())
        .clock(clock.clone())
        .create(&n)
        .unwrap();
    let ack = TrajectorySubscriber::builder("ack", "Ack").domain(&domain).create(&n).unwrap();
    // The parent's reader connected before we started.
    assert!(writer.subscriber_count() > 0);
    assert_eq!(run_script(&mut writer, &clock, script), expected.did, "outcomes");
    // Hand the history to late readers until the parent is done.
    let deadline = Instant::now() + TIMEOUT;
    loop {
        writer.update_connections().unwrap();
        if ack.wait_for_sample(Duration::from_millis(5)).unwrap().is_some() {
            break;
        }
        assert!(Instant::now() < deadline, "no acknowledgement from the parent");
    }
}

fn spawn_writer(domain: &str) -> std::process::Child {
    common::spawn_child("child_writer_role", (ROLE, "writer"), (DOMAIN, domain))
}

#[test]
fn the_history_is_read_in_other_processes() {
    let domain = unique_domain("history_cross_process");
    let (policy, start, script) = hold_and_reorder();
    let expected = in_process(&policy, start, &script);
    let n = node();
    let clock = SimClock::shared(0);
    let mut early = reader(&domain, clock.clone());
    let violations = ViolationSubscriber::builder(TRAJECTORY).domain(&domain).create(&n).unwrap();
    let ack = TrajectoryPublisher::builder("ack", "Ack").domain(&domain).create(&n).unwrap();
    let child = spawn_writer(&domain);

    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        // The whole gated stream, with the writer's add times.
        let stream = take(&mut early, expected.stream.len());
        assert_eq!(entered(&stream), entered(&expected.stream));
        let mut seen: Vec<PolicyViolation> = Vec::new();
        while seen.len() < expected.violations.len() {
            seen.push(violations.wait(TIMEOUT).unwrap().expect("a violation"));
        }
        let key = |v: &PolicyViolation| (v.constraint, v.valid_time, v.create_time, v.add_time);
        assert_eq!(
            seen.iter().map(key).collect::<Vec<_>>(),
            expected.violations.iter().map(key).collect::<Vec<_>>()
        );

        // A reader that comes late gets the cache's content from the writer's history.
        let mut late = reader(&domain, clock.clone());
        take(&mut late, expected.store.len());

        clock.set(expected.clock.now());
        assert_same_answers(&expected.store, &early);
        assert_same_answers(&expected.store, &late);

        let deadline = Instant::now() + TIMEOUT;
        while ack.subscriber_count() == 0 && Instant::now() < deadline {
            thread::sleep(Duration::from_millis(1));
        }
        ack.publish(&EntityStructure::new("ack", 0, 0)).unwrap();
    }));
    let (status, output) = common::reap(child, TIMEOUT * 2);
    if let Err(panic) = result {
        eprintln!("writer output:\n{output}");
        std::panic::resume_unwind(panic);
    }
    assert!(status.success(), "writer process failed ({status}):\n{output}");
}
