//! `esgm scale`'s targets (issue 23, P6), each checked against what was measured:
//! - a new process's `connect`, p50 ≤ 20 ms;
//! - the first add to a trajectory from a process that does not write it, p50 ≤ 5 ms;
//! - the coordinator, which writes none of the profile's trajectories, ≤ 16 MiB of
//!   private memory plus 64 KiB per trajectory;
//! - each worker ≤ 16 MiB of private memory plus 256 KiB per trajectory it writes or
//!   reads (its caches' small structures included; images stay in shared memory);
//! - `/dev/shm` committed, idle, ≤ 256 KiB per trajectory;
//! - the whole domain idle ≤ 1 % of a core;
//! - every class of trajectory delivered, no worker error, no loss of a cause the
//!   design does not choose under load (every loss is listed with its cause).

use serde::Serialize;

use super::Measured;

const MIB: f64 = 1024.0 * 1024.0;
const KIB: f64 = 1024.0;

/// One target and how the run met it.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// What it is.
    pub target: String,
    /// What was measured.
    pub measured: String,
    /// Whether it was met.
    pub met: bool,
}

/// Every target of a run.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    /// The checks, in report order.
    pub checks: Vec<Check>,
}

impl Verdict {
    /// True if every target was met.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.met)
    }

    /// The targets missed.
    pub fn missed(&self) -> impl Iterator<Item = &Check> {
        self.checks.iter().filter(|c| !c.met)
    }
}

/// The `q` quantile of `v` (0 for none).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(((v.len() as f64 - 1.0) * q).round().max(0.0) as usize).copied().unwrap_or(0.0)
}

/// Judges `m`.
pub fn judge(m: &Measured) -> Verdict {
    let mut checks = Vec::new();
    let mut check = |target: String, measured: String, met: bool| {
        checks.push(Check { target, measured, met });
    };
    let connect = quantile(&m.connect_ms, 0.5);
    check(
        "a new process's connect p50 <= 20 ms".into(),
        format!(
            "{connect:.1} ms (max {:.1} ms; at start-up, {} at once: p50 {:.0} ms)",
            quantile(&m.connect_ms, 1.0),
            m.startup_connect_ms.len(),
            quantile(&m.startup_connect_ms, 0.5)
        ),
        !m.connect_ms.is_empty() && connect <= 20.0,
    );
    let first = quantile(&m.first_add_ms, 0.5);
    check(
        "first add from a non-writer p50 <= 5 ms".into(),
        format!(
            "{first:.2} ms (max {:.2} ms; when writing starts, {} at once: p50 {:.1} ms)",
            quantile(&m.first_add_ms, 1.0),
            m.startup_first_add_ms.len(),
            quantile(&m.startup_first_add_ms, 0.5)
        ),
        !m.first_add_ms.is_empty() && first <= 5.0,
    );
    let per_traj = m.coordinator.private as f64 / m.trajectories.max(1) as f64;
    check(
        "coordinator private memory <= 16 MiB + 64 KiB per trajectory it does not write".into(),
        format!(
            "{:.1} MiB ({:.1} KiB per trajectory)",
            m.coordinator.private as f64 / MIB,
            per_traj / KIB
        ),
        m.coordinator.private as f64 <= 16.0 * MIB + 64.0 * KIB * m.trajectories as f64,
    );
    let over: Vec<String> = m
        .workers
        .iter()
        .enumerate()
        .filter(|(_, w)| w.private as f64 > 16.0 * MIB + 256.0 * KIB * (w.writes + w.reads) as f64)
        .map(|(i, w)| format!("{i} ({:.1} MiB)", w.private as f64 / MIB))
        .collect();
    let privates: Vec<f64> = m.workers.iter().map(|w| w.private as f64 / MIB).collect();
    check(
        "each process's private memory <= 16 MiB + 256 KiB per trajectory it writes or reads"
            .into(),
        format!(
            "median {:.1} MiB, max {:.1} MiB{}",
            quantile(&privates, 0.5),
            quantile(&privates, 1.0),
            if over.is_empty() { String::new() } else { format!("; over: {}", over.join(", ")) }
        ),
        over.is_empty() && !m.workers.is_empty(),
    );
    let shm_per = m.shm_bytes as f64 / m.trajectories.max(1) as f64;
    check(
        "/dev/shm committed, idle, <= 256 KiB per trajectory".into(),
        format!(
            "{:.1} MiB in {} files ({:.1} KiB per trajectory)",
            m.shm_bytes as f64 / MIB,
            m.shm_files,
            shm_per / KIB
        ),
        shm_per <= 256.0 * KIB,
    );
    let idle: f64 = m.coordinator.cpu_idle + m.workers.iter().map(|w| w.cpu_idle).sum::<f64>();
    check(
        "the whole domain idle <= 1 % of a core".into(),
        format!("{idle:.2} % (coordinator {:.2} %)", m.coordinator.cpu_idle),
        idle <= 1.0,
    );
    for class in super::profile::Class::ALL {
        let got = m.latency.get(&class).map_or(0, |l| l.received);
        check(
            format!("{} delivered", class.label()),
            format!("{got} structures received"),
            got > 0,
        );
    }
    check(
        "no worker error".into(),
        if m.errors.is_empty() { "none".into() } else { m.errors.join("; ") },
        m.errors.is_empty(),
    );
    let unexplained: Vec<String> = m
        .trajectory_counts
        .iter()
        .flat_map(|(name, c)| {
            c.losses
                .iter()
                .filter(|l| !l.explained)
                .map(move |l| format!("{name}: {} {}", l.count, l.cause))
        })
        .collect();
    check(
        "no loss without a cause chosen under load".into(),
        if unexplained.is_empty() { "none".into() } else { unexplained.join(", ") },
        unexplained.is_empty(),
    );
    Verdict { checks }
}

/// Prints the run and its verdict.
pub fn print(m: &Measured, v: &Verdict) {
    println!("\nlatency until a reader holds the structure (every reader, every structure):");
    println!("  {:<16} {:>10} {:>10} {:>10} {:>10}", "class", "received", "p50", "p99", "max");
    for (class, l) in &m.latency {
        println!(
            "  {:<16} {:>10} {:>8} µs {:>8} µs {:>8} µs",
            class.label(),
            l.received,
            l.p50_us,
            l.p99_us,
            l.max_us
        );
    }
    let cpu =
        |f: fn(&super::ProcessUse) -> f64| f(&m.coordinator) + m.workers.iter().map(f).sum::<f64>();
    println!(
        "\nCPU, % of a core: idle {:.2} (coordinator {:.2}), writing {:.1} (coordinator {:.2}); {} structures added",
        cpu(|p| p.cpu_idle),
        m.coordinator.cpu_idle,
        cpu(|p| p.cpu_loaded),
        m.coordinator.cpu_loaded,
        m.published
    );
    let mut losses: std::collections::BTreeMap<&str, u64> = std::collections::BTreeMap::new();
    for c in m.trajectory_counts.values() {
        for l in &c.losses {
            *losses.entry(l.cause.as_str()).or_default() += l.count;
        }
    }
    if losses.is_empty() {
        println!("losses: none");
    } else {
        let list: Vec<String> = losses.iter().map(|(c, n)| format!("{n} {c}")).collect();
        println!("losses: {}", list.join(", "));
    }
    println!("\ntargets:");
    for c in &v.checks {
        println!("  {} {:<78} {}", if c.met { "ok  " } else { "MISS" }, c.target, c.measured);
    }
    if !m.left_behind.is_empty() {
        println!("left behind: {}", m.left_behind.join(", "));
    }
}
