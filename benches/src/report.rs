//! The result of a run: what `--json` writes and what the table prints.
//!
//! The JSON form is a contract with the issue that defines it and with whoever
//! compares runs: `{"scenarios":[{"name","payload_bytes","wait":"spin"|"event","n",
//! "p50_ns","p99_ns","p999_ns","max_ns"}]}`. Fields may be added (the optional ones
//! below are left out when empty); none may be renamed or removed.
//!
//! `(name, wait)` identifies a row. Where a scenario measures more than the two waits
//! (esgm's default spin-then-block strategy beside pure blocking), the extra row gets
//! its own name and says its strategy in `wait_strategy` (see [`crate::wait_mode`]).

use serde::{Deserialize, Serialize};

use crate::target::Target;

/// How the receiving side waits for the next message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Wait {
    /// Busy-polling (`try_recv` in a loop): the lowest latency, at the cost of a core.
    Spin,
    /// Blocking until woken (a blocking `recv`, a sleeping sampler): what a robot
    /// program does when it must not burn a core.
    Event,
}

impl Wait {
    /// Both strategies, spin first.
    pub const BOTH: [Wait; 2] = [Wait::Spin, Wait::Event];

    /// The name used in the JSON and the table.
    pub fn as_str(self) -> &'static str {
        match self {
            Wait::Spin => "spin",
            Wait::Event => "event",
        }
    }
}

/// What a row's figures are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// One-way latency estimated as half a round trip (A → peer → back to A), timed on
    /// the sending thread's monotonic clock: no two clocks are compared.
    HalfRoundTrip,
    /// One-way latency timed directly: the same thread sends and receives.
    OneWay,
    /// Lateness of a periodic action: when it happened minus when it was scheduled.
    Lateness,
    /// Stamped in one process, read in another, both on the host's system clock (one
    /// kernel clock for every process): an add time in a sample's header against the
    /// reader's clock, or the add times of two stages of a pipeline.
    SystemClock,
    /// The duration of one call in one thread (a query, a unit's computation).
    Call,
    /// Time per item of a batch handled back to back: the batch's time (from the first
    /// item handed over to the last one done) over its items. A throughput, as
    /// nanoseconds per structure or frame.
    PerItem,
    /// CPU time a process used per second of wall time, over one-second windows: 10 ms
    /// is 1 % of a core.
    CpuPerSecond,
}

impl Method {
    /// A short label for the table.
    pub fn label(self) -> &'static str {
        match self {
            Method::HalfRoundTrip => "rtt/2",
            Method::OneWay => "one-way",
            Method::Lateness => "late",
            Method::SystemClock => "clock",
            Method::Call => "call",
            Method::PerItem => "per-item",
            Method::CpuPerSecond => "cpu/s",
        }
    }

    /// What the label means, for the table's legend.
    pub fn legend(self) -> &'static str {
        match self {
            Method::HalfRoundTrip => {
                "one-way latency = round trip / 2, timed on the sending thread (one clock)"
            }
            Method::OneWay => "one-way latency timed directly (one thread sends and receives)",
            Method::Lateness => "actual add time - scheduled sample time",
            Method::SystemClock => {
                "stamped in one process, read in another, on the host's system clock"
            }
            Method::Call => "duration of one call, timed in the calling thread",
            Method::PerItem => {
                "a batch's time (first item handed over -> last one done) / its items: a throughput"
            }
            Method::CpuPerSecond => {
                "CPU time the process used per second of wall time (10 ms = 1 % of a core)"
            }
        }
    }
}

/// One row: one scenario measured with one wait strategy. Times in nanoseconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// The scenario's name (`inproc-hop-small`, `esgm-image`, …).
    pub name: String,
    /// Size of what travels: the archived (shared-memory) form of an esgm structure,
    /// the struct itself for a raw channel.
    pub payload_bytes: u64,
    /// How the receiver waits.
    pub wait: Wait,
    /// The exact wait strategy where `wait` does not say it all (cross-process rows:
    /// `busy-spin`, `block`, `spin-then-block`; see [`crate::wait_mode::WaitMode::label`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wait_strategy: Option<String>,
    /// Samples recorded (warm-up excluded).
    pub n: u64,
    /// Median.
    pub p50_ns: u64,
    /// 99th percentile.
    pub p99_ns: u64,
    /// 99.9th percentile.
    pub p999_ns: u64,
    /// Largest sample.
    pub max_ns: u64,
    /// What the figures are.
    pub method: Method,
    /// The scenario this row is compared with; the reference is that scenario's row
    /// with the same wait, measured in the same run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline: Option<String>,
    /// Median time the producer spent completing each structure before its timed hop
    /// (e.g. writing a frame's pixels): reported beside the hop, never inside it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub producer_write_p50_ns: Option<u64>,
    /// Messages per second, for throughput rows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub msgs_per_s: Option<f64>,
    /// Samples that never arrived (throughput rows: gaps in the sequence numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lost: Option<u64>,
    /// Facts worth printing under the table (missed periods, whether data was shared).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// (quantile, ns) points of the distribution, for `--plots` (not in the JSON).
    #[serde(skip)]
    pub cdf: Vec<(f64, u64)>,
    /// What it means if this row has no samples, said when it is reported as failed
    /// ([`Report::add_rows`]); not in the JSON.
    #[serde(skip)]
    pub if_empty: Option<String>,
}

impl Measurement {
    /// Sets the payload size.
    #[must_use]
    pub fn payload_bytes(mut self, bytes: u64) -> Self {
        self.payload_bytes = bytes;
        self
    }

    /// Sets the exact wait strategy.
    #[must_use]
    pub fn wait_strategy(mut self, strategy: &str) -> Self {
        self.wait_strategy = Some(strategy.to_owned());
        self
    }

    /// Sets what the figures are.
    #[must_use]
    pub fn method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// Names the baseline scenario (its row with the same wait is the reference).
    #[must_use]
    pub fn baseline(mut self, scenario: &str) -> Self {
        self.baseline = Some(scenario.to_owned());
        self
    }

    /// Sets the producer's per-structure write time (median).
    #[must_use]
    pub fn producer_write_p50_ns(mut self, ns: u64) -> Self {
        self.producer_write_p50_ns = Some(ns);
        self
    }

    /// Sets the throughput and the losses (throughput rows).
    #[must_use]
    pub fn throughput(mut self, msgs_per_s: f64, lost: u64) -> Self {
        self.msgs_per_s = Some(msgs_per_s);
        self.lost = Some(lost);
        self
    }

    /// Adds a note printed under the table.
    #[must_use]
    pub fn note(mut self, note: impl Into<String>) -> Self {
        self.notes.push(note.into());
        self
    }

    /// Says why this row would have no samples (what was not seen), for the failure
    /// it is then reported as instead of a row of zeros.
    #[must_use]
    pub fn if_empty(mut self, reason: impl Into<String>) -> Self {
        self.if_empty = Some(reason.into());
        self
    }
}

/// A row that ran but recorded no samples: a failed measurement, never a row of "0 ns".
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Failed {
    /// The row's name.
    pub name: String,
    /// The row's wait.
    pub wait: Wait,
    /// Why it has no samples.
    pub reason: String,
}

/// One memory figure: how much of something a process or a trajectory uses, after
/// how many structures.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MemoryRow {
    /// What is measured (`coordinator-rss`, `writer-rss`, `shm-small-cache1000`, …).
    pub name: String,
    /// Structures added to the trajectory when it was measured.
    pub after_structures: u64,
    /// Resident bytes (VmRSS), or shared-memory bytes committed (tmpfs blocks in use).
    pub bytes: u64,
    /// For shared memory: the bytes mapped (file sizes), of which `bytes` are committed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mapped_bytes: Option<u64>,
    /// What the figure covers.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
}

/// A scenario that could not run here, and what to do about it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Skipped {
    /// The row it would have written (`zenoh-small`, `ros1-image`, …).
    pub name: String,
    /// Why, and how to run it.
    pub reason: String,
}

/// How the machine's idle cores were set during a run. A blocking row's wake-up is
/// mostly the woken core leaving its idle state, so two runs' blocking rows compare
/// only if these match (see `esgm_shm::process::cpu_latency`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Machine {
    /// The kernel's cpuidle driver (`haltpoll` on a KVM guest, `intel_idle`,
    /// `acpi_idle`…), if it says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpuidle_driver: Option<String>,
    /// A KVM guest's halt polling, in ns (`haltpoll`'s `guest_halt_poll_ns`; 0: an
    /// idle vCPU halts at once), if the machine has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guest_halt_poll_ns: Option<u64>,
    /// The CPU latency the kernel kept idle cores to when the run started (the
    /// smallest request held, `--cpu-latency` included), in µs; `None` if unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_latency_us: Option<u64>,
}

impl Machine {
    /// What the machine says now.
    pub fn now() -> Self {
        let read = |path: &str| std::fs::read_to_string(path).ok().map(|s| s.trim().to_owned());
        Self {
            cpuidle_driver: read("/sys/devices/system/cpu/cpuidle/current_driver"),
            guest_halt_poll_ns: read("/sys/module/haltpoll/parameters/guest_halt_poll_ns")
                .and_then(|s| s.parse().ok()),
            cpu_latency_us: esgm_shm::process::cpu_latency::current()
                .and_then(|d| u64::try_from(d.as_micros()).ok()),
        }
    }

    /// One line for the table's header.
    pub fn describe(&self) -> String {
        let driver = self.cpuidle_driver.as_deref().unwrap_or("unknown");
        let mut line = format!("idle cores: cpuidle {driver}");
        if let Some(ns) = self.guest_halt_poll_ns {
            line.push_str(&format!(", guest halt polling {ns} ns"));
        }
        match self.cpu_latency_us {
            // The kernel's default is about 2,000 s: no request held.
            Some(us) if us < 1_000_000 => line.push_str(&format!(", wake-up held within {us} µs")),
            Some(_) => line.push_str(", no CPU latency request held"),
            None => {}
        }
        line
    }
}

/// Everything a run measured, in run order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// One row per scenario and wait strategy.
    pub scenarios: Vec<Measurement>,
    /// How the machine's idle cores were set while the rows ran: what every blocking
    /// row's wake-up stands on.
    #[serde(default)]
    pub machine: Machine,
    /// Memory figures (the `memory` scenario), beside the latency rows.
    #[serde(default)]
    pub memory: Vec<MemoryRow>,
    /// Scenarios that could not run on this build or machine (peers not built or not
    /// installed), each with the way to run it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub skipped: Vec<Skipped>,
    /// Rows that ran but recorded no samples, each with the reason: failures, kept out
    /// of `scenarios` so that no reader takes their zeros for figures.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failed: Vec<Failed>,
    /// The goals the run's scenarios set, for the table; not part of the JSON.
    #[serde(skip)]
    pub targets: Vec<Target>,
}

impl Report {
    /// Adds a scenario's rows: rows with samples to `scenarios`, rows without to
    /// `failed`, with the reason the row gave ([`Measurement::if_empty`]) and its notes.
    pub fn add_rows(&mut self, rows: Vec<Measurement>) {
        for row in rows {
            if row.n > 0 {
                self.scenarios.push(row);
                continue;
            }
            let mut reason = format!(
                "no samples: {}",
                row.if_empty.as_deref().unwrap_or("the scenario recorded nothing")
            );
            for note in &row.notes {
                reason.push_str("; ");
                reason.push_str(note);
            }
            self.failed.push(Failed { name: row.name, wait: row.wait, reason });
        }
    }

    /// True if row `name` with `wait` ran but failed.
    pub fn has_failed(&self, name: &str, wait: Wait) -> bool {
        self.failed.iter().any(|f| f.name == name && f.wait == wait)
    }

    /// The reference row of `m`: its baseline scenario with the same wait, if that
    /// scenario ran.
    pub fn baseline_of(&self, m: &Measurement) -> Option<&Measurement> {
        let name = m.baseline.as_deref()?;
        self.scenarios.iter().find(|b| b.name == name && b.wait == m.wait)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, wait: Wait) -> Measurement {
        Measurement {
            name: name.into(),
            payload_bytes: 100,
            wait,
            wait_strategy: None,
            n: 10,
            p50_ns: 1,
            p99_ns: 2,
            p999_ns: 3,
            max_ns: 4,
            method: Method::HalfRoundTrip,
            baseline: None,
            producer_write_p50_ns: None,
            msgs_per_s: None,
            lost: None,
            notes: Vec::new(),
            cdf: Vec::new(),
            if_empty: None,
        }
    }

    #[test]
    fn json_has_the_issue_fields_and_leaves_empty_extras_out() {
        let report = Report { scenarios: vec![row("a", Wait::Spin)], ..Report::default() };
        let json = serde_json::to_value(&report).unwrap();
        let s = &json["scenarios"][0];
        for field in ["name", "payload_bytes", "wait", "n", "p50_ns", "p99_ns", "p999_ns", "max_ns"]
        {
            assert!(s.get(field).is_some(), "missing {field}");
        }
        assert_eq!(s["wait"], "spin");
        assert!(s.get("baseline").is_none());
        assert!(s.get("notes").is_none());
        assert!(s.get("wait_strategy").is_none());
        let back: Report = serde_json::from_value(json).unwrap();
        assert_eq!(back, report);
    }

    #[test]
    fn rows_without_samples_are_failures_with_their_reason() {
        let mut empty = row("e2e", Wait::Event).if_empty("no direction from a new blob");
        empty.n = 0;
        let mut report = Report::default();
        report.add_rows(vec![row("a", Wait::Spin), empty.note("60 blobs")]);
        assert_eq!(report.scenarios.len(), 1);
        assert_eq!(
            report.failed,
            [Failed {
                name: "e2e".into(),
                wait: Wait::Event,
                reason: "no samples: no direction from a new blob; 60 blobs".into(),
            }]
        );
        assert!(report.has_failed("e2e", Wait::Event) && !report.has_failed("a", Wait::Spin));
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["failed"][0]["name"], "e2e");
        assert_eq!(json["scenarios"].as_array().map(Vec::len), Some(1));
    }

    #[test]
    fn baseline_is_the_same_wait_row_of_the_named_scenario() {
        let report = Report {
            scenarios: vec![
                row("floor", Wait::Spin),
                row("floor", Wait::Event),
                row("hop", Wait::Event).baseline("floor"),
                row("chain", Wait::Event).baseline("missing"),
            ],
            ..Report::default()
        };
        let hop = &report.scenarios[2];
        assert_eq!(report.baseline_of(hop).map(|b| b.wait), Some(Wait::Event));
        assert!(report.baseline_of(&report.scenarios[3]).is_none());
        assert!(report.baseline_of(&report.scenarios[0]).is_none());
    }
}
