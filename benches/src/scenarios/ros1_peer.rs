//! `ros1-small` and `ros1-image`: the payload sizes of `esgm-small` and `esgm-image`
//! through ROS 1 (roscpp) publish-subscribe, process to process.
//!
//! The peer is a small C++ program, `benches/ros1/ros1_pingpong.cpp`, built from
//! Debian's ROS 1 packages by `benches/ros1/build.sh`; without the built binary both
//! rows are reported as skipped with that instruction. When it is there, esgm-bench
//! starts a private `rosmaster` on a free loopback port, the program's `pong` role and
//! its `ping` role, which measures (see the program's header: a `std_msgs/
//! UInt8MultiArray` of the structure's encoded size over TCPROS with TCP_NODELAY, half
//! the round trip, one line per hop) and prints its figures for this process to
//! collect. The C++ side cannot run esgm's codec, so it reads the bytes' sequence number
//! and last byte instead of validating an archive: a lower bound for ROS 1 doing
//! esgm's work.

use std::io::Read;
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use super::ipc_payload::Kind;
use super::peer_rows::{PeerRows, faster_than};
use crate::latency::Latency;
use crate::report::Measurement;
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// What to run to measure ROS 1.
pub const HOW: &str = "run benches/ros1/build.sh (needs Debian's ROS 1 packages)";
/// How long one ping run may take.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

/// One payload through ROS 1 (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Ros1 {
    name: &'static str,
    kind: Kind,
}

impl Ros1 {
    /// The small structure's size.
    pub const SMALL: Ros1 = Ros1 { name: "ros1-small", kind: Kind::Small };
    /// The image's size.
    pub const IMAGE: Ros1 = Ros1 { name: "ros1-image", kind: Kind::Image };
}

/// The built peer program, if there is one: `ESGM_ROS1_PINGPONG`, else the place
/// `build.sh` puts it.
pub fn program() -> Option<PathBuf> {
    built("ESGM_ROS1_PINGPONG", "ros1_pingpong")
}

/// A program `build.sh` builds, if it is there: the one the environment variable `var`
/// names, else `benches/ros1/build/<name>`.
pub(crate) fn built(var: &str, name: &str) -> Option<PathBuf> {
    let path = std::env::var_os(var)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("ros1/build").join(name));
    path.is_file().then_some(path)
}

impl Scenario for Ros1 {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "~120 bytes through ROS 1 roscpp pub/sub (TCPROS), process -> process \
                 (benches/ros1/build.sh)"
            }
            Kind::Image => {
                "~921,760 bytes through ROS 1 roscpp pub/sub (TCPROS), process -> process \
                 (benches/ros1/build.sh)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let Some(program) = program() else {
            ctx.skip(self.name, HOW);
            return Ok(Vec::new());
        };
        if which("rosmaster").is_none() {
            ctx.skip(self.name, format!("rosmaster is not installed; {HOW}"));
            return Ok(Vec::new());
        }
        let bytes = esgm_core::codec::encoded_len(&self.kind.make(0)).context("sizing")?;
        let (full, quick) = self.kind.samples();
        let samples = ctx.samples(full, quick);
        let warmup = ctx.warmup(samples);
        let cores = ctx.pinning().map(|p| (p.measuring_core(), p.peer_core()));
        let rows = PeerRows {
            name: self.name,
            baseline: self.kind.esgm_row(),
            bytes,
            peer: "ROS 1",
            note: "std_msgs/UInt8MultiArray over TCPROS (TCP_NODELAY, loopback); the C++ \
                   reader checks sequence and last byte, it cannot validate an esgm archive",
        };
        // A peer outside this project (its packages, its master) failing is a finding.
        Ok(rows.measure(ctx, |mode| run_pair(&program, mode, bytes, samples, warmup, cores)))
    }

    /// esgm is to be faster than ROS 1 at every size: ROS 1's row over esgm's ≥ 1.
    fn targets(&self) -> Vec<Target> {
        faster_than(self.name, self.kind)
    }
}

/// A private `rosmaster` on a free loopback port, with a `ROS_HOME` of its own; killed
/// and its home removed when dropped.
pub(crate) struct Master {
    /// Its port on 127.0.0.1.
    pub port: u16,
    home: PathBuf,
    process: Guard,
}

impl Master {
    /// Starts one (pinned to `cores` with taskset when given).
    pub fn start(cores: Option<String>) -> anyhow::Result<Self> {
        let port = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .context("finding a free loopback port")?
            .port();
        let home =
            std::env::temp_dir().join(format!("esgm-bench-ros-{}-{port}", std::process::id()));
        std::fs::create_dir_all(&home).context("creating ROS_HOME")?;
        let rosmaster = which("rosmaster").context("rosmaster is not installed")?;
        let mut master = command(&rosmaster, cores);
        master
            .args(["--core", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        let mut this = Self { port, home, process: Guard::none() };
        this.env(&mut master);
        this.process = Guard::new(master.spawn().context("starting rosmaster")?);
        Ok(this)
    }

    /// Its process id (to measure it with the processes it serves).
    pub fn pid(&self) -> Option<u32> {
        self.process.0.as_ref().map(Child::id)
    }

    /// Points a ROS 1 process at this master, on loopback.
    pub fn env(&self, c: &mut Command) {
        c.env("ROS_MASTER_URI", format!("http://127.0.0.1:{}", self.port))
            .env("ROS_IP", "127.0.0.1")
            .env("ROS_HOME", &self.home)
            .env("ROS_LOG_DIR", self.home.join("log"))
            .stdin(Stdio::null());
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        // The master ends before its home goes.
        self.process = Guard::none();
        if let Err(e) = std::fs::remove_dir_all(&self.home) {
            eprintln!("esgm-bench: cannot remove {}: {e}", self.home.display());
        }
    }
}

pub(crate) fn which(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?
        .to_str()?
        .split(':')
        .map(|dir| PathBuf::from(dir).join(program))
        .find(|p| p.is_file())
}

/// A child that is killed if dropped before it exits.
pub(crate) struct Guard(Option<Child>);

impl Guard {
    /// No child.
    pub(crate) fn none() -> Self {
        Self(None)
    }

    /// Holds `child`.
    pub fn new(child: Child) -> Self {
        Self(Some(child))
    }

    /// The child (a guard made with [`Guard::new`] always has one).
    pub fn child(&mut self) -> anyhow::Result<&mut Child> {
        self.0.as_mut().context("no child process")
    }

    /// Waits for the child, `what`, to exit: an error past `timeout` (it is then
    /// killed when the guard drops).
    pub fn wait(&mut self, what: &str, timeout: Duration) -> anyhow::Result<ExitStatus> {
        let started = Instant::now();
        loop {
            if let Some(status) =
                self.child()?.try_wait().with_context(|| format!("waiting for {what}"))?
            {
                return Ok(status);
            }
            if started.elapsed() > timeout {
                bail!("{what} did not finish within {timeout:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Reads all of `from` on a thread of its own (a child's pipe, which would block the
/// child if nobody read it), to join for the text.
pub(crate) fn read_all(mut from: impl Read + Send + 'static) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut s = String::new();
        // What was read before an error is all there is.
        let _ = from.read_to_string(&mut s);
        s
    })
}

/// The cores of a ROS 1 run's processes under `--pin` (all `None` without it): the
/// measuring side's, the peers', and the master's (both).
pub(super) struct Pinning {
    /// The ping or writer process.
    pub measuring: Option<String>,
    /// The pong or reader processes.
    pub peer: Option<String>,
    /// rosmaster.
    pub master: Option<String>,
}

impl Pinning {
    /// From the run's (measuring, peer) cores; pinning needs `taskset`.
    pub fn of(cores: Option<(usize, usize)>) -> anyhow::Result<Self> {
        let Some((m, p)) = cores else {
            return Ok(Self { measuring: None, peer: None, master: None });
        };
        if which("taskset").is_none() {
            bail!("--pin needs taskset (util-linux) to pin the ROS 1 processes");
        }
        Ok(Self {
            measuring: Some(m.to_string()),
            peer: Some(p.to_string()),
            master: Some(format!("{m},{p}")),
        })
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        let Some(child) = self.0.as_mut() else { return };
        // Already exited, or gone: nothing to kill.
        if let Ok(None) = child.try_wait() {
            let _ = child.kill();
        }
        let _ = child.wait();
    }
}

/// `program`, pinned to `core` with `taskset` when pinning. Children inherit the
/// affinity of the (pinned) measuring thread, so without this under `--pin` every ROS
/// process would share the measuring core.
pub(crate) fn command(program: &std::path::Path, core: Option<String>) -> Command {
    match core {
        Some(core) => {
            let mut c = Command::new("taskset");
            c.arg("-c").arg(core).arg(program);
            c
        }
        None => Command::new(program),
    }
}

fn run_pair(
    program: &std::path::Path,
    mode: WaitMode,
    bytes: usize,
    samples: u64,
    warmup: u64,
    cores: Option<(usize, usize)>,
) -> anyhow::Result<Latency> {
    let Pinning { measuring: ping_core, peer: pong_core, master: master_cores } =
        Pinning::of(cores)?;
    let master = Master::start(master_cores)?;
    let port = master.port;
    let env = |c: &mut Command| master.env(c);
    let prefix = format!("/esgm_bench_{}_{port}", std::process::id());
    let wait = if mode == WaitMode::Spin { "spin" } else { "block" };
    let mut pong = command(program, pong_core);
    pong.args(["pong", &prefix, wait]).stdout(Stdio::null()).stderr(Stdio::null());
    env(&mut pong);
    let _pong = Guard::new(pong.spawn().context("starting the ROS 1 pong process")?);
    let mut ping = command(program, ping_core);
    ping.args([
        "ping",
        &prefix,
        wait,
        &bytes.to_string(),
        &samples.to_string(),
        &warmup.to_string(),
    ])
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    env(&mut ping);
    let mut ping = Guard::new(ping.spawn().context("starting the ROS 1 ping process")?);
    let reader = read_all(ping.child()?.stdout.take().context("ping stdout")?);
    let err_reader = read_all(ping.child()?.stderr.take().context("ping stderr")?);
    let status = ping.wait("the ROS 1 ping process", RUN_TIMEOUT)?;
    let stdout = reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    if !status.success() {
        bail!("the ROS 1 ping process failed ({status}): {}", stderr.trim());
    }
    let mut latency = Latency::new()?;
    for line in stdout.lines() {
        if let Some(ns) = line.strip_prefix("r ").and_then(|v| v.trim().parse::<u64>().ok()) {
            latency.record_ns(ns);
        }
    }
    if latency.is_empty() {
        bail!("the ROS 1 ping process printed no figures");
    }
    Ok(latency)
}
