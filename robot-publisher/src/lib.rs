//! # robot-publisher
//!
//! The robot of the seed's tutorial (chapter 8.1), which pushes a `RobotState` every
//! 100 ms. The seed's robot always reports `(1, 2, 3)`; here a simulated robot moves,
//! following the `DrivingDirection` the tutorial's last unit computes, so the whole loop
//! (camera → blobs → current blob → driving direction → robot) can close.
//!
//! ## Design decisions
//! - **Pure and time-stepped.** [`Kinematics::step`] advances the state by a duration
//!   in [`esgm_core::Time`] nanoseconds; the publisher decides when to step and what
//!   clock to read, so the model runs the same under a simulated clock in tests.
//! - **Publishing is a thin adapter.** [`RobotPublisher`] steps the model on a thread,
//!   paced by the runtime's [`esgm_core::Clock`], and pushes each state with
//!   `create_at_now`; it names only esgm-core's traits, so it pushes into any runtime.
//! - **Exact integration.** Each step turns at the bounded rate until the heading is
//!   reached, then drives straight, integrating the arc in closed form: two steps of
//!   50 ms land exactly where one of 100 ms does, so the publishing period does not
//!   change the path.
//! - **One robot process.** [`serve`] is the robot as a process — its command line,
//!   starting it on any runtime, the worker — run by both the `robot-publisher` binary
//!   and `esgm worker robot`.
//!
//! ```
//! use esgm_core::library::{DrivingDirection, RobotState};
//! use esgm_core::time::secs;
//! use robot_publisher::Kinematics;
//!
//! let mut robot = Kinematics::new(RobotState { x: 0.0, y: 0.0, dir: 0.0 }, Default::default())?;
//! let state = robot.step(secs(1), &DrivingDirection { dir: 0.0, speed: 0.5 });
//! assert_eq!((state.x, state.y, state.dir), (0.5, 0.0, 0.0));
//! # Ok::<(), robot_publisher::KinematicsError>(())
//! ```
#![deny(missing_docs)]

pub mod kinematics;
pub mod publisher;
pub mod serve;

pub use kinematics::{Kinematics, KinematicsConfig, KinematicsError};
pub use publisher::{
    DEFAULT_PERIOD, PublisherStats, RobotPublisher, RobotPublisherBuilder, RobotPublisherError,
};
pub use serve::RobotArgs;
