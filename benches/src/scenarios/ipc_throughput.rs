//! `throughput-1x1` and `throughput-1x4`: small structures from one publisher process
//! to one and to four subscriber processes, as fast as they go, none lost.
//!
//! The measuring process publishes `RobotState`s ([`Kind::Small`]) on one trajectory
//! with [`Delivery::Lossless`] (the publisher waits for a full subscriber instead of
//! overwriting), back to back; each peer process subscribes, validates every sample in
//! place and reads it, checks the per-publisher sequence numbers in the headers (a gap
//! is a lost sample: counted and printed, never hidden) and records the latency of
//! each sample, from the add time the publisher stamped in its header to the moment
//! the subscriber holds it, both on the host's system clock. Throughput is the
//! measured samples over the time from the first measured send to the last receipt
//! of any subscriber. The latency is under saturation: it includes the time a sample
//! waits in a subscriber's queue ([`QUEUE`] deep) behind the ones before it.
//!
//! Rows: `spin` (subscribers busy-poll) and `event` (they block on the trajectory's
//! wake-up event). Four busy-polling subscribers and a publisher share the two cores
//! of a small machine: that row shows what oversubscribing the cores costs.

use std::hint::black_box;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{Clock, SystemClock};
use esgm_shm::{Delivery, TrajectoryPublisher, TrajectoryQos, TrajectorySubscriber, unique_domain};

use super::ipc_esgm_echo::strategy;
use super::ipc_floor_iceoryx2;
use super::ipc_node::ipc_node;
use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::patience::{PEER_TIMEOUT, Patience};
use crate::peer_process::{FINISH_TIMEOUT, PeerProcess};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The subscriber queue depth.
pub const QUEUE: usize = 256;
const TRAJECTORY: &str = "throughput";
/// The valid time of the structure that tells subscribers to stop.
const STOP: i64 = -1;
/// The create time of warm-up structures (received, not recorded).
const WARMUP: i64 = 0;

/// See the module docs: one publisher, `subscribers` subscriber processes.
#[derive(Debug, Clone, Copy)]
pub struct Throughput {
    name: &'static str,
    subscribers: usize,
}

impl Throughput {
    /// One publisher to one subscriber.
    pub const ONE: Throughput = Throughput { name: "throughput-1x1", subscribers: 1 };
    /// One publisher to four subscribers.
    pub const FOUR: Throughput = Throughput { name: "throughput-1x4", subscribers: 4 };
}

impl Scenario for Throughput {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        if self.subscribers == 1 {
            "small structures, one publisher process -> one subscriber process, lossless, \
             back to back: msgs/s, latency under load, losses"
        } else {
            "small structures, one publisher process -> four subscriber processes, lossless, \
             back to back: msgs/s, latency under load, losses"
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        WaitMode::SPIN_AND_BLOCK.iter().map(|&mode| self.measure(ctx, mode)).collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        subscribe(role)
    }
}

fn qos() -> TrajectoryQos {
    TrajectoryQos {
        subscriber_buffer_size: QUEUE,
        delivery: Delivery::Lossless,
        ..TrajectoryQos::default()
    }
}

impl Throughput {
    fn measure(&self, ctx: &Context, mode: WaitMode) -> anyhow::Result<Measurement> {
        let samples = ctx.samples(200_000, 20_000);
        let warmup = ctx.warmup(samples);
        let domain = unique_domain("esgm-bench-tp");
        let node = ipc_node()?;
        let publisher = TrajectoryPublisher::builder(TRAJECTORY, Kind::Small.type_name())
            .domain(&domain)
            .qos(qos())
            .max_len(Kind::Small.max_bytes())
            .lossless_timeout(PEER_TIMEOUT)
            .create(&node)
            .context("could not create the throughput publisher")?;
        let mut peers = Vec::with_capacity(self.subscribers);
        for i in 0..self.subscribers {
            peers.push(ctx.spawn_peer_process_as(
                self.name,
                mode,
                &domain,
                Some(&i.to_string()),
            )?);
        }
        wait_for_subscribers(&publisher, &mut peers, self.subscribers)?;

        let clock = SystemClock;
        let mut es = Kind::Small.make(0);
        let mut first_send = 0;
        for seq in 1..=warmup + samples {
            if seq == warmup + 1 {
                first_send = clock.now();
            }
            es.valid_time = seq as i64;
            es.create_time = if seq > warmup { seq as i64 } else { WARMUP };
            publisher.publish(&es).with_context(|| format!("could not publish {seq}"))?;
        }
        es.valid_time = STOP;
        publisher.publish(&es).context("could not publish the stop")?;

        let mut latency = Latency::new()?;
        let (mut lost, mut received, mut last_receipt) = (0u64, 0u64, first_send);
        for peer in peers {
            for line in peer.finish(FINISH_TIMEOUT)? {
                let mut words = line.split_whitespace();
                let (Some(key), Some(a)) = (words.next(), words.next()) else { continue };
                let a: i64 = a.parse().with_context(|| format!("bad peer line {line:?}"))?;
                match key {
                    "lost" => lost += a.unsigned_abs(),
                    "received" => received += a.unsigned_abs(),
                    "last" => last_receipt = last_receipt.max(a),
                    "h" => {
                        let count: u64 = words
                            .next()
                            .and_then(|c| c.parse().ok())
                            .with_context(|| format!("bad peer line {line:?}"))?;
                        latency.record_count(a.unsigned_abs(), count);
                    }
                    _ => {}
                }
            }
        }
        let seconds = (last_receipt - first_send).max(1) as f64 / 1e9;
        let rate = samples as f64 / seconds;
        let expected = samples * self.subscribers as u64;
        let mut row = latency
            .measurement(self.name, mode.wait())
            .payload_bytes(payload_bytes()?)
            .method(Method::SystemClock)
            .wait_strategy(mode.label())
            .baseline(ipc_floor_iceoryx2::NAME)
            .throughput(rate, lost)
            .note(format!(
                "{rate:.0} msgs/s from the publisher ({:.0} deliveries/s to {} subscriber(s)); \
                 {received} of {expected} measured deliveries received, {lost} lost",
                rate * self.subscribers as f64,
                self.subscribers
            ))
            .note(format!(
                "latency at saturation: add time in the header -> subscriber holds it, \
                 queueing in a {QUEUE}-deep lossless queue included"
            ));
        if received != expected {
            row = row.note(format!("MISSING: {} deliveries never arrived", expected - received));
        }
        Ok(row)
    }
}

/// The archived size of the small structure.
fn payload_bytes() -> anyhow::Result<u64> {
    let bytes = esgm_core::codec::encode(&Kind::Small.make(1)).context("encoding")?;
    Ok(bytes.len() as u64)
}

/// Waits until all `n` subscribers are connected (a sample sent before would not reach
/// them), failing if a peer exits or none comes in time.
fn wait_for_subscribers(
    publisher: &TrajectoryPublisher,
    peers: &mut [PeerProcess],
    n: usize,
) -> anyhow::Result<()> {
    let started = Instant::now();
    loop {
        publisher.update_connections().context("updating connections")?;
        if publisher.subscriber_count() >= n {
            return Ok(());
        }
        for peer in peers.iter_mut() {
            peer.check_running()?;
        }
        if started.elapsed() > PEER_TIMEOUT {
            bail!("only {} of {n} subscribers connected", publisher.subscriber_count());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// The peer: receives until the stop, then prints its counts and latency buckets.
fn subscribe(role: &PeerRole) -> anyhow::Result<Vec<String>> {
    let node = ipc_node()?;
    let subscriber = TrajectorySubscriber::builder(TRAJECTORY, Kind::Small.type_name())
        .domain(&role.domain)
        .qos(qos())
        .wait_strategy(strategy(role.wait))
        .create(&node)
        .context("could not subscribe")?;
    let clock = SystemClock;
    let mut patience = Patience::alone();
    let mut latency = Latency::new()?;
    let (mut next_sequence, mut lost, mut received, mut last) = (None, 0u64, 0u64, 0i64);
    loop {
        let sample = patience.block("sample", |slice| Ok(subscriber.wait_for_sample(slice)?))?;
        let header = *sample.header();
        if let Some(expected) = next_sequence {
            lost += header.sequence.saturating_sub(expected);
        }
        next_sequence = Some(header.sequence + 1);
        if header.valid_time == STOP {
            break;
        }
        black_box(Kind::Small.read(sample.structure().context("reading a sample")?)?);
        if header.create_time == WARMUP {
            continue;
        }
        let now = clock.now();
        latency.record_ns(u64::try_from(now - header.add_time).unwrap_or(0));
        received += 1;
        last = now;
    }
    let mut lines =
        vec![format!("received {received}"), format!("lost {lost}"), format!("last {last}")];
    lines.extend(latency.buckets().into_iter().map(|(v, c)| format!("h {v} {c}")));
    Ok(lines)
}
