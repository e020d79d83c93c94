//! `why` across processes: the process that writes a trajectory answers it (only it
//! knows its producer's calls and its gate's drops), asked over the admin channel; a
//! writer that does not answer is itself the reason, and this process's replica says
//! the rest.

use esgm_core::esgm::{LookupError, Peer, Unreachable, Why};
use esgm_core::{Esgm, Time};

use super::ShmEsgm;
use super::admin::{AdminAnswer, AdminOp};
use super::mirrors::SharedMirrors;
use crate::control::{Request, Response};
use crate::process::process_alive;

/// How long `why` waits for a trajectory's writer to answer before it answers from
/// this process's replica and names the writer silent.
const WRITER_PATIENCE: std::time::Duration = std::time::Duration::from_secs(2);

/// Marks each input whose writer this process knows (it reads the input) as alive or
/// gone: the pid the registry recorded for the input's writer, checked here.
pub(crate) fn inputs_alive(why: &mut Why, mirrors: &SharedMirrors) {
    let mirrors = mirrors.lock();
    for input in &mut why.inputs {
        if mirrors.exports.contains_key(&input.trajectory) {
            input.writer_alive = Some(true);
        } else if let Some(import) = mirrors.imports.get(&input.trajectory) {
            let pid = import.lock().writer_pid();
            input.writer_alive = (pid != 0).then(|| process_alive(pid));
        }
    }
}

/// The state letter of process `pid` (`R`, `S`, `T` stopped, …), if it can be read.
fn process_state(pid: u32) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?.1.trim_start().chars().next()
}

impl ShmEsgm {
    /// [`Esgm::why`] across processes: asks the trajectory's writer; if it does not
    /// answer, answers from this process's replica and says the writer is gone (its
    /// recorded pid no longer runs) or silent.
    pub(crate) fn why_anywhere(&self, trajectory: &str, since: Time) -> Result<Why, LookupError> {
        // The name exists (or the seed's error, with a suggestion), and this process
        // reads it: the fallback answer is its replica's.
        self.get_entity_trajectory_structure(trajectory)?;
        let op = AdminOp::Why { trajectory: trajectory.to_owned(), since };
        // Only the writer answers with a `Why`: stop at it, and do not wait for every
        // process of the domain (one stopped would hold every `why` for the timeout).
        let written =
            |a: &super::admin::Answers| a.iter().any(|(_, a)| matches!(a, AdminAnswer::Why(_)));
        let timeout = self.inner.timeout.min(WRITER_PATIENCE);
        let (answers, _) = self
            .inner
            .admin
            .ask_until(op, timeout, written)
            .map_err(|e| LookupError::Unavailable { reason: e.into() })?;
        // What the registry says of the writer: who, its pid, and whether it changed.
        let record = match self
            .control(Request::GetEntityTrajectoryStructure { name: trajectory.to_owned() })
        {
            Ok(Response::Trajectory(record)) => Some(record),
            _ => None,
        };
        let writer_changed = record.as_ref().and_then(|r| r.writer_changed.clone());
        for (host, answer) in answers {
            match answer {
                AdminAnswer::Why(mut why) => {
                    why.writer_changed = writer_changed;
                    why.explain();
                    return Ok(*why);
                }
                AdminAnswer::Failed { reason } => {
                    let reason = Unreachable::refused(Peer::Processes, format!("{host}: {reason}"));
                    return Err(LookupError::Unavailable { reason });
                }
                _ => {}
            }
        }
        // No writer answered: what this process's replica holds, without the
        // producer's calls and the gate's drops, which only the writer knows.
        let mut why = self.inner.local.why_evidence(trajectory, since)?;
        why.worker = None;
        why.recent_calls.clear();
        why.drops.retain(|d| {
            !matches!(
                d.cause,
                esgm_core::DropCause::Violation(_) | esgm_core::DropCause::InvalidType
            )
        });
        let pid = record.as_ref().and_then(|r| r.port.map(|p| p.pid));
        let alive = pid.is_some_and(process_alive);
        why.writer_alive = Some(alive);
        why.writer_changed = writer_changed;
        inputs_alive(&mut why, &self.inner.mirrors);
        why.explain();
        if !self.history_received(trajectory) && why.last_added.is_none() {
            // An empty replica says nothing of a writer that never handed it over.
            why.reasons.retain(|r| r != "it has never produced");
            why.reasons.push(
                "what it holds is unknown here: its writer never handed its history over".into(),
            );
        }
        let silent = match pid.filter(|_| alive).map(process_state) {
            Some(Some('T' | 't')) => {
                Some("its writer process is stopped (a signal or a debugger holds it)")
            }
            Some(_) => {
                Some("its writer process runs but did not answer in time (stuck or overloaded)")
            }
            None => None,
        };
        if let Some(silent) = silent {
            why.reasons.insert(0, silent.into());
        }
        Ok(why)
    }
}
