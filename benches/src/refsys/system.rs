//! A system that runs the reference system (esgm in one process, esgm with one process
//! per node, ROS 1, ROS 2's wire), as `esgm-bench`'s `refsys` scenario drives it: start
//! it, let it run, stop it, and hand back every node's report and what its processes
//! used. Each system lives in its own file; they differ only in how messages move.

use std::path::PathBuf;
use std::time::Duration;

use super::report::NodeReport;
use super::resources::Usage;

/// How a system is run.
#[derive(Debug, Clone)]
pub struct RunSettings {
    /// How long the topology runs once every node is up.
    pub duration: Duration,
    /// The number cruncher's limit of every processing node (upstream's default timing:
    /// 4096 on its machine, calibrated here; 0 in its CPU-usage timing).
    pub crunch: u64,
    /// A directory of this run's own, for the nodes' reports and logs.
    pub dir: PathBuf,
    /// Pin the processes (`esgm-bench --pin`): the system's processes share the peer
    /// core, or both cores when there are more of them than one core can hold.
    pub pin: bool,
}

/// What one run of a system gave.
#[derive(Debug)]
pub struct SystemRun {
    /// Every node's report.
    pub reports: Vec<NodeReport>,
    /// CPU and memory of all its processes while the topology ran.
    pub usage: Usage,
    /// Its processes (a coordinator, a rosmaster, DDS daemons included).
    pub processes: usize,
    /// What the report should say about this run (a deviation from upstream, a
    /// substitute for something the system cannot express).
    pub notes: Vec<String>,
}

/// A system that runs the topology.
pub trait System {
    /// Its rows' name: `refsys-<name>`.
    fn name(&self) -> &'static str;
    /// One line for `--list`.
    fn summary(&self) -> &'static str;
    /// Why it cannot run here (a peer not built, no root for a namespace), if so: the
    /// row is skipped with this reason.
    fn unavailable(&self) -> Option<String> {
        None
    }
    /// Runs the topology once.
    fn run(&self, settings: &RunSettings) -> anyhow::Result<SystemRun>;
}
