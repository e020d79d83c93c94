//! `refsys-ros1`: the reference system on ROS 1 (roscpp, Debian's Noetic packages), one
//! process per node, as ROS 1 users deploy nodes.
//!
//! Each node is a process of `benches/ros1/refsys_node.cpp` (built by
//! `benches/ros1/build.sh`), a C++ port of [`super::node`]'s logic, [`super::message`]'s
//! byte layout and [`super::cruncher`] on roscpp; this file tells it which node it is, in
//! arguments rendered from [`super::topology`], so the graph is written down once. The
//! processes talk through a private `rosmaster` on a free loopback port (the one the
//! `ros1-*` rows start), whose CPU and memory count with theirs.
//!
//! How upstream's rclcpp nodes map onto ROS 1 (also in each row's notes):
//! - the message is a `std_msgs/UInt8MultiArray` of Message4kb's 4,096 bytes (upstream's
//!   `reference_interfaces` type needs catkin's message generation);
//! - history depth 1 is a queue of one on every publisher and subscriber (roscpp drops
//!   the oldest when a queue is full), over TCPROS with TCP_NODELAY;
//! - sensors and the behavior planner are `ros::WallTimer`s, first firing at START;
//! - a node's callbacks run on one thread (`ros::AsyncSpinner(1)`), as on upstream's
//!   single-threaded executor; a fusion fires once both inputs have a message it has
//!   not used, in its subscription callbacks, as upstream's `fusion.hpp` does.

use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::Context as _;

use super::cruncher::number_cruncher;
use super::processes;
use super::system::{RunSettings, System, SystemRun};
use super::topology::{HOT_PATH_ROOT, HOT_PATH_SINK, Kind, NODES, Node};
use crate::scenarios::ros1_peer::{Guard, HOW, Master, built, read_all, which};

/// The environment variable that names a `refsys_node` built elsewhere.
pub const PROGRAM_VAR: &str = "ESGM_ROS1_REFSYS";

/// The built node program, if there is one: `ESGM_ROS1_REFSYS`, else the place
/// `build.sh` puts it.
pub fn program() -> Option<std::path::PathBuf> {
    built(PROGRAM_VAR, "refsys_node")
}

/// How long `refsys_node --crunch-time` may take (21 crunches).
const CRUNCH_TIMEOUT: Duration = Duration::from_secs(60);

/// One crunch to `crunch` in `program`'s C++ build (the median of its 21): the nodes'
/// work in this system, beside the Rust build's the scenario prints. The port's result
/// must be [`number_cruncher`]'s.
fn crunch_time(program: &std::path::Path, crunch: u64) -> anyhow::Result<Duration> {
    let mut c = Command::new(program);
    c.arg("--crunch-time").arg(crunch.to_string()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = Guard::new(c.spawn().context("starting refsys_node --crunch-time")?);
    let out = read_all(child.child()?.stdout.take().context("its stdout")?);
    let err = read_all(child.child()?.stderr.take().context("its stderr")?);
    let status = child.wait("refsys_node --crunch-time", CRUNCH_TIMEOUT)?;
    let (out, err) = (out.join().unwrap_or_default(), err.join().unwrap_or_default());
    anyhow::ensure!(
        status.success(),
        "refsys_node --crunch-time failed ({status}): {}",
        err.trim()
    );
    let bad = || format!("refsys_node --crunch-time printed {out:?}, not `NS RESULT`");
    let mut words = out.split_whitespace().map(str::parse::<i64>);
    let (Some(Ok(ns)), Some(Ok(result))) = (words.next(), words.next()) else {
        anyhow::bail!(bad());
    };
    let expected = number_cruncher(crunch);
    anyhow::ensure!(
        result == expected,
        "refsys_node's number cruncher to {crunch} gives {result}, esgm-bench's {expected}"
    );
    Ok(Duration::from_nanos(u64::try_from(ns).with_context(bad)?))
}

/// What ROS 1 expresses differently from upstream, for the row's notes.
const NOTES: [&str; 3] = [
    "ROS 1: Message4kb's 4,096 bytes in a std_msgs/UInt8MultiArray (upstream's message \
     type needs catkin's generation); depth 1 as publisher and subscriber queues of one \
     (roscpp drops the oldest), TCPROS with TCP_NODELAY on loopback",
    "ROS 1: one process per node, as roscpp nodes are deployed (upstream runs all nodes in \
     one process; ROS 1's way to share one, nodelets, skips serialization and TCPROS), a \
     node's callbacks and timer on one thread (AsyncSpinner(1)), sensors and the planner \
     on ros::WallTimer",
    "ROS 1: a private rosmaster, counted in CPU and memory; every subscriber connected to \
     its publisher before the run starts",
];

/// `refsys-ros1` (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Ros1;

/// The `KIND ARGS...` that tell `refsys_node` what `node` is (the program's header lists
/// them): its kind, topics and period, from the topology.
pub fn node_args(node: &Node) -> Vec<String> {
    let s = |v: &[&str]| v.iter().map(|a| (*a).to_owned()).collect::<Vec<_>>();
    let ns = |d: std::time::Duration| d.as_nanos().to_string();
    match node.kind {
        Kind::Sensor { period } => vec!["sensor".to_owned(), ns(period)],
        Kind::Transform { input } => {
            let mut a = s(&["transform", input, node.name]);
            if node.name == HOT_PATH_SINK {
                a.push(HOT_PATH_ROOT.to_owned());
            }
            a
        }
        Kind::Fusion { inputs: [a, b] } => s(&["fusion", a, b]),
        Kind::Cyclic { inputs, period } => {
            let mut a = vec!["cyclic".to_owned(), ns(period)];
            a.extend(s(&inputs));
            a
        }
        Kind::Intersection { connections: [(i0, o0), (i1, o1)] } => {
            s(&["intersection", i0, o0, i1, o1])
        }
        Kind::Command { input } => s(&["command", input]),
    }
}

impl System for Ros1 {
    fn name(&self) -> &'static str {
        "ros1"
    }

    fn summary(&self) -> &'static str {
        "ROS 1 (roscpp), one process per node and a rosmaster"
    }

    fn unavailable(&self) -> Option<String> {
        if program().is_none() {
            return Some(match std::env::var_os(PROGRAM_VAR) {
                Some(p) => format!("{PROGRAM_VAR}={} is not a file; {HOW}", p.to_string_lossy()),
                None => format!("benches/ros1/build/refsys_node is not built; {HOW}"),
            });
        }
        if which("rosmaster").is_none() {
            return Some(format!("rosmaster is not installed; {HOW}"));
        }
        None
    }

    fn run(&self, settings: &RunSettings) -> anyhow::Result<SystemRun> {
        let program = program().with_context(|| format!("refsys_node is not built; {HOW}"))?;
        let crunched = crunch_time(&program, settings.crunch)?;
        let master = Master::start(None)?;
        let master_pid = master.pid().context("the rosmaster has no process")?;
        let mut nodes = Vec::new();
        for node in &NODES {
            let mut c = Command::new(&program);
            c.arg(node.name)
                .arg(settings.crunch.to_string())
                .arg(&settings.dir)
                .args(node_args(node));
            master.env(&mut c);
            nodes.push((node.name.to_owned(), c));
        }
        let count = nodes.len() + 1;
        let (reports, usage, mut notes) = processes::run(nodes, &[master_pid], settings)?;
        notes.push(format!(
            "ROS 1: every node's work is refsys_node's C++ number cruncher to {} (g++ -O2, \
             its division written as rustc's LLVM emits it): {:.2} ms here",
            settings.crunch,
            crunched.as_secs_f64() * 1e3
        ));
        notes.extend(NOTES.iter().map(|n| (*n).to_owned()));
        // The nodes have left: the master can go.
        drop(master);
        Ok(SystemRun { reports, usage, processes: count, notes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::refsys::topology::node;

    #[test]
    fn every_node_is_told_its_kind_topics_and_period() {
        let args = |name: &str| node_args(node(name).unwrap());
        assert_eq!(args("FrontLidarDriver"), ["sensor", "100000000"]);
        assert_eq!(
            args("ObjectCollisionEstimator"),
            ["transform", "EuclideanClusterDetector", "ObjectCollisionEstimator", HOT_PATH_ROOT]
        );
        assert_eq!(args("RayGroundFilter"), ["transform", "PointCloudFusion", "RayGroundFilter"]);
        assert_eq!(
            args("PointCloudFusion"),
            ["fusion", "PointsTransformerFront", "PointsTransformerRear"]
        );
        assert_eq!(args("BehaviorPlanner").len(), 8);
        assert_eq!(args("BehaviorPlanner")[..2], ["cyclic", "100000000"]);
        assert_eq!(
            args("EuclideanClusterDetector"),
            [
                "intersection",
                "RayGroundFilter",
                "EuclideanClusterDetector",
                "EuclideanClusterSettings",
                "EuclideanIntersection"
            ]
        );
        assert_eq!(args("VehicleDBWSystem"), ["command", "VehicleInterface"]);
    }
}
