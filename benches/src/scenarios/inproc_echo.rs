//! The in-process ping-pong behind `inproc-hop-small` and `inproc-hop-image`.
//!
//! Two primitive trajectories, `ping` and `pong`. The measuring thread adds a
//! complete structure to `ping`; an echo thread subscribed to `ping` receives it, reads
//! it ([`Payload::touch`]) and adds the very same shared structure to `pong`; the
//! measuring thread, subscribed to `pong`, receives and reads it. Both legs are the
//! same operation (an add of a shared structure → delivery to a subscriber), so half
//! the round trip is one hop, timed on one clock.
//!
//! Each structure is made before its timer starts (the producer's write is timed
//! apart and reported beside the hop), and the measuring thread keeps the previous
//! one alive until its own timer has stopped, so freeing a large frame is never
//! inside a timed hop.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context as _, bail};
use esgm_core::codec;
use esgm_core::{
    AddOutcome, CacheConstraint, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InProcessEsgm, InProcessTrajectory, SubscribeOptions, TrajectorySpec,
};

use crate::inbox::receive;
use crate::latency::Latency;
use crate::report::Wait;
use crate::scenario::Context;

/// What travels in a ping-pong.
pub trait Payload {
    /// The registered type of the structures.
    const TYPE_NAME: &'static str;
    /// Makes the `i`-th structure, complete (for an image: every pixel written).
    fn make(&mut self, i: u64) -> EntityStructure;
    /// Reads what a consumer must read to hold the structure (for an image: one pixel
    /// at each end), returning something to keep the compiler from skipping it.
    fn touch(es: &esgm_core::SharedStructure) -> u64;
}

/// What one ping-pong measured.
#[derive(Debug)]
pub struct EchoRun {
    /// One-way latency (half round trips).
    pub one_way: Latency,
    /// Time the producer took to make each structure, before its hop.
    pub make: Latency,
    /// The archived size of a structure, the payload size reported.
    pub payload_bytes: u64,
    /// True if every structure came back as the very allocation sent (no copy).
    pub shared: bool,
}

/// Runs `samples` timed round trips (after a warm-up) with `wait` on both sides.
pub fn ping_pong<P: Payload>(ctx: &Context, wait: Wait, mut payload: P) -> anyhow::Result<EchoRun> {
    let samples = ctx.samples(100_000, 10_000);
    let warmup = ctx.warmup(samples);
    let total = warmup + samples;

    let payload_bytes = codec::encoded_len(&payload.make(0))
        .context("could not measure the archived size of the payload")?
        as u64;

    let esgm = InProcessEsgm::default();
    let ping = primitive(&esgm, "bench-ping", P::TYPE_NAME)?;
    let pong = primitive(&esgm, "bench-pong", P::TYPE_NAME)?;
    let options = SubscribeOptions::default();
    let ping_sub = ping.subscribe(options).context("could not subscribe to bench-ping")?;
    let pong_sub = pong.subscribe(options).context("could not subscribe to bench-pong")?;

    let echo = ctx.spawn_peer("echo", move || {
        for _ in 0..total {
            let sample = receive(&ping_sub, wait, "ping")?;
            black_box(P::touch(&sample.structure));
            expect_added(pong.add_shared(sample.structure), "bench-pong")?;
        }
        Ok(())
    })?;

    let mut one_way = Latency::new()?;
    let mut make = Latency::new()?;
    let mut shared = true;
    let mut previous: Option<Arc<EntityStructure>> = None;
    for i in 0..total {
        let making = Instant::now();
        let es = Arc::new(payload.make(i));
        let made = making.elapsed();

        ctx.before_hop(wait);
        let start = Instant::now();
        expect_added(ping.add_shared(Arc::clone(&es)), "bench-ping")?;
        let back = receive(&pong_sub, wait, "pong")?;
        black_box(P::touch(&back.structure));
        let round_trip = start.elapsed();

        shared &= back.structure.as_owned().is_some_and(|b| Arc::ptr_eq(b, &es));
        if i >= warmup {
            one_way.record_half(round_trip);
            make.record(made);
        }
        drop(back);
        // The structure before this one is now referenced only here: free it untimed.
        previous = Some(es);
    }
    drop(previous);
    echo.join()?;
    Ok(EchoRun { one_way, make, payload_bytes, shared })
}

/// A primitive trajectory that keeps only its latest structure (so a run of 100,000
/// images does not keep them all).
fn primitive(
    esgm: &InProcessEsgm,
    name: &str,
    type_name: &str,
) -> anyhow::Result<InProcessTrajectory> {
    let mut spec = TrajectorySpec::primitive(name, type_name);
    spec.policy = FluentStreamPolicy::unconstrained().cache(CacheConstraint::Elements(1));
    esgm.create_trajectory(spec).with_context(|| format!("could not create {name}"))
}

fn expect_added(
    outcome: Result<AddOutcome, esgm_core::AddError>,
    trajectory: &str,
) -> anyhow::Result<()> {
    match outcome.with_context(|| format!("add to {trajectory} failed"))? {
        AddOutcome::Added => Ok(()),
        other => bail!("add to {trajectory} was not delivered: {other:?}"),
    }
}
