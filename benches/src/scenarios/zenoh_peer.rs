//! `zenoh-small` and `zenoh-image`: the structures of `esgm-small` and `esgm-image`
//! through Zenoh publish-subscribe with its shared-memory transport, process to
//! process.
//!
//! Zenoh (the crate `zenoh`, 1.x, features `shared-memory` and `unstable`) takes
//! several minutes to build on a two-core machine, so it is behind the cargo feature
//! `zenoh` of `esgm-benches`, off by default: without it both scenarios are reported
//! as skipped, with the command that runs them. What is measured is in
//! `zenoh_echo` (built with the feature only).

use super::ipc_esgm_image;
use super::ipc_esgm_small;
use super::ipc_payload::Kind;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Wait};
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
}

impl Zenoh {
    /// The small structure.
    pub const SMALL: Zenoh = Zenoh { name: "zenoh-small", kind: Kind::Small };
    /// The image.
    pub const IMAGE: Zenoh = Zenoh { name: "zenoh-image", kind: Kind::Image };

    fn esgm_row(&self) -> &'static str {
        match self.kind {
            Kind::Small => ipc_esgm_small::NAME,
            Kind::Image => ipc_esgm_image::NAME,
        }
    }
}

impl Scenario for Zenoh {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "the ~120-byte RobotState through Zenoh pub/sub with shared memory, process -> \
                 process (feature `zenoh`)"
            }
            Kind::Image => {
                "the 921,600-byte Image through Zenoh pub/sub with shared memory, process -> \
                 process (feature `zenoh`)"
            }
        }
    }

    #[cfg(feature = "zenoh")]
    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        super::zenoh_echo::measure(ctx, self.name, self.kind, self.esgm_row())
    }

    #[cfg(not(feature = "zenoh"))]
    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        ctx.skip(self.name, HOW);
        Ok(Vec::new())
    }

    /// esgm is to be faster than Zenoh at every size: Zenoh's row over esgm's ≥ 1.
    fn targets(&self) -> Vec<Target> {
        Wait::BOTH.iter().map(|&w| Target::at_least(self.name, self.esgm_row(), w, 1.0)).collect()
    }

    #[cfg(feature = "zenoh")]
    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        super::zenoh_echo::echo(role, self.kind)
    }

    #[cfg(not(feature = "zenoh"))]
    fn run_peer(&self, _role: &PeerRole) -> anyhow::Result<Vec<String>> {
        anyhow::bail!("{}: {HOW}", self.name)
    }
}
