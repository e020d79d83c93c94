//! `uds-small`: the small structure of `esgm-small`, copied through a Unix socket.
//!
//! The codec's bytes of a `RobotState` sent over a Unix-domain stream socket to a peer
//! process and back ([`super::ipc_uds_echo`]): the baseline a shared-memory transport
//! has to beat. `spin`: non-blocking reads, busy-polled; `event`: blocking reads. Its
//! blocking row is what esgm's default wait is held to (`esgm-small-default`).

use super::ipc_floor_iceoryx2;
use super::ipc_payload::Kind;
use super::ipc_uds_echo::{echo, ping_pong};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::{Context, Scenario};
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "uds-small";

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct UdsSmall;

impl Scenario for UdsSmall {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "the ~120-byte RobotState's codec bytes over a Unix socket, process -> process \
         (validated on receipt): the baseline"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        WaitMode::SPIN_AND_BLOCK
            .iter()
            .map(|&mode| {
                let run = ping_pong(ctx, NAME, Kind::Small, mode)?;
                Ok(run
                    .one_way
                    .measurement(NAME, mode.wait())
                    .payload_bytes(run.payload_bytes)
                    .method(Method::HalfRoundTrip)
                    .wait_strategy(mode.label())
                    .baseline(ipc_floor_iceoryx2::NAME))
            })
            .collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        echo(role, Kind::Small)
    }
}
