//! The reference system as an esgm system file, `benches/refsys/refsys.toml`: what
//! both esgm systems run, read with esgm's own loader (`esgm_cli::config`) — applied by
//! a coordinator that starts a node program per sensor and unit (`refsys-esgm-procs`,
//! as `esgm up --config` does), or applied to one in-process runtime with the same
//! sensors and units registered in it (`refsys-esgm`).
//!
//! The file is generated from [`super::topology`], the topology's one definition (the
//! ROS 1 and ROS 2 peers run it too), by [`render`]; a test fails when the committed
//! file differs, and `ESGM_BLESS=1 cargo test -p esgm-benches system_file` writes it.
//! Generated rather than read back and checked against the topology: a second
//! hand-written declaration of 24 nodes would be a second definition to keep in step,
//! while a generated one is the first seen through esgm's format, and the bench runs
//! the committed bytes (compiled in, [`TEXT`]).

use std::fmt::Write as _;
use std::time::Duration;

use super::served::{ATTRIBUTE, MESSAGE_TYPE};
use super::topology::{Kind, Node, build_order};

/// The committed file, as this build runs it.
pub const TEXT: &str = include_str!("../../refsys/refsys.toml");

/// The file's path in the source tree, from the workspace's root.
pub const PATH: &str = "benches/refsys/refsys.toml";

/// The program that serves every sensor and unit of the file (`src/bin/`).
pub const PROGRAM: &str = "esgm-refsys-node";

/// The approximation of the planner's generators: see the file's header.
const PLANNER_APPROXIMATION: &str = "closest";

const HEADER: &str = r#"# The Autoware reference system (ros-realtime/reference-system, package
# autoware_reference_system; esgm issue 38) as an esgm system file: 24 nodes modelled on
# Autoware's lidar pipeline, 23 topics of one 4 KiB message (Message4kb), upstream's
# periods.
#
# Generated from benches/src/refsys/topology.rs, the topology's one definition, which
# esgm-bench's ROS 1 and ROS 2 peers run too; a test fails when this file differs from
# it (ESGM_BLESS=1 cargo test -p esgm-benches system_file writes it anew).
#
# Every sensor and unit is served by esgm-refsys-node (benches/src/bin), one process
# each, which the coordinator starts and supervises. Run it by hand:
#   cargo build --release -p esgm-cli -p esgm-benches
#   PATH=$PWD/target/release:$PATH esgm up --config benches/refsys/refsys.toml
#   esgm hz ObjectCollisionEstimator          # in another shell; `esgm down` stops it
# (ESGM_REFSYS_CRUNCH=N in esgm up's environment gives every processing node upstream's
# work, the number cruncher to N; by default there is none.) Measured, in one process
# and in one process per node, with the reference system's KPIs:
#   cargo run --release -p esgm-benches --bin esgm-bench -- --quick --only refsys-esgm
#
# The node kinds in esgm's terms:
# - a sensor is a [[sensor]] and a trajectory sampled every period with align = true:
#   its sample times are multiples of its period, so all sensors tick in phase, as
#   upstream's timers made in one process do, whichever process samples them;
# - a transform is a [[unit]] with one input and a computed trajectory, which calls it
#   on every input;
# - the intersection node (EuclideanClusterDetector) is two such transforms, one
#   [[unit]] per connection (so two processes: each [[unit]] is a worker of its own);
# - a fusion is a [[unit]] with two inputs and a computed trajectory: esgm calls it with
#   the latest of both on every update, and it makes an output once both brought a
#   message it has not used (it tells new ones by their sequence numbers);
# - the behavior planner is a generate trajectory with a function: every 100 ms
#   (aligned), the fluent generators of its six inputs give the latest message of each,
#   and the unit's temporal function (compute_at) makes the planner's output of them,
#   with what is new since its last tick. The generators are "closest": among a cache
#   of one that is the latest message, even one that arrived a few microseconds after
#   the tick's time, as a timer's callback reads its subscriptions' latest
#   ("most-recent" would find nothing then). Chosen over a sampled trajectory whose
#   sensor queries the six inputs because it is esgm's own operator for a stream
#   sampled from the latest of others. One difference with upstream: a generator has
#   no value before its input's first message, so the planner's first tick comes once
#   all six inputs have one (a few hundred ms into a run), where upstream's timer
#   fires from the start with whatever it has.
# - a command sink is a [[unit]] with one input and a computed trajectory that stays
#   empty: esgm calls it on every input, as a subscriber's callback, and it makes
#   nothing. The format declares a process by what it serves (a sensor, a unit, a
#   robot, a bridge), so a sink serves a unit that outputs nothing;
# - history depth 1 is policy = { cache = 1 } on every trajectory.
# A coordinator and 25 workers, where upstream's graph has 24 nodes (the intersection
# is two units).
"#;

fn duration(d: Duration) -> String {
    if d.subsec_nanos() == 0 {
        format!("{}s", d.as_secs())
    } else if d.as_nanos() % 1_000_000 == 0 {
        format!("{}ms", d.as_millis())
    } else {
        format!("{}", d.as_nanos())
    }
}

fn list(items: &[&str]) -> String {
    let quoted: Vec<String> = items.iter().map(|i| format!("\"{i}\"")).collect();
    format!("[{}]", quoted.join(", "))
}

/// The sensors and units a node's program serves, by the name they are declared
/// under: `("sensor" | "unit", name)`.
pub fn declared(node: &Node) -> Vec<(&'static str, &'static str)> {
    match node.kind {
        Kind::Sensor { .. } => vec![("sensor", node.name)],
        Kind::Intersection { connections } => {
            connections.iter().map(|(_, o)| ("unit", *o)).collect()
        }
        _ => vec![("unit", node.name)],
    }
}

/// The system file of the topology (the committed one is this, see the module docs).
pub fn render() -> String {
    let nodes = build_order();
    let mut s = String::from(HEADER);
    let mut w = |text: String| s.push_str(&text);
    w(format!(
        "\n[[type]]\nname = \"{MESSAGE_TYPE}\"\n# upstream's 4,096 bytes: a count, 63 per-hop stats, data\nattributes = [\"{ATTRIBUTE}: OctetSeq\"]\n"
    ));
    w("\n# --- Sensors and units: each served by its own esgm-refsys-node process -----------\n"
        .into());
    for node in &nodes {
        for (section, name) in declared(node) {
            w(format!("\n[[{section}]]\nname = \"{name}\"\nprogram = \"{PROGRAM}\"\n"));
        }
    }
    w("\n# --- Trajectories, each after its inputs ----------------------------------------\n"
        .into());
    let depth_one = "policy = { cache = 1 }\n";
    for node in &nodes {
        let mut t = String::new();
        match node.kind {
            Kind::Sensor { period } => {
                let _ = writeln!(t, "\n# {}: a sensor", node.name);
                let _ = write!(
                    t,
                    "[[trajectory]]\nname = \"{0}\"\nsampled = \"{0}\"\nperiod = \"{1}\"\nalign = true\n{depth_one}",
                    node.name,
                    duration(period)
                );
            }
            Kind::Transform { input } | Kind::Command { input } => {
                let what = if matches!(node.kind, Kind::Command { .. }) {
                    "a command sink (its trajectory stays empty)"
                } else {
                    "a transform"
                };
                let _ = writeln!(t, "\n# {}: {what}", node.name);
                let _ = write!(
                    t,
                    "[[trajectory]]\nname = \"{0}\"\ncomputed = \"{0}\"\ninputs = {1}\n{depth_one}",
                    node.name,
                    list(&[input])
                );
            }
            Kind::Intersection { connections } => {
                for (i, (input, output)) in connections.iter().enumerate() {
                    let _ =
                        writeln!(t, "\n# {}: the intersection's connection {}", node.name, i + 1);
                    let _ = write!(
                        t,
                        "[[trajectory]]\nname = \"{output}\"\ncomputed = \"{output}\"\ninputs = {}\n{depth_one}",
                        list(&[input])
                    );
                }
            }
            Kind::Fusion { inputs } => {
                let _ = writeln!(t, "\n# {}: a fusion", node.name);
                let _ = write!(
                    t,
                    "[[trajectory]]\nname = \"{0}\"\ncomputed = \"{0}\"\ninputs = {1}\n{depth_one}",
                    node.name,
                    list(&inputs)
                );
            }
            Kind::Cyclic { inputs, period } => {
                let generators: Vec<String> =
                    inputs.iter().map(|i| format!("{i}:{PLANNER_APPROXIMATION}")).collect();
                let generators: Vec<&str> = generators.iter().map(String::as_str).collect();
                let _ = writeln!(t, "\n# {}: the cyclic node, on its timer", node.name);
                let _ = write!(
                    t,
                    "[[trajectory]]\nname = \"{0}\"\ngenerate = {1}\nfunction = \"{0}\"\nperiod = \"{2}\"\nalign = true\n{depth_one}",
                    node.name,
                    list(&generators),
                    duration(period)
                );
            }
        }
        w(t);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed file is the topology's (see the module docs).
    #[test]
    fn the_committed_system_file_is_the_topologys() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("refsys/refsys.toml");
        let generated = render();
        if std::env::var_os("ESGM_BLESS").is_some() {
            std::fs::write(&path, &generated).expect("write refsys/refsys.toml");
            return;
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        if committed != generated {
            let first = committed
                .lines()
                .zip(generated.lines())
                .position(|(a, b)| a != b)
                .unwrap_or_else(|| committed.lines().count().min(generated.lines().count()));
            panic!(
                "{PATH} differs from the one generated from topology.rs (from line {}): run \
                 `ESGM_BLESS=1 cargo test -p esgm-benches system_file` and commit it",
                first + 1
            );
        }
    }

    /// esgm's own loader reads it: a worker per sensor and unit, a trajectory per
    /// topic (the sinks' stay empty), each after its inputs, every one of depth 1.
    #[test]
    fn esgms_loader_reads_the_file_as_the_topology() {
        use esgm_cli::config::Serves;
        use esgm_core::esgm::TrajectorySource;
        let plan = esgm_cli::config::parse(PATH, TEXT, std::path::Path::new("."))
            .unwrap_or_else(|e| panic!("{PATH}: {e}"));
        let declared: Vec<(&str, &str)> = build_order().iter().flat_map(|n| declared(n)).collect();
        let workers: Vec<(&str, &str)> = plan
            .workers
            .iter()
            .map(|w| match &w.what.serves {
                Serves::Sensor(n) => ("sensor", n.as_str()),
                Serves::Unit(n) => ("unit", n.as_str()),
                other => panic!("not a sensor or unit: {other:?}"),
            })
            .collect();
        assert_eq!(workers, declared);
        assert_eq!(workers.len(), 25, "24 nodes, the intersection as two units");
        assert_eq!(plan.trajectories.len(), 25);
        let order = plan.creation_order().expect("no cycle");
        let position = |name: &str| {
            order.iter().position(|&i| plan.trajectories[i].what.spec.name == name).unwrap()
        };
        for t in &plan.trajectories {
            let what = &t.what;
            assert_eq!(
                what.spec.policy.cache,
                esgm_core::policy::CacheConstraint::Elements(1),
                "{}: depth 1",
                what.spec.name
            );
            for input in &what.inputs {
                assert!(
                    position(input) < position(&what.spec.name),
                    "{input} before {}",
                    what.spec.name
                );
            }
        }
        let planner = plan
            .trajectories
            .iter()
            .find(|t| t.what.spec.name == "BehaviorPlanner")
            .expect("the planner");
        assert!(planner.what.align);
        assert!(matches!(
            planner.what.spec.source,
            TrajectorySource::SampledGenerators { sample_period: 100_000_000, .. }
        ));
        assert_eq!(planner.what.inputs.len(), 6);
    }

    #[test]
    fn durations_are_written_as_the_format_reads_them() {
        assert_eq!(duration(Duration::from_millis(25)), "25ms");
        assert_eq!(duration(Duration::from_secs(2)), "2s");
        assert_eq!(duration(Duration::from_nanos(1_500)), "1500");
    }
}
