//! CPU and memory of a whole system: every process it runs, read from `/proc` at the
//! start and the end of a run. CPU is the processes' user and system time over the
//! wall time (% of one core); memory is each process's private memory (its own pages)
//! and shared memory (pages shared with others, shared memory segments included) at
//! the end, added up, and the `/dev/shm` files the system made.

use std::time::{Duration, Instant};

use anyhow::Context as _;

/// CPU time of `pid` so far (user + system).
pub fn cpu_time(pid: u32) -> anyhow::Result<Duration> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .with_context(|| format!("cannot read /proc/{pid}/stat"))?;
    // The command name is in parentheses and may hold spaces: count after its end.
    let after = stat.rsplit_once(')').map(|(_, a)| a).context("a /proc stat without `)`")?;
    let fields: Vec<&str> = after.split_whitespace().collect();
    // utime and stime are the 14th and 15th fields; the 3rd is fields[0] here.
    let ticks = |i: usize| -> anyhow::Result<u64> {
        fields.get(i).and_then(|f| f.parse().ok()).context("a /proc stat without times")
    };
    let total = ticks(11)? + ticks(12)?;
    // SAFETY: sysconf is thread-safe and takes no pointers.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    let hz = u64::try_from(hz).ok().filter(|h| *h > 0).unwrap_or(100);
    Ok(Duration::from_nanos(total.saturating_mul(1_000_000_000) / hz))
}

/// `(private, shared)` memory of `pid` in bytes (`smaps_rollup`).
pub fn memory(pid: u32) -> anyhow::Result<(u64, u64)> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup"))
        .with_context(|| format!("cannot read /proc/{pid}/smaps_rollup"))?;
    let field = |name: &str| -> u64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.split_whitespace().next())
            .and_then(|kb| kb.parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    };
    let private = field("Private_Clean:") + field("Private_Dirty:");
    let shared = field("Shared_Clean:") + field("Shared_Dirty:");
    Ok((private, shared))
}

/// The CPU and memory of a set of processes over a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct Usage {
    /// % of one core, all processes together.
    pub cpu_percent: f64,
    /// Private memory at the end, all processes together (bytes).
    pub private_bytes: u64,
    /// Shared memory at the end, all processes together (bytes; a page two processes
    /// share counts in both).
    pub shared_bytes: u64,
    /// The processes measured.
    pub processes: usize,
}

/// Measures processes from the start of a run: [`Meter::finish`] at its end.
#[derive(Debug)]
pub struct Meter {
    pids: Vec<u32>,
    start: Instant,
    cpu_at_start: Duration,
}

impl Meter {
    /// Starts measuring `pids`.
    pub fn start(pids: Vec<u32>) -> anyhow::Result<Self> {
        let mut cpu = Duration::ZERO;
        for p in &pids {
            cpu += cpu_time(*p)?;
        }
        Ok(Self { pids, start: Instant::now(), cpu_at_start: cpu })
    }

    /// What the processes used since the start (all still running).
    pub fn finish(&self) -> anyhow::Result<Usage> {
        let wall = self.start.elapsed();
        let (mut cpu, mut private, mut shared) = (Duration::ZERO, 0, 0);
        for p in &self.pids {
            cpu += cpu_time(*p)?;
            let (pv, sh) = memory(*p)?;
            private += pv;
            shared += sh;
        }
        let used = cpu.saturating_sub(self.cpu_at_start);
        Ok(Usage {
            cpu_percent: 100.0 * used.as_secs_f64() / wall.as_secs_f64().max(1e-9),
            private_bytes: private,
            shared_bytes: shared,
            processes: self.pids.len(),
        })
    }
}
