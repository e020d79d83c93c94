//! `ros2-raw-*`, `ros2-export-*` and `ros2-import-*` (issue 25): esgm beside ROS 2,
//! against a raw DDS hop on the same DDS crate, in the same run.
//!
//! - `ros2-raw-small` / `ros2-raw-image`: a ROS 2 publisher in one process until a
//!   ROS 2 subscriber in another has read the message, both on `ros2-client`
//!   (RustDDS), the crate `esgm-ros2` is built on, with its QoS (reliable, keep last
//!   10, volatile): the floor of the bridge rows;
//! - `ros2-export-small` / `-image`: an `add` in esgm (this process, connected to a
//!   domain) until a ROS 2 subscriber in another process has read the message, through
//!   `esgm-ros2 --export` (its esgm subscription, the conversion, a DDS publish);
//! - `ros2-import-small` / `-image`: a ROS 2 publisher in another process until an
//!   esgm subscription (this process, `connect`) returned the structure and it was read,
//!   through `esgm-ros2 --import` (a DDS take, the conversion, an add, the image's
//!   pixels written once into the trajectory's shared memory).
//!
//! Small is the `RobotState` as a `geometry_msgs/msg/Pose2D`, image a 640×480 `rgb8`
//! `sensor_msgs/msg/Image`, as `esgm ros2` maps them. Target: each bridge row ≤ 1.5×
//! the raw row of its size at the same wait (the p50s of the same run).
//!
//! **Waits.** `spin`: the receiving end busy-polls (`Subscription::take` in a loop on
//! the DDS side, `try_recv` on the esgm side); `event`: it blocks (a mio `Poll` on the
//! DDS subscription, `recv_timeout` on the esgm one). The bridge waits as it always
//! does, whatever the row: its import blocks in a mio `Poll`, its export in
//! `recv_timeout`. RustDDS's own threads (its event loop, which receives the UDP
//! datagrams) block on sockets in every row: DDS offers no busy-wait of its own.
//!
//! **Timing.** One way, on the host's system clock ([`crate::report::Method::SystemClock`]): stamped
//! where the hop starts and where it ends, in two processes; the next message is sent
//! once the last one was read. Under `--pin` the sending and the receiving end are on
//! the two cores, the bridge free to run on both.
//!
//! **Network.** DDS discovery is multicast, so every DDS participant — the DDS ends and
//! `esgm-ros2` — runs inside a network namespace the row makes, whose only interface
//! is its own loopback (the tests' `netns` helper); this process stays outside and reaches
//! `esgm-ros2` through shared memory, which network namespaces do not separate. No
//! namespace (not root, no `ip`): the rows are reported as not run, with the reason;
//! DDS never runs in the host's namespace.
//!
//! DDS is behind the cargo feature `ros2` of `esgm-benches` (its crates take minutes
//! to build); the bridge rows also need the `esgm-ros2` binary beside `esgm-bench`.
//! Without either, the rows are reported as not run with the command that runs them.

use super::ipc_payload::Kind;
use crate::peer_role::PeerRole;
use crate::report::{Measurement, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// What to run to measure the ROS 2 rows.
pub const HOW: &str = "built without the `ros2` feature (cargo build --release -p esgm-ros2 && \
                       cargo run --release -p esgm-benches --features ros2 --bin esgm-bench -- \
                       --only ros2-)";

/// Which way a row's message goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// DDS publisher process → DDS subscriber process.
    Raw,
    /// esgm `add` → `esgm-ros2 --export` → DDS subscriber process.
    Export,
    /// DDS publisher process → `esgm-ros2 --import` → esgm subscription.
    Import,
}

/// One row pair (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Ros2 {
    name: &'static str,
    kind: Kind,
    path: Path,
}

impl Ros2 {
    /// The raw DDS hop, small.
    pub const RAW_SMALL: Ros2 = Ros2 { name: "ros2-raw-small", kind: Kind::Small, path: Path::Raw };
    /// The raw DDS hop, image.
    pub const RAW_IMAGE: Ros2 = Ros2 { name: "ros2-raw-image", kind: Kind::Image, path: Path::Raw };
    /// esgm to a ROS 2 subscriber, small.
    pub const EXPORT_SMALL: Ros2 =
        Ros2 { name: "ros2-export-small", kind: Kind::Small, path: Path::Export };
    /// esgm to a ROS 2 subscriber, image.
    pub const EXPORT_IMAGE: Ros2 =
        Ros2 { name: "ros2-export-image", kind: Kind::Image, path: Path::Export };
    /// A ROS 2 publisher to esgm, small.
    pub const IMPORT_SMALL: Ros2 =
        Ros2 { name: "ros2-import-small", kind: Kind::Small, path: Path::Import };
    /// A ROS 2 publisher to esgm, image.
    pub const IMPORT_IMAGE: Ros2 =
        Ros2 { name: "ros2-import-image", kind: Kind::Image, path: Path::Import };

    /// The raw row of the same size: the baseline of a bridge row.
    fn raw_row(&self) -> &'static str {
        match self.kind {
            Kind::Small => Self::RAW_SMALL.name,
            Kind::Image => Self::RAW_IMAGE.name,
        }
    }

    #[cfg(feature = "ros2")]
    fn rows(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        use crate::report::Method;

        let Some(runs) = super::ros2_hop::measure(ctx, self.name, self.kind, self.path)? else {
            return Ok(Vec::new());
        };
        let bytes = super::ros2_dds::cdr_bytes(self.kind)?;
        let path = match self.path {
            Path::Raw => {
                "DDS publisher process -> DDS subscriber process (ros2-client/RustDDS, UDP on \
                 the namespace's loopback)"
            }
            Path::Export => {
                "add in this process (esgm connect) -> esgm-ros2 --export (esgm subscription, \
                 conversion, DDS publish) -> DDS subscriber process"
            }
            Path::Import => {
                "DDS publisher process -> esgm-ros2 --import (DDS take, conversion, add into \
                 shared memory) -> esgm subscription in this process"
            }
        };
        let mut rows = Vec::new();
        for (mode, run) in runs {
            let mut row = run
                .one_way
                .measurement(self.name, mode.wait())
                .payload_bytes(bytes)
                .method(Method::SystemClock)
                .wait_strategy(mode.label())
                .if_empty("no message was held")
                .note(format!(
                    "{path}; the message's CDR is {bytes} bytes; every DDS participant in a \
                     loopback-only network namespace"
                ));
            if self.path != Path::Raw {
                row = row.baseline(self.raw_row());
            }
            for note in run.notes {
                row = row.note(note);
            }
            rows.push(row);
        }
        Ok(rows)
    }

    #[cfg(not(feature = "ros2"))]
    fn rows(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        ctx.skip(self.name, HOW);
        Ok(Vec::new())
    }
}

impl Scenario for Ros2 {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match (self.path, self.kind) {
            (Path::Raw, Kind::Small) => {
                "Pose2D, ROS 2 publisher process -> ROS 2 subscriber process on ros2-client \
                 (DDS in a loopback-only netns; feature `ros2`)"
            }
            (Path::Raw, Kind::Image) => {
                "640x480 rgb8 sensor_msgs Image, ROS 2 publisher process -> ROS 2 subscriber \
                 process on ros2-client (DDS in a netns; feature `ros2`)"
            }
            (Path::Export, Kind::Small) => {
                "RobotState add in esgm -> esgm-ros2 --export -> ROS 2 subscriber process \
                 (Pose2D; feature `ros2`)"
            }
            (Path::Export, Kind::Image) => {
                "640x480 Image add in esgm -> esgm-ros2 --export -> ROS 2 subscriber process \
                 (feature `ros2`)"
            }
            (Path::Import, Kind::Small) => {
                "Pose2D from a ROS 2 publisher process -> esgm-ros2 --import -> esgm \
                 subscription (feature `ros2`)"
            }
            (Path::Import, Kind::Image) => {
                "640x480 rgb8 Image from a ROS 2 publisher process -> esgm-ros2 --import -> \
                 esgm subscription (feature `ros2`)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        self.rows(ctx)
    }

    /// Through the bridge within 1.5 × the raw DDS hop: p50 ≤ 1.5 × the raw row of the
    /// same size, at the same wait.
    fn targets(&self) -> Vec<Target> {
        if self.path == Path::Raw {
            return Vec::new();
        }
        Wait::BOTH.iter().map(|&w| Target::at_most(self.name, self.raw_row(), w, 1.5)).collect()
    }

    #[cfg(feature = "ros2")]
    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        super::ros2_dds::run_peer(role, self.kind)
    }

    #[cfg(not(feature = "ros2"))]
    fn run_peer(&self, _role: &PeerRole) -> anyhow::Result<Vec<String>> {
        anyhow::bail!("{}: {HOW}", self.name)
    }
}
