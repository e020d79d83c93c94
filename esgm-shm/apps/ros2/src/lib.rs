//! `esgm ros2`: esgm beside a ROS 2 robot. One process joins the robot's ROS 2 graph as
//! a node (over DDS, in pure Rust: no ROS installation to source) and the esgm domain as
//! a writer: ROS 2 topics come in as primitive trajectories ([`import`]), trajectories
//! go out as ROS 2 topics ([`export`]), the library types mapped to the standard
//! messages and every other type to a generated one (crate `esgm_ros2msg`, shared with
//! recordings in the ROS 2 profile), every message counted ([`stats`]).

#![deny(missing_docs)]

pub use esgm_ros2msg::{generated, mapping, msgs};

pub mod export;
pub mod import;
pub mod node;
pub mod stats;
pub mod watch;
