//! # esgm-shm
//!
//! esgm over zero-copy shared memory: every trajectory is an iceoryx2 (0.10)
//! publish-subscribe service whose samples are codec-encoded entity structures
//! ([`esgm_core::codec`]) that readers use in place.
//!
//! This is the data plane: [`TrajectoryPublisher`], [`TrajectorySubscriber`], the
//! sample layout ([`payload`]), service naming ([`service_name`]), waiting
//! ([`wait`]) and in-place images ([`image_loan`]). The control plane (coordinator,
//! registry, `connect`) builds on it.
//!
//! ```no_run
//! use std::time::Duration;
//! use esgm_core::EntityStructure;
//! use esgm_shm::{TrajectoryPublisher, TrajectorySubscriber};
//! use iceoryx2::prelude::{NodeBuilder, ipc};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let node = NodeBuilder::new().create::<ipc::Service>()?;
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
//!   straight into shared memory. Images go further: the camera writes the pixels into
//!   the loan and only times and header are added at send ([`image_loan`]).
//! - **Validate where bytes cross a process boundary.** Every received archive is
//!   validated before it is handed out ([`Validation::InPlace`]); a trusted setup may
//!   defer or skip it, explicitly and unsafely. Bad samples are typed errors and
//!   counters ([`SubscriberStats`]), never panics.
//! - **Spin briefly, then block.** iceoryx2's event wake-up costs more than a blocking
//!   Unix-socket read here, so the default [`WaitStrategy`] spins 25 µs before sleeping;
//!   every wait has a deadline because a dead publisher is not signalled. See [`wait`].
//! - **One namespace per system, and per test.** Service names carry a domain
//!   ([`service_name`]), so parallel tests and independent systems never meet.
#![deny(missing_docs)]

pub mod image_layout;
pub mod image_loan;
pub mod payload;
pub mod publisher;
pub mod qos;
pub mod received;
pub mod service;
pub mod service_name;
pub mod size_hint;
pub mod subscriber;
pub mod type_id;
pub mod wait;

pub use image_layout::ImageError;
pub use image_loan::ImageLoan;
pub use payload::{Block16, SampleHeader};
pub use publisher::{PublishError, Published, SampleSizing, TrajectoryPublisher};
pub use qos::{Delivery, TrajectoryQos};
pub use received::ReceivedSample;
pub use service::{OpenError, ShmNode};
pub use service_name::{NameError, TrajectoryServiceNames, unique_domain};
pub use subscriber::{ReceiveError, SubscriberStats, TrajectorySubscriber, Validation};
pub use type_id::type_id;
pub use wait::WaitStrategy;
