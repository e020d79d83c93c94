//! The cross-process ping-pong behind `uds-small` and `uds-image`: the same structures
//! as esgm's, copied through a Unix-domain stream socket.
//!
//! The measuring process makes each structure on the heap and encodes it with the
//! codec into its own buffer — the producer's write, timed apart. The hop starts when
//! those bytes are complete, and ends when the other process has received them into its
//! buffer, validated them in place ([`codec::access`]) and read them ([`Kind::read`]).
//! The peer answers with the bytes it received, validated and read, as they are: each
//! leg is one copy through the kernel, and half the round trip is one hop.
//!
//! `spin` rows use non-blocking sockets, busy-polled; `event` rows blocking ones.

use std::hint::black_box;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::codec;
use esgm_shm::unique_domain;

use super::ipc_payload::Kind;
use super::ipc_uds_frames::{FrameReader, configure, send};
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::scenario::Context;
use crate::wait_mode::WaitMode;

/// How often to look for the peer's connection.
const ACCEPT_EVERY: Duration = Duration::from_millis(1);

/// What one socket ping-pong measured.
#[derive(Debug)]
pub struct UdsRun {
    /// One-way latency (half round trips).
    pub one_way: Latency,
    /// Time the producer took to make and encode each structure before its hop.
    pub write: Latency,
    /// Encoded size of a structure (the frame header not counted).
    pub payload_bytes: u64,
}

/// Runs the measuring side of scenario `scenario` with `mode` in both processes.
pub fn ping_pong(
    ctx: &Context,
    scenario: &str,
    kind: Kind,
    mode: WaitMode,
) -> anyhow::Result<UdsRun> {
    let (full, quick) = kind.samples();
    let samples = ctx.samples(full, quick);
    let warmup = ctx.warmup(samples);
    let spin = mode == WaitMode::Spin;

    let domain = unique_domain("esgm-bench");
    let socket = SocketFile::bind(&socket_path(&domain))?;
    let mut peer = ctx.spawn_peer_process(scenario, mode, &domain)?;
    let mut patience = Patience::for_peer(&mut peer);
    let stream = patience.block("connection from the peer", |slice| socket.accept(slice))?;
    // Connected: the name is no longer needed.
    drop(socket);
    configure(&stream, spin).context("could not set the socket up")?;

    let mut reader = FrameReader::new(kind.max_bytes());
    let mut run = UdsRun { one_way: Latency::new()?, write: Latency::new()?, payload_bytes: 0 };
    for i in 0..warmup + samples {
        let making = Instant::now();
        let bytes = codec::encode(&kind.make(i)).context("could not encode")?;
        let made = making.elapsed();

        ctx.before_hop(mode.wait());
        let start = Instant::now();
        send(&stream, &bytes, spin, &mut patience, "ping")?;
        let Some(back) = reader.receive(&stream, spin, &mut patience, "pong")? else {
            bail!("the peer closed the socket");
        };
        black_box(kind.read(codec::access(back).context("the pong is malformed")?)?);
        let round_trip = start.elapsed();

        if i >= warmup {
            run.one_way.record_half(round_trip);
            run.write.record(made);
            run.payload_bytes = bytes.len() as u64;
        }
        // The producer's buffer is freed here, after the timer.
        drop(bytes);
    }
    // Closing the socket tells the peer to stop.
    drop(stream);
    peer.finish(FINISH_TIMEOUT)?;
    Ok(run)
}

/// The peer side: echoes every frame until the socket closes.
pub fn echo(role: &PeerRole, kind: Kind) -> anyhow::Result<Vec<String>> {
    let spin = role.wait == WaitMode::Spin;
    let path = socket_path(&role.domain);
    let mut patience = Patience::alone();
    let stream = patience.block("connection to the measuring process", |_| {
        match UnixStream::connect(&path) {
            Ok(stream) => Ok(Some(stream)),
            Err(_) => {
                std::thread::sleep(ACCEPT_EVERY);
                Ok(None)
            }
        }
    })?;
    configure(&stream, spin).context("could not set the socket up")?;
    let mut reader = FrameReader::new(kind.max_bytes());
    while let Some(body) = reader.receive(&stream, spin, &mut patience, "ping")? {
        black_box(kind.read(codec::access(body).context("the ping is malformed")?)?);
        send(&stream, body, spin, &mut patience, "pong")?;
    }
    Ok(Vec::new())
}

/// The socket's name: in the temporary folder, named for the unique domain.
fn socket_path(domain: &str) -> PathBuf {
    std::env::temp_dir().join(format!("{domain}.sock"))
}

/// A listening socket whose file is removed when it is dropped.
#[derive(Debug)]
struct SocketFile {
    listener: UnixListener,
    path: PathBuf,
}

impl SocketFile {
    fn bind(path: &Path) -> anyhow::Result<Self> {
        let listener = UnixListener::bind(path)
            .with_context(|| format!("could not listen on {}", path.display()))?;
        let socket = Self { listener, path: path.to_owned() };
        socket.listener.set_nonblocking(true).context("could not set the listener up")?;
        Ok(socket)
    }

    /// A connection, if one comes within `within`.
    fn accept(&self, within: Duration) -> anyhow::Result<Option<UnixStream>> {
        let until = Instant::now() + within;
        loop {
            match self.listener.accept() {
                Ok((stream, _)) => return Ok(Some(stream)),
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => return Err(e).context("could not accept the peer's connection"),
            }
            if Instant::now() >= until {
                return Ok(None);
            }
            std::thread::sleep(ACCEPT_EVERY);
        }
    }
}

impl Drop for SocketFile {
    fn drop(&mut self) {
        // Gone already is fine.
        let _ = std::fs::remove_file(&self.path);
    }
}
