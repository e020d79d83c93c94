//! `esgm ros2`: esgm beside a ROS 2 robot. One process joins the robot's ROS 2 graph as
//! a node (over DDS, in pure Rust: no ROS installation to source) and the esgm domain as
//! a writer: ROS 2 topics come in as primitive trajectories ([`import`]), trajectories
//! go out as ROS 2 topics ([`export`]), the library types mapped to the standard
//! messages ([`mapping`]), every message counted ([`stats`]).

pub mod export;
pub mod generated;
pub mod import;
pub mod mapping;
pub mod msgs;
pub mod node;
pub mod stats;
