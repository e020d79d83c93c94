//! A worker's main loop: serve while the system lives, through coordinator crashes.
//!
//! The coordinator is a registry and a supervisor, not a part of the data path: a
//! worker's trajectories, its subscribers and the processes reading them exchange
//! samples over iceoryx2 without it. So a worker does not leave because the
//! coordinator stopped answering. It tells three cases apart:
//! - **slow**: the coordinator's service is there but an answer overstays its
//!   deadline (a busy machine). The worker keeps serving.
//! - **gone, the system kept**: no coordinator serves, but the domain's registry is
//!   kept on disk ([`crate::control::StateDir`]) — the coordinator crashed. The worker keeps
//!   serving and waits; a new `esgm up` takes over the control service this worker
//!   still holds, restores the registry, and the worker's control calls reach it
//!   again (re-attached, with nothing to re-register).
//! - **gone, the system stopped**: no coordinator and no registry (`esgm down`
//!   removes it). The worker leaves after `patience`.

use std::time::{Duration, Instant};

use super::ShmEsgm;
use crate::control::ControlClientError;
use crate::control::protocol::{Request, Response};
use crate::control::state::StateDir;

/// How often a serving worker looks at its coordinator.
pub const CHECK_EVERY: Duration = Duration::from_millis(250);

/// What a worker sees of its coordinator.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CoordinatorSight {
    /// It answered.
    Serving,
    /// Its service is there but the answer is late (or this process's location
    /// thread is busy with another slow call).
    Slow(String),
    /// Nobody serves the domain.
    Gone(String),
}

/// Asks the coordinator of `esgm`'s system for a sign of life. `known_pid` is the
/// coordinator's pid from its last answer, updated here: a late answer from a
/// coordinator whose process is gone is no answer to wait for (a coordinator killed
/// with `-9` leaves its server port behind until someone cleans it up, so its
/// service still looks served).
pub fn look(esgm: &ShmEsgm, known_pid: &mut Option<u32>) -> CoordinatorSight {
    match esgm.control(Request::Ping) {
        Ok(Response::Pong { pid, .. }) => {
            *known_pid = Some(pid).filter(|p| *p != 0);
            CoordinatorSight::Serving
        }
        Ok(other) => CoordinatorSight::Slow(format!("unexpected answer to a ping: {other:?}")),
        Err(
            e @ (ControlClientError::Timeout { .. }
            | ControlClientError::LocationUnavailable { .. }),
        ) => match *known_pid {
            Some(pid) if !crate::process::process_alive(pid) => {
                CoordinatorSight::Gone(format!("the coordinator (pid {pid}) has exited"))
            }
            _ => CoordinatorSight::Slow(e.to_string()),
        },
        Err(e) => CoordinatorSight::Gone(e.to_string()),
    }
}

/// Why [`serve_while_system_lives`] returned.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum Leaving {
    /// The system was stopped on purpose (no coordinator, no registry kept).
    SystemStopped,
}

/// Blocks while the system of `esgm` lives (see the module docs); returns once no
/// coordinator has served it for `patience` and its registry is no longer kept in
/// `state` (by default [`StateDir::from_env`] of the domain).
pub fn serve_while_system_lives(
    esgm: &ShmEsgm,
    state: Option<&StateDir>,
    patience: Duration,
) -> Leaving {
    let own;
    let state = match state {
        Some(s) => Some(s),
        None => match StateDir::from_env(esgm.domain()) {
            Ok(s) => {
                own = s;
                Some(&own)
            }
            Err(e) => {
                tracing::warn!(error = %e, "no state directory; leaving when the coordinator is gone");
                None
            }
        },
    };
    let mut gone_since: Option<Instant> = None;
    let mut last = CoordinatorSight::Serving;
    let mut coordinator_pid = None;
    loop {
        std::thread::sleep(CHECK_EVERY);
        let sight = look(esgm, &mut coordinator_pid);
        match (&last, &sight) {
            (CoordinatorSight::Serving, CoordinatorSight::Slow(why)) => {
                tracing::warn!(reason = %why, "the coordinator is slow; serving on");
            }
            (_, CoordinatorSight::Gone(why)) if !matches!(last, CoordinatorSight::Gone(_)) => {
                tracing::warn!(reason = %why, "the coordinator is gone; serving on");
            }
            (CoordinatorSight::Slow(_) | CoordinatorSight::Gone(_), CoordinatorSight::Serving) => {
                tracing::info!("the coordinator answers again");
            }
            _ => {}
        }
        match &sight {
            CoordinatorSight::Gone(_) => {
                let kept = state.is_some_and(StateDir::has_registry);
                let since = *gone_since.get_or_insert_with(Instant::now);
                if !kept && since.elapsed() >= patience {
                    return Leaving::SystemStopped;
                }
                if kept {
                    // Crashed, not stopped: wait for the next coordinator.
                    gone_since = Some(Instant::now());
                }
            }
            CoordinatorSight::Serving | CoordinatorSight::Slow(_) => gone_since = None,
        }
        last = sight;
    }
}
