//! `scale-<n>` (P6, issue 23): what a domain's size costs the processes that do not
//! use it. A coordinator runs on a thread of the measuring process, and a writer
//! connection creates `n` primitive `RobotState` trajectories (cache 10). Then:
//! - `scale-connect-<n>`: a new connection (`ShmEsgm::builder().connect()`), timed
//!   from the call until it returns, then dropped; compared with `scale-connect-10` of
//!   the same run (target ≤ ×1.5 at 1,000, p50 ≤ 20 ms);
//! - `scale-first-add-<n>`: a new connection's first add to one of the trajectories,
//!   which another process writes (its replica made beforehand; the add opens the
//!   writer's inbox); target p50 ≤ 5 ms;
//! - `scale-idle-<n>`: the CPU this process (coordinator and writer, holding every
//!   trajectory, nothing flowing) uses per second of wall time, over one-second
//!   windows: 10 ms per second is 1 % of a core;
//! - memory rows `scale-private-<n>` (this process's private memory, `RssAnon`, with
//!   the `n` trajectories) and `scale-shm-<n>` (the `/dev/shm` files it maps, committed).
//!
//! A `--quick` run (the CI smoke run, a debug build) measures 10 and 100, not 1,000.

use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{
    CacheConstraint, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, TrajectorySpec,
    TypeRegistry,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect_echo::connect;
use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::report::{Measurement, MemoryRow, Method, Wait};
use crate::scenario::{Context, Scenario};

/// One domain size.
#[derive(Debug, Clone, Copy)]
pub struct Scale {
    name: &'static str,
    n: usize,
}

impl Scale {
    /// 10 trajectories: the baseline.
    pub const TEN: Scale = Scale { name: "scale-10", n: 10 };
    /// 100 trajectories.
    pub const HUNDRED: Scale = Scale { name: "scale-100", n: 100 };
    /// 1,000 trajectories.
    pub const THOUSAND: Scale = Scale { name: "scale-1000", n: 1_000 };
}

impl Scenario for Scale {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.n {
            10 => {
                "rows scale-{connect,first-add,idle}-10: a domain of 10 trajectories (the baseline)"
            }
            100 => "rows scale-{connect,first-add,idle}-100: a domain of 100 trajectories",
            _ => "rows scale-{connect,first-add,idle}-1000: a domain of 1,000 trajectories",
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        if ctx.is_quick() && self.n > 100 {
            ctx.skip(
                self.name,
                "--quick measures domains of 10 and 100 trajectories; run without --quick",
            );
            return Ok(Vec::new());
        }
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let before = resident()?;
        let domain = unique_domain("esgm-bench-scale");
        let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let d = coordinator.domain().to_owned();
        let writer = connect(&d, "bench-writer")?;
        let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(10));
        let mut handles = Vec::with_capacity(self.n);
        let created = Instant::now();
        for i in 0..self.n {
            let spec = TrajectorySpec::primitive(format!("t{i}"), Kind::Small.type_name())
                .policy(policy.clone());
            handles.push(writer.create_trajectory(spec).with_context(|| format!("creating t{i}"))?);
        }
        let created = created.elapsed();
        // Settled: creation's control traffic over.
        std::thread::sleep(Duration::from_secs(if ctx.is_quick() { 1 } else { 5 }));
        let after = resident()?;
        ctx.record_memory(MemoryRow {
            name: format!("scale-private-{}", self.n),
            after_structures: 0,
            bytes: after.0.saturating_sub(before.0),
            mapped_bytes: None,
            note: format!(
                "RssAnon growth of the process holding the coordinator and the writer of {} idle trajectories",
                self.n
            ),
        });
        ctx.record_memory(MemoryRow {
            name: format!("scale-shm-{}", self.n),
            after_structures: 0,
            bytes: after.1,
            mapped_bytes: None,
            note: "RssShmem of that process (the shared memory it touched)".into(),
        });

        let mut rows = Vec::new();
        // Each sample is a new connection (a first add, two): a debug build's `--quick`
        // smoke run keeps to ten, whatever `--samples` says.
        let samples = match ctx.is_quick() {
            true => ctx.samples(50, 10).min(10),
            false => ctx.samples(50, 10),
        };
        let mut connect_times = Latency::new()?;
        for i in 0..samples + 2 {
            let t = Instant::now();
            let c = connect(&d, &format!("bench-new-{i}"))?;
            let took = t.elapsed();
            drop(c);
            if i >= 2 {
                connect_times.record(took);
            }
        }
        let mut row = connect_times
            .measurement(&format!("scale-connect-{}", self.n), Wait::Event)
            .method(Method::Call)
            .wait_strategy("none (a call)")
            .if_empty("no connect was timed")
            .note(format!("{} trajectories created in {:.2} s", self.n, created.as_secs_f64()));
        if self.n != Scale::TEN.n {
            row = row.baseline("scale-connect-10");
        }
        rows.push(row);

        let mut first_adds = Latency::new()?;
        for i in 0..samples {
            let c = connect(&d, &format!("bench-adder-{i}"))?;
            let target = format!("t{}", i as usize % self.n);
            let replica = c.get_entity_trajectory_structure(&target)?;
            let t = Instant::now();
            replica.add(Kind::Small.make(i)).with_context(|| format!("adding to {target}"))?;
            first_adds.record(t.elapsed());
            drop((replica, c));
        }
        let mut row = first_adds
            .measurement(&format!("scale-first-add-{}", self.n), Wait::Event)
            .method(Method::Call)
            .wait_strategy("none (a call)")
            .if_empty("no add was timed");
        if self.n != Scale::TEN.n {
            row = row.baseline("scale-first-add-10");
        }
        rows.push(row);

        let windows = if ctx.is_quick() { 2 } else { 10 };
        let mut idle = Latency::new()?;
        for _ in 0..windows {
            let (cpu0, t0) = (cpu_ns()?, Instant::now());
            std::thread::sleep(Duration::from_secs(1));
            let (cpu1, wall) = (cpu_ns()?, t0.elapsed().as_secs_f64());
            idle.record_ns(((cpu1.saturating_sub(cpu0)) as f64 / wall) as u64);
        }
        let mut row = idle
            .measurement(&format!("scale-idle-{}", self.n), Wait::Event)
            .method(Method::CpuPerSecond)
            .wait_strategy("idle")
            .if_empty("no window was measured");
        if self.n != Scale::TEN.n {
            row = row.baseline("scale-idle-10");
        }
        rows.push(row);
        if handles.len() != self.n {
            bail!("{} of {} trajectories made", handles.len(), self.n);
        }
        drop(handles);
        drop(writer);
        drop(coordinator);
        Ok(rows)
    }
}

/// This process's private memory and shared memory touched (`RssAnon`, `RssShmem`).
fn resident() -> anyhow::Result<(u64, u64)> {
    let text = std::fs::read_to_string("/proc/self/status").context("/proc/self/status")?;
    let field = |name: &str| -> anyhow::Result<u64> {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':'))
            .and_then(|v| v.trim().strip_suffix("kB")?.trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
            .with_context(|| format!("no {name} in /proc/self/status"))
    };
    Ok((field("RssAnon")?, field("RssShmem")?))
}

/// CPU time this process used so far, in nanoseconds.
fn cpu_ns() -> anyhow::Result<u64> {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec for the call to fill.
    if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) } != 0 {
        bail!("clock_gettime(CLOCK_PROCESS_CPUTIME_ID) failed");
    }
    Ok(u64::try_from(ts.tv_sec)? * 1_000_000_000 + u64::try_from(ts.tv_nsec)?)
}
