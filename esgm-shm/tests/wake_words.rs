//! A trajectory's futex word across processes: the sleepers of a process killed
//! asleep are counted out, and a live sleeper never is. Each test has its own domain.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::{Duration, Instant};

use common::{reap, spawn_child};
use esgm_shm::unique_domain;
use esgm_shm::unstable::wake_service_name;
use esgm_shm::unstable::{FRUITLESS_RINGS, WakeWord};

const ROLE: &str = "ESGM_TEST_WAKE_ROLE";
const SERVICE: &str = "ESGM_TEST_WAKE_SERVICE";
const WAIT: Duration = Duration::from_secs(20);

/// The child half of the tests below, run in another process: maps the word and
/// sleeps on it, `forever` (until killed) or `once` (until a ring changes the word).
#[test]
fn wake_word_child() {
    let (Ok(role), Ok(service)) = (std::env::var(ROLE), std::env::var(SERVICE)) else { return };
    let word = WakeWord::open(&service).unwrap();
    let seen = word.sequence();
    let started = Instant::now();
    while word.sequence() == seen && started.elapsed() < Duration::from_secs(60) {
        word.sleep(seen, Duration::from_secs(60));
    }
    assert_eq!(role, "once", "a forever sleeper is killed before it wakes");
    assert_ne!(word.sequence(), seen, "woken by a ring, not by the timeout");
}

/// A child process asleep on `service`'s word; killed when dropped, so that a failed
/// test leaves no sleeper behind.
struct Sleeper(Option<std::process::Child>);

impl Sleeper {
    fn spawn(service: &str, role: &str) -> Self {
        Self(Some(spawn_child("wake_word_child", (ROLE, role), (SERVICE, service))))
    }

    fn kill(mut self) {
        self.end();
    }

    /// Waits for it to end by itself; its status and output.
    fn reap(mut self) -> (std::process::ExitStatus, String) {
        reap(self.0.take().unwrap(), WAIT)
    }

    fn end(&mut self) {
        if let Some(mut child) = self.0.take() {
            child.kill().unwrap();
            child.wait().unwrap();
        }
    }
}

impl Drop for Sleeper {
    fn drop(&mut self) {
        self.end();
    }
}

/// A writer's mapping of one word, in a domain of its own that ends when this is
/// dropped (see [`DomainEnd`]).
struct Word {
    // Dropped in this order: the writer's mapping, then the domain's words.
    writer: WakeWord,
    service: String,
    _end: DomainEnd,
}

impl Word {
    fn new(prefix: &str) -> Self {
        let end = DomainEnd(unique_domain(prefix));
        let service = wake_service_name(&end.0, "t");
        Self { writer: WakeWord::open(&service).unwrap(), service, _end: end }
    }

    /// Ends the domain and checks that its word's file is gone.
    fn end(self) {
        let path = esgm_shm::unstable::path_for(&self.service);
        drop(self);
        assert!(!path.exists(), "the domain's end removed the word");
    }
}

/// Removes a domain's words when dropped, as `esgm down` would: a killed sleeper stays
/// counted as a user of the word, so its file would stay in `/dev/shm`.
struct DomainEnd(String);

impl Drop for DomainEnd {
    fn drop(&mut self) {
        esgm_shm::unstable::remove_domain(&self.0);
    }
}

/// Waits until `word` counts `n` sleepers.
fn until_sleepers(word: &WakeWord, n: u32) {
    let deadline = Instant::now() + WAIT;
    while word.sleepers() != n {
        assert!(Instant::now() < deadline, "{} sleepers, not {n}", word.sleepers());
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_process_killed_asleep_is_counted_out_by_the_writers_rings() {
    let word = Word::new("wake-dead");
    let writer = &word.writer;
    let child = Sleeper::spawn(&word.service, "forever");
    until_sleepers(writer, 1);
    child.kill();
    assert_eq!(writer.sleepers(), 1, "the dead sleeper is still counted");
    for _ in 1..FRUITLESS_RINGS {
        writer.ring();
    }
    assert_eq!(writer.sleepers(), 1, "a few rings that wake nobody are no proof of death");
    writer.ring();
    assert_eq!(writer.sleepers(), 0, "counted out at the last fruitless ring");
    word.end();
}

#[test]
fn a_live_sleeper_is_never_counted_out_in_any_process() {
    let word = Word::new("wake-live");
    let writer = &word.writer;
    let dead = Sleeper::spawn(&word.service, "forever");
    let live = Sleeper::spawn(&word.service, "once");
    std::thread::scope(|s| {
        // A thread of this process asleep through the writer's own mapping.
        let seen = writer.sequence();
        let own = s.spawn(move || {
            let deadline = Instant::now() + WAIT;
            while writer.sequence() == seen && Instant::now() < deadline {
                writer.sleep(seen, WAIT);
            }
        });
        until_sleepers(writer, 3);
        dead.kill();
        assert_eq!(writer.count_out_the_dead().unwrap(), 1, "only the dead one");
        assert_eq!(writer.sleepers(), 2);
        assert_eq!(writer.count_out_the_dead().unwrap(), 0, "nothing twice");

        writer.ring();
        let (status, output) = live.reap();
        assert!(status.success(), "the live sleeper was woken by the ring: {output}");
        own.join().unwrap();
    });
    until_sleepers(writer, 0);
    word.end();
}
