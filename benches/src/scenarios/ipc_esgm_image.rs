//! `esgm-image`: one hop of a 640×480 RGB image between two processes, never copied.
//!
//! The producer loans shared memory for the image
//! ([`esgm_shm::TrajectoryPublisher::loan_image`]) and writes every pixel into it, as a
//! camera would, then completes the archive around the pixels
//! ([`esgm_shm::ImageLoan::into_structure`]); that write is timed apart and reported
//! beside the hop. The hop starts when the structure is complete in the loaned slice
//! (it is only re-stamped with the sequence number and sent), and ends when the other process
//! holds the validated structure (in place, in shared memory) and has read one pixel at
//! each end. Same ping-pong and rows as `esgm-small` ([`super::ipc_esgm_echo`]), each
//! compared with `esgm-small` at the same wait: the target is ≤ 1.2×, i.e. the hop
//! does not grow with the image.

use super::ipc_esgm_echo::{Encode, echo, ping_pong};
use super::ipc_esgm_small::{self, default_note, esgm_row};
use super::ipc_payload::Kind;
use crate::peer_role::PeerRole;
use crate::report::Measurement;
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "esgm-image";

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct EsgmImage;

impl Scenario for EsgmImage {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "921,600-byte 640x480 RGB Image written in place into a loan, process -> process, \
         never copied; busy, blocking and default waits"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let mut rows = Vec::new();
        for mode in WaitMode::ESGM {
            let run = ping_pong(ctx, NAME, (Kind::Image, Encode::Before), mode)?;
            let n = run.one_way.len();
            let mut row = esgm_row(NAME, mode, &run)
                .baseline(&mode.row_name(ipc_esgm_small::NAME))
                .producer_write_p50_ns(run.write.quantile(0.5));
            row = row.note(if run.in_place == n {
                "pixels written in place in shared memory (loan + one write of every pixel + the archive around them), \
                 read there by the other process: never copied"
                    .to_owned()
            } else {
                format!("only {} of {n} images arrived marked as written in place", run.in_place)
            });
            if mode == WaitMode::SpinThenBlock {
                row = row.note(default_note());
            }
            rows.push(row);
        }
        Ok(rows)
    }

    fn targets(&self) -> Vec<Target> {
        WaitMode::ESGM
            .iter()
            .map(|m| {
                Target::at_most(&m.row_name(NAME), &m.row_name(ipc_esgm_small::NAME), m.wait(), 1.2)
            })
            .collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        echo(role, Kind::Image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::Wait;

    #[test]
    fn each_wait_is_compared_with_the_small_row_of_the_same_wait() {
        let targets = EsgmImage.targets();
        assert_eq!(targets.len(), 3);
        assert!(targets.iter().any(|t| t.row == "esgm-image-default"
            && t.baseline == "esgm-small-default"
            && t.wait == Wait::Event));
    }
}
