//! The rows of a peer outside this project (ROS 1, dora, Zenoh, classic iceoryx), held
//! to an esgm row of the same payload.
//!
//! Every such peer is measured the same way: one row per wait, half a round trip, each
//! with an esgm row of that size as its baseline — esgm's own (`esgm-small`,
//! `esgm-image`, [`Kind::esgm_row`]) for most, with the target that esgm is the faster
//! at both waits; esgm from C++ (`cpp-small`, `cpp-image`) for a C peer. A peer failing
//! is a finding for the table, skipped with its error, not a reason to lose the rest of
//! the run.

use super::ipc_payload::Kind;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::Context;
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// One peer's rows (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct PeerRows<'a> {
    /// The rows' name (`ros1-small`, `dora-image`).
    pub name: &'static str,
    /// The esgm row of the same payload that the rows are compared with.
    pub baseline: &'static str,
    /// The payload's size in bytes, as the table shows it.
    pub bytes: usize,
    /// The peer's name in a skip's reason (`ROS 1`, `dora`).
    pub peer: &'a str,
    /// What the rows measure, beside them in the table.
    pub note: &'a str,
}

impl PeerRows<'_> {
    /// Runs `pair` once per wait and makes its rows; a failed pair is skipped with
    /// its error.
    pub fn measure(
        &self,
        ctx: &Context,
        mut pair: impl FnMut(WaitMode) -> anyhow::Result<Latency>,
    ) -> Vec<Measurement> {
        let mut rows = Vec::new();
        for mode in WaitMode::SPIN_AND_BLOCK {
            let latency = match pair(mode) {
                Ok(latency) => latency,
                Err(e) => {
                    let why = format!("the {} pair failed ({}): {e:#}", self.peer, mode.label());
                    ctx.skip(self.name, why);
                    continue;
                }
            };
            rows.push(
                latency
                    .measurement(self.name, mode.wait())
                    .payload_bytes(self.bytes as u64)
                    .method(Method::HalfRoundTrip)
                    .wait_strategy(mode.label())
                    .baseline(self.baseline)
                    .note(self.note),
            );
        }
        rows
    }
}

/// esgm is to be faster than the peer at every size: the peer's row `name` over
/// esgm's row of `kind` ≥ 1, at both waits.
pub fn faster_than(name: &'static str, kind: Kind) -> Vec<Target> {
    Wait::BOTH.iter().map(|&w| Target::at_least(name, kind.esgm_row(), w, 1.0)).collect()
}
