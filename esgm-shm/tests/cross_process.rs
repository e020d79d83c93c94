//! Publisher and subscriber in separate processes: this test binary spawns itself as
//! the producer (selected by an environment variable), so no helper binary is needed.
//!
//! Parent: subscribes to `robot` and `cam`, spawns the child, checks what arrives, then
//! acknowledges on `ack`. Child: publishes small structures and in-place images once
//! the parent is connected, and exits cleanly after the acknowledgement. Every wait has
//! a timeout and the parent kills a child that overstays.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::thread;
use std::time::{Duration, Instant};

use common::*;
use esgm_core::EntityStructure;
use esgm_shm::{TrajectoryPublisher, TrajectorySubscriber, WaitStrategy, unique_domain};

const ROLE: &str = "ESGM_SHM_TEST_ROLE";
const DOMAIN: &str = "ESGM_SHM_TEST_DOMAIN";
const SMALL: i64 = 5;
const FRAMES: u64 = 3;

/// Runs only inside the child process; a no-op in a normal test run.
#[test]
fn child_role() {
    if std::env::var(ROLE).as_deref() != Ok("producer") {
        return;
    }
    let domain = std::env::var(DOMAIN).expect("domain from parent");
    let n = node();
    let robot_pub =
        TrajectoryPublisher::builder("robot", "RobotState").domain(&domain).create(&n).unwrap();
    let cam_pub = TrajectoryPublisher::builder("cam", "Image")
        .domain(&domain)
        .image_name("cam0")
        .max_len(1 << 20)
        .create(&n)
        .unwrap();
    let ack = TrajectorySubscriber::builder("ack", "Ack").domain(&domain).create(&n).unwrap();

    // The parent subscribed before spawning us; wait until we see it (history 1 would
    // otherwise keep only the last sample for it).
    let deadline = Instant::now() + TIMEOUT;
    while (robot_pub.subscriber_count() == 0 || cam_pub.subscriber_count() == 0)
        && Instant::now() < deadline
    {
        thread::sleep(Duration::from_millis(1));
    }
    assert!(robot_pub.subscriber_count() > 0 && cam_pub.subscriber_count() > 0);

    for i in 0..SMALL {
        robot_pub.publish(&robot(i)).unwrap();
    }
    for frame in 0..FRAMES {
        let mut loan = cam_pub.loan_image(640, 480, RGB8).unwrap();
        fill(loan.pixels_mut(), frame);
        let t = 10 * frame as i64;
        loan.send("cam0", t, t + 1).unwrap();
    }
    let got = ack.wait_for_sample(TIMEOUT).unwrap().expect("parent's acknowledgement");
    assert_eq!(got.header().valid_time, SMALL + FRAMES as i64);
}

fn spawn_producer(domain: &str) -> std::process::Child {
    common::spawn_child("child_role", (ROLE, "producer"), (DOMAIN, domain))
}

#[test]
fn structures_and_in_place_images_cross_processes() {
    let domain = unique_domain("cross_process");
    let n = node();
    let robot_sub =
        TrajectorySubscriber::builder("robot", "RobotState").domain(&domain).create(&n).unwrap();
    let cam_sub = TrajectorySubscriber::builder("cam", "Image")
        .domain(&domain)
        .wait_strategy(WaitStrategy::Block)
        .create(&n)
        .unwrap();
    let ack = TrajectoryPublisher::builder("ack", "Ack").domain(&domain).create(&n).unwrap();
    let child = spawn_producer(&domain);

    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        for i in 0..SMALL {
            let sample = robot_sub.wait_for_sample(TIMEOUT).unwrap().expect("small structure");
            assert_eq!(sample.header().sequence, i as u64);
            assert_eq!(sample.to_owned().unwrap(), robot(i));
        }
        for frame in 0..FRAMES {
            let sample = cam_sub.wait_for_sample(TIMEOUT).unwrap().expect("image");
            assert!(sample.is_image_in_place());
            let archived = sample.structure().unwrap();
            assert_eq!(archived.name.as_str(), "cam0");
            let (w, h, f, px) = image(archived);
            assert_eq!((w, h, f, px.len()), (640, 480, RGB8, 921_600));
            check_pattern(px, frame);
        }
        // The child waits for a subscriber on `ack` (ours is connected at its send).
        let deadline = Instant::now() + TIMEOUT;
        while ack.subscriber_count() == 0 && Instant::now() < deadline {
            thread::sleep(Duration::from_millis(1));
        }
        ack.publish(&EntityStructure::new("ack", SMALL + FRAMES as i64, 0)).unwrap();
    }));
    let (status, output) = reap(child, TIMEOUT * 2);
    if let Err(panic) = result {
        eprintln!("producer output:\n{output}");
        std::panic::resume_unwind(panic);
    }
    assert!(status.success(), "producer process failed ({status}):\n{output}");
    assert_eq!(robot_sub.stats().malformed + cam_sub.stats().malformed, 0);
}
