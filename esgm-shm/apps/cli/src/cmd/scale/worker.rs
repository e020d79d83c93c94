//! One process of `esgm scale`'s synthetic robot (`esgm scale-worker`, started by the
//! harness): it connects, creates the trajectories the profile has it write, reads
//! those it has it read, and reports to the harness on its stdout:
//! - `READY {json}` once every read trajectory is subscribed to ([`Ready`]);
//! - `REPORT {json}` when it is told to stop ([`Report`]).
//!
//! Between the two it idles until the harness writes `go` to its stdin, then writes its
//! trajectories at their rates (a camera's pixels rendered into the trajectory's own
//! shared memory, as a camera does), adds once to a trajectory another process
//! writes (the first add from a non-writer, timed), and stamps each structure with its
//! creation time, so that every reader measures how long it took to hold it. It stops
//! at `stop`, reports, and leaves at `exit` (the harness asks every process for its
//! counters in between), or when its stdin closes (the harness is gone). Waiting on a
//! pipe costs nothing while idle: polling files in 60 workers cost 1 % of a core, the
//! whole domain's budget.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use esgm_core::esgm::TrajectorySpec;
use esgm_core::library::{Image, RobotState};
use esgm_core::policy::FluentStreamPolicy;
use esgm_core::{
    CacheConstraint, Clock, Entity, EntityStructure, EntityTrajectoryStructure, Esgm,
    InProcessTrajectory, SubscribeOptions, SystemClock,
};
use esgm_shm::ShmEsgm;
use serde::{Deserialize, Serialize};

use super::profile::{Class, Profile};

/// The options of one process of a synthetic robot (`esgm scale-worker`,
/// `esgm chaos-worker`).
#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    /// The run directory (the profile as `profile.json`).
    #[arg(long, value_name = "DIR")]
    pub run: PathBuf,
    /// This process's number in the profile.
    #[arg(long)]
    pub index: usize,
}

/// What a worker says once it is set up.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Ready {
    /// Its number.
    pub index: usize,
    /// Its pid.
    pub pid: u32,
    /// How long `connect` took, in milliseconds.
    pub connect_ms: f64,
}

/// What a worker says at the end.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Report {
    /// Its number.
    pub index: usize,
    /// How long its first add to a trajectory another process writes took, in
    /// milliseconds (`None`: it reads none it can add to).
    pub first_add_ms: Option<f64>,
    /// Structures it added to its own trajectories.
    pub published: u64,
    /// Per class, the latency of every structure it received, in microseconds (from
    /// the writer's creation to this process holding it).
    pub latency_us: BTreeMap<Class, Vec<u32>>,
    /// Adds or subscriptions that failed, with why.
    pub errors: Vec<String>,
}

/// Cache of each trajectory: enough history for late readers, bounded memory.
pub(crate) const CACHE: usize = 10;
/// Images of a camera trajectory kept.
pub(crate) const IMAGE_CACHE: usize = 4;
const WIDTH: i64 = 640;
const HEIGHT: i64 = 480;
/// Readers a trajectory admits beyond the profile's: the processes `esgm scale`
/// starts later to time a new process's connect and first add.
pub(crate) const JOINING: usize = 1;
/// How long a worker waits for the trajectories it reads to be created by others.
const PATIENCE: Duration = Duration::from_secs(120);

/// Runs one worker.
pub fn run(domain: &str, a: &WorkerArgs) -> anyhow::Result<()> {
    let profile: Profile = serde_json::from_slice(
        &std::fs::read(a.run.join("profile.json")).context("cannot read the profile")?,
    )
    .context("malformed profile")?;
    let started = Instant::now();
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(format!("scale-{}", a.index))
        .timeout(Duration::from_secs(10))
        .connect()
        .context("cannot connect")?;
    let connect_ms = started.elapsed().as_secs_f64() * 1e3;
    let mut report = Report { index: a.index, ..Report::default() };

    let mut written = Vec::new();
    for t in profile.written_by(a.index) {
        let cache = if t.class == Class::Image { IMAGE_CACHE } else { CACHE };
        let spec = TrajectorySpec::primitive(&t.name, t.class.type_name())
            .policy(FluentStreamPolicy::default().cache(CacheConstraint::Elements(cache)))
            .readers(t.readers.len() + JOINING);
        let handle =
            esgm.create_trajectory(spec).with_context(|| format!("cannot create `{}`", t.name))?;
        written.push((handle, t.class, t.hz));
    }
    let latencies: Arc<Mutex<BTreeMap<Class, Vec<u32>>>> = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let mut reads = Vec::new();
    for t in profile.read_by(a.index) {
        let handle = wait_for_trajectory(&esgm, &t.name)?;
        let subscription = handle
            .subscribe(SubscribeOptions::default())
            .with_context(|| format!("cannot subscribe to `{}`", t.name))?;
        let (class, latencies, stop) = (t.class, Arc::clone(&latencies), Arc::clone(&stop));
        // Blocked in a long receive while idle, as a robot's reader is: a short timeout
        // here would be the harness's own wake-ups, counted as esgm's idle cost. Each
        // latency is kept at once; the thread ends with the process.
        std::thread::spawn(move || {
            let clock = SystemClock;
            while !stop.load(Ordering::Acquire) {
                if let Ok(sample) = subscription.recv_timeout(Duration::from_secs(3600)) {
                    let held = clock.now();
                    let us = (held - sample.structure.create_time()).max(0) / 1_000;
                    if stop.load(Ordering::Acquire) {
                        break;
                    }
                    if let Ok(mut all) = latencies.lock() {
                        all.entry(class).or_default().push(u32::try_from(us).unwrap_or(u32::MAX));
                    }
                }
            }
        });
        reads.push((handle, t.class));
    }
    let phase = Phases::from_stdin();
    let ready = Ready { index: a.index, pid: std::process::id(), connect_ms };
    println!("READY {}", serde_json::to_string(&ready)?);

    phase.wait(Phase::Go);
    // The first add from a process that does not write the trajectory.
    if let Some((handle, _)) = reads.iter().find(|(_, c)| *c != Class::Image) {
        let es = robot_state(SystemClock.now());
        let t = Instant::now();
        match handle.add(es) {
            Ok(_) => report.first_add_ms = Some(t.elapsed().as_secs_f64() * 1e3),
            Err(e) => report.errors.push(format!("first add to `{}`: {e}", handle.name())),
        }
    }
    publish(&written, &phase, &mut report);
    stop.store(true, Ordering::Release);
    match latencies.lock() {
        Ok(mut all) => report.latency_us = std::mem::take(&mut *all),
        // Poisoned: a reader panicked, which the report says.
        Err(_) => report.errors.push("a reader thread panicked".into()),
    }
    println!("REPORT {}", serde_json::to_string(&report)?);
    // Connected until told to leave: the harness asks every process for its counters.
    phase.wait(Phase::Exit);
    drop(esgm);
    Ok(())
}

/// A handle on `name` once its writer created it.
pub(crate) fn wait_for_trajectory(
    esgm: &ShmEsgm,
    name: &str,
) -> anyhow::Result<InProcessTrajectory> {
    let deadline = Instant::now() + PATIENCE;
    loop {
        match esgm.get_entity_trajectory_structure(name) {
            Ok(h) => return Ok(h),
            Err(esgm_core::esgm::LookupError::NoSuchEntityStructure { .. })
                if Instant::now() < deadline =>
            {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => return Err(e).with_context(|| format!("cannot read `{name}`")),
        }
    }
}

/// Waits until `file` exists (or `or_else` does).
/// The phases of a run, in order; the harness moves every worker on with one line
/// each on its stdin (`go`, `stop`, `exit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Phase {
    /// Connected and subscribed, idle.
    Setup,
    /// Writing at the profile's rates.
    Go,
    /// Reporting.
    Stop,
    /// Leaving.
    Exit,
}

impl Phase {
    /// The line that moves a worker to this phase.
    pub fn line(self) -> &'static str {
        match self {
            Phase::Setup => "setup",
            Phase::Go => "go",
            Phase::Stop => "stop",
            Phase::Exit => "exit",
        }
    }
}

/// The phase the harness has moved this worker to, read from stdin by a thread of its
/// own; a closed stdin is [`Phase::Exit`]. A later phase passes every earlier wait.
#[derive(Clone)]
struct Phases(Arc<(Mutex<Phase>, std::sync::Condvar)>);

impl Phases {
    fn from_stdin() -> Self {
        let phases = Phases(Arc::new((Mutex::new(Phase::Setup), std::sync::Condvar::new())));
        let reader = phases.clone();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                let next = [Phase::Go, Phase::Stop, Phase::Exit]
                    .into_iter()
                    .find(|p| p.line() == line.trim());
                if let Some(next) = next {
                    reader.advance(next);
                }
            }
            reader.advance(Phase::Exit);
        });
        phases
    }

    fn advance(&self, to: Phase) {
        let (phase, changed) = &*self.0;
        if let Ok(mut p) = phase.lock() {
            *p = (*p).max(to);
        }
        changed.notify_all();
    }

    fn reached(&self, at: Phase) -> bool {
        self.0.0.lock().map_or(true, |p| *p >= at)
    }

    fn wait(&self, at: Phase) {
        let (phase, changed) = &*self.0;
        let Ok(mut p) = phase.lock() else { return };
        while *p < at {
            p = match changed.wait(p) {
                Ok(p) => p,
                // Poisoned: the thread that panicked reports it; stop waiting.
                Err(_) => return,
            };
        }
    }
}

fn robot_state(now: i64) -> EntityStructure {
    RobotState { x: 1.0, y: 2.0, dir: 3.0 }.to_structure("robot", now, now)
}

/// The next structure of `handle`, made now: an image's pixels rendered into the
/// trajectory's own buffer.
fn make(handle: &InProcessTrajectory, class: Class, n: u64) -> EntityStructure {
    let now = SystemClock.now();
    make_at(handle, class, n, (now, now))
}

/// The `n`th structure of `handle` of `class`, valid and created at `times`: a
/// `RobotState`, or an image whose pixels are rendered into the trajectory's own
/// buffer, as a camera does (`esgm chaos` writes the same robot).
pub(crate) fn make_at(
    handle: &InProcessTrajectory,
    class: Class,
    n: u64,
    (valid, created): (i64, i64),
) -> EntityStructure {
    if class != Class::Image {
        return RobotState { x: n as f64, y: 2.0, dir: 3.0 }.to_structure("robot", valid, created);
    }
    let octets = match handle.image_buffer(WIDTH, HEIGHT, Image::FORMAT_RGB8) {
        Some(mut buffer) => {
            let shade = (n % 251) as u8;
            buffer.pixels_mut().fill(shade);
            buffer.into_octets()
        }
        None => vec![0u8; (WIDTH * HEIGHT * 3) as usize].into(),
    };
    Image { width: WIDTH, height: HEIGHT, format: Image::FORMAT_RGB8, image_data: octets }
        .to_structure("camera", valid, created)
}

/// A frame of the profile's cameras (on the heap), to size their caches.
pub(crate) fn image_of_profile() -> EntityStructure {
    let pixels = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    Image { width: WIDTH, height: HEIGHT, format: Image::FORMAT_RGB8, image_data: pixels.into() }
        .to_structure("camera", 0, 0)
}

/// Adds to every written trajectory at its rate until the harness says `stop`.
fn publish(written: &[(InProcessTrajectory, Class, f64)], phase: &Phases, report: &mut Report) {
    let mut pacer = Pacer::new(written.iter().map(|(_, _, hz)| *hz));
    let mut n = 0u64;
    while let Some(i) = pacer.next(|| phase.reached(Phase::Stop)) {
        let (handle, class, _) = &written[i];
        n += 1;
        match handle.add(make(handle, *class, n)) {
            Ok(_) => report.published += 1,
            Err(e) => {
                if report.errors.len() < 10 {
                    report.errors.push(format!("add to `{}`: {e}", handle.name()));
                }
            }
        }
    }
}

/// When each of several trajectories is next due, each at its own rate, the first
/// adds spread over a period as independent sensors' would be; a trajectory behind by
/// more than a period (a stalled machine) skips, it does not burst.
pub(crate) struct Pacer {
    due: Vec<(Instant, Duration)>,
    next_look: Instant,
}

impl Pacer {
    /// A pacer of trajectories at `hz`, due from now.
    pub(crate) fn new(hz: impl Iterator<Item = f64>) -> Self {
        let start = Instant::now();
        let due = hz
            .enumerate()
            .map(|(i, hz)| {
                let period = Duration::from_secs_f64(1.0 / hz);
                (start + period.mul_f64((i % 16) as f64 / 16.0), period)
            })
            .collect();
        Self { due, next_look: start }
    }

    /// Waits until a trajectory is due and returns it, then due again a period later;
    /// `None` once `stop` (asked at most every 50 ms) says so.
    pub(crate) fn next(&mut self, mut stop: impl FnMut() -> bool) -> Option<usize> {
        loop {
            let now = Instant::now();
            if now >= self.next_look {
                if stop() {
                    return None;
                }
                self.next_look = now + Duration::from_millis(50);
            }
            let Some((i, when)) =
                self.due.iter().enumerate().map(|(i, d)| (i, d.0)).min_by_key(|d| d.1)
            else {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            };
            if when > now {
                std::thread::sleep((when - now).min(Duration::from_millis(50)));
                continue;
            }
            let (at, period) = &mut self.due[i];
            *at += *period;
            if *at + *period < now {
                *at = now + *period;
            }
            return Some(i);
        }
    }
}
