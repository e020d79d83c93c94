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

impl ShmEsgm {
    /// [`Esgm::why`] across processes: asks the trajectory's writer; if it does not
    /// answer, answers from this process's replica and says the writer is gone (its
    /// recorded pid no longer runs) or silent.
    pub(crate) fn why_anywhere(&self, trajectory: &str, since: Time) -> Result<Why, LookupError> {
        // The name exists (or the seed's error, with a suggestion), and this process
        // reads it: the fallback answer is its replica's.
        self.get_entity_trajectory_structure(trajectory)?;
        let op = AdminOp::Why { trajectory: trajectory.to_owned(), since };
        let answers = self
            .inner
            .admin
            .ask(op, self.inner.timeout)
            .map_err(|e| LookupError::Unavailable { reason: e.into() })?;
        for (host, answer) in answers {
            match answer {
                AdminAnswer::Why(why) => return Ok(*why),
                AdminAnswer::Failed { reason } => {
                    let reason = Unreachable::refused(Peer::Processes, format!("{host}: {reason}"));
                    return Err(LookupError::Unavailable { reason });
                }
                _ => {}
            }
        }
        let mut why = self.inner.local.why_here(trajectory, since)?;
        let pid = match self
            .control(Request::GetEntityTrajectoryStructure { name: trajectory.to_owned() })
        {
            Ok(Response::Trajectory(record)) => record.port.map(|p| p.pid),
            _ => None,
        };
        why.writer_alive = Some(pid.is_some_and(process_alive));
        inputs_alive(&mut why, &self.inner.mirrors);
        why.explain();
        if pid.is_some_and(process_alive) {
            why.reasons.insert(0, "its writer process runs but did not answer in time".into());
        }
        Ok(why)
    }
}
