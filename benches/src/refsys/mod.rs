//! The Autoware reference system (ros-realtime/reference-system, package
//! `autoware_reference_system`): a published robot topology — 24 nodes modelled on
//! Autoware's lidar pipeline, 23 topics of one 4 KiB message, fixed periods, dummy work
//! — that esgm and its peers run side by side (SPEC W1). What is the same for every
//! system lives here, once:
//! - [`topology`]: the nodes, their kinds, periods, inputs and work, read from upstream's
//!   `autoware_system_builder.hpp` and `system/timing/default.hpp` (where upstream's
//!   README and code disagree, the code);
//! - [`message`]: `Message4kb`, byte for byte (an 8-byte count, 63 per-hop stats of 64
//!   bytes, 56 bytes of data), and upstream's rules for filling its per-hop trace;
//! - [`cruncher`]: upstream's number cruncher, the nodes' work;
//! - [`node`]: what each kind of node does with its inputs, whatever carries them;
//! - [`report`]: what every node writes when it stops, and [`kpi`]: the reference
//!   system's own KPIs computed from those reports, for every system alike;
//! - [`system_file`]: the topology as an esgm system file (`benches/refsys/refsys.toml`,
//!   generated from [`topology`]), in esgm's own terms: sensors, units, trajectories;
//!   [`served`]: the sensors and units its node program serves, on either runtime, and
//!   [`node_program`]: that program (`esgm-refsys-node`), with [`window`] and
//!   [`run_dir`]: how its processes take part in a run;
//! - [`esgm`]: the file run in one process, or one process per sensor and unit started
//!   by a coordinator;
//! - [`ros1`]: the topology on ROS 1 (roscpp), a C++ process per node and a rosmaster;
//! - `ros2` (feature `ros2`): the topology on ROS 2's wire, DDS through ros2-client,
//!   one process per node in a loopback-only network namespace;
//! - [`resources`]: the CPU and memory of all of a system's processes;
//! - [`system`]: what a system that runs the topology gives the `refsys` scenario, and
//!   [`processes`]: how its processes are started, run and stopped together.

pub mod cruncher;
pub mod esgm;
pub mod kpi;
pub mod message;
pub mod node;
pub mod node_program;
pub mod processes;
pub mod report;
pub mod resources;
pub mod ros1;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod run_dir;
pub mod served;
pub mod system;
pub mod system_file;
pub mod topology;
pub mod window;
