//! The Zenoh ping-pong behind `zenoh-small` and `zenoh-image` (feature `zenoh`).
//!
//! Two Zenoh sessions, one per process, joined directly over loopback TCP (the
//! measuring process listens on a free port, the peer connects; multicast scouting
//! off), with shared memory enabled on both: each payload travels in a Zenoh
//! shared-memory buffer, the TCP link carries only its descriptor. The measuring
//! process allocates a buffer from its shared-memory provider and encodes the structure
//! into it with the codec — the producer's write, timed apart like the socket's. The
//! hop starts when the buffer is complete and ends when the other process has
//! validated the archive in the received buffer ([`codec::access`]) and read it
//! ([`Kind::read`]). The peer answers by publishing the received buffer itself (no
//! copy), so half the round trip is one hop. `spin` rows poll the subscriber's queue
//! (`try_recv`), `event` rows block on it (`recv_timeout`).

use std::hint::black_box;
use std::net::TcpListener;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use esgm_core::codec;
use esgm_shm::unique_domain;
use zenoh::Wait as _;
use zenoh::bytes::ZBytes;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::sample::Sample;
use zenoh::shm::{AllocAlignment, MemoryLayout, PosixShmProviderBackend, ShmProviderBuilder};

use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::Context;
use crate::wait_mode::WaitMode;

const HELLO: i64 = 0;
const STOP: i64 = -1;
const HELLO_EVERY: Duration = Duration::from_millis(5);

type Queue = zenoh::handlers::FifoChannelHandler<Sample>;

fn zerr(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("zenoh: {e}")
}

/// A session listening on (`listen`) or connecting to loopback `port`, with Zenoh's
/// shared-memory transport or (`shm` false) every payload through the TCP link, as
/// between two hosts.
fn session(port: u16, listen: bool, shm: bool) -> anyhow::Result<zenoh::Session> {
    let mut config = zenoh::Config::default();
    let endpoint = format!(r#"["tcp/127.0.0.1:{port}"]"#);
    let key = if listen { "listen/endpoints" } else { "connect/endpoints" };
    config.insert_json5(key, &endpoint).map_err(zerr)?;
    config.insert_json5("scouting/multicast/enabled", "false").map_err(zerr)?;
    let shm = if shm { "true" } else { "false" };
    config.insert_json5("transport/shared_memory/enabled", shm).map_err(zerr)?;
    zenoh::open(config).wait().map_err(zerr)
}

struct Ends {
    _session: zenoh::Session,
    publisher: Publisher<'static>,
    subscriber: Subscriber<Queue>,
}

fn ends(
    port: u16,
    listen: bool,
    shm: bool,
    domain: &str,
    send_on: &str,
    receive_on: &str,
) -> anyhow::Result<Ends> {
    let session = session(port, listen, shm)?;
    let publisher =
        session.declare_publisher(format!("esgm-bench/{domain}/{send_on}")).wait().map_err(zerr)?;
    let subscriber = session
        .declare_subscriber(format!("esgm-bench/{domain}/{receive_on}"))
        .wait()
        .map_err(zerr)?;
    Ok(Ends { _session: session, publisher, subscriber })
}

/// The next sample, spinning or blocking as `mode` says.
fn receive(ends: &Ends, patience: &mut Patience<'_>, mode: WaitMode) -> anyhow::Result<Sample> {
    match mode {
        WaitMode::Spin => {
            patience.spin("zenoh sample", || ends.subscriber.try_recv().map_err(zerr))
        }
        WaitMode::Block | WaitMode::SpinThenBlock => patience
            .block("zenoh sample", |slice| ends.subscriber.recv_timeout(slice).map_err(zerr)),
    }
}

/// Validates and reads a received payload; returns its valid time (the sequence).
fn read(kind: Kind, payload: &ZBytes) -> anyhow::Result<(i64, bool)> {
    let shared = payload.as_shm().is_some();
    let bytes = payload.to_bytes();
    // Bytes from the TCP link sit wherever the receive buffer put them: an archive is
    // read in place only on its alignment, so a misaligned one is copied first (as the
    // bridge does with what it receives).
    let aligned: Vec<u128>;
    let bytes: &[u8] = if (bytes.as_ptr() as usize) % codec::ARCHIVE_ALIGNMENT == 0 {
        &bytes
    } else {
        let mut words = vec![0u128; bytes.len().div_ceil(16)];
        bytemuck::cast_slice_mut::<u128, u8>(&mut words)[..bytes.len()].copy_from_slice(&bytes);
        aligned = words;
        &bytemuck::cast_slice::<u128, u8>(&aligned)[..bytes.len()]
    };
    let archived = codec::access(bytes).context("validating a zenoh payload")?;
    if archived.valid_time.to_native() >= HELLO {
        black_box(kind.read(archived)?);
    }
    Ok((archived.valid_time.to_native(), shared))
}

/// Measures one wait mode: see the module docs.
pub fn measure(
    ctx: &Context,
    name: &str,
    kind: Kind,
    esgm_row: &str,
    shm: bool,
) -> anyhow::Result<Vec<Measurement>> {
    let mut rows = Vec::new();
    for mode in WaitMode::SPIN_AND_BLOCK {
        // A peer outside this project failing is a finding for the table, not a reason
        // to lose the rest of the run.
        let (one_way, write, bytes, shared) = match ping_pong(ctx, name, kind, mode, shm) {
            Ok(run) => run,
            Err(e) => {
                ctx.skip(name, format!("the Zenoh pair failed ({}): {e:#}", mode.label()));
                continue;
            }
        };
        {
            let mut row = one_way
                .measurement(name, mode.wait())
                .payload_bytes(bytes)
                .method(Method::HalfRoundTrip)
                .wait_strategy(mode.label())
                .baseline(esgm_row)
                .producer_write_p50_ns(write.quantile(0.5));
            row = if shm {
                row.note("the producer's write: allocate a Zenoh shared-memory buffer, encode the structure into it")
                    .note(if shared == one_way.len() {
                        "every payload arrived in a Zenoh shared-memory buffer".to_owned()
                    } else {
                        format!("only {shared} of {} payloads arrived in shared memory", one_way.len())
                    })
            } else {
                row.note("the producer's write: encode the structure into a buffer; shared memory off, every payload crosses the loopback TCP link as between two hosts")
            };
            rows.push(row);
        }
    }
    // A peer stopped by a signal leaves its Zenoh segments in /dev/shm: removed now
    // that every peer of the scenario is gone.
    zenoh::shm::cleanup_orphaned_shm_segments();
    Ok(rows)
}

fn ping_pong(
    ctx: &Context,
    name: &str,
    kind: Kind,
    mode: WaitMode,
    shm: bool,
) -> anyhow::Result<(Latency, Latency, u64, u64)> {
    let (full, quick) = kind.samples();
    let samples = ctx.samples(full, quick);
    let warmup = ctx.warmup(samples);
    let domain = unique_domain("esgm-bench-zenoh");
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("finding a free loopback port")?
        .port();
    let ends = ends(port, true, shm, &domain, "ping", "pong")?;
    let mut peer = ctx.spawn_peer_process_as(name, mode, &domain, Some(&port.to_string()))?;
    let mut patience = Patience::for_peer(&mut peer);

    let template = kind.make(0);
    let len = codec::encoded_len(&template).context("sizing the structure")?;
    // Buffers aligned as the codec's archives need (16 bytes), from a segment aligned
    // the same. Zenoh wants a layout's size to be a multiple of its alignment, and the
    // buffer holds exactly the archive (its envelope states the length): a structure
    // whose encoding is not a multiple of 16 bytes gets the largest power of two
    // dividing it, at least 8 (its 64-bit fields' alignment).
    let align = AllocAlignment::new(len.trailing_zeros().clamp(3, 4) as u8).map_err(zerr)?;
    // Room for 32 buffers in flight: a buffer is free again only once both processes
    // dropped it, which Zenoh learns asynchronously.
    let segment = MemoryLayout::new((len * 32).next_multiple_of(4096), align).map_err(zerr)?;
    let backend = PosixShmProviderBackend::builder(segment).wait().map_err(zerr)?;
    let provider = ShmProviderBuilder::backend(backend).wait();
    let layout =
        provider.alloc_layout(MemoryLayout::new(len, align).map_err(zerr)?).map_err(zerr)?;
    let mut es = template;
    let mut prepare = |seq: i64| -> anyhow::Result<ZBytes> {
        es.valid_time = seq;
        es.create_time = seq;
        if !shm {
            return Ok(ZBytes::from(codec::encode(&es).context("encoding")?.to_vec()));
        }
        let mut buffer = layout
            .alloc()
            .with_policy::<zenoh::shm::BlockOn<zenoh::shm::GarbageCollect>>()
            .wait()
            .map_err(zerr)?;
        codec::encode_into(&es, &mut buffer).context("encoding into the zenoh buffer")?;
        Ok(ZBytes::from(buffer))
    };

    // The peer's subscriber may not be matched yet: ping until it answers.
    let started = Instant::now();
    loop {
        ends.publisher.put(prepare(HELLO)?).wait().map_err(zerr)?;
        if ends.subscriber.recv_timeout(HELLO_EVERY).map_err(zerr)?.is_some() {
            break;
        }
        patience.check("answer to the first ping", started)?;
    }
    std::thread::sleep(Duration::from_millis(50));
    while ends.subscriber.try_recv().map_err(zerr)?.is_some() {}

    let (mut one_way, mut write) = (Latency::new()?, Latency::new()?);
    let mut shared = 0;
    for i in 1..=warmup + samples {
        let seq = i as i64;
        let making = Instant::now();
        let payload = prepare(seq)?;
        let made = making.elapsed();
        ctx.before_hop(mode.wait());
        let start = Instant::now();
        ends.publisher.put(payload).wait().map_err(zerr)?;
        let in_shm = loop {
            let sample = receive(&ends, &mut patience, mode)?;
            let (got, in_shm) = read(kind, sample.payload())?;
            if got == seq {
                break in_shm;
            }
        };
        let round_trip = start.elapsed();
        if i > warmup {
            one_way.record_half(round_trip);
            write.record(made);
            shared += u64::from(in_shm);
        }
    }
    ends.publisher.put(prepare(STOP)?).wait().map_err(zerr)?;
    peer.finish(FINISH_TIMEOUT)?;
    Ok((one_way, write, len as u64, shared))
}

/// The peer: answers every ping with the buffer it received, until the stop.
pub fn echo(role: &PeerRole, kind: Kind, shm: bool) -> anyhow::Result<Vec<String>> {
    let port: u16 = role.arg.as_deref().and_then(|p| p.parse().ok()).context("--peer-arg port")?;
    let ends = ends(port, false, shm, &role.domain, "pong", "ping")?;
    let mut patience = Patience::alone();
    loop {
        let sample = receive(&ends, &mut patience, role.wait)?;
        let (seq, _) = read(kind, sample.payload())?;
        if seq == STOP {
            return Ok(Vec::new());
        }
        ends.publisher.put(sample.payload().clone()).wait().map_err(zerr)?;
    }
}
