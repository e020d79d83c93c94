//! `dora-small` and `dora-image` (issue 27): the payload sizes of `esgm-small` and
//! `esgm-image` through dora, the closest modern peer (a Rust dataflow with shared
//! memory), process to process, in the same run as esgm's rows.
//!
//! The peer is `benches/dora/`, one Rust node binary on `dora-node-api` with two roles,
//! built with the `dora` CLI (PyPI's `dora-rs-cli` of the same version) into a venv
//! by `benches/dora/build.sh`; without either, both rows are reported as skipped with
//! that instruction. When both are there, esgm-bench writes a two-node dataflow and
//! runs it with `dora run` ([`super::dora_run`]), dora's daemon in one process: the
//! `ping` node sends, the `pong` node answers, and ping measures half of each round
//! trip (the node's docs say exactly where a hop starts and ends) into a file this
//! process reads.
//!
//! dora 1.1 carries a node's output straight to the receiving node over Zenoh
//! (publishers declared `express`, real-time priority); the daemon spawns, connects and
//! supervises the nodes and is only the fallback for data. That is dora's default path,
//! and the one measured.
//! - Small is an Arrow `UInt8` array of the structure's encoded size; under dora's
//!   zero-copy threshold (4 KiB) it is sent as bytes in the Zenoh message.
//! - Image is 921,600 bytes, written by ping straight into dora's output sample (Zenoh
//!   shared memory) inside `send_output_raw`, the write untimed as in `esgm-image`; the pong
//!   answers with a fresh sample of the same size (dora cannot send a received sample
//!   on without a copy), only its sequence number and last byte written.
//! - The readers check the sequence number and last byte, read in place; they cannot
//!   validate an esgm archive. A lower bound for dora doing esgm's work.
//!
//! Waits: `spin` polls the node's event stream with `EventStream::try_recv` in both
//! nodes (dora's own threads that feed the stream still block on the daemon), `event`
//! blocks in `recv_timeout` after a 50 µs busy gap, as the esgm rows do. Under `--pin`
//! ping is on the measuring core, pong on the peer core (each node pins itself, since
//! dora starts them) and the daemon (`dora run`) may use both.

use std::path::PathBuf;

use anyhow::Context as _;

use super::dora_run::{self, Pair};
use super::ipc_payload::Kind;
use super::peer_rows::{PeerRows, faster_than};
use crate::report::Measurement;
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// The dora release measured: the CLI build.sh installs and the node's `dora-node-api`.
pub const VERSION: &str = "1.1.0";
/// What to run to measure dora.
pub const HOW: &str = "run benches/dora/build.sh (a venv with PyPI's dora-rs-cli 1.1.0 and \
                       the node on dora-node-api 1.1.0; or set ESGM_DORA and ESGM_DORA_NODE)";

/// One payload through dora (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Dora {
    name: &'static str,
    kind: Kind,
}

impl Dora {
    /// The small structure's size.
    pub const SMALL: Dora = Dora { name: "dora-small", kind: Kind::Small };
    /// The image's size.
    pub const IMAGE: Dora = Dora { name: "dora-image", kind: Kind::Image };

    fn bytes(&self) -> anyhow::Result<usize> {
        match self.kind {
            Kind::Small => esgm_core::codec::encoded_len(&self.kind.make(0)).context("sizing"),
            // The pixels alone, as esgm-image's headline size.
            Kind::Image => Ok(ipc_payload_pixels()),
        }
    }
}

fn ipc_payload_pixels() -> usize {
    use super::ipc_payload::{IMAGE_HEIGHT, IMAGE_WIDTH};
    (IMAGE_WIDTH * IMAGE_HEIGHT * 3) as usize
}

/// The workspace's target folder, where build.sh puts the venv and the node: the
/// `CARGO_TARGET_DIR` esgm-bench was built with, else `target` beside `benches`.
fn target_dir() -> PathBuf {
    option_env!("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"))
}

/// The `dora` CLI: `ESGM_DORA`, else the venv build.sh makes.
pub fn cli() -> Option<PathBuf> {
    let path = std::env::var_os("ESGM_DORA")
        .map_or_else(|| target_dir().join("bench-dora-venv/bin/dora"), PathBuf::from);
    path.is_file().then_some(path)
}

/// The node binary: `ESGM_DORA_NODE`, else where build.sh builds it.
pub fn node() -> Option<PathBuf> {
    let path = std::env::var_os("ESGM_DORA_NODE")
        .map_or_else(|| target_dir().join("dora/release/esgm-dora-pingpong"), PathBuf::from);
    path.is_file().then_some(path)
}

impl Scenario for Dora {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "~120 bytes through dora 1.1 (Rust nodes, `dora run`), process -> process \
                 (benches/dora/build.sh)"
            }
            Kind::Image => {
                "921,600 bytes written into dora 1.1's shared-memory sample, process -> \
                 process (benches/dora/build.sh)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let (Some(cli), Some(node)) = (cli(), node()) else {
            ctx.skip(self.name, HOW);
            return Ok(Vec::new());
        };
        let bytes = self.bytes()?;
        let (full, quick) = self.kind.samples();
        let samples = ctx.samples(full, quick);
        let warmup = ctx.warmup(samples);
        let cores = ctx.pinning().map(|p| (p.measuring_core(), p.peer_core()));
        let note = self.note();
        let rows = PeerRows {
            name: self.name,
            baseline: self.kind.esgm_row(),
            bytes,
            peer: "dora",
            note: &note,
        };
        Ok(rows.measure(ctx, |mode| {
            dora_run::run(&Pair { cli: &cli, node: &node, mode, bytes, samples, warmup, cores })
        }))
    }

    /// esgm is to be faster than its closest peer at every size: dora's row over
    /// esgm's ≥ 1.
    fn targets(&self) -> Vec<Target> {
        faster_than(self.name, self.kind)
    }
}

impl Dora {
    fn note(&self) -> String {
        let how = match self.kind {
            Kind::Small => "under dora's zero-copy threshold: bytes in the Zenoh message",
            Kind::Image => {
                "written in place into dora's shared-memory sample (send_output_raw), untimed; \
                 pong answers with a fresh sample, sequence and last byte written"
            }
        };
        format!(
            "dora {VERSION} (`dora run`, Rust nodes on dora-node-api, node to node over Zenoh), an Arrow UInt8 array; {how}; \
             the reader checks sequence and last byte in place, it cannot validate an esgm archive"
        )
    }
}
