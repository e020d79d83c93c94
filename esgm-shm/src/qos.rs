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
