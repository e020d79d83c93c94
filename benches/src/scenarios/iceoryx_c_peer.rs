//! `iceoryx-c-small` and `iceoryx-c-image` (issue 37): a C peer in the same run as
//! `cpp-small` and `cpp-image` — the same payload sizes between two C processes on
//! classic iceoryx's C binding (iceoryx 2.0, Debian's `libiceoryx-binding-c-dev`), the
//! shared-memory middleware a C or C++ robot program would otherwise reach for.
//!
//! The peer is `benches/iceoryx/iceoryx_pingpong.c`, built by
//! `benches/iceoryx/build.sh`; without the built program or `iox-roudi` both rows are
//! reported as skipped with that instruction. Each pair runs against a RouDi of its own
//! ([`super::iceoryx_roudi`], in a private mount namespace, so root only), started
//! before the pair and stopped after it. The program's `ping` role measures and prints
//! its figures (see its header), as the ROS 1 peer's does:
//! - small: a chunk of the small structure's encoded size; image: a chunk of 921,600
//!   bytes of pixels. The writer loans the chunk from its publisher and writes every
//!   byte in place before the timer; the reader takes it and reads a byte at each end
//!   in place, checking one against the other (it cannot validate an esgm archive: a
//!   lower bound for classic iceoryx doing esgm's work).
//! - `spin` polls `iox_sub_take_chunk`; `event` blocks in a WaitSet on the subscriber's
//!   data, after the same 50 µs busy gap as esgm's rows.
//! - The image's hops are paced as `cpp-image`'s (`ready`/`done`), so the rows compare.
//!
//! Each row's baseline is the `cpp-*` row of its payload: what a C++ program pays for
//! esgm over a bare shared-memory transport of the same bytes. The issue sets no target
//! for this peer, so none is printed.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context as _, bail};

use super::iceoryx_roudi::Roudi;
use super::inproc_hop_image::PIXEL_BYTES;
use super::ipc_cpp;
use super::ipc_payload::Kind;
use super::peer_rows::PeerRows;
use super::program_pair;
use super::ros1_peer::which;
use crate::latency::Latency;
use crate::patience::PEER_TIMEOUT;
use crate::report::Measurement;
use crate::scenario::{Context, EVENT_GAP, Scenario};
use crate::wait_mode::WaitMode;

/// What to run to measure classic iceoryx.
pub const HOW: &str = "run benches/iceoryx/build.sh (needs Debian's libiceoryx-binding-c-dev \
                       and iceoryx packages; installs them as root)";
/// How long one pair may take.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// One payload through classic iceoryx (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct IceoryxC {
    name: &'static str,
    kind: Kind,
}

impl IceoryxC {
    /// The small structure's size.
    pub const SMALL: IceoryxC = IceoryxC { name: "iceoryx-c-small", kind: Kind::Small };
    /// The image's pixels.
    pub const IMAGE: IceoryxC = IceoryxC { name: "iceoryx-c-image", kind: Kind::Image };
}

/// The built peer program, if there is one: `ESGM_ICEORYX_PINGPONG`, else the place
/// `build.sh` puts it.
pub fn program() -> Option<PathBuf> {
    let path = std::env::var_os("ESGM_ICEORYX_PINGPONG").map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("iceoryx/build/iceoryx_pingpong")
    });
    path.is_file().then_some(path)
}

impl Scenario for IceoryxC {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "~120 bytes between two C processes on classic iceoryx 2.0's C binding, loaned \
                 and read in place (benches/iceoryx/build.sh)"
            }
            Kind::Image => {
                "921,600 bytes of pixels between two C processes on classic iceoryx 2.0's C \
                 binding, written into the loan, paced as cpp-image (benches/iceoryx/build.sh)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let Some(program) = program() else {
            ctx.skip(self.name, HOW);
            return Ok(Vec::new());
        };
        if which("iox-roudi").is_none() {
            ctx.skip(self.name, format!("iox-roudi is not installed; {HOW}"));
            return Ok(Vec::new());
        }
        let bytes = match self.kind {
            Kind::Small => esgm_core::codec::encoded_len(&self.kind.make(0)).context("sizing")?,
            Kind::Image => PIXEL_BYTES,
        };
        let (full, quick) = self.kind.samples();
        let samples = ctx.samples(full, quick);
        let warmup = ctx.warmup(samples);
        let (baseline, paced) = match self.kind {
            Kind::Small => (ipc_cpp::SMALL_NAME, false),
            Kind::Image => (ipc_cpp::IMAGE_NAME, true),
        };
        let rows = PeerRows {
            name: self.name,
            baseline,
            bytes,
            peer: "classic iceoryx",
            note: "one chunk per message, loaned and written in place by the writer, read in \
                   place by the reader (a byte at each end; it cannot validate an esgm \
                   archive); iceoryx 2.0's C binding with a private RouDi; spin: \
                   iox_sub_take_chunk in a loop, event: a WaitSet on the subscriber's data",
        };
        let pair = Pair { program: &program, bytes, paced, samples, warmup };
        // A peer outside this project (its packages, its daemon) failing is a finding.
        Ok(rows.measure(ctx, |mode| pair.run(ctx, mode)))
    }
}

/// One pair's settings.
struct Pair<'a> {
    program: &'a Path,
    bytes: usize,
    paced: bool,
    samples: u64,
    warmup: u64,
}

impl Pair<'_> {
    fn run(&self, ctx: &Context, mode: WaitMode) -> anyhow::Result<Latency> {
        let (ping_core, pong_core) = program_pair::cores(ctx)?;
        // RouDi may use both cores, as rosmaster does in the ROS 1 rows.
        let roudi_cores = match (&ping_core, &pong_core) {
            (Some(m), Some(p)) => Some(format!("{m},{p}")),
            _ => None,
        };
        let roudi = Roudi::start(roudi_cores.as_deref())?;
        let enter = roudi.enter();
        let prefix: Vec<&str> = enter.iter().map(String::as_str).collect();
        let wait = if mode == WaitMode::Spin { "spin" } else { "block" };
        let (bytes, paced) = (self.bytes.to_string(), if self.paced { "1" } else { "0" });
        let timeout = PEER_TIMEOUT.as_secs().to_string();
        let mut ping = program_pair::command(&prefix, self.program, ping_core.as_deref());
        ping.args(["ping", "pair", wait, &bytes, paced])
            .arg(self.samples.to_string())
            .arg(self.warmup.to_string())
            .arg(EVENT_GAP.as_nanos().to_string())
            .arg(&timeout);
        let mut pong = program_pair::command(&prefix, self.program, pong_core.as_deref());
        pong.args(["pong", "pair", wait, &bytes, paced, &timeout]);
        let printed = program_pair::run("iceoryx", ping, pong, RUN_TIMEOUT)?;
        // The programs are gone before their RouDi.
        drop(roudi);

        let mut latency = Latency::new()?;
        // Only the figures: iceoryx may log on stdout too.
        for line in printed.ping.lines() {
            let Some(value) = line.strip_prefix("r ") else { continue };
            match value.trim().parse::<u64>() {
                Ok(ns) => latency.record_ns(ns),
                Err(_) => bail!("the iceoryx ping process printed {line:?}"),
            }
        }
        if latency.len() != self.samples {
            bail!(
                "the iceoryx ping process printed {} figures for {} samples",
                latency.len(),
                self.samples
            );
        }
        Ok(latency)
    }
}
