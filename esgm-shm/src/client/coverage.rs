//! Whether this connection's receiver needs the writer's notify for an import: counted
//! in the trajectory's futex word, so that the writer skips a notify that would only
//! wake the receiver for nothing.
//!
//! A sample from another process wakes the subscription or worker sleeping on the
//! writer's word, which feeds the replica itself ([`super::import`]). While the
//! receiver thread also listens to the writer's event, the same sample wakes it too:
//! a datagram and a second wake-up, 3–4 µs of every hop on this machine, for a
//! replica already fed. So each import counts its connection in the word (see
//! [`crate::data_plane::wake_word`]; two connections of one process count as two):
//! - as a *receiver* while the receiver thread listens to the writer's event
//!   ([`Coverage::receiving`], from after the listener exists until before it goes);
//! - as *covered* while, in addition, one of its threads is asleep on the word
//!   ([`Coverage::asleep`]: counted before it looks at the word for the last time, and
//!   out before it feeds the replica).
//!
//! A sample sent while the connection is covered is fed by its thread asleep, which
//! feeds after it is counted out, on every path; one sent while it is not reaches the
//! receiver through the notify. Every sample is fed either way. A thread asleep on a
//! word made anew (the domain restarted while this connection stayed) covers nothing:
//! this count is in the old file.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::data_plane::wake_word::WakeWord;

/// One import's count in its trajectory's word: its own mapping of the word (its own
/// slot, which a look for the dead can count out if this process dies), made when a
/// thread of the connection first sleeps on the word, and what it has counted there.
#[derive(Debug)]
pub(crate) struct Coverage {
    /// The wake-up service whose word this counts in.
    service: String,
    state: Mutex<State>,
}

/// What this connection has counted: its threads asleep on the word, the receiver's
/// listeners, and whether the word counts it as a receiver and as covered.
#[derive(Debug, Default)]
struct State {
    /// Mapped at the first sleep: an import nobody sleeps on costs no file, no
    /// descriptor and no page (its receiver is then not counted, and the writer
    /// notifies it, as every listener nobody counts).
    word: Option<WakeWord>,
    /// The mapping was tried (it failed if `word` is `None`).
    tried: bool,
    asleep: usize,
    listeners: usize,
    receiver: bool,
    covered: bool,
}

impl State {
    /// Counts the connection as a receiver in the word, if it is mapped and the
    /// receiver listens, and as covered if a thread sleeps.
    fn count_receiver(&mut self) {
        let Some(word) = &self.word else { return };
        if self.listeners > 0 && !self.receiver && word.count_receiver_in() {
            self.receiver = true;
        }
        if self.asleep > 0 {
            self.cover();
        }
    }

    /// Counts the connection as covered, if it is counted as a receiver and not yet.
    fn cover(&mut self) {
        if let Some(word) = self.word.as_ref().filter(|_| self.receiver && !self.covered) {
            word.count_covered_in();
            self.covered = true;
        }
    }

    /// Counts the connection out of the covered, if it is counted.
    fn uncover(&mut self) {
        if let Some(word) = self.word.as_ref().filter(|_| self.covered) {
            word.count_covered_out();
            self.covered = false;
        }
    }

    /// Counts the connection out of the receivers (and the covered), if it is counted.
    fn uncount_receiver(&mut self) {
        self.uncover();
        if let Some(word) = self.word.as_ref().filter(|_| self.receiver) {
            word.count_receiver_out();
            self.receiver = false;
        }
    }
}

impl Coverage {
    /// This connection's count in the word of the wake-up service `service`; `None`
    /// where readers do not sleep on words ([`crate::data_plane::wake_word::WAKE_ENV`]). Nothing is
    /// mapped until a thread sleeps ([`Coverage::asleep`]).
    pub fn new(service: &str) -> Option<Arc<Coverage>> {
        crate::data_plane::wake_word::futex_enabled()
            .then(|| Arc::new(Coverage { service: service.to_owned(), state: Mutex::default() }))
    }

    /// Counts the receiver's listener on the writer's event until the result is
    /// dropped: take it after the listener exists, and drop it before the listener.
    pub fn receiving(self: &Arc<Self>) -> Receiving {
        let mut state = self.state.lock();
        state.listeners += 1;
        state.count_receiver();
        Receiving(Arc::clone(self))
    }

    /// Counts the calling thread asleep on `word` until the result is dropped: take it
    /// before the last look at the word before sleeping, and drop it before feeding
    /// the replica. Maps the word the first time. `None` if it cannot be mapped, or if
    /// `word` is not the file this count is in (it was made anew): the writer of the
    /// other one must still notify.
    pub fn asleep(self: &Arc<Self>, word: &WakeWord) -> Option<Asleep> {
        let mut state = self.state.lock();
        if !state.tried {
            state.tried = true;
            match WakeWord::open(&self.service) {
                Ok(mapped) => state.word = Some(mapped),
                Err(e) => tracing::debug!(service = %self.service, error = %e,
                    "cannot map the wake-up word; the writer always notifies the receiver"),
            }
            state.count_receiver();
        }
        if !state.word.as_ref().is_some_and(|w| w.same_file(word)) {
            return None;
        }
        state.asleep += 1;
        state.cover();
        Some(Asleep(Arc::clone(self)))
    }
}

/// The receiver's listener counted ([`Coverage::receiving`]).
#[derive(Debug)]
pub(crate) struct Receiving(Arc<Coverage>);

impl Drop for Receiving {
    fn drop(&mut self) {
        let mut state = self.0.state.lock();
        state.listeners -= 1;
        if state.listeners == 0 {
            state.uncount_receiver();
        }
    }
}

/// A thread counted asleep ([`Coverage::asleep`]).
#[derive(Debug)]
pub(crate) struct Asleep(Arc<Coverage>);

impl Drop for Asleep {
    fn drop(&mut self) {
        let mut state = self.0.state.lock();
        state.asleep -= 1;
        if state.asleep == 0 {
            state.uncover();
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "a failure is a failed test")]
mod tests {
    use super::*;

    /// A word's writer, and the service it belongs to (each `Coverage::open` of it is
    /// a mapping of its own, as another connection's would be).
    fn word() -> (WakeWord, String) {
        let domain = crate::data_plane::service_name::unique_domain("coverage");
        let service = crate::data_plane::service_name::wake_service_name(&domain, "t");
        (WakeWord::open(&service).unwrap(), service)
    }

    /// How many receivers a ring of `writer` finds, and whether every one is covered,
    /// with `listeners` on the event (one per connection with a receiving guard).
    fn ring(writer: &WakeWord, listeners: usize) -> (u32, bool) {
        let ring = writer.ring_counting(|| listeners);
        (ring.receivers, ring.covered)
    }

    /// Rings `writer` while a thread of each of `connections` sleeps on the word (through
    /// a mapping of its own, as a subscription's waiter does), covering it; returns what
    /// the ring found, once the ring woke them. Rings only once every one of them is
    /// asleep in the kernel, not merely counted.
    fn ring_with_sleepers(
        writer: &WakeWord,
        service: &str,
        connections: &[&Arc<Coverage>],
        listeners: usize,
    ) -> (u32, bool) {
        std::thread::scope(|s| {
            let (tx, rx) = std::sync::mpsc::channel();
            for coverage in connections {
                let word = WakeWord::open(service).unwrap();
                let tx = tx.clone();
                s.spawn(move || {
                    // SAFETY: no argument; the calling thread's id.
                    tx.send(unsafe { libc::gettid() }).unwrap();
                    let seen = word.sequence();
                    let _asleep = coverage.asleep(&word).unwrap();
                    word.sleep(seen, std::time::Duration::from_secs(20));
                });
            }
            let tids: Vec<i32> = rx.iter().take(connections.len()).collect();
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
            while writer.sleepers() < connections.len() as u32 || !tids.iter().all(|&t| asleep(t)) {
                assert!(std::time::Instant::now() < deadline, "the sleepers never slept");
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            ring(writer, listeners)
        })
    }

    /// True if the thread `tid` of this process sleeps in the kernel (after its count,
    /// a sleeper's only blocking call is its futex wait).
    fn asleep(tid: i32) -> bool {
        let stat = std::fs::read_to_string(format!("/proc/self/task/{tid}/stat")).unwrap();
        // The state follows the command name's closing parenthesis.
        stat.rsplit_once(") ").is_some_and(|(_, rest)| rest.starts_with('S'))
    }

    #[test]
    fn a_connection_is_covered_only_while_its_receiver_listens_and_a_thread_sleeps() {
        let (writer, service) = word();
        let coverage = Coverage::new(&service).unwrap();
        let receiving = coverage.receiving();
        assert_eq!(writer.receivers(), (0, 0), "nothing is mapped before a thread sleeps");
        let asleep = coverage.asleep(&writer).unwrap();
        assert_eq!(writer.receivers(), (1, 1), "the first sleep counts the receiver, covered");
        let second = coverage.asleep(&writer).unwrap();
        drop(asleep);
        assert_eq!(writer.receivers(), (1, 1), "one thread still sleeps");
        drop(second);
        assert_eq!(writer.receivers(), (1, 0), "nobody sleeps: the receiver needs the notify");
        assert_eq!(ring(&writer, 1), (1, false));
        assert_eq!(ring_with_sleepers(&writer, &service, &[&coverage], 1), (1, true));
        assert_eq!(
            ring_with_sleepers(&writer, &service, &[&coverage], 2),
            (1, false),
            "a listener nobody counts"
        );
        let asleep = coverage.asleep(&writer).unwrap();
        assert_eq!(ring(&writer, 1), (1, false), "counted covered, but no thread the ring woke");
        drop(receiving);
        assert_eq!(writer.receivers(), (0, 0), "the receiver left, covered or not");
        drop(asleep);
        let again = coverage.receiving();
        let _asleep = coverage.asleep(&writer).unwrap();
        assert_eq!(writer.receivers(), (1, 1), "a receiver that comes finds the sleeper");
        drop(again);
        assert_eq!(writer.receivers(), (0, 0));
    }

    #[test]
    fn a_thread_asleep_on_a_word_made_anew_covers_nothing() {
        let (writer, service) = word();
        let coverage = Coverage::new(&service).unwrap();
        let _receiving = coverage.receiving();
        drop(coverage.asleep(&writer).unwrap());
        // The domain ended and the word was made again while this connection stayed.
        assert_eq!(
            crate::data_plane::wake_word::remove_domain(service.split('/').nth(1).unwrap()),
            1
        );
        let anew = WakeWord::open(&service).unwrap();
        assert!(coverage.asleep(&anew).is_none(), "its count is in the old file");
        assert_eq!(writer.receivers(), (1, 0), "the old file's writer still notifies");
    }

    #[test]
    fn a_dead_receivers_count_is_counted_out_once_iceoryx2_has_no_listener_for_it() {
        let domain = crate::data_plane::service_name::unique_domain("coverage-unheard");
        let node = iceoryx2::prelude::NodeBuilder::new()
            .config(crate::data_plane::service::iceoryx2_config())
            .create::<crate::ShmService>()
            .unwrap();
        let publisher =
            crate::data_plane::publisher::TrajectoryPublisher::builder("t", "RobotState")
                .domain(&domain)
                .create(&node)
                .unwrap();
        let service = crate::data_plane::service_name::wake_service_name(&domain, "t");
        let watcher = WakeWord::open(&service).unwrap();
        // A receiver whose process died after iceoryx2 cleaned its listener up: its
        // count stays, its slot's lock went.
        let dead = WakeWord::open(&service).unwrap();
        assert!(dead.count_receiver_in());
        drop(dead);
        let es = esgm_core::EntityStructure::new("robot1", 10, 11).with("x", 1.0);
        for _ in 1..crate::data_plane::wake_word::FRUITLESS_RINGS {
            publisher.publish(&es).unwrap();
        }
        assert_eq!(watcher.receivers(), (1, 0), "not before as many sends as fruitless rings");
        publisher.publish(&es).unwrap();
        assert_eq!(watcher.receivers(), (0, 0), "counted out by the writer's look");
        drop(publisher);
        crate::data_plane::wake_word::remove_domain(&domain);
    }

    #[test]
    fn a_receiver_not_covered_is_notified_whoever_else_is() {
        let (writer, service) = word();
        let (one, other) = (Coverage::new(&service).unwrap(), Coverage::new(&service).unwrap());
        let (_one, _other) = (one.receiving(), other.receiving());
        // The other's thread slept once, and is busy now: counted, not covered.
        drop(other.asleep(&writer).unwrap());
        assert_eq!(
            ring_with_sleepers(&writer, &service, &[&one], 2),
            (2, false),
            "the other needs it"
        );
        assert_eq!(ring_with_sleepers(&writer, &service, &[&one, &other], 2), (2, true));
    }
}
