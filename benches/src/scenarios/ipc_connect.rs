//! `connect-small` and `connect-image`: one hop between two processes through the API a
//! user calls, [`esgm_shm::ShmEsgm`] (`connect`), rather than the data plane under it
//! (`esgm-small`, `esgm-image`).
//!
//! - `connect-small`: a `RobotState` added in one process (`add` on a primitive
//!   trajectory it created) until a subscriber in the other process, connected too,
//!   holds it (its [`esgm_core::Subscription`] returned the sample and `x` was read);
//! - `connect-image`: a camera's 640×480 RGB `Image` (921,600 bytes of pixels, written
//!   into a fresh buffer before the timer, as a camera renders a frame) added in one
//!   process until a subscriber in the other has read a pixel at each end. The pixels
//!   arrive as an [`esgm_core::Octets`] held in shared memory; the rows say how many
//!   were.
//!
//! Two rows each ([`super::ipc_connect_echo`] has the ping-pong): `spin`, both
//! subscribers polling `try_recv`, and `event`, both blocking in `recv_timeout`. `event`
//! is what a user gets: `connect` has no wait strategy to choose, so there is no
//! `-default` row. `connect-small-paced` is `connect-small` with each hop after the
//! `ready`/`done` exchange the image's hops wait for (a camera's pace rather than back
//! to back). Targets, as ratios of rows of the same run: `connect-small` within 2×
//! `esgm-small` at the same wait (what the API adds to the data plane),
//! `connect-image` within 1.2× `connect-small-paced` (pixels are not copied on the way), and
//! `connect-small` (`event`) faster than ROS 1 and Zenoh (`event`), which are reported
//! as not run when their peers are not built.
//!
//! Under `--pin` every thread of a process — the subscriber, the threads `connect`
//! starts and, in the measuring process, the coordinator's — runs on that process's
//! core: what a user's pinned process would get.

use super::ipc_connect_echo::{CACHE, ConnectRun, History, echo, ping_pong};
use super::ipc_esgm_small;
use super::ipc_payload::Kind;
use super::{ros1_peer, zenoh_peer};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The name of the small structure's scenario.
pub const SMALL_NAME: &str = "connect-small";
/// The name of the image's scenario.
pub const IMAGE_NAME: &str = "connect-image";
/// The name of the small structure's scenario paced as the image's.
pub const SMALL_PACED_NAME: &str = "connect-small-paced";
/// `connect-small` on volatile trajectories: what keeping the history costs a hop.
pub const SMALL_VOLATILE_NAME: &str = "connect-small-volatile";
/// `connect-image` on volatile trajectories.
pub const IMAGE_VOLATILE_NAME: &str = "connect-image-volatile";

/// One payload through `connect` (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Connect {
    name: &'static str,
    kind: Kind,
    /// Each hop after the `ready`/`done` exchange, as a camera's frames
    /// ([`super::ipc_connect_echo`]).
    paced: bool,
    /// Whether the trajectories keep their history beyond their writer.
    history: History,
}

impl Connect {
    /// The small structure, back to back.
    pub const SMALL: Connect =
        Connect { name: SMALL_NAME, kind: Kind::Small, paced: false, history: History::Kept };
    /// The small structure, paced as the image.
    pub const SMALL_PACED: Connect =
        Connect { name: SMALL_PACED_NAME, kind: Kind::Small, paced: true, history: History::Kept };
    /// The image.
    pub const IMAGE: Connect =
        Connect { name: IMAGE_NAME, kind: Kind::Image, paced: true, history: History::Kept };
    /// The small structure, back to back, on volatile trajectories.
    pub const SMALL_VOLATILE: Connect = Connect {
        name: SMALL_VOLATILE_NAME,
        kind: Kind::Small,
        paced: false,
        history: History::Volatile,
    };
    /// The image on volatile trajectories.
    pub const IMAGE_VOLATILE: Connect = Connect {
        name: IMAGE_VOLATILE_NAME,
        kind: Kind::Image,
        paced: true,
        history: History::Volatile,
    };

    /// The scenario each row is compared with (same wait).
    fn baseline(&self) -> &'static str {
        match (self.kind, self.paced, self.history) {
            // The kept row, which the targets hold to its volatile one.
            (Kind::Small, _, History::Volatile) => SMALL_NAME,
            (Kind::Image, _, History::Volatile) => IMAGE_NAME,
            (Kind::Small, false, History::Kept) => ipc_esgm_small::NAME,
            (Kind::Small, true, History::Kept) => SMALL_NAME,
            (Kind::Image, _, History::Kept) => SMALL_PACED_NAME,
        }
    }

    fn row(&self, mode: WaitMode, run: &ConnectRun, payload_bytes: u64) -> Measurement {
        let how = match mode {
            WaitMode::Spin => {
                "both subscribers poll Subscription::try_recv in a loop (a sample reaches a \
                 subscription through a thread connect runs in each process, which a spinning \
                 subscriber competes with for a core)"
            }
            WaitMode::Block | WaitMode::SpinThenBlock => {
                "both subscribers block in Subscription::recv_timeout: what a user of connect \
                 gets (connect has no wait strategy to choose)"
            }
        };
        let mut row = run
            .one_way
            .measurement(&mode.row_name(self.name), mode.wait())
            .payload_bytes(payload_bytes)
            .method(Method::HalfRoundTrip)
            .wait_strategy(mode.label())
            .baseline(self.baseline())
            .producer_write_p50_ns(run.write.quantile(0.5))
            .if_empty("no reply was measured")
            .note(format!(
                "each leg: add in one connected process -> the Sample held by a subscriber in \
                 the other; {how}; primitive trajectories with a cache of {CACHE}, {}; \
                 coordinator on a thread of the measuring process",
                match self.history {
                    History::Kept => "their history kept beyond their writer (the default)",
                    History::Volatile => "volatile (their history is not kept beyond the writer)",
                }
            ));
        if self.kind == Kind::Image {
            row = row.note(format!(
                "{} of {} replies' pixels read in place in shared memory (held), {} copied onto \
                 the reader's heap",
                run.held,
                run.replies,
                run.replies - run.held
            ));
        }
        row = row.note(format!(
            "{} of {} pings sent without the iceoryx2 notify (the peer's connection covered \
             by its thread asleep on the trajectory's word, so its receiver thread was not \
             woken)",
            run.notifies_spared, run.replies
        ));
        for note in &run.peer_notes {
            row = row.note(format!("peer: {note}"));
        }
        row
    }
}

impl Scenario for Connect {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        if self.history == History::Volatile {
            return match self.kind {
                Kind::Small => {
                    "connect-small on volatile trajectories: the history is not kept beyond the \
                     writer, so the pair says what keeping costs a hop"
                }
                Kind::Image => {
                    "connect-image on volatile trajectories: the pair says what keeping an \
                     image costs a hop (the pixels are encoded into the kept history)"
                }
            };
        }
        match (self.kind, self.paced) {
            (Kind::Small, false) => {
                "~120-byte RobotState, add in one connected process -> subscriber in another \
                 (esgm_shm connect on both sides); busy and blocking waits"
            }
            (Kind::Small, true) => {
                "connect-small paced as connect-image: each hop after the same ready/done \
                 exchange a camera's frame waits for; busy and blocking waits"
            }
            (Kind::Image, _) => {
                "921,600-byte 640x480 RGB Image, add in one connected process -> subscriber in \
                 another reads a pixel at each end (connect on both sides); busy and blocking"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let payload_bytes = esgm_core::codec::encoded_len(&self.kind.make(0))? as u64;
        let mut rows = Vec::new();
        for mode in WaitMode::SPIN_AND_BLOCK {
            let run = ping_pong(ctx, self.name, (self.kind, self.history), self.paced, mode)?;
            rows.push(self.row(mode, &run, payload_bytes));
        }
        Ok(rows)
    }

    fn targets(&self) -> Vec<Target> {
        if self.history == History::Volatile {
            // Keeping the history costs a small hop at most a tenth, an image's a fifth:
            // said of this row, which runs after the kept one, as volatile / kept.
            let (kept, limit) = match self.kind {
                Kind::Small => (SMALL_NAME, 1.1),
                Kind::Image => (IMAGE_NAME, 1.2),
            };
            return Wait::BOTH
                .iter()
                .map(|&w| Target::at_least(self.name, kept, w, 1.0 / limit))
                .collect();
        }
        match (self.kind, self.paced) {
            // Shown beside its back-to-back row; the image's row is held to it.
            (Kind::Small, true) => Vec::new(),
            (Kind::Small, false) => {
                let mut targets: Vec<Target> = Wait::BOTH
                    .iter()
                    .map(|&w| Target::at_most(SMALL_NAME, ipc_esgm_small::NAME, w, 2.0))
                    .collect();
                for peer in [ros1_peer::Ros1::SMALL.name(), zenoh_peer::Zenoh::SMALL.name()] {
                    targets.push(Target::at_most(SMALL_NAME, peer, Wait::Event, 1.0));
                }
                targets
            }
            (Kind::Image, _) => Wait::BOTH
                .iter()
                .map(|&w| Target::at_most(IMAGE_NAME, SMALL_PACED_NAME, w, 1.2))
                .collect(),
        }
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        echo(role, (self.kind, self.history), self.paced)
    }
}
