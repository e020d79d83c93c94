//! # esgm-shm
//!
//! esgm over zero-copy shared memory: every trajectory is an iceoryx2 (0.10)
//! publish-subscribe service whose samples are codec-encoded entity structures
//! ([`esgm_core::codec`]) that readers use in place.
//!
//! This is the data plane: [`TrajectoryPublisher`], [`TrajectorySubscriber`], the
//! sample layout ([`SampleHeader`]), service naming ([`TrajectoryServiceNames`]), waiting
//! ([`WaitStrategy`]), structures encoded ahead of sending ([`StructureLoan`]) and in-place
//! images ([`ImageLoan`]), and the violations of a trajectory ([`ViolationSubscriber`]). The
//! control plane (coordinator, registry) and [`connect`], the `Esgm` interface across
//! processes, build on it: policy, history and queries are esgm-core's.
//!
//! ```no_run
//! use std::time::Duration;
//! use esgm_core::EntityStructure;
//! use esgm_shm::{TrajectoryPublisher, TrajectorySubscriber};
//! use esgm_shm::ShmService;
//! use iceoryx2::prelude::NodeBuilder;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let node = NodeBuilder::new().config(esgm_shm::iceoryx2_config()).create::<ShmService>()?;
//! let publisher = TrajectoryPublisher::builder("robot_state", "RobotState")
//!     .domain("lab")
//!     .create(&node)?;
//! let subscriber = TrajectorySubscriber::builder("robot_state", "RobotState")
//!     .domain("lab")
//!     .create(&node)?;
//!
//! publisher.publish(&EntityStructure::new("robot1", 10, 11).with("x", 1.0))?;
//! if let Some(sample) = subscriber.wait_for_sample(Duration::from_millis(100))? {
//!     let archived = sample.structure()?; // validated, read in shared memory
//!     assert_eq!(archived.name.as_str(), "robot1");
//! }
//! # Ok(())
//! # }
//! ```
//!
//! ## Design decisions
//! - **A payload of 16-byte blocks, not bytes.** The archive needs 16-byte alignment;
//!   iceoryx2's `[u8]` is only 8-aligned, and asking for 16 pads every byte to 16
//!   (a 385 MB segment for one image publisher). See `payload`.
//! - **Everything a filter needs is in the header.** Times, archive length, type id and
//!   sequence travel in the iceoryx2 user header ([`SampleHeader`]), so type checks and
//!   time lookups never touch the payload; the header is plain integers, so a corrupt
//!   one is rejected by comparison, never undefined behaviour.
//! - **Encode once, into the loan.** The publisher sizes the loan with a cheap walk of
//!   the structure (`size_hint`) instead of a trial encode, and the codec writes
//!   straight into shared memory. A producer that knows its structure early encodes it
//!   into a loan beforehand and only re-stamps its times and sends when the moment
//!   comes (`structure_loan`). Images go further: the camera writes the pixels into
//!   the loan and the codec completes the archive around them (`image_loan`).
//! - **Validate where bytes cross a process boundary.** Every received archive is
//!   validated before it is handed out ([`Validation::InPlace`]); a trusted setup may
//!   defer or skip it, explicitly and unsafely. Bad samples are typed errors and
//!   counters ([`SubscriberStats`]), never panics.
//! - **Spin briefly, then sleep on a futex.** A blocking reader sleeps on its
//!   trajectory's futex word in shared memory ([`wake_word`](crate::unstable::WakeWord)), half the cost of
//!   iceoryx2's event (a Unix datagram), which stays for waits over many trajectories.
//!   The default [`WaitStrategy`] still spins 25 µs before sleeping; every wait has a
//!   deadline because a dead publisher is not signalled. See `wait`.
//! - **One namespace per system, and per test.** Service names carry a domain
//!   (`service_name`), so parallel tests and independent systems never meet.
//!
//! ## One writer per trajectory, and it gates
//! Exactly one process writes a trajectory (the coordinator places it, see
//! [`connect`]), and there it is an ordinary esgm-core [`esgm_core::TrajectoryStore`]:
//! its policy — type check, duration, delay, filter, order, change, and the
//! hold-and-reorder of late samples — gates every add, from that process or forwarded
//! from others, and the add forms return the in-process outcomes and errors. The
//! store's tap publishes what it admits inline, stamped with the gate's add time, and
//! what it drops on the trajectory's violations service (`violations`), so every
//! reader receives exactly the stream, already checked, in order.
//!
//! ## Where the history lives
//! **In each reading process, in an esgm-core store.** A process that reads a
//! trajectory written elsewhere keeps a *replica*: an esgm-core store with the
//! trajectory's policy, fed from a [`TrajectorySubscriber`] (entries, violations and
//! resets in stream order). Queries (T1, T2), subscriptions, units and syncs run on it
//! as in one process, answered by esgm-core's store: there is one valid-time index and
//! one approximation, esgm-core's. Why there:
//! - **Queries without a round trip.** `get_latest` in a control loop is a lookup in
//!   the reader's own memory, not a request to another process (≥ 10 µs, and a failure
//!   mode when that process is slow or gone).
//! - **No process holds every image.** No coordinator accumulates every trajectory's
//!   history.
//! - **Consistent because the writer gates.** Every replica receives the same, already
//!   constrained stream, so replicas agree with each other and with the writer.
//!
//! A replica's small fields are decoded (cheaper than bookkeeping); its images are
//! not: each octet sequence of a large sample stays in the writer's chunk, kept
//! borrowed until the last value reading it — in the cache, a unit's input, a
//! subscriber's queue, a query answer — is dropped ([`holdings`](crate::HoldingStats)). A process that keeps
//! more images than its subscriber may borrow (cache bound + a slack of 8) gets copies
//! of the later ones, counted in [`ShmEsgm::holding_stats`].
//!
//! The publisher keeps the cache's bound of samples ([`qos::history_bound`](data_plane::qos::history_bound)), so a
//! replica made late starts with the writer's view; an `All` or `Duration` cache, which
//! iceoryx2 needs as a number, gives late replicas at most [`DEFAULT_MAX_HISTORY`]
//! (1024). Each replica holds its own view: one made late, or one that fell a whole
//! queue behind (the writer overwrites its oldest unread samples), holds less — and
//! counts every sample it missed that way as dropped (`lost`), from the gap in the
//! writer's sequence numbers.
//!
//! How a sample crosses with one wake-up, and how images are written once, by their
//! producer, where every reader reads them: see `client`.
//!
//! ## The coordinator is not a single point of failure
//! The coordinator ([`control`]) is a registry and a supervisor; samples never pass
//! through it. If it dies, the processes that run keep exchanging samples, and workers
//! wait for a new one ([`client::attach`] tells a slow coordinator from a gone one).
//! A new coordinator comes back whole from a **persisted state file**, not from the
//! processes re-registering: the registry holds what no live process holds in full
//! (types and trajectories declared by processes that have left, the process table
//! with pids and restarts) and each trajectory's generation, which every process
//! compares with what it mirrors once a second — a registry rebuilt piecemeal would
//! make readers drop what they read. The file is replaced atomically after every
//! change, in a per-domain directory ([`crate::control::StateDir`] says where and why).
#![deny(missing_docs)]

pub(crate) mod client;
pub mod control;
pub(crate) mod data_plane;
pub mod process;

// `use esgm_shm::prelude::*;`: connect, ShmEsgm and esgm_core's prelude.
pub use client::prelude;

pub use client::attach;

pub use client::holdings::HoldingStats;
pub use data_plane::capacity::{
    DEFAULT_MAX_PROCESSES, DEFAULT_READERS, DomainLimits, EventCapacity, IllegalLimit, Readers,
};
pub use data_plane::image_layout::ImageError;
pub use data_plane::image_loan::ImageLoan;
pub use data_plane::payload::{Block16, SampleHeader};
pub use data_plane::publisher::{
    PublishError, Published, SampleSizing, TrajectoryPublisher, TrajectoryPublisherBuilder,
};
pub use data_plane::qos::{
    DEFAULT_MAX_HISTORY, Delivery, TrajectoryQos, history_bound, history_qos,
};
pub use data_plane::received::ReceivedSample;
pub use data_plane::sample_check::{SampleVerdict, check_sample};
pub use data_plane::service::{
    Cleanup, CleanupFailure, CleanupReporter, DEFAULT_ICEORYX2_ROOT, DeadNodeCleanup,
    ICEORYX2_ROOT_ENV, OpenError, ShmNode, ShmService, cleanup_dead_nodes, iceoryx2_config,
    node_config,
};
pub use data_plane::service_name::{
    DEFAULT_DOMAIN, NameError, SYSTEM_DOMAIN, TrajectoryServiceNames, node_name, nodes_of,
    processes_of, unique_domain,
};
pub use data_plane::structure_loan::StructureLoan;
pub use data_plane::subscriber::{
    ReceiveError, SubscriberStats, TrajectorySubscriber, TrajectorySubscriberBuilder, Validation,
};
pub use data_plane::type_id::type_id;
pub use data_plane::violations::{
    ViolationPublisher, ViolationRecord, ViolationSubscriber, ViolationSubscriberBuilder,
    ViolationSubscriberStats,
};
pub use data_plane::wait::{WaitAnyError, WaitStrategy};
pub use data_plane::writer_check::{Decided, WriterCheck};

pub mod unstable;

pub use client::{
    ConnectError, CoordinatorWatch, DEFAULT_TIMEOUT, DOMAIN_ENV, ShmEsgm, ShmEsgmBuilder,
    WORKER_ENV, connect, trajectory_qos,
};
