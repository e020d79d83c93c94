//! `--pin`: the measuring thread on one core, its peers on another.
//!
//! Pinning removes migrations and makes a cross-core hop really cross-core, so runs
//! compare; without it the scheduler places threads as it likes (what an unpinned
//! robot program gets). The first two cores the OS reports are used (0 and 1 on a
//! two-core machine). A peer *process* is pinned to the peer core too.

use std::cell::Cell;

use anyhow::{Context as _, bail};
use core_affinity::CoreId;

thread_local! {
    /// The core this thread was pinned to by [`Pinning::pin_peer_thread_once`].
    static PINNED_TO: Cell<Option<usize>> = const { Cell::new(None) };
}

/// The two cores of a pinned run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pinning {
    measuring: CoreId,
    peer: CoreId,
}

impl Pinning {
    /// The first two cores of this machine.
    pub fn detect() -> anyhow::Result<Self> {
        let cores =
            core_affinity::get_core_ids().context("--pin: could not list this machine's cores")?;
        match cores.as_slice() {
            [measuring, peer, ..] => Ok(Self { measuring: *measuring, peer: *peer }),
            _ => bail!("--pin needs two cores; this machine reports {}", cores.len()),
        }
    }

    /// The core of the thread that times (core 0 on a two-core machine).
    pub fn measuring_core(&self) -> usize {
        self.measuring.id
    }

    /// The core of its peers: echo threads, unit and sampler workers.
    pub fn peer_core(&self) -> usize {
        self.peer.id
    }

    /// Pins the calling thread to the measuring core.
    pub fn pin_measuring_thread(&self) -> anyhow::Result<()> {
        pin(self.measuring)
    }

    /// Pins the calling thread to the peer core.
    pub fn pin_peer_thread(&self) -> anyhow::Result<()> {
        pin(self.peer)
    }

    /// Pins the calling thread to the peer core unless that was done already: for
    /// threads the runtime starts (unit and sampler workers), pinned from inside the
    /// user code they call, on its first call.
    pub fn pin_peer_thread_once(&self) -> anyhow::Result<()> {
        if PINNED_TO.get() == Some(self.peer.id) {
            return Ok(());
        }
        self.pin_peer_thread()?;
        PINNED_TO.set(Some(self.peer.id));
        Ok(())
    }
}

/// Pins the calling thread to core `id`: for a peer process, which is told its core
/// (see [`crate::peer_role::PeerRole::core`]).
pub fn pin_to_core(id: usize) -> anyhow::Result<()> {
    pin(CoreId { id })
}

fn pin(core: CoreId) -> anyhow::Result<()> {
    if core_affinity::set_for_current(core) {
        Ok(())
    } else {
        bail!("could not pin a thread to core {}", core.id)
    }
}
