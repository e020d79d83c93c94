//! CPU time of the calling thread, to report what a waiting subscriber costs when idle.
//!
//! Read from the scheduler's accounting (`/proc/thread-self/schedstat`, nanoseconds on
//! a CPU), which needs no unsafe code and counts exactly this thread — not the
//! process's other threads (output readers of peer processes).

use std::time::{Duration, Instant};

use anyhow::Context as _;

/// Nanoseconds the calling thread has spent on a CPU.
pub fn thread_cpu_time() -> anyhow::Result<Duration> {
    const PATH: &str = "/proc/thread-self/schedstat";
    let text = std::fs::read_to_string(PATH).with_context(|| format!("could not read {PATH}"))?;
    let ns: u64 = text
        .split_whitespace()
        .next()
        .and_then(|field| field.parse().ok())
        .with_context(|| format!("{PATH} does not start with a CPU time: {text:?}"))?;
    Ok(Duration::from_nanos(ns))
}

/// What a thread used while calling something for a while.
#[derive(Debug, Clone, Copy)]
pub struct CpuUse {
    /// CPU time of the thread.
    pub cpu: Duration,
    /// Wall-clock time.
    pub wall: Duration,
}

impl CpuUse {
    /// CPU time as a percentage of one core.
    pub fn percent_of_a_core(&self) -> f64 {
        100.0 * self.cpu.as_secs_f64() / self.wall.as_secs_f64().max(f64::MIN_POSITIVE)
    }
}

/// Calls `f` until `window` has passed, on the calling thread, and measures it.
pub fn cpu_while(
    window: Duration,
    mut f: impl FnMut() -> anyhow::Result<()>,
) -> anyhow::Result<CpuUse> {
    let cpu_before = thread_cpu_time()?;
    let start = Instant::now();
    while start.elapsed() < window {
        f()?;
    }
    let wall = start.elapsed();
    let cpu = thread_cpu_time()?.saturating_sub(cpu_before);
    Ok(CpuUse { cpu, wall })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleeping_costs_little_and_spinning_a_lot() {
        let idle = cpu_while(Duration::from_millis(50), || {
            std::thread::sleep(Duration::from_millis(10));
            Ok(())
        })
        .unwrap();
        let busy = cpu_while(Duration::from_millis(50), || Ok(())).unwrap();
        assert!(idle.cpu < busy.cpu, "{idle:?} vs {busy:?}");
        assert!(busy.percent_of_a_core() > 0.0);
    }
}
