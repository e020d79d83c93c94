//! `zenoh-small` and `zenoh-image`: the structures of `esgm-small` and `esgm-image`
//! through Zenoh publish-subscribe with its shared-memory transport, process to
//! process.
//!
//! Zenoh (the crate `zenoh`, 1.x, features `shared-memory` and `unstable`) takes
//! several minutes to build on a two-core machine, so it is behind the cargo feature
//! `zenoh` of `esgm-benches`, off by default: without it both scenarios are reported
//! as skipped, with the command that runs them. What is measured is in
//! `zenoh_echo` (built with the feature only).

use super::ipc_payload::Kind;
use super::peer_rows::faster_than;
use crate::peer_role::PeerRole;
use crate::report::Measurement;
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// What to run to measure Zenoh.
pub const HOW: &str = "built without the `zenoh` feature (cargo run --release -p esgm-benches \
                       --features zenoh --bin esgm-bench)";

/// One payload through Zenoh (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Zenoh {
    name: &'static str,
    kind: Kind,
    /// Zenoh's shared-memory transport on; off, every payload crosses the TCP link.
    shm: bool,
}

impl Zenoh {
    /// The small structure.
    pub const SMALL: Zenoh = Zenoh { name: "zenoh-small", kind: Kind::Small, shm: true };
    /// The image.
    pub const IMAGE: Zenoh = Zenoh { name: "zenoh-image", kind: Kind::Image, shm: true };
    /// The small structure with shared memory off: what crosses between hosts (the
    /// bridge's baseline).
    pub const TCP_SMALL: Zenoh = Zenoh { name: "zenoh-tcp-small", kind: Kind::Small, shm: false };
    /// The image with shared memory off.
    pub const TCP_IMAGE: Zenoh = Zenoh { name: "zenoh-tcp-image", kind: Kind::Image, shm: false };
}

impl Scenario for Zenoh {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match (self.kind, self.shm) {
            (Kind::Small, false) => {
                "the ~120-byte RobotState through Zenoh pub/sub over loopback TCP, shared memory \
                 off, process -> process (feature `zenoh`)"
            }
            (Kind::Image, false) => {
                "the 921,600-byte Image through Zenoh pub/sub over loopback TCP, shared memory \
                 off, process -> process (feature `zenoh`)"
            }
            (Kind::Small, true) => {
                "the ~120-byte RobotState through Zenoh pub/sub with shared memory, process -> \
                 process (feature `zenoh`)"
            }
            (Kind::Image, true) => {
                "the 921,600-byte Image through Zenoh pub/sub with shared memory, process -> \
                 process (feature `zenoh`)"
            }
        }
    }

    #[cfg(feature = "zenoh")]
    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        super::zenoh_echo::measure(ctx, self.name, self.kind, self.kind.esgm_row(), self.shm)
    }

    #[cfg(not(feature = "zenoh"))]
    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        ctx.skip(self.name, HOW);
        Ok(Vec::new())
    }

    /// esgm is to be faster than Zenoh at every size: Zenoh's row over esgm's ≥ 1
    /// (with shared memory, as esgm's rows are; the TCP rows are the bridge's baseline).
    fn targets(&self) -> Vec<Target> {
        if !self.shm {
            return Vec::new();
        }
        faster_than(self.name, self.kind)
    }

    #[cfg(feature = "zenoh")]
    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        super::zenoh_echo::echo(role, self.kind, self.shm)
    }

    #[cfg(not(feature = "zenoh"))]
    fn run_peer(&self, _role: &PeerRole) -> anyhow::Result<Vec<String>> {
        anyhow::bail!("{}: {HOW}", self.name)
    }
}
