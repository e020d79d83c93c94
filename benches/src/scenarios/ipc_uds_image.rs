//! `uds-image`: the image of `esgm-image`, copied through a Unix socket.
//!
//! A 640×480 RGB `Image` made on the heap and encoded by the codec (the producer's
//! write, timed apart), then sent as bytes over a Unix-domain stream socket to a peer
//! process and back ([`super::ipc_uds_echo`]); each reader validates the bytes in its
//! own buffer and reads one pixel at each end. Compared with `esgm-image` at the same
//! wait: the target is that the socket copy takes tens of times longer (≥ 50×, the
//! benchmarks issue's figure).

use super::ipc_esgm_image;
use super::ipc_payload::Kind;
use super::ipc_uds_echo::{echo, ping_pong};
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Method};
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The scenario's name.
pub const NAME: &str = "uds-image";

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct UdsImage;

impl Scenario for UdsImage {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "the 921,600-byte Image's codec bytes over a Unix socket, process -> process: \
         two copies per hop"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        WaitMode::SPIN_AND_BLOCK
            .iter()
            .map(|&mode| {
                let run = ping_pong(ctx, NAME, Kind::Image, mode)?;
                Ok(run
                    .one_way
                    .measurement(NAME, mode.wait())
                    .payload_bytes(run.payload_bytes)
                    .method(Method::HalfRoundTrip)
                    .wait_strategy(mode.label())
                    .baseline(ipc_esgm_image::NAME)
                    .producer_write_p50_ns(run.write.quantile(0.5))
                    .note("the producer's write: make the image on the heap, encode it into the send buffer"))
            })
            .collect()
    }

    fn targets(&self) -> Vec<Target> {
        WaitMode::SPIN_AND_BLOCK
            .iter()
            .map(|m| Target::at_least(NAME, ipc_esgm_image::NAME, m.wait(), 50.0))
            .collect()
    }

    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        echo(role, Kind::Image)
    }
}
