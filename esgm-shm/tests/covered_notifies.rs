//! The notify a writer skips: a process whose thread sleeps on the trajectory's word
//! covers its receiver thread, and every sample still reaches every process, covered
//! or not. Each test has its own domain; two connections are two processes of the
//! registry, each with its own receiver.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::{Duration, Instant};

use common::{TIMEOUT, coordinator, location, state, wait_for, x};
use esgm_core::{EntityTrajectoryStructure, Esgm, SubscribeOptions};
use esgm_shm::unstable::wake_service_name;
use esgm_shm::unstable::{WakeWord, path_for};

/// Samples sent while the reader's thread sleeps.
const SAMPLES: usize = 20;

/// A fifth of the receiver's five-second sweep, which would feed a replica whose
/// receiver was never notified: a sample later than this was not notified. Of
/// [`CHECKS`] such windows in a row, a sweep can rescue one at most.
const NOTIFIED_WITHIN: Duration = Duration::from_secs(1);
const CHECKS: usize = 3;

/// The wake-up service of `trajectory` in `domain`, whatever generation the registry
/// gave it, and its word.
fn word_of(domain: &str, trajectory: &str) -> (String, WakeWord) {
    let service = (0..16)
        .map(|g| wake_service_name(&format!("{domain}.g{g}"), trajectory))
        .find(|s| path_for(s).exists())
        .expect("the trajectory's word exists");
    let word = WakeWord::open(&service).unwrap();
    (service, word)
}

#[test]
fn a_reader_asleep_covers_its_receiver_and_an_uncovered_receiver_is_still_notified() {
    let c = coordinator("covered");
    let writer = location(&c, "writer");
    let robot = writer.create_primitive_entity_trajectory_structure("robot", "RobotState").unwrap();
    let reader = location(&c, "reader");
    assert!(wait_for(|| reader.get_entity_trajectory_structure("robot").is_ok()));
    let replica = reader.get_entity_trajectory_structure("robot").unwrap();
    let stream = replica.subscribe(SubscribeOptions::default().capacity(64)).unwrap();
    let (service, word) = word_of(c.domain(), "robot");
    assert_eq!(word.receivers(), (0, 0), "nothing is counted before the reader sleeps");

    // The reader's thread sleeps on the word between samples: each one finds its
    // receiver covered, and wakes the thread, which feeds the replica.
    let spared = esgm_shm::unstable::notifies_spared_here();
    std::thread::scope(|s| {
        let got = s.spawn(|| {
            (0..SAMPLES).map(|_| x(&stream.recv_timeout(TIMEOUT).unwrap())).collect::<Vec<_>>()
        });
        for i in 0..SAMPLES {
            assert!(
                wait_for(|| word.receivers() == (1, 1) || got.is_finished()),
                "the reader's thread asleep covers its receiver: {:?}",
                word.receivers()
            );
            robot.add(state(i as i64 + 1, i as f64)).unwrap();
        }
        let got = got.join().unwrap();
        assert_eq!(
            got,
            (0..SAMPLES).map(|i| i as f64).collect::<Vec<_>>(),
            "every sample, in order"
        );
    });
    // Not every one: a ring that finds the thread between its count and its sleep
    // notifies, to be sure.
    assert!(esgm_shm::unstable::notifies_spared_here() > spared, "the writer skipped notifies");
    assert!(wait_for(|| word.receivers() == (1, 0)), "nobody asleep: {:?}", word.receivers());

    // A second reading process, whose thread slept once and now never waits: only its
    // receiver feeds its replica. The reader asleep covers its own process, not this.
    let other = location(&c, "other");
    assert!(wait_for(|| other.get_entity_trajectory_structure("robot").is_ok()));
    let seen = other.get_entity_trajectory_structure("robot").unwrap();
    let once = seen.subscribe(SubscribeOptions::default()).unwrap();
    assert!(
        wait_for(|| {
            let _nothing_sent = once.recv_timeout(Duration::from_millis(5));
            word.receivers() == (2, 0)
        }),
        "both receivers counted: {:?}",
        word.receivers()
    );
    drop(once);
    assert!(wait_for(|| seen.get_latest().is_ok_and(|s| x(&s) == (SAMPLES - 1) as f64)));
    for check in 0..CHECKS {
        let value = 1_000.0 + check as f64;
        std::thread::scope(|s| {
            let woken = s.spawn(|| stream.recv_timeout(TIMEOUT).map(|s| x(&s)));
            assert!(wait_for(|| word.receivers() == (2, 1)), "{:?}", word.receivers());
            let sent = Instant::now();
            robot.add(state(1_000 + check as i64, value)).unwrap();
            let mut latest = None;
            while sent.elapsed() < NOTIFIED_WITHIN && latest != Some(value) {
                latest = seen.get_latest().ok().map(|s| x(&s));
                std::thread::sleep(Duration::from_millis(1));
            }
            assert_eq!(latest, Some(value), "the uncovered connection's receiver was notified");
            assert_eq!(woken.join().unwrap(), Ok(value), "and the reader asleep was woken");
        });
    }
    drop((seen, other));
    assert!(wait_for(|| word.receivers() == (1, 0)), "the other left: {:?}", word.receivers());

    // A listener that no process counts (a reader that sleeps on the event itself, as
    // every reader does with ESGM_WAKE=event): notified, whoever else is covered.
    let node = common::node();
    let name = iceoryx2::prelude::ServiceName::new(&service).unwrap();
    let listener =
        node.service_builder(&name).event().open().unwrap().listener_builder().create().unwrap();
    std::thread::scope(|s| {
        let woken = s.spawn(|| stream.recv_timeout(TIMEOUT).map(|s| x(&s)));
        assert!(wait_for(|| word.receivers() == (1, 1)), "{:?}", word.receivers());
        robot.add(state(2_000, 2_000.0)).unwrap();
        let notified = listener.timed_wait(|_| {}, NOTIFIED_WITHIN).unwrap();
        assert!(notified > 0, "the listener nobody covers was notified");
        assert_eq!(woken.join().unwrap(), Ok(2_000.0), "and the reader asleep was woken");
    });
}
