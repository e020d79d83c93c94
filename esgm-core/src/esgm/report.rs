//! What the ESGM reports about itself (E7): statistics, memory, log level.

use crate::esgm::spec::TrajectoryKind;
use crate::policy::FluentStreamPolicy;
use crate::store::TrajectoryStats;

/// One trajectory as listed: name, kind, type, where it reads from.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajectoryInfo {
    /// The name.
    pub name: String,
    /// Primitive, sampled, computed, …
    pub kind: TrajectoryKind,
    /// The registered type name of its structures.
    pub type_name: String,
    /// The sensor or unit feeding it, if any.
    pub source: Option<String>,
    /// The trajectories it reads, in order.
    pub inputs: Vec<String>,
    /// Its policy.
    pub policy: FluentStreamPolicy,
}

impl TrajectoryInfo {
    /// The listing of `name`, of `kind` and `type_name`, with no source, no inputs and
    /// the default policy: what a recording or a tool declares, before it sets the
    /// rest with [`Self::policy`] and [`Self::source`].
    pub fn new(
        name: impl Into<String>,
        kind: TrajectoryKind,
        type_name: impl Into<String>,
    ) -> Self {
        Self {
            name: name.into(),
            kind,
            type_name: type_name.into(),
            source: None,
            inputs: Vec::new(),
            policy: FluentStreamPolicy::default(),
        }
    }

    /// The same listing with `policy`.
    #[must_use]
    pub fn policy(mut self, policy: FluentStreamPolicy) -> Self {
        self.policy = policy;
        self
    }

    /// The same listing fed by the sensor or unit `source`.
    #[must_use]
    pub fn source(mut self, source: impl Into<String>) -> Self {
        self.source = Some(source.into());
        self
    }
}

/// Counters of the worker that feeds a sampled, computed or operator trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct WorkerStats {
    /// Sensor or unit calls made.
    pub calls: u64,
    /// Calls that produced a structure.
    pub outputs: u64,
    /// Calls that answered "no value" (not an error).
    pub no_value: u64,
    /// Calls that failed with an error.
    pub failures: u64,
    /// Calls that panicked (isolated; the worker carried on).
    pub panics: u64,
    /// Outputs refused by the trajectory's type check.
    pub invalid_outputs: u64,
    /// Sample times skipped because the worker was late by a period or more.
    pub missed_periods: u64,
    /// Times the worker was restarted (out-of-process runtimes).
    pub restarts: u64,
    /// Input samples an operator discarded without using them (e.g. a sync that found
    /// no partner for them).
    pub discarded: u64,
    /// Input samples discarded because the worker fell behind its inputs (its input
    /// buffer was full; the oldest went first).
    pub input_overflow: u64,
}

/// One trajectory in [`EsgmStats`]: its listing, its store's statistics and its
/// worker's counters.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajectoryReport {
    /// The trajectory as listed (kind, type, source, inputs, policy).
    pub info: TrajectoryInfo,
    /// Its store's statistics (added, dropped and why, stored, subscribers, delays).
    pub stats: TrajectoryStats,
    /// The counters of the worker feeding it (zero for a primitive trajectory or a
    /// replica, whose worker runs in the writing process).
    pub worker: WorkerStats,
}

/// Statistics of the whole ESGM: every trajectory by name (`stats.trajectories["r"]`,
/// or [`EsgmStats::get`] where the name may be missing).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EsgmStats {
    /// Per trajectory name: its listing, its store's stats, its worker's.
    pub trajectories: std::collections::BTreeMap<String, TrajectoryReport>,
}

impl EsgmStats {
    /// The report of the trajectory called `name`, if there is one.
    pub fn get(&self, name: &str) -> Option<&TrajectoryReport> {
        self.trajectories.get(name)
    }
}

/// Memory held by the ESGM's trajectories.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct MemoryStats {
    /// Trajectories.
    pub trajectories: usize,
    /// Samples stored in all caches.
    pub stored_samples: usize,
    /// Samples held for reordering.
    pub held_samples: usize,
    /// Approximate bytes of stored structures (images counted once per buffer).
    pub approx_bytes: usize,
}

/// Log verbosity (E7's `Logable`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Default,
    serde::Serialize,
    serde::Deserialize,
)]
pub enum LogLevel {
    /// Errors only.
    Error,
    /// Warnings and errors.
    Warn,
    /// Informational messages (the default).
    #[default]
    Info,
    /// Debugging detail (every drop).
    Debug,
    /// Everything.
    Trace,
}

impl LogLevel {
    /// Parses `error|warn|info|debug|trace`.
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "error" => Some(LogLevel::Error),
            "warn" | "warning" => Some(LogLevel::Warn),
            "info" => Some(LogLevel::Info),
            "debug" => Some(LogLevel::Debug),
            "trace" => Some(LogLevel::Trace),
            _ => None,
        }
    }
}
