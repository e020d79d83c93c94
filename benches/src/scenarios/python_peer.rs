//! `python-small` and `python-image` (issue 26): one hop from a Python process to a
//! Python subscriber in another process through esgm's own package, beside the same
//! hop through iceoryx2's Python package (`python-iceoryx2-*`) and Zenoh's with shared
//! memory (`python-zenoh-*`).
//!
//! Both ends are `benches/python/pingpong.py` (its docstring says exactly what a leg
//! is), run by the venv [`crate::python_env`] makes: a `pong` process, then a `ping`
//! process that measures, each leg a user's send (esgm: `Trajectory.add`) until the
//! other process's subscriber holds the sample and has read `x`, or a pixel at each end
//! of a 640×480 RGB frame written into a loan of shared memory before the hop. Half the
//! round trip, timed by the ping on its own clock, is one hop, as in every
//! cross-process row; the ping prints one line per hop, which this process reads into
//! the row. For the esgm rows this process runs the domain's coordinator on a thread
//! (as `connect-small` does); it is not on the data path.
//!
//! Two rows each: `spin` (both ends poll without blocking) and `event` (both block).
//! Targets, as the issue sets them: `python-small` ≤ 1.5 × `python-iceoryx2-small` at
//! the same wait; `python-image` ≤ 1.2 × `python-small` (flat in size); both faster
//! than the Zenoh rows (Zenoh's over esgm's ≥ 1, as for the Rust Zenoh rows).
//!
//! A venv that cannot be made leaves every row unmeasured with the reason (a failure
//! under CI, see [`crate::python_env`]). A pair of the other packages that fails is
//! reported as not run with its error, as the ROS 1 and Zenoh peers are: a finding for
//! the table, not a reason to lose the rest of the run; esgm's own pair failing fails
//! the scenario. Under `--pin` the ping runs on the measuring core and the pong on the
//! peer core (`taskset`, every thread of each process).

use std::net::TcpListener;
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context as _, bail};
use esgm_core::TypeRegistry;
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_floor_iceoryx2;
use super::ipc_payload::Kind;
use super::ros1_peer::{Guard, Pinning, command, read_all};
use crate::latency::Latency;
use crate::python_env::{self, PythonEnv};
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// How long one ping process may run (it also stops itself after this).
const RUN_TIMEOUT: Duration = Duration::from_secs(300);
/// How long the pong may take to exit after the ping's stop.
const PONG_EXIT_TIMEOUT: Duration = Duration::from_secs(20);

/// Which Python package carries the hop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// esgm's own (`esgm.connect`).
    Esgm,
    /// iceoryx2's Python package.
    Iceoryx2,
    /// Zenoh's Python package with shared memory.
    Zenoh,
}

impl Transport {
    fn arg(self) -> &'static str {
        match self {
            Transport::Esgm => "esgm",
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Zenoh => "zenoh",
        }
    }
}

/// One payload through one Python package (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Python {
    name: &'static str,
    transport: Transport,
    kind: Kind,
}

/// esgm's small row.
pub const SMALL_NAME: &str = "python-small";
/// esgm's image row.
pub const IMAGE_NAME: &str = "python-image";
/// iceoryx2's small row.
pub const ICEORYX2_SMALL_NAME: &str = "python-iceoryx2-small";
/// iceoryx2's image row.
pub const ICEORYX2_IMAGE_NAME: &str = "python-iceoryx2-image";

impl Python {
    /// A RobotState through iceoryx2's package (run first: esgm's row is held to it).
    pub const ICEORYX2_SMALL: Python =
        Python { name: ICEORYX2_SMALL_NAME, transport: Transport::Iceoryx2, kind: Kind::Small };
    /// A frame through iceoryx2's package.
    pub const ICEORYX2_IMAGE: Python =
        Python { name: ICEORYX2_IMAGE_NAME, transport: Transport::Iceoryx2, kind: Kind::Image };
    /// A RobotState through esgm's package.
    pub const SMALL: Python =
        Python { name: SMALL_NAME, transport: Transport::Esgm, kind: Kind::Small };
    /// An Image through esgm's package.
    pub const IMAGE: Python =
        Python { name: IMAGE_NAME, transport: Transport::Esgm, kind: Kind::Image };
    /// A RobotState through Zenoh's package.
    pub const ZENOH_SMALL: Python =
        Python { name: "python-zenoh-small", transport: Transport::Zenoh, kind: Kind::Small };
    /// A frame through Zenoh's package.
    pub const ZENOH_IMAGE: Python =
        Python { name: "python-zenoh-image", transport: Transport::Zenoh, kind: Kind::Image };

    /// The row each of this scenario's rows is compared with (same wait).
    fn baseline(&self) -> &'static str {
        match (self.transport, self.kind) {
            (Transport::Iceoryx2, Kind::Small) => ipc_floor_iceoryx2::NAME,
            (Transport::Iceoryx2, Kind::Image) => ICEORYX2_SMALL_NAME,
            (Transport::Esgm, Kind::Small) => ICEORYX2_SMALL_NAME,
            (Transport::Esgm, Kind::Image) => SMALL_NAME,
            (Transport::Zenoh, Kind::Small) => SMALL_NAME,
            (Transport::Zenoh, Kind::Image) => IMAGE_NAME,
        }
    }

    /// What one leg carries, in bytes: esgm's archived structure; the other packages'
    /// payload (an 8-byte sequence and three doubles, or the sequence and the pixels).
    fn payload_bytes(&self) -> anyhow::Result<u64> {
        let pixels = 640 * 480 * 3;
        Ok(match (self.transport, self.kind) {
            (Transport::Esgm, kind) => esgm_core::codec::encoded_len(&kind.make(0))? as u64,
            (_, Kind::Small) => 32,
            (_, Kind::Image) => 8 + pixels,
        })
    }

    /// Samples of a full run and of a `--quick` one: Python hops take tens of
    /// microseconds, so fewer than the Rust rows'.
    fn samples(&self) -> (u64, u64) {
        match self.kind {
            Kind::Small => (20_000, 2_000),
            Kind::Image => (5_000, 500),
        }
    }
}

impl Scenario for Python {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match (self.transport, self.kind) {
            (Transport::Esgm, Kind::Small) => {
                "RobotState, Python add in one connected process -> Python subscriber in \
                 another (esgm's package); busy and blocking"
            }
            (Transport::Esgm, Kind::Image) => {
                "640x480 RGB Image written into a loan, Python add -> Python subscriber in \
                 another process reads a pixel at each end (esgm's package)"
            }
            (Transport::Iceoryx2, Kind::Small) => {
                "RobotState as a ctypes struct, Python -> Python process through iceoryx2's \
                 Python package (PyPI iceoryx2)"
            }
            (Transport::Iceoryx2, Kind::Image) => {
                "640x480 RGB frame in a loaned slice, Python -> Python process through \
                 iceoryx2's Python package, a pixel read at each end"
            }
            (Transport::Zenoh, Kind::Small) => {
                "RobotState bytes, Python -> Python process through Zenoh's Python package \
                 with shared memory (PyPI eclipse-zenoh)"
            }
            (Transport::Zenoh, Kind::Image) => {
                "640x480 RGB frame in a Zenoh shared-memory buffer, Python -> Python process, \
                 a pixel read at each end (eclipse-zenoh)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let env = match python_env::get() {
            Ok(env) => env,
            Err(reason) if python_env::in_ci() => {
                bail!("the Python venv of the python-* rows could not be made: {reason}")
            }
            Err(reason) => {
                ctx.skip(self.name, format!("the Python venv could not be made: {reason}"));
                return Ok(Vec::new());
            }
        };
        let (full, quick) = self.samples();
        let samples = ctx.samples(full, quick);
        let warmup = ctx.warmup(samples);
        let bytes = self.payload_bytes()?;
        let mut rows = Vec::new();
        for mode in WaitMode::SPIN_AND_BLOCK {
            let run = match run_pair(ctx, env, self, mode, samples, warmup) {
                Ok(run) => run,
                Err(e) if self.transport != Transport::Esgm && !python_env::in_ci() => {
                    ctx.skip(
                        self.name,
                        format!("the Python pair failed ({}): {e:#}", mode.label()),
                    );
                    continue;
                }
                Err(e) => return Err(e.context(format!("the Python pair ({})", mode.label()))),
            };
            let mut row = run
                .one_way
                .measurement(self.name, mode.wait())
                .payload_bytes(bytes)
                .method(Method::HalfRoundTrip)
                .wait_strategy(mode.label())
                .baseline(self.baseline())
                .producer_write_p50_ns(run.write.quantile(0.5))
                .if_empty("no answer was measured");
            for note in run.notes {
                row = row.note(note);
            }
            rows.push(row);
        }
        Ok(rows)
    }

    fn targets(&self) -> Vec<Target> {
        let each = |row: &str, base: &str, at_most: bool, x: f64| -> Vec<Target> {
            Wait::BOTH
                .iter()
                .map(|&w| {
                    if at_most {
                        Target::at_most(row, base, w, x)
                    } else {
                        Target::at_least(row, base, w, x)
                    }
                })
                .collect()
        };
        match (self.transport, self.kind) {
            (Transport::Esgm, Kind::Small) => each(SMALL_NAME, ICEORYX2_SMALL_NAME, true, 1.5),
            (Transport::Esgm, Kind::Image) => each(IMAGE_NAME, SMALL_NAME, true, 1.2),
            // Faster than Zenoh: Zenoh's row over esgm's ≥ 1.
            (Transport::Zenoh, _) => each(self.name, self.baseline(), false, 1.0),
            (Transport::Iceoryx2, _) => Vec::new(),
        }
    }
}

/// What one ping-pong measured.
struct PairRun {
    one_way: Latency,
    write: Latency,
    notes: Vec<String>,
}

fn run_pair(
    ctx: &Context,
    env: &PythonEnv,
    scenario: &Python,
    mode: WaitMode,
    samples: u64,
    warmup: u64,
) -> anyhow::Result<PairRun> {
    let Pinning { measuring: ping_core, peer: pong_core, .. } =
        Pinning::of(ctx.pinning().map(|p| (p.measuring_core(), p.peer_core())))?;
    let domain = unique_domain("esgm-bench-py");
    // Dropped last: the coordinator of the esgm rows' domain outlives both processes.
    let _coordinator = match scenario.transport {
        Transport::Esgm => {
            // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
            iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
            Some(
                Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
                    .with_context(|| format!("could not start a coordinator for {domain}"))?,
            )
        }
        Transport::Iceoryx2 | Transport::Zenoh => None,
    };
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("finding a free loopback port")?
        .port();
    let wait = if mode == WaitMode::Spin { "spin" } else { "event" };
    let kind = if scenario.kind == Kind::Small { "small" } else { "image" };
    let common = |role: &str, core: Option<String>| {
        let mut c = command(&env.python, core);
        c.arg(env.scripts.join("pingpong.py"))
            .arg(role)
            .args(["--transport", scenario.transport.arg(), "--kind", kind, "--wait", wait])
            .args(["--domain", &domain, "--port", &port.to_string()])
            .args(["--timeout", &RUN_TIMEOUT.as_secs().to_string()])
            .current_dir(&env.scripts)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c
    };
    let mut pong = Guard::new(common("pong", pong_core).spawn().context("starting the pong")?);
    let pong_out = read_all(pong.child()?.stdout.take().context("pong stdout")?);
    let pong_err = read_all(pong.child()?.stderr.take().context("pong stderr")?);
    let mut ping_command = common("ping", ping_core);
    ping_command.args(["--samples", &samples.to_string(), "--warmup", &warmup.to_string()]);
    let mut ping = Guard::new(ping_command.spawn().context("starting the ping")?);
    let ping_out = read_all(ping.child()?.stdout.take().context("ping stdout")?);
    let ping_err = read_all(ping.child()?.stderr.take().context("ping stderr")?);
    // The script stops itself at RUN_TIMEOUT; a little more for it to say so.
    let status = ping.wait("the Python ping", RUN_TIMEOUT + Duration::from_secs(10))?;
    if !status.success() {
        drop(pong);
        let said = ping_err.join().unwrap_or_default();
        let pong_said = pong_err.join().unwrap_or_default();
        bail!("the Python ping failed ({status}): {} / pong: {}", last(&said), last(&pong_said));
    }
    let pong_status = pong.wait("the Python pong", PONG_EXIT_TIMEOUT)?;
    if !pong_status.success() {
        let said = pong_err.join().unwrap_or_default();
        bail!("the Python pong failed ({pong_status}): {}", last(&said));
    }
    let mut run = parse(&ping_out.join().unwrap_or_default())?;
    for line in pong_out.join().unwrap_or_default().lines() {
        if let Some(note) = line.strip_prefix("note ") {
            run.notes.push(format!("pong: {note}"));
        }
    }
    Ok(run)
}

/// The ping's output: `<one-way ns> <write ns>` per hop, `note <text>` lines.
fn parse(stdout: &str) -> anyhow::Result<PairRun> {
    let mut run = PairRun { one_way: Latency::new()?, write: Latency::new()?, notes: Vec::new() };
    for line in stdout.lines() {
        if let Some(note) = line.strip_prefix("note ") {
            run.notes.push(note.to_owned());
            continue;
        }
        let mut fields = line.split_whitespace().map(str::parse::<u64>);
        match (fields.next(), fields.next(), fields.next()) {
            (Some(Ok(one_way)), Some(Ok(write)), None) => {
                run.one_way.record_ns(one_way);
                run.write.record_ns(write);
            }
            _ => bail!("the Python ping printed an unexpected line: {line:?}"),
        }
    }
    if run.one_way.is_empty() {
        bail!("the Python ping printed no figures");
    }
    Ok(run)
}

/// The last non-empty line of a process's stderr: its error.
fn last(stderr: &str) -> &str {
    stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("(nothing on stderr)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pings_output_becomes_a_row() {
        let run = parse("2000 10\n4000 30\nnote read in place\n").unwrap();
        assert_eq!(run.one_way.len(), 2);
        assert_eq!(run.write.len(), 2);
        assert_eq!(run.notes, ["read in place"]);
        assert!(parse("note only\n").is_err(), "no figures is a failure, never 0 ns");
        assert!(parse("12 x\n").is_err());
    }

    #[test]
    fn the_targets_are_the_issues() {
        let names: Vec<String> = [Python::SMALL, Python::IMAGE, Python::ZENOH_SMALL]
            .iter()
            .flat_map(|s| s.targets())
            .map(|t| format!("{} {} {}", t.row, t.baseline, t.bound_label()))
            .collect();
        assert!(
            names.contains(&"python-small python-iceoryx2-small ≤ ×1.50".to_owned()),
            "{names:?}"
        );
        assert!(names.contains(&"python-image python-small ≤ ×1.20".to_owned()), "{names:?}");
        assert!(names.contains(&"python-zenoh-small python-small ≥ ×1.00".to_owned()), "{names:?}");
    }
}
