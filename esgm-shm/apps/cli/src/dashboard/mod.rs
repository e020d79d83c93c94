//! `esgm top`'s data: what a running system looks like at one moment, per trajectory
//! and per process, and how it is sorted, filtered and shown.
//!
//! - this file: [`Sampler`], which reads a [`Snapshot`]: each trajectory's statistics
//!   from the process that writes it (E7 across the domain), the memory of every
//!   process, and the processes; it keeps a handle on every trajectory between
//!   refreshes for the size of its latest sample;
//! - [`procfs`]: CPU % and resident memory from `/proc`;
//! - [`table`]: sort keys, the filter, and the plain-text table (`--once`, or stdout not
//!   a terminal);
//! - [`tui`]: the ratatui dashboard.

pub mod procfs;
pub mod table;
pub mod tui;

use std::collections::{BTreeMap, HashSet};

use anyhow::bail;
use esgm_core::esgm::MemoryStats;
use esgm_core::{DropCause, EntityTrajectoryStructure, Esgm, InProcessTrajectory, Time};
use esgm_shm::ShmEsgm;
use esgm_shm::control::{Request, Response};

use self::procfs::CpuMeter;

/// One trajectory's line.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TrajectoryRow {
    /// Its name.
    pub name: String,
    /// Primitive, sampled, computed, …
    pub kind: String,
    /// Its type's name.
    pub type_name: String,
    /// Adds per second (over the last adds).
    pub rate_hz: f64,
    /// Structures that entered it.
    pub added: u64,
    /// Median add delay (valid → add), ns.
    pub add_delay_p50: Option<Time>,
    /// 99th percentile add delay, ns.
    pub add_delay_p99: Option<Time>,
    /// Structures lost, by cause (not policy violations), and samples discarded from
    /// slow subscribers' buffers (`subscriber_overflow`).
    pub losses: BTreeMap<String, u64>,
    /// Structures dropped for breaking a policy constraint, by constraint.
    pub violations: BTreeMap<String, u64>,
    /// Live subscribers.
    pub subscribers: usize,
    /// Samples stored in its cache.
    pub stored: usize,
    /// The bytes its cache holds, estimated as stored × the latest sample's size
    /// (images: their pixels, which stay in the writer's shared memory).
    pub bytes: Option<u64>,
}

impl TrajectoryRow {
    /// Every loss and violation.
    pub fn dropped(&self) -> u64 {
        self.losses.values().chain(self.violations.values()).sum()
    }
}

/// One process's line.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ProcessRow {
    /// Its name (`coordinator`, or the name it was declared under).
    pub name: String,
    /// Its pid, while it runs.
    pub pid: Option<u32>,
    /// CPU % since the last refresh (100 = one core busy).
    pub cpu_percent: Option<f64>,
    /// Resident memory, bytes.
    pub rss_bytes: Option<u64>,
    /// Restarts after unexpected exits.
    pub restarts: u32,
    /// How it last ended, if it did.
    pub last_exit: Option<String>,
}

/// The system at one refresh.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Snapshot {
    /// Every trajectory, by name.
    pub trajectories: Vec<TrajectoryRow>,
    /// The coordinator, then every declared process.
    pub processes: Vec<ProcessRow>,
    /// The memory of every connected process's trajectories, added up (`None` when the
    /// processes did not answer).
    pub memory: Option<MemoryStats>,
    /// Why the statistics are this process's replicas' rather than the writers', or
    /// the memory figures are missing (the domain's processes did not answer), if so.
    pub note: Option<String>,
}

/// Reads snapshots of one system, keeping a handle on each trajectory between reads.
pub struct Sampler {
    esgm: ShmEsgm,
    handles: BTreeMap<String, InProcessTrajectory>,
    cpu: CpuMeter,
}

impl std::fmt::Debug for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sampler").field("trajectories", &self.handles.len()).finish()
    }
}

impl Sampler {
    /// A sampler over the system `esgm` is connected to.
    pub fn new(esgm: ShmEsgm) -> Self {
        Self { esgm, handles: BTreeMap::new(), cpu: CpuMeter::default() }
    }

    /// Opens trajectories that appeared (waiting for their history, as every CLI
    /// reader does) and closes those that went.
    pub fn follow_trajectories(&mut self) -> anyhow::Result<()> {
        let listed: HashSet<String> =
            self.esgm.trajectories()?.into_iter().map(|info| info.name).collect();
        self.handles.retain(|name, _| listed.contains(name));
        for name in listed {
            if !self.handles.contains_key(&name) {
                match crate::session::trajectory(&self.esgm, &name) {
                    Ok(t) => {
                        self.handles.insert(name, t);
                    }
                    // Destroyed between the listing and the lookup: the next refresh
                    // will not list it.
                    Err(e) => tracing::debug!(trajectory = %name, "not opened: {e:#}"),
                }
            }
        }
        Ok(())
    }

    /// The system now.
    pub fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.follow_trajectories()?;
        let infos = self.esgm.trajectories()?;
        // Each trajectory's writer's statistics (what was offered, dropped and why, its
        // subscribers); this process's replicas' where the writers do not answer.
        let (writers, note) = match self.esgm.domain_stats() {
            Ok(s) => (Some(s), None),
            Err(e) => (
                None,
                Some(format!(
                    "the writers' statistics are unavailable ({e}); these are this process's replicas'"
                )),
            ),
        };
        // Unanswered, the memory line says why instead of vanishing.
        let (memory, note) = match self.esgm.domain_memory() {
            Ok(m) => (Some(m), note),
            Err(e) => {
                let why = format!("the memory figures are unavailable ({e})");
                (None, Some(note.map_or(why.clone(), |n| format!("{n}; {why}"))))
            }
        };
        let mut trajectories = Vec::with_capacity(infos.len());
        for info in infos {
            let Some(t) = self.handles.get(&info.name) else { continue };
            let from_writer =
                writers.as_ref().and_then(|w| w.get(&info.name)).map(|r| r.stats.clone());
            // Only a trajectory destroyed since the listing has no stats: it leaves the table.
            let Some(s) = from_writer.or_else(|| t.stats().ok()) else { continue };
            let mut losses = BTreeMap::new();
            let mut violations = BTreeMap::new();
            for (cause, n) in &s.dropped {
                let into = match cause {
                    DropCause::Violation(_) => &mut violations,
                    _ => &mut losses,
                };
                *into.entry(cause.to_string()).or_default() += n;
            }
            if s.subscriber_overflow > 0 {
                losses.insert("subscriber_overflow".into(), s.subscriber_overflow);
            }
            if s.missed_sample_points > 0 {
                losses.insert("missed_sample_points".into(), s.missed_sample_points);
            }
            // Empty (or destroyed since): no size to estimate.
            let bytes = t.get_latest().ok().map(|latest| {
                let one = latest.structure.approx_bytes(&mut HashSet::new()) as u64;
                one * s.stored as u64
            });
            trajectories.push(TrajectoryRow {
                name: info.name,
                kind: info.kind.name().to_owned(),
                type_name: info.type_name,
                rate_hz: s.rate_hz,
                added: s.added,
                add_delay_p50: s.add_delay_p50,
                add_delay_p99: s.add_delay_p99,
                losses,
                violations,
                subscribers: s.subscribers,
                stored: s.stored,
                bytes,
            });
        }
        let processes = self.processes()?;
        Ok(Snapshot { trajectories, processes, memory, note })
    }

    fn processes(&mut self) -> anyhow::Result<Vec<ProcessRow>> {
        let coordinator = match self.esgm.control(Request::Ping)? {
            Response::Pong { pid, .. } => (pid != 0).then_some(pid),
            other => bail!("unexpected answer from the coordinator: {other:?}"),
        };
        let declared = match self.esgm.control(Request::ListProcesses)? {
            Response::Processes(p) => p,
            other => bail!("unexpected answer from the coordinator: {other:?}"),
        };
        let mut rows = vec![ProcessRow {
            name: "coordinator".into(),
            pid: coordinator,
            cpu_percent: None,
            rss_bytes: None,
            restarts: 0,
            last_exit: None,
        }];
        rows.extend(declared.into_iter().map(|p| ProcessRow {
            name: p.spec.name,
            pid: p.status.pid,
            cpu_percent: None,
            rss_bytes: None,
            restarts: p.status.restarts,
            last_exit: p.status.last_exit,
        }));
        for row in &mut rows {
            if let Some(pid) = row.pid {
                row.cpu_percent = self.cpu.percent(pid);
                row.rss_bytes = procfs::rss_bytes(pid);
            }
        }
        let alive: Vec<u32> = rows.iter().filter_map(|r| r.pid).collect();
        self.cpu.retain(&alive);
        Ok(rows)
    }
}
