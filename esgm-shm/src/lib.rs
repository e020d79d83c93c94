//! # esgm-shm
//!
//! esgm over zero-copy shared memory: every trajectory is an iceoryx2 (0.10)
//! publish-subscribe service whose samples are codec-encoded entity structures
//! ([`esgm_core::codec`]) that readers use in place.
//!
//! This is the data plane: [`TrajectoryPublisher`], [`TrajectorySubscriber`], the
//! sample layout ([`payload`]), service naming ([`service_name`]), waiting
//! ([`wait`]), structures encoded ahead of sending ([`structure_loan`]) and in-place
//! images ([`image_loan`]); and on top of it trajectories with
//! policy and history: [`ShmTrajectoryWriter`], [`ShmTrajectoryReader`],
//! [`violations`]. The control plane (coordinator, registry, `connect`) builds on it.
//!
//! ```no_run
//! use std::time::Duration;
//! use esgm_core::EntityStructure;
//! use esgm_shm::{TrajectoryPublisher, TrajectorySubscriber};
//! use esgm_shm::ShmService;
//! use iceoryx2::prelude::NodeBuilder;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let node = NodeBuilder::new().create::<ShmService>()?;
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
//!   (a 385 MB segment for one image publisher). See [`payload`].
//! - **Everything a filter needs is in the header.** Times, archive length, type id and
//!   sequence travel in the iceoryx2 user header ([`SampleHeader`]), so type checks and
//!   time lookups never touch the payload; the header is plain integers, so a corrupt
//!   one is rejected by comparison, never undefined behaviour.
//! - **Encode once, into the loan.** The publisher sizes the loan with a cheap walk of
//!   the structure ([`size_hint`]) instead of a trial encode, and the codec writes
//!   straight into shared memory. A producer that knows its structure early encodes it
//!   into a loan beforehand and only re-stamps its times and sends when the moment
//!   comes ([`structure_loan`]). Images go further: the camera writes the pixels into
//!   the loan and the codec completes the archive around them ([`image_loan`]).
//! - **Validate where bytes cross a process boundary.** Every received archive is
//!   validated before it is handed out ([`Validation::InPlace`]); a trusted setup may
//!   defer or skip it, explicitly and unsafely. Bad samples are typed errors and
//!   counters ([`SubscriberStats`]), never panics.
//! - **Spin briefly, then block.** iceoryx2's event wake-up costs more than a blocking
//!   Unix-socket read here, so the default [`WaitStrategy`] spins 25 µs before sleeping;
//!   every wait has a deadline because a dead publisher is not signalled. See [`wait`].
//! - **One namespace per system, and per test.** Service names carry a domain
//!   ([`service_name`]), so parallel tests and independent systems never meet.
//!
//! ## One writer per trajectory, and it gates
//! Exactly one process writes a trajectory: its [`ShmTrajectoryWriter`]. The writer runs
//! the trajectory's policy — type check, duration, delay, filter, order, change, and the
//! hold-and-reorder of late samples — *before* publishing, with esgm-core's own
//! [`esgm_core::TrajectoryStore`] as the gate, so every reader receives exactly the
//! stream, already checked, with the gate's add time in the header, and the add forms
//! return the in-process outcomes and errors. Dropped structures are published on the
//! trajectory's violations service ([`violations`]) for any process to watch (C7). A
//! second writer would gate a second, different stream, so the writer refuses to start
//! on a trajectory that already has a publisher.
//!
//! ## Where the history lives
//! **In each reader.** A [`ShmTrajectoryReader`] keeps the iceoryx2 samples it received
//! — the structures stay in shared memory, where the writer encoded them — up to the
//! cache bound, evicts them as the policy's cache constraint says, and answers the
//! queries (T1, T2) itself, looking samples up by the times in their headers. The
//! publisher's iceoryx2 history is sized to the same bound, so a reader that connects
//! late receives the last N samples and starts with the writer's view. Why there:
//! - **Zero copy end to end.** A cached image is the writer's shared-memory chunk; a
//!   query answers with it in place. A cache in the producer or a coordinator would
//!   answer across a process boundary, i.e. copy the answer into a response.
//! - **No process holds every image.** The writer keeps only what its gate needs; no
//!   coordinator accumulates every trajectory's history.
//! - **Queries without a round trip.** `get_latest` in a control loop is a lookup in
//!   the reader's own memory (≈ nanoseconds), not a request to another process
//!   (≥ 10 µs, and a failure mode when that process is slow or gone).
//! - **Consistent because the writer gates.** Every reader receives the same, already
//!   constrained stream, so their histories agree with each other and with what an
//!   in-process store of the same policy would hold.
//!
//! The costs: each reader holds its own view (one that started late or fell behind —
//! counted as lost — may hold less); shared memory is sized for the cache in every
//! reader at once — each reader may borrow `bound + 1` chunks and the writer keeps
//! `bound` for late joiners, so a segment has about
//! `max_subscribers × (queue + bound) + bound` chunks of the largest sample (tmpfs
//! commits only the chunks in use); and an
//! `All` or `Duration` cache, which iceoryx2 needs as a number, holds at most a
//! configured maximum ([`DEFAULT_MAX_HISTORY`], 1024) — see [`history`]. Readers are
//! single-threaded like the ports they hold; [`HostedTrajectoryReader`] puts one on a
//! thread of its own for queries from anywhere (answers then are owned copies).
//!
//! Through [`connect`], the reader is the process's replica of the trajectory: an
//! ordinary esgm-core store fed from the subscriber, so units, syncs, subscriptions and
//! queries run there as in one process. Its small fields are decoded (cheaper than
//! bookkeeping); its images are not: each octet sequence of a large sample stays in
//! the writer's chunk, which the location thread keeps borrowed until the last value
//! reading it — in the cache, a unit's input, a subscriber's queue, a query answer —
//! is dropped ([`holdings`]). A process that keeps more images than its subscriber may
//! borrow (cache bound + a slack of 8) gets copies of the later ones, counted in
//! [`ShmEsgm::holding_stats`].
#![deny(missing_docs)]

pub mod history;
pub mod holdings;
pub mod hosted_reader;
pub mod image_layout;
pub mod image_loan;
pub mod payload;
pub mod publisher;
pub mod qos;
pub mod reader;
pub mod received;
mod sequence_gaps;
pub mod service;
pub mod service_name;
pub mod size_hint;
pub mod structure_loan;
pub mod subscriber;
pub mod type_id;
pub mod violations;
pub mod wait;
pub mod writer;

pub use history::{DEFAULT_MAX_HISTORY, history_bound, history_qos};
pub use holdings::HoldingStats;
pub use hosted_reader::{HostError, HostedTrajectoryReader};
pub use image_layout::ImageError;
pub use image_loan::ImageLoan;
pub use payload::{Block16, SampleHeader};
pub use publisher::{PublishError, Published, SampleSizing, TrajectoryPublisher};
pub use qos::{Delivery, TrajectoryQos};
pub use reader::{
    Approximated, CachedSample, HistoryError, ReaderCreateError, ReaderStats, ShmTrajectoryReader,
};
pub use received::ReceivedSample;
pub use service::{OpenError, ShmNode, ShmService};
pub use service_name::{NameError, TrajectoryServiceNames, node_name, nodes_of, unique_domain};
pub use structure_loan::StructureLoan;
pub use subscriber::{ReceiveError, SubscriberStats, TrajectorySubscriber, Validation};
pub use type_id::type_id;
pub use violations::{ViolationPublisher, ViolationRecord, ViolationSubscriber};
pub use wait::WaitStrategy;
pub use writer::{ShmTrajectoryWriter, WriteError, WriterCreateError, WriterStats};
pub mod client;
pub mod control;

pub use client::{ConnectError, DOMAIN_ENV, ShmEsgm, ShmEsgmBuilder, WORKER_ENV, connect};
