//! `query-<op>-<n>`: what a query costs on a trajectory another location writes, as a
//! user of `connect` calls it, on histories of 10^3 and 10^6 small structures.
//!
//! A coordinator runs on a thread of the measuring process, with two connections
//! ([`esgm_shm::ShmEsgm`], hosts `bench-writer` and `bench-reader`: two locations, as two
//! processes of one robot are). The writer creates a primitive `RobotState` trajectory
//! and adds `n` structures, one per millisecond of valid time; the reader's handle
//! ([`Esgm::get_entity_trajectory_structure`]) is its replica — an esgm-core store fed
//! from shared memory — and answers the queries ([`EntityTrajectoryStructure`]). Once
//! the replica holds all `n`, each query is timed alone, at random points of the
//! history:
//! - `latest`: `get_latest`, reading `x`;
//! - `at`: `get_at(t)` for an existing valid time, reading `x`;
//! - `closest`: `get_closest_at_or_before(t + 0.5 ms)`, reading `x`;
//! - `between`: `get_between(t, t + 9 ms)` (10 samples), reading `x` of each;
//! - `approx`: `get_at_approximating(t + 0.5 ms, Linear)`: interpolates the two samples
//!   around `t` into a new structure.
//!
//! The cache is `All`: the replica keeps every structure it receives, as its policy
//! says, while the writer's shared-memory history for replicas made later stays at
//! [`esgm_shm::DEFAULT_MAX_HISTORY`] (an `Elements(10^6)` cache would size the service
//! for a million samples per reader). So the replica is made before the first add, and
//! the writer adds in batches of `BATCH` — fewer than the replica's queue holds —
//! waiting after each until the replica has them all: a replica a whole queue behind
//! would lose the oldest.
//!
//! One scenario per size (`query-1000`, `query-1000000`) runs the five queries on one
//! replica; its rows are named `query-<op>-<n>`. Each row is one call timed in the
//! calling thread (an `Instant` pair costs about 20–40 ns and is included).

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{
    EntityTrajectoryStructure, Esgm, FluentStreamPolicy, InProcessTrajectory, Time, TrajectorySpec,
    TypeRegistry, ValueApproximation,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{DEFAULT_MAX_HISTORY, unique_domain};

use super::ipc_connect_echo::connect;
use super::ipc_floor_iceoryx2;
use super::ipc_payload::{Kind, read_value};
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

const TRAJECTORY: &str = "history";
/// Valid time of the first structure, and the step between two.
const START: Time = 1_000_000_000;
const STEP: Time = 1_000_000;
/// Structures added between two waits for the replica: half its queue
/// ([`DEFAULT_MAX_HISTORY`] deep for an `All` cache).
const BATCH: usize = DEFAULT_MAX_HISTORY / 2;
/// How long the replica may take to catch up with one batch.
const CATCH_UP: Duration = Duration::from_secs(60);
/// The largest history of a `--quick` run.
const QUICK_MAX: usize = 100_000;
/// The five queries.
pub const OPS: [&str; 5] = ["latest", "at", "closest", "between", "approx"];

/// See the module docs: queries on a replica holding `n` structures.
#[derive(Debug, Clone, Copy)]
pub struct Query {
    name: &'static str,
    n: usize,
}

impl Query {
    /// A history of 1,000.
    pub const THOUSAND: Query = Query { name: "query-1000", n: 1_000 };
    /// A history of 1,000,000.
    pub const MILLION: Query = Query { name: "query-1000000", n: 1_000_000 };
}

impl Scenario for Query {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        if self.n == 1_000 {
            "rows query-{latest,at,closest,between,approx}-1000: queries on a connect replica \
             holding 10^3 structures another location wrote"
        } else {
            "rows query-{latest,at,closest,between,approx}-1000000: queries on a connect \
             replica holding 10^6 structures another location wrote"
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        // A debug build takes minutes to replicate a million: `--quick` (the CI smoke
        // run) fills at most QUICK_MAX, and says so.
        let n = if ctx.is_quick() { self.n.min(QUICK_MAX) } else { self.n };
        // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let domain = unique_domain("esgm-bench-query");
        // Dropped last (declared first): the connections leave before it stops.
        let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let writer = connect(coordinator.domain(), "bench-writer")?;
        let reader = connect(coordinator.domain(), "bench-reader")?;
        let spec = TrajectorySpec::primitive(TRAJECTORY, Kind::Small.type_name())
            .policy(FluentStreamPolicy::default());
        let written = writer.create_trajectory(spec).context("creating the trajectory")?;
        let replica = reader
            .get_entity_trajectory_structure(TRAJECTORY)
            .context("the reader's replica of the trajectory")?;
        let filled = fill(&written, &replica, n)?;

        let samples = ctx.samples(100_000, 10_000);
        let bytes = esgm_core::codec::encoded_len(&Kind::Small.make(0))? as u64;
        let mut rows = Vec::new();
        let mut rng = Lcg(0x9e37_79b9_7f4a_7c15);
        for op in OPS {
            let mut latency = Latency::new()?;
            for i in 0..ctx.warmup(samples) + samples {
                let t = START + (rng.below(n as u64 - 10) as Time) * STEP;
                let start = Instant::now();
                let value = query(&replica, op, t)?;
                let took = start.elapsed();
                black_box(value);
                if i >= ctx.warmup(samples) {
                    latency.record(took);
                }
            }
            let name = format!("query-{op}-{}", self.n);
            let mut row = latency
                .measurement(&name, Wait::Spin)
                .payload_bytes(bytes)
                .method(Method::Call)
                .wait_strategy("none (a lookup in this process)")
                .baseline(ipc_floor_iceoryx2::NAME)
                .if_empty("no query was timed");
            if n != self.n {
                row = row.note(format!("--quick: a history of {n}, not {}", self.n));
            }
            if op == "latest" {
                row = row
                    .note(
                        "every row: on the reader's connect replica \
                         (get_entity_trajectory_structure) of a trajectory with an All cache, \
                         written through another connection; coordinator on a thread of this \
                         process",
                    )
                    .note(format!(
                        "the writer added {n} structures and the replica took them in within \
                         {:.2} s",
                        filled.as_secs_f64()
                    ));
            }
            rows.push(row);
        }
        // The connections go before their coordinator.
        drop((replica, written));
        drop((reader, writer));
        drop(coordinator);
        Ok(rows)
    }
}

/// Adds `n` structures through `written` in batches, each time waiting until `replica`
/// holds all of them; returns how long that took.
fn fill(
    written: &InProcessTrajectory,
    replica: &InProcessTrajectory,
    n: usize,
) -> anyhow::Result<Duration> {
    let started = Instant::now();
    let mut added = 0;
    while added < n {
        let end = (added + BATCH).min(n);
        for i in added..end {
            let mut es = Kind::Small.make(i as u64);
            es.valid_time = START + i as Time * STEP;
            es.create_time = es.valid_time;
            written.add(es).with_context(|| format!("adding structure {i}"))?;
        }
        added = end;
        let since = Instant::now();
        loop {
            let stored = replica.stats().context("the replica's stats")?.stored;
            if stored == added {
                break;
            }
            if stored > added || since.elapsed() > CATCH_UP {
                bail!(
                    "the replica holds {stored} structures, the writer added {added} (within {} s)",
                    CATCH_UP.as_secs()
                );
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    Ok(started.elapsed())
}

/// Runs query `op` at `t`; returns something read from the answer.
fn query(replica: &InProcessTrajectory, op: &str, t: Time) -> anyhow::Result<u64> {
    let read = |s: &esgm_core::Sample| read_value(Kind::Small, &s.structure).map(|(x, _)| x);
    Ok(match op {
        "latest" => read(&replica.get_latest()?)?,
        "at" => read(&replica.get_at(t)?)?,
        "closest" => read(&replica.get_closest_at_or_before(t + STEP / 2)?)?,
        "between" => {
            let mut sum = 0u64;
            for s in &replica.get_between(t, t + 9 * STEP)? {
                sum = sum.wrapping_add(read(s)?);
            }
            sum
        }
        _ => {
            let answer = replica.get_at_approximating(t + STEP / 2, &ValueApproximation::Linear)?;
            answer.structure.valid_time().unsigned_abs()
        }
    })
}

/// A tiny deterministic generator for query points.
#[derive(Debug)]
struct Lcg(u64);

impl Lcg {
    fn below(&mut self, bound: u64) -> u64 {
        self.0 =
            self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 33) % bound.max(1)
    }
}
