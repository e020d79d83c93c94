//! What every reader of another process's trajectory checks before a sample or reset
//! counts: that it comes from the writer's publisher port as the registry names it,
//! and which of the writer's samples it never saw.
//!
//! Anyone may open a trajectory's data service and publish on it, and a writer that
//! restarts publishes from a new port before the registry names it. So an arrival
//! from the named port enters at once; one from another port is held, in order, until
//! the registry answers, and then enters or is refused as not the writer's. Held
//! arrivals are bounded ([`MAX_HELD`]): past it the oldest is refused. The writer
//! numbers what it sends; a jump in its numbers is samples lost before this reader
//! read them (its queue overwrote them), counted per port, since a restarted writer
//! numbers afresh.
//!
//! One implementation for every reader: the client's replicas (`client/import.rs`,
//! through which the recorder, `esgm echo` and every subscription read) and
//! `esgm-bridge`'s exporter, which reads the services with a subscriber of its own. It holds
//! whatever the reader makes of an arrival (`T`: a decoded structure, wire bytes) and
//! needs no shared memory, so its rules are tested on their own.

use std::collections::VecDeque;

use crate::data_plane::sequence_gaps::SequenceGaps;

/// The most arrivals held while the registry has not named the writer's port: a
/// restarted writer is named within a location tick, so this bounds only what a
/// process that is not the writer can make a reader hold.
pub const MAX_HELD: usize = 1024;

/// The most arrivals of a trajectory of images held ([`WriterCheck::holding`]): a
/// camera's frames held while a restarted writer waits to be named (its coordinator
/// restarting too) would otherwise be 1,024 frames, copied onto the heap past the
/// reader's borrow budget (a gigabyte of 640×480 frames).
pub const MAX_HELD_IMAGES: usize = 32;

/// What the check decided about an arrival (or a held one, once the writer is named).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decided<T> {
    /// The writer's: it counts. `lost` of the writer's samples came before it that
    /// this reader never saw.
    Enter {
        /// What the reader made of the arrival.
        item: T,
        /// Samples of the writer's skipped just before this one.
        lost: u64,
    },
    /// Not the writer's (another port, or held past `MAX_HELD`): refused, to be
    /// counted as not the writer's.
    NotWriter {
        /// The port it came from.
        port: u128,
        /// What the reader made of the arrival.
        item: T,
    },
}

/// The writer check of one reader; see the module docs.
#[derive(Debug)]
pub struct WriterCheck<T> {
    writer: Option<u128>,
    max_held: usize,
    held: VecDeque<(u128, u64, T)>,
    gaps: SequenceGaps<u128>,
    asked: bool,
    not_writer: u64,
    lost: u64,
}

impl<T> WriterCheck<T> {
    /// A check for the writer whose port the registry names as `writer` (`None`: not
    /// yet).
    pub fn new(writer: Option<u128>) -> Self {
        Self {
            writer,
            max_held: MAX_HELD,
            held: VecDeque::new(),
            gaps: SequenceGaps::default(),
            asked: false,
            not_writer: 0,
            lost: 0,
        }
    }

    /// This check holding at most `max_held` arrivals (at least one) instead of
    /// `MAX_HELD`: `MAX_HELD_IMAGES` for a trajectory of images.
    #[must_use]
    pub fn holding(mut self, max_held: usize) -> Self {
        self.max_held = max_held.max(1);
        self
    }

    /// The port the registry names as the writer's.
    pub fn writer(&self) -> Option<u128> {
        self.writer
    }

    /// Checks an arrival numbered `sequence` from `port`. What is decided now is
    /// returned (the arrival itself if it is the writer's; the oldest held one if the
    /// hold is full); the rest is held until [`WriterCheck::set_writer`].
    pub fn arrive(&mut self, port: u128, sequence: u64, item: T) -> Option<Decided<T>> {
        if self.writer == Some(port) {
            return Some(self.enter(port, sequence, item));
        }
        let evicted = if self.held.len() >= self.max_held {
            self.held.pop_front().map(|(port, _, item)| self.refuse(port, item))
        } else {
            None
        };
        self.held.push_back((port, sequence, item));
        evicted
    }

    /// True once per wait: arrivals are held and nobody asked the registry yet since
    /// its last answer. The caller asks, and passes the answer to
    /// [`WriterCheck::set_writer`].
    pub fn should_ask(&mut self) -> bool {
        if self.held.is_empty() || self.asked {
            return false;
        }
        self.asked = true;
        true
    }

    /// True while arrivals wait for the registry to name the writer's port.
    pub fn awaits_writer(&self) -> bool {
        !self.held.is_empty()
    }

    /// The registry names `port` as the writer's (`None`: not yet): what was held is
    /// decided, in order of arrival.
    pub fn set_writer(&mut self, port: Option<u128>) -> Vec<Decided<T>> {
        // Answered: the next arrival from an unnamed port asks again.
        self.asked = false;
        let Some(port) = port else { return Vec::new() };
        self.writer = Some(port);
        let held = std::mem::take(&mut self.held);
        held.into_iter()
            .map(|(from, sequence, item)| {
                if from == port {
                    self.enter(from, sequence, item)
                } else {
                    self.refuse(from, item)
                }
            })
            .collect()
    }

    /// Arrivals refused as not the writer's so far.
    pub fn not_writer(&self) -> u64 {
        self.not_writer
    }

    /// The writer's samples this reader never saw, so far.
    pub fn lost(&self) -> u64 {
        self.lost
    }

    fn enter(&mut self, port: u128, sequence: u64, item: T) -> Decided<T> {
        let lost = self.gaps.observe(port, sequence);
        self.lost += lost;
        Decided::Enter { item, lost }
    }

    fn refuse(&mut self, port: u128, item: T) -> Decided<T> {
        self.not_writer += 1;
        Decided::NotWriter { port, item }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    const WRITER: u128 = 7;
    const OTHER: u128 = 9;

    fn entered(c: Option<Decided<&str>>) -> (&str, u64) {
        match c {
            Some(Decided::Enter { item, lost }) => (item, lost),
            other => panic!("expected an entry, got {other:?}"),
        }
    }

    #[test]
    fn the_named_writers_samples_enter_and_its_gaps_are_lost() {
        let mut check = WriterCheck::new(Some(WRITER));
        assert_eq!(entered(check.arrive(WRITER, 0, "a")), ("a", 0));
        assert_eq!(entered(check.arrive(WRITER, 1, "b")), ("b", 0));
        // 2, 3 and 4 were overwritten before this reader read them.
        assert_eq!(entered(check.arrive(WRITER, 5, "c")), ("c", 3));
        assert_eq!((check.lost(), check.not_writer()), (3, 0));
        assert!(!check.awaits_writer());
    }

    #[test]
    fn another_ports_arrivals_wait_for_the_registry_then_enter_or_are_refused() {
        let mut check = WriterCheck::new(None);
        assert_eq!(check.arrive(WRITER, 0, "w0"), None);
        assert_eq!(check.arrive(OTHER, 0, "x0"), None);
        assert_eq!(check.arrive(WRITER, 1, "w1"), None);
        assert!(check.awaits_writer());
        // One question per wait.
        assert!(check.should_ask());
        assert!(!check.should_ask());
        // Not named yet: still held, and the next arrival may ask again.
        assert_eq!(check.set_writer(None), vec![]);
        assert!(check.should_ask());
        let decided = check.set_writer(Some(WRITER));
        assert_eq!(
            decided,
            vec![
                Decided::Enter { item: "w0", lost: 0 },
                Decided::NotWriter { port: OTHER, item: "x0" },
                Decided::Enter { item: "w1", lost: 0 },
            ]
        );
        assert_eq!(check.not_writer(), 1);
        assert!(!check.awaits_writer());
        // From now on the writer's enter at once, another port's wait.
        assert_eq!(entered(check.arrive(WRITER, 2, "w2")), ("w2", 0));
        assert_eq!(check.arrive(OTHER, 1, "x1"), None);
    }

    #[test]
    fn a_restarted_writer_numbers_afresh_without_a_loss() {
        let mut check = WriterCheck::new(Some(WRITER));
        for s in 0..10 {
            entered(check.arrive(WRITER, s, "old"));
        }
        // The restarted writer's new port, named by the registry.
        assert_eq!(check.arrive(OTHER, 0, "new0"), None);
        assert_eq!(check.set_writer(Some(OTHER)), vec![Decided::Enter { item: "new0", lost: 0 }]);
        assert_eq!(entered(check.arrive(OTHER, 1, "new1")), ("new1", 0));
        // The former port is no longer the writer's.
        assert!(check.arrive(WRITER, 10, "stale").is_none());
        assert_eq!(check.lost(), 0);
    }

    #[test]
    fn a_trajectory_of_images_holds_fewer() {
        let mut check = WriterCheck::new(None).holding(MAX_HELD_IMAGES);
        for s in 0..MAX_HELD_IMAGES as u64 {
            assert_eq!(check.arrive(OTHER, s, s), None);
        }
        assert_eq!(check.arrive(OTHER, 99, 99), Some(Decided::NotWriter { port: OTHER, item: 0 }));
        let entered = check.set_writer(Some(OTHER));
        assert_eq!(entered.len(), MAX_HELD_IMAGES);
    }

    #[test]
    fn the_hold_is_bounded_and_refuses_the_oldest() {
        let mut check = WriterCheck::new(None);
        for s in 0..MAX_HELD as u64 {
            assert_eq!(check.arrive(OTHER, s, s), None);
        }
        assert_eq!(
            check.arrive(OTHER, 5000, 5000),
            Some(Decided::NotWriter { port: OTHER, item: 0 })
        );
        assert_eq!(check.not_writer(), 1);
        let decided = check.set_writer(Some(WRITER));
        assert_eq!(decided.len(), MAX_HELD);
        assert!(decided.iter().all(|c| matches!(c, Decided::NotWriter { .. })));
        assert_eq!(check.not_writer(), 1 + MAX_HELD as u64);
    }
}
