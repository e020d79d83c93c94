//! `cpp-small` and `cpp-image` (issue 37): the hops of `connect-small` and
//! `connect-image`, made by two C++ processes through esgm's C ABI (`esgm.h`,
//! `libesgm_c`) instead of two Rust ones through [`esgm_shm::ShmEsgm`]. What a C++
//! camera driver or controller pays for esgm, next to what a Rust one pays.
//!
//! The program is `benches/cpp/cpp_pingpong.cpp`, built on first use against the C
//! ABI's library of this build ([`super::cpp_program`]); without a C++ compiler the rows
//! are skipped with that reason. It mirrors [`super::ipc_connect_echo`] step for step:
//! the same trajectories (primitive, a cache of [`CACHE`] samples, created by the
//! process that writes them), the same structures (a `RobotState`; a 640×480 RGB
//! `Image` written into a loan of the trajectory's shared memory, its pixels read at
//! each end and checked by the reader), the same start-up, the same `ready`/`done`
//! pacing of the image's hops, and the same waits: `spin` polls
//! `esgm_subscription_recv` with a timeout of 0, `event` blocks in it. The
//! measuring side is the program's `ping` process, which times half of each round trip
//! and prints its figures for this process to collect; `esgm-bench` runs the
//! coordinator on a thread of its own, as the `connect` rows do (there the measuring
//! process holds it; here it is a third process, which only the control plane uses).
//!
//! Not in these rows: the `connect` rows' count of notifies spared, a counter of the
//! Rust process (`esgm_shm::publisher`) that the C ABI does not expose.
//!
//! Target (issue 37): each row within 1.2× its `connect` row at the same wait. A row
//! whose pair fails is reported as failed with the reason, and the run goes on.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context as _, bail};
use esgm_core::TypeRegistry;
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect;
use super::ipc_connect_echo::CACHE;
use super::ipc_payload::Kind;
use super::{cpp_program, program_pair};
use crate::domain_end::DomainEnd;
use crate::latency::Latency;
use crate::patience::PEER_TIMEOUT;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, EVENT_GAP, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// The name of the small structure's scenario.
pub const SMALL_NAME: &str = "cpp-small";
/// The name of the image's scenario.
pub const IMAGE_NAME: &str = "cpp-image";
/// How long one pair may take (a full image run in a debug build takes minutes).
const RUN_TIMEOUT: Duration = Duration::from_secs(900);
/// The most one row may take over its `connect` row (issue 37).
const TARGET_RATIO: f64 = 1.2;

/// One payload through the C ABI (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Cpp {
    name: &'static str,
    kind: Kind,
    /// Each hop after the `ready`/`done` exchange, as `connect-image`'s.
    paced: bool,
}

impl Cpp {
    /// The small structure, back to back, as `connect-small`.
    pub const SMALL: Cpp = Cpp { name: SMALL_NAME, kind: Kind::Small, paced: false };
    /// The image, paced, as `connect-image`.
    pub const IMAGE: Cpp = Cpp { name: IMAGE_NAME, kind: Kind::Image, paced: true };

    /// The row each is held to (same wait).
    fn baseline(&self) -> &'static str {
        match self.kind {
            Kind::Small => ipc_connect::SMALL_NAME,
            Kind::Image => ipc_connect::IMAGE_NAME,
        }
    }

    fn row(&self, mode: WaitMode, run: &CppRun, payload_bytes: u64) -> Measurement {
        let how = match mode {
            WaitMode::Spin => {
                "both subscribers poll esgm_subscription_recv with a timeout of 0 in a loop \
                 (a sample reaches a subscription through a thread the library runs in each \
                 process, which a spinning subscriber competes with for a core)"
            }
            WaitMode::Block | WaitMode::SpinThenBlock => {
                "both subscribers block in esgm_subscription_recv with a timeout (20 ms, in a \
                 loop)"
            }
        };
        let mut row = run
            .one_way
            .measurement(self.name, mode.wait())
            .payload_bytes(payload_bytes)
            .method(Method::HalfRoundTrip)
            .wait_strategy(mode.label())
            .baseline(self.baseline())
            .producer_write_p50_ns(run.write.quantile(0.5))
            .if_empty("no reply was measured")
            .note(format!(
                "each leg: esgm_add in one C++ process -> the esgm_sample_t held by a \
                 subscriber in the other (the C ABI on both sides, statically linked \
                 libesgm_c of this build, -O2); {how}; primitive trajectories with a cache of \
                 {CACHE}; coordinator on a thread of esgm-bench, a third process"
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
        for note in &run.peer_notes {
            row = row.note(format!("peer: {note}"));
        }
        row
    }

    /// A row whose pair failed: no samples, the reason.
    fn failed(&self, mode: WaitMode, error: &anyhow::Error) -> anyhow::Result<Measurement> {
        Ok(Latency::new()?
            .measurement(self.name, mode.wait())
            .wait_strategy(mode.label())
            .baseline(self.baseline())
            .if_empty(format!("the C++ pair failed: {error:#}")))
    }
}

impl Scenario for Cpp {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "connect-small from C++: ~120-byte RobotState, esgm_add in one C++ process -> \
                 subscriber in another, through the C ABI; busy and blocking waits"
            }
            Kind::Image => {
                "connect-image from C++: 640x480 RGB Image written into a loan, esgm_add -> a \
                 C++ subscriber reads a pixel at each end, through the C ABI; busy and blocking"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let program = match cpp_program::program() {
            Ok(program) => program,
            Err(e) => {
                ctx.skip(self.name, format!("{e:#}"));
                return Ok(Vec::new());
            }
        };
        let payload_bytes = esgm_core::codec::encoded_len(&self.kind.make(0))? as u64;
        let mut rows = Vec::new();
        for mode in WaitMode::SPIN_AND_BLOCK {
            rows.push(match pair(ctx, &program, self.kind, self.paced, mode) {
                Ok(run) => self.row(mode, &run, payload_bytes),
                Err(e) => self.failed(mode, &e)?,
            });
        }
        Ok(rows)
    }

    fn targets(&self) -> Vec<Target> {
        Wait::BOTH
            .iter()
            .map(|&w| Target::at_most(self.name, self.baseline(), w, TARGET_RATIO))
            .collect()
    }
}

/// What one pair measured.
#[derive(Debug)]
struct CppRun {
    /// One-way latency (half round trips).
    one_way: Latency,
    /// Time ping took to make each structure before its hop.
    write: Latency,
    /// Replies measured.
    replies: u64,
    /// Replies whose pixels ping read in shared memory.
    held: u64,
    /// What pong reported.
    peer_notes: Vec<String>,
}

/// Runs one pair with `mode` in both processes, in a domain of its own whose
/// coordinator runs on a thread of this process.
fn pair(
    ctx: &Context,
    program: &Path,
    kind: Kind,
    paced: bool,
    mode: WaitMode,
) -> anyhow::Result<CppRun> {
    let (full, quick) = kind.samples();
    let samples = ctx.samples(full, quick);
    let warmup = ctx.warmup(samples);
    // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let domain = unique_domain("esgm-bench-cpp");
    // Dropped after every process of the domain: removes its futex words, which a
    // program killed on a failure would leave in /dev/shm.
    let _end = DomainEnd::new(&domain);
    // Dropped last (declared first): it stops when the pair is over or failed.
    let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
        .with_context(|| format!("could not start a coordinator for {domain}"))?;
    let (ping_core, pong_core) = program_pair::cores(ctx)?;
    let kind_arg = match kind {
        Kind::Small => "small",
        Kind::Image => "image",
    };
    let wait = if mode == WaitMode::Spin { "spin" } else { "block" };
    let paced = if paced { "1" } else { "0" };
    let timeout = PEER_TIMEOUT.as_secs().to_string();
    let mut ping = program_pair::command(&[], program, ping_core.as_deref());
    ping.args(["ping", &domain, kind_arg, wait, paced])
        .arg(samples.to_string())
        .arg(warmup.to_string())
        .arg(EVENT_GAP.as_nanos().to_string())
        .arg(&timeout);
    let mut pong = program_pair::command(&[], program, pong_core.as_deref());
    pong.args(["pong", &domain, kind_arg, wait, paced, &timeout]);
    let printed = program_pair::run("C++", ping, pong, RUN_TIMEOUT);
    if printed.is_err() {
        // A program killed on the failure left its iceoryx2 nodes behind.
        super::ipc_node::remove_dead_nodes();
    }
    let printed = printed?;
    drop(coordinator);

    let mut run = CppRun {
        one_way: Latency::new()?,
        write: Latency::new()?,
        replies: 0,
        held: 0,
        peer_notes: Vec::new(),
    };
    for line in printed.ping.lines() {
        let Some((key, value)) = line.split_once(' ') else { continue };
        let value: u64 = match value.trim().parse() {
            Ok(v) => v,
            Err(_) => bail!("the C++ ping process printed {line:?}"),
        };
        match key {
            "r" => {
                run.one_way.record_ns(value);
                run.replies += 1;
            }
            "w" => run.write.record_ns(value),
            "held" => run.held = value,
            _ => bail!("the C++ ping process printed {line:?}"),
        }
    }
    if run.replies != samples {
        bail!("the C++ ping process printed {} figures for {samples} samples", run.replies);
    }
    run.peer_notes =
        printed.pong.lines().filter_map(|l| l.strip_prefix("note ")).map(str::to_owned).collect();
    Ok(run)
}
