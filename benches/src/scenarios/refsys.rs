//! `refsys-*`: the Autoware reference system (ros-realtime/reference-system, SPEC W1),
//! one scenario per system that runs it — esgm in one process (`refsys-esgm`), esgm
//! with a process per node (`refsys-esgm-procs`), and its peers, which add themselves
//! to [`systems`] — judged by its own KPIs, computed alike for each
//! ([`crate::refsys::kpi`]). `--only refsys` runs them all, `--only refsys-esgm` esgm's
//! two.
//!
//! Every system runs the topology twice, in upstream's two timings at its periods:
//! `Default`, where every processing node crunches numbers for what upstream's limit
//! costs on its reference machine (the limit calibrated here once per run, as upstream
//! says, and the same for every system: row `refsys-esgm-work`), and
//! `BenchmarkCPUUsage`, with no work, where what is left is the middleware (rows
//! `-nowork`).
//!
//! Each system's row is the hot path's latency (front lidar → object collision
//! estimator, from the per-hop trace of the estimator's input, on the host's system
//! clock); its notes hold every other KPI: what the transforms missed, front-lidar
//! samples that never reached the estimator, the behavior planner's jitter and drift,
//! and CPU and memory of all the system's processes. Beside it, per timing, are the
//! CPU row and the planner's jitter row. The topology runs 30 s per system and timing
//! (`--quick`: 3 s).

use std::time::Duration;

use anyhow::Context as _;

use crate::peer_role::PeerRole;
use crate::refsys::cruncher::{REFERENCE_WORK, calibrate, crunch_time};
use crate::refsys::esgm::{EsgmInProcess, EsgmProcesses};
use crate::refsys::kpi::Kpis;
use crate::refsys::system::{RunSettings, System, SystemRun};
use crate::refsys::topology::{HOT_PATH, Kind, PLANNER, node};
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

/// Whether `row` is a system's hot path row (`refsys-<system>` or
/// `refsys-<system>-nowork`, not its planner, CPU or work row).
pub fn is_hot_path_row(row: &str) -> bool {
    row.starts_with("refsys-")
        && !row.ends_with("-planner")
        && !row.ends_with("-cpu")
        && row != WORK_ROW
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

/// Upstream's two timings that run the topology at its periods.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Timing {
    /// `timing::Default`: every processing node crunches numbers to the limit that takes,
    /// here, what upstream's 4096 takes on its reference machine.
    Default,
    /// `timing::BenchmarkCPUUsage`: the same periods, no work: what is left is the
    /// middleware's own cost (rows `-nowork`).
    CpuUsage,
}

impl Timing {
    fn suffix(self) -> &'static str {
        match self {
            Timing::Default => "",
            Timing::CpuUsage => "-nowork",
        }
    }

    fn crunch(self, limit: u64) -> u64 {
        match self {
            Timing::Default => limit,
            Timing::CpuUsage => 0,
        }
    }
}

/// The row of one node's work on this machine, at the calibrated limit (a hop's work in
/// the processes' budget).
pub const WORK_ROW: &str = "refsys-esgm-work";

/// The number cruncher's limit for every system of this run: calibrated once, so every
/// system does the same work.
fn calibrated_limit() -> u64 {
    static LIMIT: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *LIMIT.get_or_init(|| calibrate(REFERENCE_WORK))
}

/// One node's work at `limit`, 101 times.
fn work_row(limit: u64) -> anyhow::Result<Measurement> {
    let mut work = crate::latency::Latency::new()?;
    for _ in 0..101 {
        work.record_ns(u64::try_from(crunch_time(limit, 1).as_nanos()).unwrap_or(u64::MAX));
    }
    Ok(work.measurement(WORK_ROW, Wait::Event).method(Method::Call).note(format!(
        "the number cruncher to {limit}: the limit that takes here what upstream's default \
         (4096) takes on its reference machine ({:.3} ms); every processing node's work per \
         message in every system of this run; 5 of them on the hot path",
        REFERENCE_WORK.as_secs_f64() * 1e3
    )))
}

/// A system's KPI rows for one timing (see the module docs).
fn kpi_rows(
    name: &str,
    timing: Timing,
    settings: &RunSettings,
    run: &SystemRun,
) -> anyhow::Result<Vec<Measurement>> {
    let period = match node(PLANNER).map(|n| n.kind) {
        Some(Kind::Cyclic { period, .. }) => period,
        _ => Duration::from_millis(100),
    };
    let k =
        Kpis::from_reports(&run.reports, period).with_context(|| format!("{name}: its reports"))?;
    let work = match timing {
        Timing::Default => format!(
            "every node's work: the number cruncher to {} ({} here)",
            settings.crunch,
            ms(u64::try_from(crunch_time(settings.crunch, 21).as_nanos()).unwrap_or(u64::MAX))
        ),
        Timing::CpuUsage => "no work (upstream's BenchmarkCPUUsage timing)".to_owned(),
    };
    let mut row = k
        .hot_path
        .measurement(name, Wait::Event)
        .payload_bytes(crate::refsys::message::MESSAGE_LEN as u64)
        .method(Method::SystemClock)
        .if_empty("no message reached the object collision estimator")
        .note(format!(
            "hot path FrontLidarDriver -> ObjectCollisionEstimator, {} samples over {:?}; {work}",
            k.hot_path.len(),
            settings.duration,
        ))
        .note(format!(
            "front lidar: {} published, {} reached the estimator, {} did not",
            k.front_published,
            k.front_reached_sink,
            k.front_not_reaching_sink()
        ))
        .note({
            let which: Vec<String> = k
                .transform_drops
                .iter()
                .filter(|d| d.3 > 0)
                .map(|(n, i, r, m)| format!("{n} <- {i}: {m} of {}", r + m))
                .collect();
            let which =
                if which.is_empty() { String::new() } else { format!(": {}", which.join(", ")) };
            format!(
                "transforms missed {} samples of their inputs (sequence gaps){which}",
                k.transforms_missed()
            )
        })
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
    let mut cpu = crate::latency::Latency::new()?;
    // CPU time per second of wall time: 10 ms is 1 % of a core.
    cpu.record_ns((run.usage.cpu_percent * 1e5).round() as u64);
    let cpu = cpu
        .measurement(&format!("{name}-cpu"), Wait::Event)
        .method(Method::CpuPerSecond)
        .note(format!("all {} processes of the system while the topology ran", run.processes));
    let planner = k
        .planner_jitter
        .measurement(&format!("{name}-planner"), Wait::Event)
        .method(Method::Lateness)
        .if_empty("the behavior planner did not tick twice")
        .note(format!(
            "|interval - {period:?}| between the behavior planner's ticks; drift {:+.2} ms",
            k.planner_drift_ns as f64 / 1e6
        ));
    Ok(vec![row, cpu, planner])
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
        let limit = calibrated_limit();
        let root = tempfile::tempdir().context("a directory for the nodes' reports")?;
        let mut rows = Vec::new();
        if self.system == "esgm" {
            rows.push(work_row(limit)?);
        }
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
            for timing in [Timing::Default, Timing::CpuUsage] {
                let name = format!("refsys-{}{}", system.name(), timing.suffix());
                if let Some(why) = system.unavailable() {
                    ctx.skip(&name, why);
                    continue;
                }
                let settings = RunSettings {
                    duration,
                    crunch: timing.crunch(limit),
                    dir: root.path().join(format!("{}{}", system.name(), timing.suffix())),
                    pin: ctx.pinning().is_some(),
                };
                let run = system.run(&settings).with_context(|| format!("{name}: the run"))?;
                rows.extend(kpi_rows(&name, timing, &settings, &run)?);
            }
        }
        Ok(rows)
    }

    /// The targets, as ratios in the same run, in both timings: esgm's hot path
    /// at most ⅓ of each peer's, its CPU and its planner's jitter at most each peer's;
    /// and the processes' hot path within the in-process one plus five paced wake-ups
    /// (`floor-futex-paced`, one per hop between processes) plus the hot path's work.
    fn targets(&self) -> Vec<Target> {
        let mut t = Vec::new();
        if !self.system.starts_with("esgm") {
            return t;
        }
        for timing in [Timing::Default, Timing::CpuUsage] {
            let esgm = format!("{}{}", self.name, timing.suffix());
            for peer in [Refsys::ROS1.name, Refsys::ROS2.name] {
                let peer = format!("{peer}{}", timing.suffix());
                t.push(Target::at_most(&esgm, &peer, Wait::Event, 1.0 / 3.0));
                for kpi in ["-cpu", "-planner"] {
                    t.push(Target::at_most(
                        &format!("{esgm}{kpi}"),
                        &format!("{peer}{kpi}"),
                        Wait::Event,
                        1.0,
                    ));
                }
            }
            if self.system == "esgm-procs" {
                let inproc = format!("{}{}", Refsys::ESGM.name, timing.suffix());
                let hops = (HOT_PATH.len() - 1) as f64;
                let mut budget = Target::at_most(&esgm, &inproc, Wait::Event, 1.0).plus(
                    crate::scenarios::ipc_floor_futex::PACED_NAME,
                    Wait::Event,
                    hops,
                );
                if timing == Timing::Default {
                    budget = budget.plus(WORK_ROW, Wait::Event, hops);
                }
                t.push(budget);
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
