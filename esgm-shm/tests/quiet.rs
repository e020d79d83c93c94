//! A program that links `esgm_shm` prints nothing of its own on stderr: iceoryx2's log
//! goes through `tracing`, so it appears only where the program sends its own log
//! (issue 24: every program printed iceoryx2's "No config file was loaded" and
//! "Subscriber max borrowed samples is larger than expired connection buffer!").
//!
//! The test runs itself again as a child that uses the data plane the way a user's
//! program does (no log set up, iceoryx2's level untouched), and reads the child's
//! stderr.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use esgm_core::EntityStructure;
use esgm_shm::{
    Cleanup, TrajectoryPublisher, TrajectoryQos, TrajectorySubscriber, node_config, unique_domain,
};
use iceoryx2::prelude::NodeBuilder;

const CHILD: &str = "ESGM_QUIET_TEST_DOMAIN";
const NAME: &str = "a_program_using_esgm_shm_prints_nothing_on_stderr";
const DEADLINE: Duration = Duration::from_secs(60);

#[test]
fn a_program_using_esgm_shm_prints_nothing_on_stderr() {
    if let Ok(domain) = std::env::var(CHILD) {
        return child(&domain);
    }
    let mut run = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", NAME, "--nocapture", "--test-threads=1"])
        .env(CHILD, unique_domain("quiet"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    let status = loop {
        if let Some(status) = run.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > DEADLINE {
            let _ = run.kill();
            panic!("the child did not finish within {DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    run.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    assert!(status.success(), "the child failed: {stderr}");
    assert_eq!(stderr, "", "a program using esgm_shm printed on stderr");
}

/// What a user's program does: a node with esgm's configuration, and a trajectory
/// whose readers may hold more samples than the node keeps room for by default (as an
/// image trajectory's do).
fn child(domain: &str) {
    let node = NodeBuilder::new()
        .config(&node_config(Cleanup::None))
        .create::<esgm_shm::ShmService>()
        .unwrap();
    let qos = TrajectoryQos { max_borrowed_samples: 40, ..TrajectoryQos::default() };
    let p = TrajectoryPublisher::builder("images", "Blob")
        .domain(domain)
        .qos(qos)
        .create(&node)
        .unwrap();
    let s = TrajectorySubscriber::builder("images", "Blob")
        .domain(domain)
        .qos(qos)
        .create(&node)
        .unwrap();
    p.publish(&EntityStructure::new("b", 1, 1)).unwrap();
    assert!(s.wait_for_sample(Duration::from_secs(10)).unwrap().is_some());
}
