//! `esgm-small`: one hop of a small structure between two processes through esgm-shm.
//!
//! A `RobotState` (about 120 bytes archived) encoded straight into loaned shared
//! memory ([`esgm_shm::TrajectoryPublisher::loan_structure`]), sent
//! ([`esgm_shm::StructureLoan::send`]) and received by a subscriber in another process,
//! validated in place ([`esgm_shm::ReceivedSample::structure`]); see
//! [`super::ipc_esgm_echo`] for the ping-pong. The hop starts when the structure is
//! complete in the loan, as the floor's starts when its message is written; the encode
//! is timed apart and reported beside. Three rows, one per wait of esgm's subscribers
//! ([`WaitMode`]):
//! - `esgm-small` / `spin`: [`esgm_shm::WaitStrategy::BusySpin`], against the raw
//!   iceoryx2 floor (target ≤ 1.5×);
//! - `esgm-small` / `event`: [`esgm_shm::WaitStrategy::Block`] on the trajectory's
//!   iceoryx2 event, against the floor blocking on its event (target ≤ 1.5×);
//! - `esgm-small-default` / `event`: the default strategy (spin, then block), against
//!   the blocking Unix socket (target ≤ 1×). Each hop starts after the event gap, so the
//!   peer has stopped spinning and sleeps when the ping comes: its wake-up is in every
//!   round trip; the reply, coming within the measuring side's spin, is not.
//!
//! - `esgm-small-publish` / `spin`: as `esgm-small` / `spin`, but every leg is a whole
//!   [`esgm_shm::TrajectoryPublisher::publish`] (loan, encode, send): what a producer
//!   that encodes at the moment of sending pays. No target; it shows the encode's
//!   share.
//!
//! The default row also reports what that strategy costs when nothing comes: the CPU
//! time of a thread waiting one second on an idle trajectory, in `wait_for_sample`
//! calls with 100 ms timeouts.

use std::time::Duration;

use anyhow::{Context as _, bail};
use esgm_shm::unstable::DEFAULT_SPIN;
use esgm_shm::{TrajectoryPublisher, TrajectorySubscriber, WaitStrategy, unique_domain};

use super::ipc_esgm_echo::{Encode, EsgmRun, echo, ping_pong};
use super::ipc_floor_iceoryx2;
use super::ipc_node::ipc_node;
use super::ipc_payload::Kind;
use super::ipc_uds_small;
use crate::cpu::{CpuUse, cpu_while};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, EVENT_GAP, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "esgm-small";

/// The row whose hops include the encode.
pub const PUBLISH_ROW: &str = "esgm-small-publish";

/// What the hop of the target rows starts from.
const ENCODED_BEFORE: &str = "encoded into the loan before the hop (loan_structure; the \
    producer write column); the hop is set_times + send + receive + validate + read";

/// How long the idle subscriber waits.
const IDLE_WINDOW: Duration = Duration::from_secs(1);
/// The timeout of each of its `wait_for_sample` calls.
const IDLE_TIMEOUT: Duration = Duration::from_millis(100);

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct EsgmSmall;

impl Scenario for EsgmSmall {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "~120-byte RobotState, process -> process through esgm-shm (validated in place); \
         busy, blocking and default waits"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let mut rows = Vec::new();
        for mode in WaitMode::ESGM {
            let run = ping_pong(ctx, NAME, (Kind::Small, Encode::Before), mode)?;
            let mut row = esgm_row(NAME, mode, &run)
                .producer_write_p50_ns(run.write.quantile(0.5))
                .note(ENCODED_BEFORE);
            if mode == WaitMode::SpinThenBlock {
                row = row.baseline(ipc_uds_small::NAME).note(default_note());
                let idle = idle_cpu()?;
                row = row.note(format!(
                    "idle: a subscriber with this default wait used {:.3} % of a core ({} µs CPU) \
                     waiting {} s on a silent trajectory ({} ms timeouts)",
                    idle.percent_of_a_core(),
                    idle.cpu.as_micros(),
                    IDLE_WINDOW.as_secs(),
                    IDLE_TIMEOUT.as_millis()
                ));
            } else {
                row = row.baseline(ipc_floor_iceoryx2::NAME);
            }
            rows.push(row);
        }
        let run = ping_pong(ctx, NAME, (Kind::Small, Encode::InHop), WaitMode::Spin)?;
        rows.push(
            esgm_row(PUBLISH_ROW, WaitMode::Spin, &run)
                .baseline(ipc_floor_iceoryx2::NAME)
                .note("each leg a whole publish: loan, encode into the loan, send"),
        );
        Ok(rows)
    }

    fn targets(&self) -> Vec<Target> {
        let default = WaitMode::SpinThenBlock.row_name(NAME);
        vec![
            Target::at_most(NAME, ipc_floor_iceoryx2::NAME, Wait::Spin, 1.5),
            Target::at_most(NAME, ipc_floor_iceoryx2::NAME, Wait::Event, 1.5),
            Target::at_most(&default, ipc_uds_small::NAME, Wait::Event, 1.0),
        ]
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        echo(role, Kind::Small)
    }
}

/// The row of an esgm ping-pong, with the peer's notes (shared with `esgm-image`).
pub fn esgm_row(scenario: &str, mode: WaitMode, run: &EsgmRun) -> Measurement {
    let mut row = run
        .one_way
        .measurement(&mode.row_name(scenario), mode.wait())
        .payload_bytes(run.payload_bytes)
        .method(Method::HalfRoundTrip)
        .wait_strategy(mode.label());
    for note in &run.peer_notes {
        row = row.note(format!("peer: {note}"));
    }
    row
}

/// What the `-default` rows are.
pub fn default_note() -> String {
    format!(
        "esgm's default WaitStrategy: spin {} µs, then block on the iceoryx2 event; the \
         peer has gone to sleep when each ping comes ({} µs gap), the reply comes within the \
         measuring side's spin",
        DEFAULT_SPIN.as_micros(),
        EVENT_GAP.as_micros()
    )
}

/// CPU used by a default-strategy subscriber waiting on a trajectory nobody writes to.
fn idle_cpu() -> anyhow::Result<CpuUse> {
    let domain = unique_domain("esgm-bench-idle");
    let node = ipc_node()?;
    // A publisher that stays silent: the trajectory exists, as in a real program.
    let _silent = TrajectoryPublisher::builder("idle", Kind::Small.type_name())
        .domain(&domain)
        .create(&node)
        .context("could not create the idle trajectory")?;
    let subscriber = TrajectorySubscriber::builder("idle", Kind::Small.type_name())
        .domain(&domain)
        .wait_strategy(WaitStrategy::default())
        .create(&node)
        .context("could not subscribe to the idle trajectory")?;
    cpu_while(IDLE_WINDOW, || {
        if subscriber.wait_for_sample(IDLE_TIMEOUT).context("idle wait")?.is_some() {
            bail!("a sample arrived on the idle trajectory");
        }
        Ok(())
    })
}
