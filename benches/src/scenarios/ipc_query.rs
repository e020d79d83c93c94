//! `query-<op>-<n>`: what a query on a trajectory's history costs in a process that
//! does not write it, on caches of 10^3 and 10^6 small structures.
//!
//! A peer process writes the trajectory ([`esgm_shm::ShmTrajectoryWriter`], cache
//! constraint `Elements(n)`, one `RobotState` per millisecond of valid time); this
//! process reads it with an [`esgm_shm::ShmTrajectoryReader`] — the reader a program in
//! another process uses for queries (`esgm_shm::connect` feeds its local replica the
//! same way; see the crate docs of esgm-shm: the history lives in each reader). Once
//! the reader holds all `n` samples (still in the writer's shared memory), each query
//! is timed alone, at random points of the history:
//! - `latest`: `get_latest`, reading `x` in place;
//! - `at`: `get_at(t)` for an existing valid time, reading `x` in place;
//! - `between`: `get_between(t, t + 9 ms)` (10 samples), reading `x` of each in place;
//! - `approx`: `get_at_approximating(t + 0.5 ms, Linear)`: decodes the two samples
//!   around `t` and interpolates (an owned answer).
//!
//! One scenario per cache size (`query-1000`, `query-1000000`) runs the four queries on
//! one history; its rows are named `query-<op>-<n>`. Each row is one call timed in the
//! calling thread (an `Instant` pair costs about 20–40 ns and is included).

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{
    CacheConstraint, FluentStreamPolicy, Time, TypeChecker, TypeRegistry, ValueApproximation,
};
use esgm_shm::{
    SampleSizing, ShmTrajectoryReader, ShmTrajectoryWriter, TrajectoryQos, unique_domain,
};

use super::ipc_floor_iceoryx2;
use super::ipc_node::ipc_node;
use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

const TRAJECTORY: &str = "history";
/// Valid time of the first structure, and the step between two.
const START: Time = 1_000_000_000;
const STEP: Time = 1_000_000;
/// How long the writer waits for the reader to finish before giving up.
const WRITER_PATIENCE: Duration = Duration::from_secs(600);
/// The largest cache of a `--quick` run.
const QUICK_MAX: usize = 100_000;
/// The four queries.
pub const OPS: [&str; 4] = ["latest", "at", "between", "approx"];

/// See the module docs: queries on a history of `n` structures.
#[derive(Debug, Clone, Copy)]
pub struct Query {
    name: &'static str,
    n: usize,
}

impl Query {
    /// A cache of 1,000.
    pub const THOUSAND: Query = Query { name: "query-1000", n: 1_000 };
    /// A cache of 1,000,000.
    pub const MILLION: Query = Query { name: "query-1000000", n: 1_000_000 };
}

impl Scenario for Query {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        if self.n == 1_000 {
            "rows query-{latest,at,between,approx}-1000: queries on a history of 10^3 \
             written by another process (ShmTrajectoryReader)"
        } else {
            "rows query-{latest,at,between,approx}-1000000: queries on a history of 10^6 \
             written by another process (ShmTrajectoryReader)"
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        // A debug build takes minutes to fill a million: `--quick` (the CI smoke run)
        // fills a tenth of it, and says so.
        let n = if ctx.is_quick() { self.n.min(QUICK_MAX) } else { self.n };
        let domain = unique_domain("esgm-bench-query");
        let node = ipc_node()?;
        let mut reader = ShmTrajectoryReader::builder(TRAJECTORY, checker()?)
            .domain(&domain)
            .policy(policy(n))
            .qos(qos())
            .create(&node)
            .context("could not create the reader")?;
        let mut peer =
            ctx.spawn_peer_process_as(self.name, WaitMode::Spin, &domain, Some(&n.to_string()))?;
        let filling = Instant::now();
        let deadline = filling + WRITER_PATIENCE;
        while reader.len() < n {
            if reader.update().context("receiving the history")? == 0 {
                peer.check_running()?;
                if Instant::now() > deadline {
                    bail!("the reader holds {} of {} samples", reader.len(), n);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        let filled = filling.elapsed();

        let samples = ctx.samples(100_000, 10_000);
        let bytes = u64::from(
            reader.get_latest().map(|s| s.header().archive_len).unwrap_or_default() as u32,
        );
        let mut rows = Vec::new();
        let mut rng = Lcg(0x9e37_79b9_7f4a_7c15);
        for op in OPS {
            let mut latency = Latency::new()?;
            for i in 0..ctx.warmup(samples) + samples {
                let t = START + (rng.below(n as u64 - 10) as Time) * STEP;
                let start = Instant::now();
                let value = query(&reader, op, t)?;
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
                .baseline(ipc_floor_iceoryx2::NAME);
            if n != self.n {
                row = row.note(format!("--quick: a cache of {n}, not {}", self.n));
            }
            if op == "latest" {
                row = row.note(format!(
                    "the reader took in {} structures from the writer's process in {:.2} s",
                    n,
                    filled.as_secs_f64()
                ));
            }
            rows.push(row);
        }
        drop(reader);
        let done = done_file(&domain);
        std::fs::write(&done, b"done").with_context(|| format!("writing {}", done.display()))?;
        let finished = peer.finish(Duration::from_secs(60));
        let _ = std::fs::remove_file(&done);
        for note in finished? {
            if let Some(first) = rows.first_mut() {
                first.notes.push(format!("peer: {note}"));
            }
        }
        Ok(rows)
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        let n: usize = role.arg.as_deref().and_then(|a| a.parse().ok()).context("--peer-arg n")?;
        write(&role.domain, n)
    }
}

/// Runs query `op` at `t`; returns something read from the answer.
fn query(reader: &ShmTrajectoryReader, op: &str, t: Time) -> anyhow::Result<u64> {
    let read = |s: esgm_shm::CachedSample<'_>| -> anyhow::Result<u64> {
        Kind::Small.read(s.structure().context("reading a cached sample")?)
    };
    Ok(match op {
        "latest" => read(reader.get_latest()?)?,
        "at" => read(reader.get_at(t)?)?,
        "between" => {
            let mut sum = 0u64;
            for s in reader.get_between(t, t + 9 * STEP) {
                sum = sum.wrapping_add(read(s)?);
            }
            sum
        }
        _ => {
            let answer = reader.get_at_approximating(t + STEP / 2, &ValueApproximation::Linear)?;
            answer.valid_time().unsigned_abs()
        }
    })
}

fn checker() -> anyhow::Result<TypeChecker> {
    TypeChecker::new(&TypeRegistry::with_library(), Kind::Small.type_name())
        .context("the RobotState type")
}

fn policy(n: usize) -> FluentStreamPolicy {
    FluentStreamPolicy::default().cache(CacheConstraint::Elements(n))
}

/// One reader and one writer: the segment holds about `3 n` chunks, not `17 n`.
fn qos() -> TrajectoryQos {
    TrajectoryQos {
        max_publishers: 1,
        max_subscribers: 1,
        max_nodes: 4,
        ..TrajectoryQos::default()
    }
}

/// The peer: writes `n` structures, then stays until the reader has gone.
fn write(domain: &str, n: usize) -> anyhow::Result<Vec<String>> {
    let node = ipc_node()?;
    let bytes = esgm_core::codec::encode(&Kind::Small.make(1)).context("encoding")?.len();
    let mut writer = ShmTrajectoryWriter::builder(TRAJECTORY, checker()?)
        .domain(domain)
        .policy(policy(n))
        .qos(qos())
        .max_len(bytes.next_multiple_of(64))
        .sizing(SampleSizing::Grow)
        .create(&node)
        .context("could not create the writer")?;
    let started = Instant::now();
    for i in 0..n {
        let mut es = Kind::Small.make(i as u64);
        es.valid_time = START + i as Time * STEP;
        es.create_time = es.valid_time;
        writer.add(es).with_context(|| format!("adding structure {i}"))?;
    }
    let wrote = started.elapsed();
    // Told to stop by a file: the reader's going away is not seen reliably while it
    // releases a million samples.
    let done = done_file(domain);
    while !done.exists() {
        if started.elapsed() > WRITER_PATIENCE {
            bail!("the reader did not finish within {} s", WRITER_PATIENCE.as_secs());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(vec![format!("wrote {n} in {:.2} s", wrote.as_secs_f64())])
}

/// The file that tells the writer the reader is done.
fn done_file(domain: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("{domain}.done"))
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
