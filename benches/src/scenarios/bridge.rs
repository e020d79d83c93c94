//! `bridge-small` and `bridge-image`: a structure added in domain A until a subscriber
//! in domain B holds it, through both domains' bridges (`esgm-bridge`, Zenoh over
//! loopback TCP). Compared with `zenoh-tcp-small` and `zenoh-tcp-image`, raw Zenoh
//! between two processes with its shared memory off (every payload through the TCP
//! link, as between two hosts, which the bridge is for), in the same run.
//!
//! The measuring process runs both domains' coordinators on threads of its own, and
//! connects to both: it writes A's primitive trajectory `bench` (the Image through the
//! trajectory's shared-memory loans, as a camera renders) and subscribes to B's
//! `bench`, which B's bridge imports. The exporting and importing bridges are two
//! `esgm-bridge` processes, so a structure crosses four processes: the writer, A's
//! bridge (reads A's shared memory, sends one Zenoh message), B's bridge (validates the
//! payload, adds it through B's gate into B's shared memory) and the subscriber. One
//! clock and one thread time it ([`Method::OneWay`]): the add until the subscription
//! returned the sample with that valid time. `spin` polls the subscription, `event`
//! blocks on it; the next add waits until the last one arrived.
//!
//! Under `--pin` the measuring process (writer, subscriber, both coordinators) is on
//! the measuring core and both bridges on the peer core, as raw Zenoh's peer process
//! is. (Started from the pinned measuring thread, they used to inherit its core and
//! share it with the busy-polling subscriber: `spin` was then about 1 ms, the time
//! each of their wake-ups waited for the poller's time slice to end.)
//!
//! Throughput: after the latency rows, a burst of structures is added back to back
//! and the row notes how many arrived per second in B and how many were lost, as the
//! importer's counters say (a full queue, a gap in the exporter's sequence).
//!
//! The bridges are the release `esgm-bridge` next to `esgm-bench` (built by
//! `cargo build --release -p esgm-bridge`); without it, both rows are skipped with
//! that command.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::{
    CacheConstraint, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, TrajectorySpec,
    TypeRegistry,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::ipc_connect_echo::{connect, make_for, next, stamped, subscribe};
use super::ipc_payload::Kind;
use super::zenoh_peer;
use crate::domain_end::DomainEnd;
use crate::latency::Latency;
use crate::patience::Patience;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// What to build to measure the bridge.
pub const HOW: &str = "esgm-bridge is not built next to esgm-bench (cargo build --release -p \
                       esgm-bridge)";

/// The trajectory both domains call `bench`.
const TRAJECTORY: &str = "bench";

/// How long a bridge may take to start, or B to see the imported trajectory.
const START_WITHIN: Duration = Duration::from_secs(60);

/// One payload through two bridges (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Bridge {
    name: &'static str,
    kind: Kind,
}

impl Bridge {
    /// The small structure.
    pub const SMALL: Bridge = Bridge { name: "bridge-small", kind: Kind::Small };
    /// The image.
    pub const IMAGE: Bridge = Bridge { name: "bridge-image", kind: Kind::Image };

    /// Raw Zenoh between two processes with shared memory off: what crosses between
    /// hosts, as the bridge's payloads do.
    fn zenoh_row(&self) -> &'static str {
        match self.kind {
            Kind::Small => zenoh_peer::Zenoh::TCP_SMALL.name(),
            Kind::Image => zenoh_peer::Zenoh::TCP_IMAGE.name(),
        }
    }

    /// Structures per latency row, and in the throughput burst.
    fn counts(&self, ctx: &Context) -> (u64, u64) {
        match self.kind {
            Kind::Small => (ctx.samples(5_000, 500), ctx.samples(20_000, 2_000)),
            Kind::Image => (ctx.samples(1_000, 100), ctx.samples(300, 50)),
        }
    }
}

/// The `esgm-bridge` next to this executable.
fn bridge_binary() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let path = exe.with_file_name("esgm-bridge");
    path.exists().then_some(path)
}

/// An `esgm-bridge` process, killed when dropped, whose counter lines are kept.
struct BridgeProcess {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl BridgeProcess {
    /// Starts a bridge, on the peer core under `--pin` (as the raw Zenoh row's peer
    /// process).
    fn start(ctx: &Context, binary: &PathBuf, domain: &str, args: &[&str]) -> anyhow::Result<Self> {
        let mut command = Command::new(binary);
        command
            .args(["--domain", domain, "--report-every", "200ms"])
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null());
        let mut child = ctx
            .spawn_peer_command(&mut command)
            .with_context(|| format!("cannot run {}", binary.display()))?;
        let stdout = child.stdout.take().context("no stdout")?;
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        let mut bridge = Self { child, lines };
        bridge.wait(|l| l.starts_with("esgm-bridge: domain"))?;
        Ok(bridge)
    }

    /// The first line `accept` takes, within [`START_WITHIN`].
    fn wait(&mut self, accept: impl Fn(&str) -> bool) -> anyhow::Result<String> {
        let deadline = Instant::now() + START_WITHIN;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if accept(&line) => return Ok(line),
                Ok(_) => {}
                Err(_) => {
                    let status = self.child.try_wait().ok().flatten();
                    bail!("esgm-bridge gave no expected line within {START_WITHIN:?} ({status:?})")
                }
            }
        }
    }

    /// The importer's latest counters of `bench` (a JSON line), waiting for the next.
    fn import_counters(&mut self) -> Option<serde_json::Value> {
        while self.lines.try_recv().is_ok() {}
        let line = self.wait(|l| l.contains("\"import\"") && l.contains(TRAJECTORY)).ok()?;
        serde_json::from_str(&line).ok()
    }
}

impl Drop for BridgeProcess {
    fn drop(&mut self) {
        // Already gone is as good as killed.
        let _killed = self.child.kill();
        let _reaped = self.child.wait();
    }
}

impl Scenario for Bridge {
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        match self.kind {
            Kind::Small => {
                "~120-byte RobotState, add in domain A -> subscriber in domain B, through A's \
                 and B's esgm-bridge (Zenoh, loopback TCP)"
            }
            Kind::Image => {
                "921,600-byte Image, add in domain A -> subscriber in domain B, through A's and \
                 B's esgm-bridge (Zenoh, loopback TCP)"
            }
        }
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let Some(binary) = bridge_binary() else {
            ctx.skip(self.name, HOW);
            return Ok(Vec::new());
        };
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let (a, b) = (unique_domain("esgm-bench-bridge-a"), unique_domain("esgm-bench-bridge-b"));
        let _ends = (DomainEnd::new(&a), DomainEnd::new(&b));
        let _coordinator_a = Coordinator::spawn(&a, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {a}"))?;
        let _coordinator_b = Coordinator::spawn(&b, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {b}"))?;
        let esgm_a = connect(&a, "bench-writer")?;
        let esgm_b = connect(&b, "bench-reader")?;
        let cache = match self.kind {
            Kind::Small => 1024,
            Kind::Image => 8,
        };
        let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(cache));
        let writer = esgm_a
            .create_trajectory(
                TrajectorySpec::primitive(TRAJECTORY, self.kind.type_name()).policy(policy),
            )
            .context("could not create the exported trajectory")?;

        let port = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let import = format!("{a}/{TRAJECTORY}");
        let mut importer =
            BridgeProcess::start(ctx, &binary, &b, &["--listen", &endpoint, "--import", &import])?;
        let _exporter = BridgeProcess::start(
            ctx,
            &binary,
            &a,
            &["--connect", &endpoint, "--export", TRAJECTORY],
        )?;

        // B sees the trajectory once the first structure crossed.
        let started = Instant::now();
        let first = make_for(&writer, self.kind, 0);
        writer.add(stamped(first, 1))?;
        while esgm_b.get_entity_trajectory_structure(TRAJECTORY).is_err() {
            if started.elapsed() > START_WITHIN {
                bail!("domain B did not import `{TRAJECTORY}` within {START_WITHIN:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let reader = esgm_b.get_entity_trajectory_structure(TRAJECTORY)?;
        let sub = subscribe(&esgm_b, TRAJECTORY)?;
        let payload_bytes = esgm_core::codec::encoded_len(&self.kind.make(0))? as u64;
        let (samples, burst) = self.counts(ctx);
        let warmup = ctx.warmup(samples);
        let mut seq: i64 = 10;
        let mut rows = Vec::new();
        for mode in WaitMode::SPIN_AND_BLOCK {
            let mut one_way = Latency::new()?;
            let mut write = Latency::new()?;
            let mut patience = Patience::alone();
            drop(sub.drain());
            for i in 0..warmup + samples {
                seq += 1;
                let made = Instant::now();
                let es = stamped(make_for(&writer, self.kind, i), seq);
                let written = made.elapsed();
                let t0 = Instant::now();
                writer.add(es)?;
                loop {
                    let s = next(&sub, mode, &mut patience, "the structure through the bridges")?;
                    if s.valid_time() == seq {
                        break;
                    }
                }
                if i >= warmup {
                    one_way.record(t0.elapsed());
                    write.record(written);
                }
            }
            let mut row = one_way
                .measurement(&mode.row_name(self.name), mode.wait())
                .payload_bytes(payload_bytes)
                .method(Method::OneWay)
                .wait_strategy(mode.label())
                .baseline(self.zenoh_row())
                .producer_write_p50_ns(write.quantile(0.5))
                .if_empty("nothing crossed")
                .note(
                    "add in domain A (this process) -> A's esgm-bridge -> Zenoh over loopback \
                     TCP -> B's esgm-bridge (validates, adds through B's gate) -> a subscriber \
                     in domain B (this process); both coordinators on threads of this process",
                );
            if mode == WaitMode::Block {
                let ends =
                    Ends { writer: &writer, reader: &reader, sub: &sub, importer: &mut importer };
                row = self.burst(row, ends, burst, &mut seq)?;
            }
            rows.push(row);
        }
        Ok(rows)
    }

    /// p50 ≤ 1.5 × raw Zenoh between two processes, at the same wait.
    fn targets(&self) -> Vec<Target> {
        Wait::BOTH.iter().map(|&w| Target::at_most(self.name, self.zenoh_row(), w, 1.5)).collect()
    }
}

/// Both ends of the measured path: A's trajectory, B's, B's subscription, B's bridge.
struct Ends<'a> {
    writer: &'a esgm_core::InProcessTrajectory,
    reader: &'a esgm_core::InProcessTrajectory,
    sub: &'a esgm_core::Subscription<esgm_core::Sample>,
    importer: &'a mut BridgeProcess,
}

impl Bridge {
    /// Adds `n` structures back to back and notes what arrived in B per second, and
    /// what the importer counted lost.
    fn burst(
        &self,
        row: Measurement,
        ends: Ends<'_>,
        n: u64,
        seq: &mut i64,
    ) -> anyhow::Result<Measurement> {
        let Ends { writer, reader, sub, importer } = ends;
        drop(sub.drain());
        let first = *seq + 1;
        let started = Instant::now();
        for i in 0..n {
            *seq += 1;
            writer.add(stamped(make_for(writer, self.kind, i), *seq))?;
        }
        let last = *seq;
        let mut arrived = 0_u64;
        let mut last_at = started;
        let quiet = Duration::from_secs(2);
        loop {
            match sub.recv_timeout(quiet) {
                Ok(s) if (first..=last).contains(&s.valid_time()) => {
                    arrived += 1;
                    last_at = Instant::now();
                    if s.valid_time() == last {
                        break;
                    }
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
        let secs = last_at.duration_since(started).as_secs_f64().max(1e-9);
        let rate = arrived as f64 / secs;
        let lost = importer.import_counters().map(|c| c["lost"].clone());
        let in_b = match reader.stats() {
            Ok(s) => format!(
                "B's subscription overflowed {} times in all, and B's shared-memory queue was \
                 overwritten before this process read {} (both: this process reading slower \
                 than they came)",
                s.subscriber_overflow,
                s.dropped_for(esgm_core::DropCause::Lost)
            ),
            Err(e) => format!("B's counters could not be read: {e}"),
        };
        let unit = match self.kind {
            Kind::Small => "structures/s",
            Kind::Image => "frames/s",
        };
        Ok(row.throughput(rate, n - arrived).note(format!(
            "burst: {n} added back to back in A, {arrived} held by B's subscriber at {rate:.0} \
             {unit}; the importer's loss counters: {}; {in_b}",
            lost.map_or_else(|| "not reported".to_owned(), |l| l.to_string())
        )))
    }
}
