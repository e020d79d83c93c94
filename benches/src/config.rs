//! The validated settings of one `esgm-bench` run.

use std::path::PathBuf;

use crate::peer_role::PeerRole;
use crate::pin::Pinning;

/// What to run and how, checked (see [`crate::args::Args::into_config`]).
#[derive(Debug, Clone, Default)]
pub struct RunConfig {
    /// Fewer samples: the whole run takes under a minute.
    pub quick: bool,
    /// Where to write the JSON report, if anywhere.
    pub json: Option<PathBuf>,
    /// Where to draw the PNG charts, if anywhere.
    pub plots: Option<PathBuf>,
    /// The cores to pin to, if pinning.
    pub pin: Option<Pinning>,
    /// Only scenarios whose name contains this.
    pub only: Option<String>,
    /// Samples per scenario and wait strategy, overriding the defaults.
    pub samples: Option<u64>,
    /// List the scenarios instead of running them.
    pub list: bool,
    /// The CPU latency held for the run (`--cpu-latency`), if any.
    pub cpu_latency: Option<std::time::Duration>,
    /// Run as the peer process of a cross-process scenario instead of measuring.
    pub peer: Option<PeerRole>,
}
