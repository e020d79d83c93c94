//! `fanout-<k>` (P6, issue 23): one writer and k readers of one trajectory, each a
//! connection of its own (its own node, receiver thread and subscription, as k
//! processes would have), in the measuring process with a coordinator on a thread.
//!
//! The writer adds a small structure stamped with the system clock, every 2 ms (a
//! `tf`-like stream at a rate every reader keeps up with); each reader's subscription
//! takes it and notes when it held it: blocking (a reader that does not burn a core,
//! the `event` row) or busy-waiting (polling and yielding, the `spin` row).
//! A row's sample is, per structure, the time until the *last* reader held it: the
//! figure a stream read by every process is held to. The physical floor grows by one
//! wake-up per reader (iceoryx2 notifies each listener), so `fanout-<k>` is compared
//! with `fanout-1` of the same run: ×k at most.
//!
//! Every reader must receive every structure (counted as lost otherwise).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context as _, bail};
use esgm_core::{
    CacheConstraint, Clock, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, SubscribeOptions,
    SystemClock, TrajectorySpec, TypeRegistry,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect_echo::connect;
use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// One fan-out.
#[derive(Debug, Clone, Copy)]
pub struct Fanout {
    name: &'static str,
    k: usize,
}

impl Fanout {
    /// One reader: the baseline.
    pub const ONE: Fanout = Fanout { name: "fanout-1", k: 1 };
    /// 8 readers.
    pub const EIGHT: Fanout = Fanout { name: "fanout-8", k: 8 };
    /// 32 readers.
    pub const THIRTY_TWO: Fanout = Fanout { name: "fanout-32", k: 32 };
    /// 64 readers.
    pub const SIXTY_FOUR: Fanout = Fanout { name: "fanout-64", k: 64 };
}

/// Time between two structures.
const PERIOD: Duration = Duration::from_millis(2);

impl Scenario for Fanout {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.k {
            1 => "row fanout-1: one writer, one reader connection (the baseline)",
            8 => "row fanout-8: one writer, 8 reader connections, until the last holds it",
            32 => "row fanout-32: one writer, 32 reader connections, until the last holds it",
            _ => "row fanout-64: one writer, 64 reader connections, until the last holds it",
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        if ctx.is_quick() && self.k > 8 {
            ctx.skip(self.name, "--quick measures 1 and 8 readers; run without --quick");
            return Ok(Vec::new());
        }
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let mut rows = vec![self.measure(ctx, Wait::Event)?];
        // Busy-waiting readers beyond the cores take turns on them: a reader that missed
        // structures is reported with its count, without losing the blocking row.
        match self.measure(ctx, Wait::Spin) {
            Ok(row) => rows.push(row),
            Err(e) => ctx.skip(self.name, format!("busy-wait readers: {e:#}")),
        }
        Ok(rows)
    }
}

impl Fanout {
    /// One row: `wait` says whether the readers block on their subscription or
    /// busy-wait on it (polling, yielding the core between polls).
    fn measure(&self, ctx: &Context, wait: Wait) -> anyhow::Result<Measurement> {
        let domain = unique_domain("esgm-bench-fanout");
        let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let d = coordinator.domain().to_owned();
        let writer = connect(&d, "bench-writer")?;
        let spec = TrajectorySpec::primitive("tf", Kind::Small.type_name())
            .policy(FluentStreamPolicy::default().cache(CacheConstraint::Elements(10)))
            .readers(self.k);
        let tf = writer.create_trajectory(spec).context("creating tf")?;
        let samples = ctx.samples(2_000, 100) as usize;
        let stop = Arc::new(AtomicBool::new(false));
        let mut readers = Vec::with_capacity(self.k);
        let mut connections = Vec::with_capacity(self.k);
        for r in 0..self.k {
            let c = connect(&d, &format!("bench-reader-{r}"))?;
            let sub = c
                .get_entity_trajectory_structure("tf")?
                .subscribe(SubscribeOptions::default())
                .context("subscribing")?;
            let stop = Arc::clone(&stop);
            readers.push(std::thread::spawn(move || {
                // (valid time = sequence, held at) of every structure received.
                let mut held = Vec::with_capacity(samples);
                while !stop.load(Ordering::Acquire) {
                    let got = match wait {
                        Wait::Event => sub.recv_timeout(Duration::from_millis(50)).ok(),
                        Wait::Spin => sub.try_recv().or_else(|| {
                            std::thread::yield_now();
                            None
                        }),
                    };
                    if let Some(s) = got {
                        held.push((s.structure.valid_time(), SystemClock.now()));
                    }
                }
                held
            }));
            connections.push(c);
        }
        // Every reader set up: its replica holds the writer's (empty) history.
        std::thread::sleep(Duration::from_millis(500));
        let warmup = ctx.warmup(samples as u64) as usize;
        let mut sent = Vec::with_capacity(samples + warmup);
        for i in 0..samples + warmup {
            let now = SystemClock.now();
            let mut es = Kind::Small.make(i as u64);
            es.valid_time = i as i64;
            es.create_time = now;
            tf.add(es).with_context(|| format!("adding {i}"))?;
            sent.push(now);
            std::thread::sleep(PERIOD);
        }
        std::thread::sleep(Duration::from_millis(500));
        stop.store(true, Ordering::Release);
        let mut last = vec![0i64; sent.len()];
        let mut lost = 0u64;
        for r in readers {
            let held = r.join().map_err(|_| anyhow::anyhow!("a reader thread panicked"))?;
            let mut seen = vec![false; sent.len()];
            for (seq, at) in held {
                let Some(i) = usize::try_from(seq).ok().filter(|i| *i < sent.len()) else {
                    continue;
                };
                seen[i] = true;
                last[i] = last[i].max(at);
            }
            lost += seen.iter().filter(|s| !**s).count() as u64;
        }
        let mut latency = Latency::new()?;
        for i in warmup..sent.len() {
            if last[i] > 0 {
                latency.record_ns(u64::try_from(last[i] - sent[i]).unwrap_or(0));
            }
        }
        if latency.is_empty() {
            bail!("no structure reached every reader");
        }
        if lost > 0 {
            // A reader that missed structures did not keep up: every sample must arrive.
            bail!("{lost} receptions missing over {} readers ({})", self.k, wait.as_str());
        }
        let strategy = match wait {
            Wait::Event => "block (a subscription)",
            Wait::Spin => "busy-wait (try_recv, yielding between polls)",
        };
        let mut row = latency
            .measurement(self.name, wait)
            .method(Method::SystemClock)
            .wait_strategy(strategy)
            .payload_bytes(esgm_core::codec::encoded_len(&Kind::Small.make(0))? as u64)
            .if_empty("no structure reached every reader")
            .note(format!(
                "until the last of {} reader connections held each structure; every reader received every one",
                self.k
            ));
        if self.k != 1 {
            row = row.baseline(Fanout::ONE.name);
        }
        drop(connections);
        drop(tf);
        drop(writer);
        drop(coordinator);
        Ok(row)
    }
}
