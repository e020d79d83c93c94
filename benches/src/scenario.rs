//! A benchmark scenario and what it is handed to run.

use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;

use crate::config::RunConfig;
use crate::peer_process::PeerProcess;
use crate::peer_role::PeerRole;
use crate::pin::Pinning;
use crate::report::{Measurement, MemoryRow, Skipped, Wait};
use crate::target::Target;
use crate::wait_mode::WaitMode;

/// How long the measuring thread pauses before each `event` hop.
///
/// A blocking crossbeam `recv` spins and yields for a few microseconds before it
/// parks the thread. Back to back, hops would land in that spin and an `event` row
/// would hide the wake-up; a scenario that pauses before some hops (to write a frame)
/// would pay it and others not. After this pause every blocked receiver is asleep, as
/// it is between messages at robot rates, so every `event` row includes one wake-up
/// per hop and rows compare.
pub const EVENT_GAP: Duration = Duration::from_micros(50);

/// One benchmark: measures one thing on one runtime or peer.
///
/// `run` is called on the measuring thread (pinned to the measuring core under
/// `--pin`) and returns one [`Measurement`] per wait strategy it covers. A scenario
/// that compares itself with another names it as the row's baseline; the baseline
/// scenario must be listed before it in [`crate::scenarios::all`].
pub trait Scenario {
    /// The name in the table, the JSON and `--only` (`inproc-hop-small`, …).
    fn name(&self) -> &'static str;
    /// One line saying what is measured, for `--list`.
    fn summary(&self) -> &'static str;
    /// Measures.
    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>>;

    /// The goals this scenario's rows are held to, printed with the table (none by
    /// default).
    fn targets(&self) -> Vec<Target> {
        Vec::new()
    }

    /// The peer side of a cross-process scenario, run in the peer process that
    /// [`Context::spawn_peer_process`] starts: echoes until told to stop, then returns
    /// notes for the report. Scenarios without a peer process keep this default.
    fn run_peer(&self, role: &PeerRole) -> anyhow::Result<Vec<String>> {
        anyhow::bail!("scenario {} has no peer process (asked for {:?})", self.name(), role.wait)
    }
}

/// The settings a scenario runs with.
#[derive(Debug, Clone, Default)]
pub struct Context {
    quick: bool,
    samples: Option<u64>,
    pin: Option<Pinning>,
    memory: Arc<Mutex<Vec<MemoryRow>>>,
    skipped: Arc<Mutex<Vec<Skipped>>>,
}

impl Context {
    /// The context of a run with `config`.
    pub fn new(config: &RunConfig) -> Self {
        Self {
            quick: config.quick,
            samples: config.samples,
            pin: config.pin,
            memory: Arc::default(),
            skipped: Arc::default(),
        }
    }

    /// Records a memory figure for the report's `memory` section.
    pub fn record_memory(&self, row: MemoryRow) {
        if let Ok(mut rows) = self.memory.lock() {
            rows.push(row);
        }
    }

    /// Records that row `name` could not be measured here, and why.
    pub fn skip(&self, name: &str, reason: impl Into<String>) {
        if let Ok(mut rows) = self.skipped.lock() {
            rows.push(Skipped { name: name.to_owned(), reason: reason.into() });
        }
    }

    /// The skipped rows recorded so far, taken out.
    pub fn take_skipped(&self) -> Vec<Skipped> {
        self.skipped.lock().map(|mut rows| std::mem::take(&mut *rows)).unwrap_or_default()
    }

    /// The memory figures recorded so far, taken out.
    pub fn take_memory(&self) -> Vec<MemoryRow> {
        self.memory.lock().map(|mut rows| std::mem::take(&mut *rows)).unwrap_or_default()
    }

    /// How many samples to record: `--samples` if given, else `quick` under `--quick`,
    /// else `full`.
    pub fn samples(&self, full: u64, quick: u64) -> u64 {
        self.samples.unwrap_or(if self.quick { quick } else { full })
    }

    /// Untimed iterations before `samples` timed ones: enough to fault in pages, fill
    /// caches and let the CPU clock up, never more than a tenth of the run.
    pub fn warmup(&self, samples: u64) -> u64 {
        (samples / 10).clamp(1, 10_000)
    }

    /// The cores, if pinning.
    pub fn pinning(&self) -> Option<Pinning> {
        self.pin
    }

    /// Call right before starting a hop's timer: under [`Wait::Event`], waits
    /// [`EVENT_GAP`] (busy, so the measuring core itself stays awake).
    pub fn before_hop(&self, wait: Wait) {
        if wait == Wait::Event {
            let start = Instant::now();
            while start.elapsed() < EVENT_GAP {
                std::hint::spin_loop();
            }
        }
    }

    /// Pins threads the runtime starts (unit and sampler workers) to the peer core
    /// under `--pin`, from inside the user code they call.
    pub fn worker_pin(&self) -> WorkerPin {
        WorkerPin { pin: self.pin, failed: Arc::new(AtomicBool::new(false)) }
    }

    /// Starts a peer thread (an echo, a producer), pinned to the peer core under
    /// `--pin`. Its result comes back through [`Peer::join`].
    pub fn spawn_peer<F>(&self, name: &str, body: F) -> anyhow::Result<Peer>
    where
        F: FnOnce() -> anyhow::Result<()> + Send + 'static,
    {
        let pin = self.pin;
        let thread = std::thread::Builder::new()
            .name(format!("esgm-bench-{name}"))
            .spawn(move || {
                if let Some(p) = pin {
                    p.pin_peer_thread()?;
                }
                body()
            })
            .with_context(|| format!("could not start the {name} thread"))?;
        Ok(Peer { name: name.to_owned(), thread })
    }

    /// Starts `esgm-bench` again as the peer process of `scenario`, waiting with `wait`
    /// and meeting in `domain`; pinned to the peer core under `--pin`.
    pub fn spawn_peer_process(
        &self,
        scenario: &str,
        wait: WaitMode,
        domain: &str,
    ) -> anyhow::Result<PeerProcess> {
        self.spawn_peer_process_as(scenario, wait, domain, None)
    }

    /// [`Context::spawn_peer_process`] for a scenario with several kinds of peer:
    /// `arg` tells the peer which it is ([`PeerRole::arg`]).
    pub fn spawn_peer_process_as(
        &self,
        scenario: &str,
        wait: WaitMode,
        domain: &str,
        arg: Option<&str>,
    ) -> anyhow::Result<PeerProcess> {
        PeerProcess::spawn(&PeerRole {
            scenario: scenario.to_owned(),
            wait,
            domain: domain.to_owned(),
            core: self.pin.map(|p| p.peer_core()),
            arg: arg.map(str::to_owned),
        })
    }

    /// Starts `command`, a peer that is not `esgm-bench` (a bridge, a server), pinned to
    /// the peer core under `--pin`, every thread of it. A child inherits the affinity of
    /// the thread that starts it, and the measuring thread is pinned to the measuring
    /// core: started from there, the peer would share that core with the measuring
    /// thread (which busy-polls in `spin` rows) and leave the peer core idle. So it is
    /// started from a thread pinned to the peer core.
    pub fn spawn_peer_command(&self, command: &mut Command) -> anyhow::Result<Child> {
        let Some(pin) = self.pin else {
            return Ok(command.spawn()?);
        };
        std::thread::scope(|s| {
            s.spawn(|| {
                pin.pin_peer_thread()?;
                Ok(command.spawn()?)
            })
            .join()
            .map_err(|_| anyhow::anyhow!("the thread starting a peer process panicked"))?
        })
    }

    /// True under `--quick`.
    pub fn is_quick(&self) -> bool {
        self.quick
    }
}

/// Pins runtime worker threads on their first call into bench code; cloned into each
/// sensor or unit closure.
#[derive(Debug, Clone)]
pub struct WorkerPin {
    pin: Option<Pinning>,
    failed: Arc<AtomicBool>,
}

impl WorkerPin {
    /// Pins the calling thread (once) if pinning. A failure cannot be returned from
    /// inside a unit or sensor, so it is remembered for [`WorkerPin::check`].
    pub fn apply(&self) {
        if let Some(p) = self.pin {
            if p.pin_peer_thread_once().is_err() {
                self.failed.store(true, Ordering::Relaxed);
            }
        }
    }

    /// Fails if any worker could not be pinned.
    pub fn check(&self) -> anyhow::Result<()> {
        if self.failed.load(Ordering::Relaxed) {
            anyhow::bail!("--pin: a runtime worker thread could not be pinned to its core");
        }
        Ok(())
    }
}

/// A running peer thread.
#[derive(Debug)]
pub struct Peer {
    name: String,
    thread: JoinHandle<anyhow::Result<()>>,
}

impl Peer {
    /// Waits for the peer to finish and returns its error, if any.
    ///
    /// Only join a peer that is expected to finish: after a failure on the measuring
    /// side, drop the `Peer` instead (the thread then ends on its own timeout).
    pub fn join(self) -> anyhow::Result<()> {
        match self.thread.join() {
            Ok(result) => result.with_context(|| format!("the {} thread failed", self.name)),
            Err(_) => anyhow::bail!("the {} thread panicked", self.name),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_follow_quick_and_override() {
        let full = Context::new(&RunConfig::default());
        assert_eq!(full.samples(100, 10), 100);
        let quick = Context::new(&RunConfig { quick: true, ..RunConfig::default() });
        assert_eq!(quick.samples(100, 10), 10);
        let over = Context::new(&RunConfig { quick: true, samples: Some(3), ..Default::default() });
        assert_eq!(over.samples(100, 10), 3);
        assert_eq!(over.warmup(3), 1);
        assert_eq!(full.warmup(1_000_000), 10_000);
    }

    #[test]
    fn a_failing_peer_reports_its_name() {
        let ctx = Context::default();
        let peer = ctx.spawn_peer("echo", || anyhow::bail!("boom")).unwrap();
        let e = format!("{:#}", peer.join().unwrap_err());
        assert!(e.contains("echo") && e.contains("boom"), "{e}");
    }
}
