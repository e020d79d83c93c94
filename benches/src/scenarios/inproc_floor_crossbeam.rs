//! `inproc-floor-crossbeam`: the floor of an in-process hop.
//!
//! A 100-byte struct, sent by value over a bounded crossbeam channel to an echo thread
//! and back over a second one. esgm's in-process subscriptions are bounded crossbeam
//! channels too, so what an esgm hop costs above this is esgm's own work (store, type
//! check, stats, fan-out), not the channel's.

use std::hint::black_box;
use std::time::Instant;

use anyhow::Context as _;

use crate::inbox::receive;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "inproc-floor-crossbeam";

/// The message: 100 bytes, like a small entity structure.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct Message {
    seq: u32,
    body: [u8; 96],
}

/// Same capacity as an esgm subscription's default buffer.
const CAPACITY: usize = 1024;

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct InprocFloorCrossbeam;

impl Scenario for InprocFloorCrossbeam {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "raw crossbeam channel ping-pong of a 100-byte struct: the floor of an in-process hop"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        Wait::BOTH.iter().map(|&wait| measure(ctx, wait)).collect()
    }
}

fn measure(ctx: &Context, wait: Wait) -> anyhow::Result<Measurement> {
    let samples = ctx.samples(100_000, 10_000);
    let warmup = ctx.warmup(samples);
    let total = warmup + samples;
    let (to_echo, echo_in) = crossbeam_channel::bounded::<Message>(CAPACITY);
    let (to_me, my_in) = crossbeam_channel::bounded::<Message>(CAPACITY);

    let echo = ctx.spawn_peer("echo", move || {
        for _ in 0..total {
            let m = receive(&echo_in, wait, "ping")?;
            to_me.send(m).context("the measuring thread went away")?;
        }
        Ok(())
    })?;

    let mut latency = Latency::new()?;
    let mut message = Message { seq: 0, body: [0x5a; 96] };
    for i in 0..total {
        message.seq = i as u32;
        message.body[0] = i as u8;
        ctx.before_hop(wait);
        let start = Instant::now();
        to_echo.send(message).context("the echo thread went away")?;
        let back = receive(&my_in, wait, "pong")?;
        let round_trip = start.elapsed();
        black_box(back.seq);
        if i >= warmup {
            latency.record_half(round_trip);
        }
    }
    echo.join()?;

    Ok(latency
        .measurement(NAME, wait)
        .payload_bytes(size_of::<Message>() as u64)
        .method(Method::HalfRoundTrip))
}
