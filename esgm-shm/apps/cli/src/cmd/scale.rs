//! `esgm scale`: a synthetic robot in a fresh domain, to see how esgm holds up at a
//! real robot's size (P6).
//!
//! It starts a coordinator sized for the profile (`--max-processes`), then one
//! `esgm scale-worker` process per process of the profile ([`profile`]: by default 300
//! trajectories in 60 processes, `tf` at 100 Hz read by all of them, ten 640×480
//! cameras at 30 Hz, the rest small structures at 10–50 Hz with 1–4 readers). Once
//! every worker is set up it measures, with nothing flowing, each process's private
//! memory (`RssAnon`) and resident size, the domain's `/dev/shm` files (those its
//! processes map, by allocated blocks) and CPU over `--idle-seconds`; then it lets the
//! workers write at their rates for `--seconds` and measures CPU again; then it
//! collects what each worker measured (connect time, first add to a trajectory it
//! does not write, every structure's latency until the reader held it) and every
//! trajectory's losses by cause (`esgm stats`).
//!
//! It prints a table and a verdict against the targets ([`verdict`]), writes
//! `scale.json` and `scale.png` into `--out`, stops the system and checks that nothing
//! of the domain is left. A missed target exits 1 (unless `--no-check`); something
//! left behind always does.

mod chart;
pub mod profile;
mod verdict;
pub mod worker;

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufRead;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_shm::control::StateDir;
use esgm_shm::unique_domain;
use esgm_shm::{DEFAULT_MAX_PROCESSES, DEFAULT_READERS, DomainLimits};
use serde::Serialize;

use super::soak::probe;
use super::soak::sample::Counts;
use profile::{Class, Profile};
use worker::{Phase, Ready, Report};

pub use worker::WorkerArgs;

/// `esgm scale` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The robot's size.
    #[command(flatten)]
    pub size: profile::Size,
    /// Processes reading `tf` (default: every other process).
    #[arg(long)]
    pub readers: Option<usize>,
    /// Seconds the domain has to settle once every process is set up, before the
    /// idle measurement (a robot's domain settles within 10 s).
    #[arg(long, default_value_t = 10.0, value_parser = crate::span_arg::seconds)]
    pub settle_seconds: f64,
    /// Seconds of idle measurement, once the domain settled.
    #[arg(long, default_value_t = 60.0, value_parser = crate::span_arg::seconds)]
    pub idle_seconds: f64,
    /// Seconds of writing at the profile's rates.
    #[arg(long, default_value_t = 20.0, value_parser = crate::span_arg::seconds)]
    pub seconds: f64,
    /// Directory for `scale.json`, `scale.png` and the workers' logs (created).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
    /// Only report: exit 0 even when a target is missed.
    #[arg(long)]
    pub no_check: bool,
}

/// What one process used.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ProcessUse {
    /// Its pid.
    pub pid: u32,
    /// Private memory (`RssAnon`) once set up, bytes.
    pub private: u64,
    /// Resident size (`VmRSS`) once set up, bytes.
    pub resident: u64,
    /// Private memory at the end of the writing phase, bytes.
    pub private_loaded: u64,
    /// Percent of a core while idle.
    pub cpu_idle: f64,
    /// Percent of a core while writing.
    pub cpu_loaded: f64,
    /// Trajectories it writes and reads.
    pub writes: usize,
    /// Trajectories it reads.
    pub reads: usize,
}

/// Latency of one class of trajectory, over every reader.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Latency {
    /// Structures received.
    pub received: usize,
    /// Median, microseconds.
    pub p50_us: u32,
    /// 99th percentile, microseconds.
    pub p99_us: u32,
    /// Largest, microseconds.
    pub max_us: u32,
}

/// The whole run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Measured {
    /// The domain.
    pub domain: String,
    /// The profile's size.
    pub trajectories: usize,
    /// The profile's processes.
    pub processes: usize,
    /// Readers of `tf`.
    pub tf_readers: usize,
    /// The coordinator's use (it writes none of the profile's trajectories).
    pub coordinator: ProcessUse,
    /// Each worker's use, by number.
    pub workers: Vec<ProcessUse>,
    /// The domain's `/dev/shm` once set up: files and allocated bytes.
    pub shm_files: usize,
    /// Allocated bytes of those files.
    pub shm_bytes: u64,
    /// A new process's connect to the running domain, milliseconds: connections made
    /// one after another by this command, idle domain.
    pub connect_ms: Vec<f64>,
    /// A new process's first add to a trajectory another process writes, milliseconds
    /// (connected and its replica made beforehand).
    pub first_add_ms: Vec<f64>,
    /// The workers' connects at start-up (all at once), milliseconds.
    pub startup_connect_ms: Vec<f64>,
    /// The workers' first adds when writing starts (all at once), milliseconds.
    pub startup_first_add_ms: Vec<f64>,
    /// Latency by class.
    pub latency: BTreeMap<Class, Latency>,
    /// Structures the workers added.
    pub published: u64,
    /// Every trajectory's counters from its writer (with losses by cause).
    pub trajectory_counts: BTreeMap<String, Counts>,
    /// Errors the workers met.
    pub errors: Vec<String>,
    /// What of the domain was left after the stop.
    pub left_behind: Vec<String>,
}

/// Runs `esgm scale`.
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    let (trajectories, processes) = (a.size.trajectories, a.size.processes);
    let tf_readers = a.readers.unwrap_or(processes.saturating_sub(1));
    let profile = Profile::new(trajectories, processes, tf_readers)?;
    for (flag, v) in [("--idle-seconds", a.idle_seconds), ("--seconds", a.seconds)] {
        if !v.is_finite() || v <= 0.0 {
            bail!("{flag} must be a positive number of seconds, got {v}");
        }
    }
    if !a.settle_seconds.is_finite() || a.settle_seconds < 0.0 {
        bail!("--settle-seconds must be zero or more seconds, got {}", a.settle_seconds);
    }
    let domain =
        if domain == esgm_shm::SYSTEM_DOMAIN { unique_domain("scale") } else { domain.to_owned() };
    let run_dir = a.out.join("scale-run");
    std::fs::create_dir_all(run_dir.join("logs"))
        .with_context(|| format!("cannot create {}", run_dir.display()))?;
    std::fs::write(run_dir.join("profile.json"), serde_json::to_vec(&profile)?)
        .context("cannot write the profile")?;
    println!(
        "esgm scale: {} trajectories in {} processes (tf read by {}), domain `{domain}`",
        profile.trajectories.len(),
        profile.processes,
        profile.trajectories[0].readers.len()
    );
    // Room for every worker, this command and a margin.
    let limits = DomainLimits {
        max_processes: DEFAULT_MAX_PROCESSES.max(profile.processes + 16),
        readers: DEFAULT_READERS,
    };
    let state = StateDir::at(std::env::temp_dir().join(format!("esgm-{domain}")));
    let setup = super::up::Setup { limits, ..super::up::Setup::default() };
    let coordinator = super::up::spawn_detached_with(
        &domain,
        Some(state.path()),
        &setup,
        Stdio::inherit(),
        true,
    )?;
    let mut system = System { domain: domain.clone(), coordinator, state, workers: Vec::new() };
    let mut seen = BTreeSet::new();
    let measured = system.measure(&profile, a, &run_dir, &mut seen);
    let stopped = system.stop();
    let mut m = measured?;
    stopped?;
    m.left_behind = left_behind(&domain, &seen, &m);
    let v = verdict::judge(&m);
    verdict::print(&m, &v);
    let json = a.out.join("scale.json");
    let report = serde_json::json!({ "measured": &m, "verdict": &v });
    std::fs::write(&json, serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let png = a.out.join("scale.png");
    chart::draw(&m, &png)?;
    println!("\nwrote {} and {}", json.display(), png.display());
    if !m.left_behind.is_empty() {
        bail!("the run left {} things of `{domain}` behind", m.left_behind.len());
    }
    if !a.no_check && !v.passed() {
        bail!("{} targets missed", v.missed().count());
    }
    Ok(())
}

/// The system of one run: its coordinator and workers, stopped in order.
struct System {
    domain: String,
    coordinator: Child,
    state: StateDir,
    workers: Vec<Child>,
}

/// How long every worker has to be set up (connect, create, subscribe).
const SETUP: Duration = Duration::from_secs(300);
/// How long every worker has to report once told to stop.
const WIND_DOWN: Duration = Duration::from_secs(60);

impl System {
    /// Moves every worker to `phase` (a line on its stdin).
    fn tell(&mut self, phase: Phase) -> std::io::Result<()> {
        use std::io::Write;
        for w in &mut self.workers {
            if let Some(stdin) = &mut w.stdin {
                writeln!(stdin, "{}", phase.line())?;
                stdin.flush()?;
            }
        }
        Ok(())
    }

    fn measure(
        &mut self,
        profile: &Profile,
        a: &Args,
        run_dir: &std::path::Path,
        seen: &mut BTreeSet<PathBuf>,
    ) -> anyhow::Result<Measured> {
        let exe = std::env::current_exe().context("cannot find the esgm executable")?;
        let (lines, heard) = mpsc::channel::<(usize, String)>();
        for i in 0..profile.processes {
            let log = std::fs::File::create(run_dir.join("logs").join(format!("worker-{i}.log")))
                .context("cannot create a worker's log")?;
            let mut child = Command::new(&exe)
                .args(["--domain", &self.domain, "scale-worker", "--index", &i.to_string()])
                .arg("--run")
                .arg(run_dir)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .stderr(Stdio::from(log))
                .spawn()
                .context("cannot start a worker")?;
            let stdout = child.stdout.take().context("a worker without stdout")?;
            let lines = lines.clone();
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
                    if lines.send((i, line)).is_err() {
                        return;
                    }
                }
            });
            self.workers.push(child);
        }
        drop(lines);
        let mut m = Measured {
            domain: self.domain.clone(),
            trajectories: profile.trajectories.len(),
            processes: profile.processes,
            tf_readers: profile.trajectories[0].readers.len(),
            workers: vec![ProcessUse::default(); profile.processes],
            ..Measured::default()
        };
        let ready: Vec<Ready> =
            collect(&heard, "READY", profile.processes, SETUP, &mut self.workers)?;
        let mut pids = vec![self.coordinator.id()];
        for r in &ready {
            m.startup_connect_ms.push(r.connect_ms);
            m.workers[r.index].pid = r.pid;
            m.workers[r.index].writes = profile.written_by(r.index).count();
            m.workers[r.index].reads = profile.read_by(r.index).count();
        }
        pids.extend(m.workers.iter().map(|w| w.pid));
        m.coordinator.pid = self.coordinator.id();
        println!(
            "  every process set up; settling {:.0} s, then {:.0} s idle",
            a.settle_seconds, a.idle_seconds
        );
        std::thread::sleep(Duration::from_secs_f64(a.settle_seconds));
        let idle = cpu_percent(&pids, Duration::from_secs_f64(a.idle_seconds))?;
        let mut files = BTreeSet::new();
        for (k, pid) in pids.iter().enumerate() {
            let r = probe::resident(*pid)?;
            files.extend(probe::mapped_shm(*pid)?);
            let p = if k == 0 { &mut m.coordinator } else { &mut m.workers[k - 1] };
            (p.private, p.resident, p.cpu_idle) = (r.anon, r.rss, idle[k]);
        }
        let shm = probe::usage(&files)?;
        (m.shm_files, m.shm_bytes) = (shm.files, shm.allocated);
        seen.extend(files);
        let small = profile.trajectories.iter().filter(|t| t.class == Class::Small);
        let targets: Vec<&str> = small.map(|t| t.name.as_str()).take(NEW_PROCESSES).collect();
        (m.connect_ms, m.first_add_ms) = new_processes(&self.domain, &targets)?;
        println!("  writing at the profile's rates for {:.0} s", a.seconds);
        self.tell(Phase::Go).context("cannot start the workers")?;
        let loaded = cpu_percent(&pids, Duration::from_secs_f64(a.seconds))?;
        for (k, pid) in pids.iter().enumerate() {
            let r = probe::resident(*pid)?;
            seen.extend(probe::mapped_shm(*pid)?);
            let p = if k == 0 { &mut m.coordinator } else { &mut m.workers[k - 1] };
            (p.private_loaded, p.cpu_loaded) = (r.anon, loaded[k]);
        }
        self.tell(Phase::Stop).context("cannot stop the workers")?;
        let reports: Vec<Report> =
            collect(&heard, "REPORT", profile.processes, WIND_DOWN, &mut self.workers)?;
        // Every worker still connected, nothing flowing: every trajectory's counters.
        let tool = esgm_shm::ShmEsgm::builder()
            .domain(&self.domain)
            .host("esgm-scale")
            .timeout(WIND_DOWN)
            .tool()
            .connect()
            .context("cannot connect to collect the counters")?;
        let stats = tool.domain_stats().context("cannot collect the trajectories' counters")?;
        m.trajectory_counts =
            stats.trajectories.iter().map(|(n, r)| (n.clone(), Counts::of(r))).collect();
        drop(tool);
        self.tell(Phase::Exit).context("cannot let the workers leave")?;
        let mut latency: BTreeMap<Class, Vec<u32>> = BTreeMap::new();
        for r in reports {
            m.startup_first_add_ms.extend(r.first_add_ms);
            m.published += r.published;
            m.errors.extend(r.errors.into_iter().map(|e| format!("worker {}: {e}", r.index)));
            for (class, l) in r.latency_us {
                latency.entry(class).or_default().extend(l);
            }
        }
        m.latency = latency.into_iter().map(|(c, l)| (c, summary(l))).collect();
        Ok(m)
    }

    /// Stops the workers and the system (as `esgm demo` does).
    fn stop(&mut self) -> anyhow::Result<()> {
        // Whatever phase the run stopped in, the workers are told to leave: their stdin
        // closes (a worker that already left cannot be told).
        for w in &mut self.workers {
            drop(w.stdin.take());
        }
        let deadline = Instant::now() + Duration::from_secs(20);
        for w in &mut self.workers {
            while w.try_wait()?.is_none() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            if w.try_wait()?.is_none() {
                eprintln!("esgm: a worker did not leave; killing it");
                w.kill().context("cannot kill a worker")?;
                w.wait().context("cannot reap a worker")?;
            }
        }
        self.workers.clear();
        super::demo::stop(&self.domain, &mut self.coordinator, &self.state)
    }
}

impl Drop for System {
    fn drop(&mut self) {
        for w in &mut self.workers {
            if let Err(e) = w.kill() {
                tracing::debug!(error = %e, "a worker had left");
            }
            if let Err(e) = w.wait() {
                tracing::debug!(error = %e, "cannot reap a worker");
            }
        }
    }
}

/// Processes that join the running domain, one after another, to time a connect and a
/// first add.
const NEW_PROCESSES: usize = 10;

/// Times [`NEW_PROCESSES`] new connections to `domain` (as a process that stays, not a
/// tool) and, for each, its first add to one of `targets` (written by a worker),
/// its replica made beforehand.
fn new_processes(domain: &str, targets: &[&str]) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let (mut connects, mut adds) = (Vec::new(), Vec::new());
    for (i, target) in targets.iter().enumerate() {
        let t = Instant::now();
        let esgm = esgm_shm::ShmEsgm::builder()
            .domain(domain)
            .host(format!("esgm-scale-new-{i}"))
            .connect()
            .context("a new process cannot connect")?;
        connects.push(t.elapsed().as_secs_f64() * 1e3);
        let replica = esgm_core::Esgm::get_entity_trajectory_structure(&esgm, target)?;
        let now = esgm_core::Clock::now(&esgm_core::SystemClock);
        let es = esgm_core::Entity::to_structure(
            &esgm_core::library::RobotState { x: 0.0, y: 0.0, dir: 0.0 },
            "robot",
            now,
            now,
        );
        let t = Instant::now();
        esgm_core::EntityTrajectoryStructure::add(&replica, es)
            .with_context(|| format!("a new process cannot add to `{target}`"))?;
        adds.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok((connects, adds))
}

/// The `tag`ged line of every one of `n` workers, within `within`: fails naming the
/// workers that did not say it (and any that exited).
fn collect<T: serde::de::DeserializeOwned>(
    heard: &mpsc::Receiver<(usize, String)>,
    tag: &str,
    n: usize,
    within: Duration,
    workers: &mut [Child],
) -> anyhow::Result<Vec<T>> {
    let deadline = Instant::now() + within;
    let mut got: BTreeMap<usize, T> = BTreeMap::new();
    while got.len() < n {
        let left = deadline.saturating_duration_since(Instant::now());
        match heard.recv_timeout(left.min(Duration::from_secs(1))) {
            Ok((i, line)) => {
                if let Some(json) = line.strip_prefix(tag).map(str::trim) {
                    let value = serde_json::from_str(json)
                        .with_context(|| format!("worker {i}: malformed {tag} line"))?;
                    got.insert(i, value);
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) if Instant::now() < deadline => {
                for (i, w) in workers.iter_mut().enumerate() {
                    if !got.contains_key(&i) {
                        if let Some(status) = w.try_wait()? {
                            bail!(
                                "worker {i} exited ({status}) before {tag}; see its log in scale-run/logs"
                            );
                        }
                    }
                }
            }
            // Past the deadline (or every worker gone): the missing ones are named.
            Err(_) => {
                let missing: Vec<String> =
                    (0..n).filter(|i| !got.contains_key(i)).map(|i| i.to_string()).collect();
                bail!("workers {} did not say {tag} within {within:?}", missing.join(", "));
            }
        }
    }
    Ok(got.into_values().collect())
}

/// Percent of a core each of `pids` used over `window` (as `top` counts: one busy
/// core is 100 %); fails naming a process that could not be read.
fn cpu_percent(pids: &[u32], window: Duration) -> anyhow::Result<Vec<f64>> {
    let mut meter = crate::dashboard::procfs::CpuMeter::default();
    for pid in pids {
        // The first read of each only primes the meter.
        let _first = meter.percent(*pid);
    }
    std::thread::sleep(window);
    pids.iter()
        .map(|pid| {
            meter
                .percent(*pid)
                .with_context(|| format!("cannot read the CPU time of process {pid}"))
        })
        .collect()
}

/// Percentiles of `l`.
fn summary(mut l: Vec<u32>) -> Latency {
    l.sort_unstable();
    let at = |q: f64| l.get(((l.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(0);
    Latency {
        received: l.len(),
        p50_us: at(0.5),
        p99_us: at(0.99),
        max_us: l.last().copied().unwrap_or(0),
    }
}

/// What of the domain is still there after the stop (as `esgm soak` checks).
fn left_behind(domain: &str, seen: &BTreeSet<PathBuf>, m: &Measured) -> Vec<String> {
    let pids = std::iter::once(("coordinator".to_owned(), m.coordinator.pid))
        .chain(m.workers.iter().enumerate().map(|(i, w)| (format!("scale-worker-{i}"), w.pid)));
    super::soak::left_behind_of(domain, seen, pids.filter(|(_, pid)| *pid != 0).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_latencies() {
        let s = summary((1..=100).collect());
        assert_eq!((s.received, s.p50_us, s.p99_us, s.max_us), (100, 51, 99, 100));
        assert_eq!(summary(Vec::new()).received, 0);
    }
}
