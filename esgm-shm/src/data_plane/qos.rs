//! The settings of a trajectory's publish-subscribe service, shared by its publishers
//! and subscribers.
//!
//! iceoryx2 fixes these when the service is created and checks them when a port opens
//! it: an opener may ask for *at most* the history, buffer and port counts the service
//! has, and must agree on overflow behaviour. Both ends therefore build from one
//! [`TrajectoryQos`]; the first to come creates the service with it. Create publishers
//! first, or give every port the same settings — a subscriber that created the service
//! with a small history makes a publisher asking for a larger one fail to open.
//!
//! Memory: each publisher preallocates about
//! `max_subscribers × (subscriber_buffer_size + max_borrowed_samples) + history_size`
//! chunks of its largest sample size, rounded up to a power of two. With the defaults a
//! VGA RGB image publisher maps a 103 MB segment (measured); tmpfs commits pages only
//! as chunks are used, but size `max_subscribers` and the buffers down for image
//! trajectories on small machines.
//!
//! # How much history
//! The cache constraint (C2) decides what a trajectory keeps, and iceoryx2 needs a
//! number up front (its history size and the samples a subscriber may hold). So one
//! bound serves every process of the trajectory ([`history_bound`]):
//! - `Elements(n)` keeps `n`: the publisher's history is `n`, so a replica made late
//!   starts with the last `n`, what the writer's own store holds;
//! - `All` and `Duration(t)` keep at most a maximum ([`DEFAULT_MAX_HISTORY`]) for late
//!   readers: shared memory is allocated up front, so "everything" must have a number.
//!   A reader connected from the start receives the whole stream and keeps what its
//!   policy says.
//!
//! [`history_qos`] turns the bound into the service settings; writer and readers derive
//! them from the same policy and maximum, so whoever comes first creates a service the
//! others can open.
//!
//! Memory, measured: a writer of small structures with an `All` cache and the defaults
//! (bound 1024, 8 readers, 4 KiB samples) maps a 73 MB segment in `/dev/shm` but
//! commits 0.1 MB at start; with one reader holding 1024 samples, 9 MB (the samples and
//! that reader's 1024-deep queue). Image trajectories want an `Elements(n)` cache and
//! fewer `max_subscribers`; through `connect`, a trajectory of octets without an
//! element cache keeps only the last 16 for other processes (with a warning), since
//! 1024 camera frames would reserve gigabytes.

use esgm_core::CacheConstraint;

use crate::data_plane::capacity::{EventCapacity, Readers};

/// What a publisher does when a subscriber's buffer is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum Delivery {
    /// Overwrite the oldest unread sample (iceoryx2's safe overflow): a slow reader
    /// loses old samples, the producer never waits. Right for sensor streams, where
    /// the newest value is what matters.
    #[default]
    LatestWins,
    /// Never drop: the publisher retries until every subscriber has room
    /// (backpressure). A stuck subscriber stalls the producer — use it for streams
    /// where each sample must arrive (e.g. events, commands).
    Lossless,
}

/// Settings of a trajectory's publish-subscribe service (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrajectoryQos {
    /// Samples a publisher keeps for subscribers that connect later (the last N).
    pub history_size: usize,
    /// Unread samples a subscriber can queue.
    pub subscriber_buffer_size: usize,
    /// Samples a subscriber may hold at once (e.g. in a cache) without returning them.
    pub max_borrowed_samples: usize,
    /// Publishers per trajectory.
    pub max_publishers: usize,
    /// Subscribers per trajectory.
    pub max_subscribers: usize,
    /// Nodes (processes or threads with their own node) that may open the service.
    pub max_nodes: usize,
    /// Overflow behaviour.
    pub delivery: Delivery,
}

impl Default for TrajectoryQos {
    fn default() -> Self {
        Self {
            history_size: 1,
            subscriber_buffer_size: 8,
            max_borrowed_samples: 4,
            max_publishers: 4,
            max_subscribers: 8,
            max_nodes: 16,
            delivery: Delivery::LatestWins,
        }
    }
}

impl TrajectoryQos {
    /// Room for `readers` reader processes ([`crate::DomainLimits`]): their subscribers and
    /// nodes, with the tools' reserve.
    #[must_use]
    pub fn readers(self, readers: Readers) -> Self {
        Self { max_subscribers: readers.ports(), max_nodes: readers.nodes(), ..self }
    }

    /// How the wake-up service of a data service with these settings is sized: two
    /// waiting threads per subscriber, a notifier per publisher (and a margin for
    /// one being replaced), the data service's nodes.
    pub fn wake_capacity(&self) -> EventCapacity {
        EventCapacity {
            listeners: 2 * self.max_subscribers,
            notifiers: self.max_publishers + 3,
            nodes: self.max_nodes.max(2 * self.max_subscribers),
        }
    }
}

/// The history kept for late readers of a trajectory whose cache constraint is
/// `CacheConstraint::All` or `CacheConstraint::Duration`, when no other maximum is
/// configured.
pub const DEFAULT_MAX_HISTORY: usize = 1024;

/// How many samples the shared-memory history of a trajectory whose cache constraint is
/// `cache` holds: `n` for `Elements(n)`, `max_history` for every other constraint
/// (including `Elements(0)`, which means all). At least 1.
pub fn history_bound(cache: CacheConstraint, max_history: usize) -> usize {
    match cache {
        CacheConstraint::Elements(n) if n > 0 => n,
        _ => max_history.max(1),
    }
}

/// The service settings of a trajectory whose history keeps `bound` samples
/// ([`history_bound`]), starting from `base` for everything else.
///
/// The publisher keeps `bound` samples for late readers; each reader may hold `bound`
/// samples plus the one it is receiving; a reader's queue holds at least `bound` so
/// that the whole history fits when it connects. Queue and held samples only grow from
/// `base`, so a plain [`crate::TrajectorySubscriber`] with `base` settings (e.g. a unit
/// that needs no history) can still open the service.
pub fn history_qos(bound: usize, base: TrajectoryQos) -> TrajectoryQos {
    TrajectoryQos {
        history_size: bound,
        subscriber_buffer_size: base.subscriber_buffer_size.max(bound),
        max_borrowed_samples: base.max_borrowed_samples.max(bound + 1),
        ..base
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_settings() {
        assert_eq!(history_bound(CacheConstraint::Elements(4), 1024), 4);
        assert_eq!(history_bound(CacheConstraint::Elements(0), 16), 16);
        assert_eq!(history_bound(CacheConstraint::All, 0), 1);
        assert_eq!(history_bound(CacheConstraint::Duration(5), 32), 32);
        let base = TrajectoryQos::default();
        let q = history_qos(20, base);
        assert_eq!(
            (q.history_size, q.subscriber_buffer_size, q.max_borrowed_samples),
            (20, 20, 21)
        );
        assert_eq!(q.max_subscribers, base.max_subscribers);
        // Never below the base: plain subscribers with the base settings still fit.
        let q = history_qos(1, base);
        assert_eq!((q.subscriber_buffer_size, q.max_borrowed_samples), (8, 4));
    }
}
