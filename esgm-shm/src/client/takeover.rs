//! Taking over a primitive trajectory whose writer is gone.
//!
//! A trajectory created through the API outlives its creator, as one made with
//! `esgm traj create` does. When the process that writes it exits (or closes its
//! connection) without destroying it, the next process that adds to it asks the
//! registry to write it ([`crate::control::protocol::Request::TakeOverTrajectory`]),
//! and its replica becomes the writer's store with the history it holds: readers
//! elsewhere receive a reset and that history from the new writer, and adds are
//! served again. Until then an add is refused with a typed error, never acknowledged
//! and lost.
//!
//! The adding thread asks; the location thread, which alone changes what this process
//! writes, carries it out ([`super::location::Location`]).

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Duration;

use crossbeam_channel::Sender;
use esgm_core::AddError;
use esgm_core::esgm::{Peer, Unreachable};

/// What a replica's adders know of its writer: the pid of the process that holds the
/// writer's port, and whether the writer is known to have let the trajectory go.
/// Shared by the import (which the location thread updates from the registry) and the
/// outbox (which reads it before each add).
#[derive(Debug, Default)]
pub(crate) struct WriterLiveness {
    /// The writer's pid, as the registry recorded it (0: not recorded yet).
    pid: AtomicU32,
    /// The writer released the trajectory (the registry says so), or its inbox was
    /// found without a reader: an add would reach nobody.
    released: AtomicBool,
}

impl WriterLiveness {
    /// Liveness of a writer whose pid the registry recorded as `pid` (0: none yet).
    pub fn new(pid: u32) -> Self {
        Self { pid: AtomicU32::new(pid), released: AtomicBool::new(false) }
    }

    /// The writer's pid as last recorded (0: none).
    pub fn pid(&self) -> u32 {
        self.pid.load(Ordering::Relaxed)
    }

    /// Records the writer's pid (0: none yet).
    pub fn set_pid(&self, pid: u32) {
        self.pid.store(pid, Ordering::Relaxed);
    }

    /// Records whether the writer let the trajectory go.
    pub fn set_released(&self, released: bool) {
        self.released.store(released, Ordering::Relaxed);
    }

    /// True if an add would reach nobody: the writer released the trajectory, or the
    /// process recorded as its writer is not alive. One `kill(pid, 0)` per call.
    pub fn gone(&self) -> bool {
        let pid = self.pid();
        self.released.load(Ordering::Relaxed) || (pid != 0 && !crate::process::process_alive(pid))
    }
}

/// An adding thread's request to the location thread: take `trajectory` (of
/// `generation`, the one this process mirrors) over, and answer on `reply`.
#[derive(Debug)]
pub(crate) struct TakeOverAsk {
    /// The trajectory.
    pub trajectory: String,
    /// The generation this process mirrors.
    pub generation: u64,
    /// Where the outcome goes.
    pub reply: Sender<Result<(), AddError>>,
}

/// How long an adding thread waits for the location thread to take a trajectory over:
/// a call to the coordinator and the opening of the writer's ports (which may clean up
/// after the dead writer first).
pub(crate) const TAKE_OVER_WAIT: Duration = Duration::from_secs(15);

/// Asks the location thread behind `location` to take `trajectory` over and waits for
/// its answer, at most [`TAKE_OVER_WAIT`].
pub(crate) fn ask(
    location: &Sender<TakeOverAsk>,
    trajectory: &str,
    generation: u64,
) -> Result<(), AddError> {
    let unavailable =
        |reason: Unreachable| AddError::Unavailable { trajectory: trajectory.to_owned(), reason };
    let (reply, answer) = crossbeam_channel::bounded(1);
    let ask = TakeOverAsk { trajectory: trajectory.to_owned(), generation, reply };
    location.send(ask).map_err(|_| unavailable(Unreachable::Closing))?;
    answer
        .recv_timeout(TAKE_OVER_WAIT)
        .map_err(|_| unavailable(Unreachable::no_answer(Peer::Connection, TAKE_OVER_WAIT)))?
}
