//! The reference system's node graph, as upstream's code builds it
//! (`autoware_system_builder.hpp`, timing `default.hpp`): 6 sensors, 9 transforms, 5
//! fusions, 1 cyclic node, 1 intersection node (two transforms in one node), 2 command
//! sinks. Every topic is named after the node that publishes it (the intersection's
//! second output is `EuclideanIntersection`) and keeps only its latest message.

use std::time::Duration;

/// What a node does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Publishes a fresh message every `period`.
    Sensor {
        /// Its period.
        period: Duration,
    },
    /// One input, one output, fires on every input.
    Transform {
        /// Its input topic.
        input: &'static str,
    },
    /// Two inputs, one output, fires once both have a message it has not used.
    Fusion {
        /// Its input topics.
        inputs: [&'static str; 2],
    },
    /// Six inputs, one output, fires on a timer with what arrived since.
    Cyclic {
        /// Its input topics.
        inputs: [&'static str; 6],
        /// Its timer's period.
        period: Duration,
    },
    /// Two transforms in one node: each input to its own output.
    Intersection {
        /// `(input, output)` of each.
        connections: [(&'static str, &'static str); 2],
    },
    /// A sink: receives one topic.
    Command {
        /// Its input topic.
        input: &'static str,
    },
}

/// One node of the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Node {
    /// Its name (and its output topic's, but for the intersection's second output).
    pub name: &'static str,
    /// What it does.
    pub kind: Kind,
}

const fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

const fn sensor(name: &'static str, period: Duration) -> Node {
    Node { name, kind: Kind::Sensor { period } }
}

const fn transform(name: &'static str, input: &'static str) -> Node {
    Node { name, kind: Kind::Transform { input } }
}

const fn fusion(name: &'static str, a: &'static str, b: &'static str) -> Node {
    Node { name, kind: Kind::Fusion { inputs: [a, b] } }
}

/// The 24 nodes, in upstream's order.
pub const NODES: [Node; 24] = [
    sensor("FrontLidarDriver", ms(100)),
    sensor("RearLidarDriver", ms(100)),
    sensor("PointCloudMap", ms(120)),
    sensor("Visualizer", ms(60)),
    sensor("Lanelet2Map", ms(100)),
    sensor("EuclideanClusterSettings", ms(25)),
    transform("PointsTransformerFront", "FrontLidarDriver"),
    transform("PointsTransformerRear", "RearLidarDriver"),
    transform("VoxelGridDownsampler", "PointCloudFusion"),
    transform("PointCloudMapLoader", "PointCloudMap"),
    transform("RayGroundFilter", "PointCloudFusion"),
    transform("ObjectCollisionEstimator", "EuclideanClusterDetector"),
    transform("MPCController", "BehaviorPlanner"),
    transform("ParkingPlanner", "Lanelet2MapLoader"),
    transform("LanePlanner", "Lanelet2MapLoader"),
    fusion("PointCloudFusion", "PointsTransformerFront", "PointsTransformerRear"),
    fusion("NDTLocalizer", "VoxelGridDownsampler", "PointCloudMapLoader"),
    fusion("VehicleInterface", "MPCController", "BehaviorPlanner"),
    fusion("Lanelet2GlobalPlanner", "Visualizer", "NDTLocalizer"),
    fusion("Lanelet2MapLoader", "Lanelet2Map", "Lanelet2GlobalPlanner"),
    Node {
        name: "BehaviorPlanner",
        kind: Kind::Cyclic {
            inputs: [
                "ObjectCollisionEstimator",
                "NDTLocalizer",
                "Lanelet2GlobalPlanner",
                "Lanelet2MapLoader",
                "ParkingPlanner",
                "LanePlanner",
            ],
            period: ms(100),
        },
    },
    Node {
        name: "EuclideanClusterDetector",
        kind: Kind::Intersection {
            connections: [
                ("RayGroundFilter", "EuclideanClusterDetector"),
                ("EuclideanClusterSettings", "EuclideanIntersection"),
            ],
        },
    },
    Node { name: "VehicleDBWSystem", kind: Kind::Command { input: "VehicleInterface" } },
    Node { name: "IntersectionOutput", kind: Kind::Command { input: "EuclideanIntersection" } },
];

/// The hot path, root to sink.
pub const HOT_PATH: [&str; 6] = [
    "FrontLidarDriver",
    "PointsTransformerFront",
    "PointCloudFusion",
    "RayGroundFilter",
    "EuclideanClusterDetector",
    "ObjectCollisionEstimator",
];

/// The hot path's root (its latency is measured from this sensor's timestamp).
pub const HOT_PATH_ROOT: &str = "FrontLidarDriver";
/// The hot path's sink.
pub const HOT_PATH_SINK: &str = "ObjectCollisionEstimator";
/// The cyclic node, whose timer's jitter and drift are KPIs.
pub const PLANNER: &str = "BehaviorPlanner";

impl Node {
    /// The topics it publishes.
    pub fn outputs(&self) -> Vec<&'static str> {
        match self.kind {
            Kind::Command { .. } => Vec::new(),
            Kind::Intersection { connections } => connections.iter().map(|(_, o)| *o).collect(),
            _ => vec![self.name],
        }
    }

    /// The topics it subscribes to.
    pub fn inputs(&self) -> Vec<&'static str> {
        match self.kind {
            Kind::Sensor { .. } => Vec::new(),
            Kind::Transform { input } | Kind::Command { input } => vec![input],
            Kind::Fusion { inputs } => inputs.to_vec(),
            Kind::Cyclic { inputs, .. } => inputs.to_vec(),
            Kind::Intersection { connections } => connections.iter().map(|(i, _)| *i).collect(),
        }
    }

    /// Whether it is a transform (its input gaps are a KPI), or one of the
    /// intersection's two.
    pub fn transforms(&self) -> bool {
        matches!(self.kind, Kind::Transform { .. } | Kind::Intersection { .. })
    }
}

/// The node called `name`.
pub fn node(name: &str) -> Option<&'static Node> {
    NODES.iter().find(|n| n.name == name)
}

/// The nodes in an order where each node's inputs are published by nodes before it (a
/// computed trajectory can only be declared once its inputs are).
pub fn build_order() -> Vec<&'static Node> {
    let mut done: Vec<&'static Node> = Vec::new();
    while done.len() < NODES.len() {
        let published: Vec<&str> = done.iter().flat_map(|n| n.outputs()).collect();
        let next = NODES.iter().find(|n| {
            !done.iter().any(|d| d.name == n.name)
                && n.inputs().iter().all(|i| published.contains(i))
        });
        match next {
            Some(n) => done.push(n),
            // The graph has no cycle through declarations (tested below).
            None => break,
        }
    }
    done
}

/// The shortest time after which every timer of the topology ticks again at once (the
/// least common multiple of the sensors' and the planner's periods, 600 ms upstream).
/// Starting a run on a multiple of it puts every process's timers in phase, as
/// upstream's, made together in one process, are.
pub fn common_period() -> Duration {
    fn gcd(a: u128, b: u128) -> u128 {
        if b == 0 { a } else { gcd(b, a % b) }
    }
    let lcm = NODES
        .iter()
        .filter_map(|n| match n.kind {
            Kind::Sensor { period } | Kind::Cyclic { period, .. } => Some(period.as_nanos()),
            _ => None,
        })
        .fold(1u128, |acc, p| acc / gcd(acc, p) * p);
    Duration::from_nanos(u64::try_from(lcm).unwrap_or(u64::MAX))
}

/// Every topic, each once.
pub fn topics() -> Vec<&'static str> {
    NODES.iter().flat_map(|n| n.outputs()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_graph_is_upstreams() {
        let count = |f: fn(&Kind) -> bool| NODES.iter().filter(|n| f(&n.kind)).count();
        assert_eq!(count(|k| matches!(k, Kind::Sensor { .. })), 6);
        assert_eq!(count(|k| matches!(k, Kind::Transform { .. })), 9);
        assert_eq!(count(|k| matches!(k, Kind::Fusion { .. })), 5);
        assert_eq!(count(|k| matches!(k, Kind::Cyclic { .. })), 1);
        assert_eq!(count(|k| matches!(k, Kind::Intersection { .. })), 1);
        assert_eq!(count(|k| matches!(k, Kind::Command { .. })), 2);
        assert_eq!(topics().len(), 23);
        let subscriptions: usize = NODES.iter().map(|n| n.inputs().len()).sum();
        assert_eq!(subscriptions, 29);
        // Every input is some node's output.
        let all = topics();
        for n in &NODES {
            for i in n.inputs() {
                assert!(all.contains(&i), "{} reads {i}, which nobody publishes", n.name);
            }
        }
        assert_eq!(build_order().len(), NODES.len(), "every node can be declared in turn");
        assert_eq!(common_period(), Duration::from_millis(600));
        for (a, b) in HOT_PATH.iter().zip(HOT_PATH.iter().skip(1)) {
            let reader = NODES.iter().find(|n| n.outputs().contains(b) || n.name == *b).unwrap();
            assert!(reader.inputs().contains(a), "{b} does not read {a}");
        }
    }
}
