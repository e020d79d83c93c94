//! The measuring side of the `ros2-*` rows (feature `ros2`); what they measure is in
//! [`super::ros2_peer`].
//!
//! Per row and wait, a fresh set: a loopback-only network namespace
//! (`netns::Namespace`, the tests' helper), the DDS ends ([`super::ros2_dds`]) and, for the
//! bridge rows, an `esgm-ros2` process and an esgm domain whose coordinator runs on a
//! thread of this process. Every DDS participant is inside the namespace; this process
//! stays outside and reaches `esgm-ros2` through shared memory only.
//!
//! Each hop is stamped on the host's system clock where it starts (before `add`, or
//! before the DDS publisher's `publish`) and where it ends (when the DDS subscriber has
//! read the message, or when this process's esgm subscription returned the sample and
//! it was read), and the next hop starts only once this one ended. Start-up: the first
//! message (number 0) is sent, ever less often, until one arrives, since a message sent
//! before DDS discovery matched the two ends is lost (volatile QoS); then the ends
//! settle and the replies are forgotten.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{Clock as _, Sample, SystemClock, TypeRegistry};
use esgm_shm::control::{Coordinator, CoordinatorThread, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

use super::ipc_connect_echo::{add, connect, create, make_for, next, received, stamped};
use super::ipc_payload::{Kind, read_value};
use super::ros2_dds::{PUBLISHER, SUBSCRIBER, TOPIC, WAIT_AT_MOST};
use super::ros2_peer::Path;
use super::ros2_process::LinkedProcess;
use crate::domain_end::DomainEnd;
use crate::latency::Latency;
use crate::patience::Patience;
use crate::peer_process::FINISH_TIMEOUT;
use crate::peer_role::PeerRole;
use crate::scenario::Context;
use crate::wait_mode::WaitMode;

/// Whether this process may make network namespaces (root), for `netns` (the tests'
/// helpers, included rather than copied).
#[path = "../../../esgm-shm/apps/cli/tests/common/capability.rs"]
mod capability;
/// A loopback-only network namespace, removed when dropped (the tests' helper); also
/// where `refsys-ros2`'s nodes run.
#[path = "../../../esgm-shm/apps/cli/tests/common/netns.rs"]
pub(crate) mod netns;

use netns::Namespace;

/// A loopback-only network namespace `esgm-<tag>-<pid>` for DDS, or why there is none,
/// as a DDS row's reason for not running (not root, no `ip`).
pub(crate) fn dds_namespace(tag: &str) -> Result<Namespace, String> {
    Namespace::create(tag).map_err(|e| {
        format!("no loopback-only network namespace for DDS, where alone it runs: {e}")
    })
}

/// What to build to measure the bridge.
pub const HOW: &str =
    "esgm-ros2 is not built next to esgm-bench (cargo build --release -p esgm-ros2)";

/// The trajectory the bridge exports or imports.
const TRAJECTORY: &str = "bench";
/// The first wait for the start-up message; it doubles up to [`HELLO_EVERY_MAX`].
const HELLO_EVERY: Duration = Duration::from_millis(5);
/// The longest wait between two start-up messages.
const HELLO_EVERY_MAX: Duration = Duration::from_millis(200);
/// Time for start-up messages still under way to arrive, before they are forgotten.
const HELLO_SETTLE: Duration = Duration::from_millis(100);

/// What one row measured.
#[derive(Debug)]
pub struct Ros2Run {
    /// One-way latency of each hop, on the system clock.
    pub one_way: Latency,
    /// How the row's ends were set up, for its notes.
    pub notes: Vec<String>,
}

/// The `esgm-ros2` next to this executable.
fn bridge_binary() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let path = exe.with_file_name("esgm-ros2");
    path.exists().then_some(path)
}

/// Measures `name` (both waits): see the module docs. Reported as not run, with the
/// reason, without a namespace for DDS or without the `esgm-ros2` binary.
pub fn measure(
    ctx: &Context,
    name: &str,
    kind: Kind,
    path: Path,
) -> anyhow::Result<Option<Vec<(WaitMode, Ros2Run)>>> {
    let bridge = match path {
        Path::Raw => None,
        Path::Export | Path::Import => match bridge_binary() {
            Some(b) => Some(b),
            None => {
                ctx.skip(name, HOW);
                return Ok(None);
            }
        },
    };
    let samples = match kind {
        Kind::Small => ctx.samples(5_000, 500),
        Kind::Image => ctx.samples(1_000, 100),
    };
    let mut runs = Vec::new();
    for mode in WaitMode::SPIN_AND_BLOCK {
        let ns = match dds_namespace(&format!("bench-{name}-{}", mode.arg())) {
            Ok(ns) => ns,
            Err(why) => {
                ctx.skip(name, why);
                return Ok(None);
            }
        };
        let row = Row { ctx, name, kind, mode, ns: &ns, samples };
        let run = match (&bridge, path) {
            (_, Path::Raw) => row.raw(),
            (Some(bridge), Path::Export) => row.export(bridge),
            (Some(bridge), Path::Import) => row.import(bridge),
            (None, _) => bail!("no esgm-ros2 for a bridge row"),
        }
        .with_context(|| format!("{name} ({})", mode.label()))?;
        runs.push((mode, run));
    }
    Ok(Some(runs))
}

/// One row and wait.
struct Row<'a> {
    ctx: &'a Context,
    name: &'a str,
    kind: Kind,
    mode: WaitMode,
    ns: &'a Namespace,
    samples: u64,
}

impl Row<'_> {
    /// `ros2-raw-*`: a DDS publisher process to a DDS subscriber process.
    fn raw(&self) -> anyhow::Result<Ros2Run> {
        // The receiving end where the bridge rows' esgm reader is (the measuring core),
        // the sending end on the peer core.
        let mut subscriber = self.dds_end(SUBSCRIBER, self.measuring_core())?;
        let mut publisher = self.dds_end(PUBLISHER, self.peer_core())?;
        let mut every = HELLO_EVERY;
        let started = Instant::now();
        loop {
            publisher.send("0")?;
            if subscriber.line_within(every, |l| held_seq(l) == Some(0))?.is_some() {
                break;
            }
            give_up_after(started, "the DDS subscriber to hear the publisher")?;
            every = (every * 2).min(HELLO_EVERY_MAX);
        }
        std::thread::sleep(HELLO_SETTLE);
        subscriber.drain();
        let mut held = HashMap::new();
        for seq in 1..=self.hops() {
            self.ctx.before_hop(self.mode.wait());
            publisher.send(&seq.to_string())?;
            let t1 = held_at(&mut subscriber, seq)?;
            held.insert(seq, t1);
        }
        let sent = sent_at(publisher.finish(FINISH_TIMEOUT)?)?;
        subscriber.finish(FINISH_TIMEOUT)?;
        Ok(Ros2Run { one_way: self.one_way(&sent, &held)?, notes: Vec::new() })
    }

    /// `ros2-export-*`: an add in this process, through `esgm-ros2 --export`, to a DDS
    /// subscriber process.
    fn export(&self, bridge: &std::path::Path) -> anyhow::Result<Ros2Run> {
        let esgm = EsgmSide::start(self.name)?;
        let writer = create(&esgm.esgm, TRAJECTORY, self.kind)?;
        let mut subscriber = self.dds_end(SUBSCRIBER, self.peer_core())?;
        let spec = format!("{TRAJECTORY}={TOPIC}");
        let mut bridge = self.bridge(bridge, &esgm.domain, &["--export", &spec])?;
        // On the heap: the start-up messages share its pixels.
        let hello = stamped(self.kind.make(0), 0);
        let mut every = HELLO_EVERY;
        let started = Instant::now();
        loop {
            add(&writer, hello.clone())?;
            if subscriber.line_within(every, |l| held_seq(l) == Some(0))?.is_some() {
                break;
            }
            bridge.line_within(Duration::ZERO, |_| false)?;
            give_up_after(started, "the DDS subscriber to hear esgm-ros2's export")?;
            every = (every * 2).min(HELLO_EVERY_MAX);
        }
        std::thread::sleep(HELLO_SETTLE);
        subscriber.drain();
        let (mut sent, mut held) = (HashMap::new(), HashMap::new());
        for seq in 1..=self.hops() {
            // Made before the hop, as a camera renders into its loan.
            let es = stamped(make_for(&writer, self.kind, seq as u64), seq);
            self.ctx.before_hop(self.mode.wait());
            sent.insert(seq, SystemClock.now());
            add(&writer, es)?;
            held.insert(seq, held_at(&mut subscriber, seq)?);
        }
        subscriber.finish(FINISH_TIMEOUT)?;
        let counters = stop_bridge(bridge)?;
        let notes = vec![format!("esgm-ros2's counters of {TOPIC} at its exit: {counters}")];
        Ok(Ros2Run { one_way: self.one_way(&sent, &held)?, notes })
    }

    /// `ros2-import-*`: a DDS publisher process, through `esgm-ros2 --import`, to an
    /// esgm subscription in this process.
    fn import(&self, bridge: &std::path::Path) -> anyhow::Result<Ros2Run> {
        let esgm = EsgmSide::start(self.name)?;
        let mut publisher = self.dds_end(PUBLISHER, self.peer_core())?;
        let spec = format!("{TOPIC}:{}={TRAJECTORY}", self.ros_type());
        let mut bridge = self.bridge(bridge, &esgm.domain, &["--import", &spec])?;
        // esgm-ros2 made the trajectory (so it writes it) before it said it runs.
        let subscription = super::ipc_connect_echo::subscribe(&esgm.esgm, TRAJECTORY)?;
        let mut every = HELLO_EVERY;
        let started = Instant::now();
        loop {
            publisher.send("0")?;
            if let Some(s) = received(&subscription, every)? {
                if self.seq_of(&s)?.0 == 0 {
                    break;
                }
            }
            bridge.line_within(Duration::ZERO, |_| false)?;
            give_up_after(started, "esgm-ros2 to import the DDS publisher's messages")?;
            every = (every * 2).min(HELLO_EVERY_MAX);
        }
        std::thread::sleep(HELLO_SETTLE);
        drop(subscription.drain());
        let (mut held, mut in_place) = (HashMap::new(), 0u64);
        let mut patience = Patience::alone();
        for seq in 1..=self.hops() {
            self.ctx.before_hop(self.mode.wait());
            publisher.send(&seq.to_string())?;
            loop {
                let sample = next(&subscription, self.mode, &mut patience, "an imported sample")?;
                let (got, shm) = self.seq_of(&sample)?;
                if got == seq {
                    held.insert(seq, SystemClock.now());
                    in_place += u64::from(shm && seq > self.warmup());
                    break;
                }
            }
        }
        let sent = sent_at(publisher.finish(FINISH_TIMEOUT)?)?;
        let counters = stop_bridge(bridge)?;
        let mut notes = vec![format!("esgm-ros2's counters of {TOPIC} at its exit: {counters}")];
        if self.kind == Kind::Image {
            notes.push(format!(
                "{in_place} of {} imported frames' pixels read in place, in the shared memory \
                 esgm-ros2 wrote them into once (held), {} copied onto this process's heap",
                self.samples,
                self.samples - in_place.min(self.samples)
            ));
        }
        Ok(Ros2Run { one_way: self.one_way(&sent, &held)?, notes })
    }

    /// The structure's message number (its `x`, or an image's valid time, which is the
    /// message's stamp) after reading what a consumer reads, and whether its pixels are
    /// held in shared memory.
    fn seq_of(&self, sample: &Sample) -> anyhow::Result<(i64, bool)> {
        let (value, held) = read_value(self.kind, &sample.structure)?;
        let seq = match self.kind {
            Kind::Small => f64::from_bits(value) as i64,
            Kind::Image => sample.valid_time(),
        };
        Ok((seq, held))
    }

    fn ros_type(&self) -> &'static str {
        match self.kind {
            Kind::Small => "geometry_msgs/msg/Pose2D",
            Kind::Image => "sensor_msgs/msg/Image",
        }
    }

    fn warmup(&self) -> i64 {
        self.ctx.warmup(self.samples) as i64
    }

    fn hops(&self) -> i64 {
        self.warmup() + self.samples as i64
    }

    fn measuring_core(&self) -> Option<usize> {
        self.ctx.pinning().map(|p| p.measuring_core())
    }

    fn peer_core(&self) -> Option<usize> {
        self.ctx.pinning().map(|p| p.peer_core())
    }

    /// A DDS end (`esgm-bench` in the peer role `arg`) inside the namespace.
    fn dds_end(&self, arg: &str, core: Option<usize>) -> anyhow::Result<LinkedProcess> {
        let role = PeerRole {
            scenario: self.name.to_owned(),
            wait: self.mode,
            // DDS ends meet in the namespace; they have no esgm domain.
            domain: TOPIC.to_owned(),
            core,
            arg: Some(arg.to_owned()),
        };
        let exe = std::env::current_exe().context("finding esgm-bench to start a DDS end")?;
        let exe = exe.to_str().with_context(|| format!("{} is not UTF-8", exe.display()))?;
        let mut command = self.ns.command(exe);
        command.args(role.to_args());
        LinkedProcess::spawn(format!("{} {arg} ({})", self.name, self.mode.arg()), command)
    }

    /// `esgm-ros2 --domain <domain> <args>` inside the namespace, once it says it runs.
    /// Under `--pin` it may run on both cores (taskset), as an unpinned process does:
    /// a child would otherwise inherit the measuring thread's core.
    fn bridge(
        &self,
        binary: &std::path::Path,
        domain: &str,
        args: &[&str],
    ) -> anyhow::Result<LinkedProcess> {
        let binary =
            binary.to_str().with_context(|| format!("{} is not UTF-8", binary.display()))?;
        let mut command = match self.ctx.pinning() {
            Some(p) => {
                let mut c = self.ns.command("taskset");
                c.arg("-c").arg(format!("{},{}", p.measuring_core(), p.peer_core())).arg(binary);
                c
            }
            None => self.ns.command(binary),
        };
        command.args(["--domain", domain]).args(args).env("RUST_LOG", "warn");
        let mut bridge = LinkedProcess::spawn(format!("esgm-ros2 of {}", self.name), command)?;
        bridge.line("start line", WAIT_AT_MOST, |l| l.starts_with("esgm-ros2: esgm domain"))?;
        Ok(bridge)
    }

    /// The measured hops' latencies: held − sent, warm-up left out.
    fn one_way(
        &self,
        sent: &HashMap<i64, i64>,
        held: &HashMap<i64, i64>,
    ) -> anyhow::Result<Latency> {
        let mut one_way = Latency::new()?;
        for seq in self.warmup() + 1..=self.hops() {
            let (Some(t0), Some(t1)) = (sent.get(&seq), held.get(&seq)) else {
                bail!("message {seq} has no send or hold time");
            };
            // The system clock may be stepped; a negative hop is reported, not hidden.
            let ns = u64::try_from(t1 - t0)
                .with_context(|| format!("message {seq} held before it was sent"))?;
            one_way.record_ns(ns);
        }
        Ok(one_way)
    }
}

/// The esgm side of a bridge row: a coordinator on a thread of this process, and this
/// process connected to it.
struct EsgmSide {
    // Dropped first: the connection goes before its coordinator.
    esgm: ShmEsgm,
    _coordinator: CoordinatorThread,
    /// Dropped after them: the domain's words go.
    _end: DomainEnd,
    domain: String,
}

impl EsgmSide {
    fn start(name: &str) -> anyhow::Result<Self> {
        // iceoryx2's warnings (no config file, buffer sizes adjusted) are not news here.
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let domain = unique_domain("esgm-bench-ros2");
        let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let esgm = connect(&domain, &format!("bench-{name}"))?;
        Ok(Self { esgm, _coordinator: coordinator, _end: DomainEnd::new(&domain), domain })
    }
}

/// Fails once start-up took [`WAIT_AT_MOST`].
fn give_up_after(started: Instant, what: &str) -> anyhow::Result<()> {
    if started.elapsed() > WAIT_AT_MOST {
        bail!("waited {WAIT_AT_MOST:?} for {what} (DDS discovery or the bridge failed)");
    }
    Ok(())
}

/// The number of a `held <seq> <ns>` line.
fn held_seq(line: &str) -> Option<i64> {
    line.strip_prefix("held ")?.split(' ').next()?.parse().ok()
}

/// The time of `<word> <seq> <ns>`.
fn stamp(line: &str) -> Option<(i64, i64)> {
    let mut parts = line.split(' ').skip(1);
    Some((parts.next()?.parse().ok()?, parts.next()?.parse().ok()?))
}

/// When the DDS subscriber held message `seq`.
fn held_at(subscriber: &mut LinkedProcess, seq: i64) -> anyhow::Result<i64> {
    let line = subscriber.line("held line", WAIT_AT_MOST, |l| held_seq(l) == Some(seq))?;
    stamp(&line).map(|(_, t)| t).with_context(|| format!("a held line without a time: {line:?}"))
}

/// The send times the DDS publisher printed at its end.
fn sent_at(lines: Vec<String>) -> anyhow::Result<HashMap<i64, i64>> {
    lines
        .iter()
        .filter(|l| l.starts_with("sent "))
        .map(|l| stamp(l).with_context(|| format!("a sent line without a time: {l:?}")))
        .collect()
}

/// Stops `esgm-ros2` (SIGTERM) and returns its last report of [`TOPIC`] (a JSON line).
fn stop_bridge(mut bridge: LinkedProcess) -> anyhow::Result<String> {
    bridge.terminate()?;
    let lines = bridge.finish(FINISH_TIMEOUT)?;
    lines
        .into_iter()
        .rev()
        .find(|l| l.starts_with('{') && l.contains(TOPIC))
        .context("esgm-ros2 printed no report of the topic at its exit")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_of_the_dds_ends_parse() {
        assert_eq!(held_seq("held 12 1764000000000000000"), Some(12));
        assert_eq!(held_seq("sent 12 5"), None);
        assert_eq!(stamp("held 12 345"), Some((12, 345)));
        assert_eq!(stamp("held 12"), None);
        let sent = sent_at(vec!["sent 1 10".into(), "note".into(), "sent 2 20".into()]).unwrap();
        assert_eq!((sent[&1], sent[&2]), (10, 20));
        assert!(sent_at(vec!["sent x 1".into()]).is_err());
    }
}
