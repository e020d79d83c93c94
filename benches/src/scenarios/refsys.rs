//! `refsys-*`: the Autoware reference system (ros-realtime/reference-system, SPEC W1),
//! one scenario per system that runs it — esgm in one process (`refsys-esgm`), esgm
//! with a process per node (`refsys-esgm-procs`), and its peers, which add themselves
//! to [`systems`] — judged by its own KPIs, computed alike for each
//! ([`crate::refsys::kpi`]). `--only refsys` runs them all, `--only refsys-esgm` esgm's
//! two.
//!
//! Each system's row is the hot path's latency (front lidar → object collision
//! estimator, from the per-hop trace of the estimator's input, on the host's system
//! clock); its notes hold every other KPI: what the transforms missed, front-lidar
//! samples that never reached the estimator, the behavior planner's jitter and drift,
//! and CPU and memory of all the system's processes. A second row per system is the
//! planner's jitter. The topology runs 30 s per system (`--quick`: 3 s).

use std::time::Duration;

use anyhow::Context as _;

use crate::peer_role::PeerRole;
use crate::refsys::cruncher::crunch_time;
use crate::refsys::esgm::{EsgmInProcess, EsgmProcesses};
use crate::refsys::kpi::Kpis;
use crate::refsys::system::{RunSettings, System};
use crate::refsys::topology::{DEFAULT_CRUNCH, Kind, PLANNER, node};
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// The scenario the systems' processes are started as peers of (every `refsys-*`
/// scenario's peer side runs any of them).
pub const NAME: &str = "refsys-esgm";

/// Every system that runs the topology, esgm's first.
pub fn systems() -> Vec<Box<dyn System>> {
    vec![
        Box::new(EsgmInProcess),
        Box::new(EsgmProcesses),
        Box::new(crate::refsys::ros1::Ros1),
        #[cfg(feature = "ros2")]
        Box::new(crate::refsys::ros2::Ros2),
    ]
}

/// Whether `row` is a system's hot path row (`refsys-<system>`, not its planner or CPU
/// row).
pub fn is_hot_path_row(row: &str) -> bool {
    row.starts_with("refsys-") && !row.ends_with("-planner") && !row.ends_with("-cpu")
}

/// The reference system on one system (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Refsys {
    /// The scenario's and its rows' name.
    name: &'static str,
    /// The system's name in [`systems`].
    system: &'static str,
    summary: &'static str,
}

impl Refsys {
    /// esgm in one process.
    pub const ESGM: Refsys = Refsys {
        name: "refsys-esgm",
        system: "esgm",
        summary: "the Autoware reference system (24 nodes, 4 KiB messages, upstream's periods \
                  and work) on esgm's in-process runtime, every node in one process; its KPIs",
    };
    /// esgm, one process per node.
    pub const ESGM_PROCS: Refsys = Refsys {
        name: "refsys-esgm-procs",
        system: "esgm-procs",
        summary: "the Autoware reference system on esgm through connect, one process per node \
                  and a coordinator; its KPIs",
    };
    /// ROS 1.
    pub const ROS1: Refsys = Refsys {
        name: "refsys-ros1",
        system: "ros1",
        summary: "the Autoware reference system on ROS 1 (roscpp), one process per node; its KPIs",
    };
    /// ROS 2's wire.
    pub const ROS2: Refsys = Refsys {
        name: "refsys-ros2",
        system: "ros2",
        summary: "the Autoware reference system over DDS (ros2-client), one process per node, \
                  in a network namespace; its KPIs",
    };
}

fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1024.0 * 1024.0))
}

fn ms(ns: u64) -> String {
    format!("{:.2} ms", ns as f64 / 1e6)
}

impl Scenario for Refsys {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        self.summary
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let duration =
            if ctx.is_quick() { Duration::from_secs(3) } else { Duration::from_secs(30) };
        let crunch = DEFAULT_CRUNCH;
        let crunched = crunch_time(crunch, 21);
        let root = tempfile::tempdir().context("a directory for the nodes' reports")?;
        let period = match node(PLANNER).map(|n| n.kind) {
            Some(Kind::Cyclic { period, .. }) => period,
            _ => Duration::from_millis(100),
        };
        let mut rows = Vec::new();
        let mine = systems().into_iter().filter(|s| s.name() == self.system).collect::<Vec<_>>();
        if mine.is_empty() {
            ctx.skip(
                self.name,
                match self.system {
                    "ros2" => "built without the `ros2` feature (--features ros2)",
                    _ => "this system is not built into esgm-bench",
                },
            );
        }
        for system in mine {
            let name = format!("refsys-{}", system.name());
            if let Some(why) = system.unavailable() {
                ctx.skip(&name, why);
                continue;
            }
            let settings = RunSettings {
                duration,
                crunch,
                dir: root.path().join(system.name()),
                pin: ctx.pinning().is_some(),
            };
            let run = system.run(&settings).with_context(|| format!("{name}: the run"))?;
            let k = Kpis::from_reports(&run.reports, period)
                .with_context(|| format!("{name}: its reports"))?;
            let mut row = k
                .hot_path
                .measurement(&name, Wait::Event)
                .payload_bytes(crate::refsys::message::MESSAGE_LEN as u64)
                .method(Method::SystemClock)
                .if_empty("no message reached the object collision estimator")
                .note(format!(
                    "hot path FrontLidarDriver -> ObjectCollisionEstimator, {} samples over {:?}; \
                     every node's work: the number cruncher to {crunch} ({} here)",
                    k.hot_path.len(),
                    duration,
                    ms(u64::try_from(crunched.as_nanos()).unwrap_or(u64::MAX))
                ))
                .note(format!(
                    "front lidar: {} published, {} reached the estimator, {} did not",
                    k.front_published,
                    k.front_reached_sink,
                    k.front_not_reaching_sink()
                ))
                .note(format!(
                    "transforms missed {} samples of their inputs (sequence gaps): {}",
                    k.transforms_missed(),
                    k.transform_drops
                        .iter()
                        .filter(|d| d.3 > 0)
                        .map(|(n, i, r, m)| format!("{n} <- {i}: {m} of {}", r + m))
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
                .note(format!(
                    "behavior planner: {} ticks, jitter p50 {} p99 {} max {}, drift {:+.2} ms",
                    k.planner_ticks,
                    ms(k.planner_jitter.quantile(0.5)),
                    ms(k.planner_jitter.quantile(0.99)),
                    ms(k.planner_jitter.quantile(1.0)),
                    k.planner_drift_ns as f64 / 1e6
                ))
                .note(format!(
                    "{} processes: CPU {:.1} % of a core, private memory {}, shared {}",
                    run.processes,
                    run.usage.cpu_percent,
                    mib(run.usage.private_bytes),
                    mib(run.usage.shared_bytes)
                ));
            for n in &run.notes {
                row = row.note(n.clone());
            }
            rows.push(row);
            let mut cpu = crate::latency::Latency::new()?;
            // CPU time per second of wall time: 10 ms is 1 % of a core.
            cpu.record_ns((run.usage.cpu_percent * 1e5).round() as u64);
            rows.push(
                cpu.measurement(&format!("{name}-cpu"), Wait::Event)
                    .method(Method::CpuPerSecond)
                    .note(format!(
                        "all {} processes of the system while the topology ran",
                        run.processes
                    )),
            );
            rows.push(
                k.planner_jitter
                    .measurement(&format!("{name}-planner"), Wait::Event)
                    .method(Method::Lateness)
                    .if_empty("the behavior planner did not tick twice")
                    .note(format!(
                        "|interval - {period:?}| between the behavior planner's ticks; drift {:+.2} ms",
                        k.planner_drift_ns as f64 / 1e6
                    )),
            );
        }
        Ok(rows)
    }

    /// The targets, as ratios in the same run: esgm's hot path at most ⅓ of the
    /// better peer's (so of each peer's), its CPU at most the better peer's, its
    /// planner's jitter at most the better peer's (its p99 ratio is printed beside).
    fn targets(&self) -> Vec<Target> {
        let mut t = Vec::new();
        if !self.system.starts_with("esgm") {
            return t;
        }
        for esgm in [self.name] {
            for peer in ["refsys-ros1", "refsys-ros2"] {
                t.push(Target::at_most(esgm, peer, Wait::Event, 1.0 / 3.0));
                t.push(Target::at_most(
                    &format!("{esgm}-cpu"),
                    &format!("{peer}-cpu"),
                    Wait::Event,
                    1.0,
                ));
                t.push(Target::at_most(
                    &format!("{esgm}-planner"),
                    &format!("{peer}-planner"),
                    Wait::Event,
                    1.0,
                ));
            }
        }
        t
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        let arg = role.arg.as_deref().unwrap_or_default();
        if let Some(done) = crate::refsys::esgm::peer_main(&role.domain, arg) {
            done?;
            return Ok(Vec::new());
        }
        #[cfg(feature = "ros2")]
        if let Some(done) = crate::refsys::ros2::peer_main(arg) {
            done?;
            return Ok(Vec::new());
        }
        anyhow::bail!("refsys: no process `{arg}`")
    }
}
