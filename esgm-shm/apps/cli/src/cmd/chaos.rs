//! `esgm chaos`: `esgm scale`'s robot under faults. Nothing acknowledged may be lost
//! (SPEC D1, issue 39).
//!
//! It starts a supervised coordinator (`esgm up --supervise`) in a fresh domain and
//! declares one supervised `esgm chaos-worker` per process of the profile
//! ([`worker`]: they write and read as `esgm scale`'s do, and log every structure `add`
//! acknowledged). Once all are set up it measures the domain's `/dev/shm` files and
//! the processes' private memory, then for `--seconds` kills a random process with
//! SIGKILL every `--kill-every` — a worker (a writer, a reader or both) or the
//! coordinator — chosen by a generator seeded with `--seed` (printed, so that a run can
//! be repeated). `esgm up` restarts each.
//!
//! Then it waits for every process to be back, lets them write a moment, stops their
//! adds, and checks as a process that wrote nothing ([`check`]): every acknowledged
//! structure is held or was evicted by the policy, none twice; every loss the readers
//! counted has a cause; `/dev/shm` and memory are back within their bound; `esgm down`
//! leaves no process and no file of the domain. It prints a report, writes
//! `chaos.json` into `--out`, and exits 1 if any of it failed.

pub mod check;
pub mod worker;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_shm::control::{ControlClient, ProcessSpec, Request, Response, StateDir};
use esgm_shm::unique_domain;
use esgm_shm::{DEFAULT_MAX_PROCESSES, DEFAULT_READERS, DomainLimits};
use serde::Serialize;

use super::scale::profile::Profile;
use super::soak::probe;
use check::Checked;

pub use worker::WorkerArgs;

/// `esgm chaos` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The robot's size (`esgm scale`'s profile).
    #[command(flatten)]
    pub size: super::scale::profile::Size,
    /// Seconds of killing.
    #[arg(long, default_value_t = 600.0, value_parser = crate::span_arg::seconds)]
    pub seconds: f64,
    /// Seconds between two kills.
    #[arg(long, default_value_t = 2.0, value_parser = crate::span_arg::seconds)]
    pub kill_every: f64,
    /// The random generator's seed (default: the clock's), printed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Directory for `chaos.json` and the run's files (created).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
}

/// Kills of each kind that the system survived.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Kills {
    /// Workers that write trajectories and read others.
    pub writer_and_reader: u64,
    /// Workers that only write.
    pub writer: u64,
    /// Workers that only read.
    pub reader: u64,
    /// The coordinator.
    pub coordinator: u64,
    /// Rounds whose victim was being restarted (no pid to kill).
    pub skipped: u64,
}

/// The use of the domain once set up, and once everything was back at the end.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Footprint {
    /// Files of the domain in `/dev/shm` its processes map.
    pub shm_files: usize,
    /// Their allocated bytes.
    pub shm_bytes: u64,
    /// Private memory of every process, summed, bytes.
    pub private_bytes: u64,
    /// Private memory of each process, bytes.
    pub private_by_process: BTreeMap<String, u64>,
}

/// The whole run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Report {
    /// The domain.
    pub domain: String,
    /// The seed.
    pub seed: u64,
    /// The profile's size.
    pub trajectories: usize,
    /// The profile's processes.
    pub processes: usize,
    /// Seconds of killing.
    pub seconds: f64,
    /// The kills survived.
    pub kills: Kills,
    /// What the check of acknowledged structures found.
    pub checked: Checked,
    /// What the trajectories dropped, by cause (`esgm stats`: each process counts what
    /// it dropped, a replica what never reached it): every drop has its cause.
    pub losses_by_cause: BTreeMap<String, u64>,
    /// Once set up.
    pub before: Footprint,
    /// Once every process was back.
    pub after: Footprint,
    /// The caches' data, once per trajectory: what its writer's shared memory may hold
    /// beyond what it held once set up (a restarted writer hands its history over
    /// again), allowed on top of the growth bound of `/dev/shm`.
    pub cache_bytes: u64,
    /// The caches' data, held once by each trajectory's writer and each reader: what a
    /// restarted process may hold on its heap instead of in shared memory (a history
    /// recovered from the kept file is decoded), allowed on top of the growth bound of
    /// private memory.
    pub caches_bytes: u64,
    /// What of the domain was left after `esgm down`.
    pub left_behind: Vec<String>,
    /// What failed, if anything.
    pub failures: Vec<String>,
}

/// How long every process has to (re)start and set up.
const SETUP: Duration = Duration::from_secs(300);
/// How long the workers write once all are back, before they stop.
const SETTLE: Duration = Duration::from_secs(5);
/// The bound on `/dev/shm` and memory once everything is back: this much of what the
/// domain used once set up, plus [`SLACK_BYTES`].
const GROWTH: f64 = 1.25;
const SLACK_BYTES: u64 = 16 << 20;

/// Runs `esgm chaos`.
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    for (flag, v) in [("--seconds", a.seconds), ("--kill-every", a.kill_every)] {
        if !v.is_finite() || v <= 0.0 {
            bail!("{flag} must be a positive number of seconds, got {v}");
        }
    }
    let (trajectories, processes) = (a.size.trajectories, a.size.processes);
    let profile = Profile::new(trajectories, processes, processes.saturating_sub(1))?;
    let seed = a.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
    });
    let domain =
        if domain == esgm_shm::SYSTEM_DOMAIN { unique_domain("chaos") } else { domain.to_owned() };
    let run_dir = a.out.join("chaos-run");
    if run_dir.exists() {
        std::fs::remove_dir_all(&run_dir)
            .with_context(|| format!("cannot empty {}", run_dir.display()))?;
    }
    std::fs::create_dir_all(&run_dir)
        .with_context(|| format!("cannot create {}", run_dir.display()))?;
    let run_dir = run_dir.canonicalize()?;
    std::fs::write(run_dir.join("profile.json"), serde_json::to_vec(&profile)?)
        .context("cannot write the profile")?;
    println!(
        "esgm chaos: {} trajectories in {} processes, a SIGKILL every {:.1} s for {:.0} s, \
         seed {seed}, domain `{domain}`",
        profile.trajectories.len(),
        profile.processes,
        a.kill_every,
        a.seconds
    );
    let limits = DomainLimits {
        max_processes: DEFAULT_MAX_PROCESSES.max(profile.processes + 16),
        readers: DEFAULT_READERS,
    };
    let state = StateDir::at(std::env::temp_dir().join(format!("esgm-{domain}")));
    let setup = super::up::Setup { limits, supervise: true, ..super::up::Setup::default() };
    // The coordinator's log (and its successors', which inherit it) stays with the run.
    let log = std::fs::File::create(run_dir.join("coordinator.log"))
        .context("cannot create the coordinator's log")?;
    let mut coordinator = super::up::spawn_detached_with(
        &domain,
        Some(state.path()),
        &setup,
        Stdio::from(log),
        true,
    )?;
    let mut report = Report {
        domain: domain.clone(),
        seed,
        trajectories: profile.trajectories.len(),
        processes: profile.processes,
        seconds: a.seconds,
        ..Report::default()
    };
    (report.cache_bytes, report.caches_bytes) = caches_bytes(&profile)?;
    let mut pids_seen = BTreeSet::new();
    let mut files_seen = BTreeSet::new();
    let ran = campaign(
        &domain,
        &profile,
        a,
        seed,
        &run_dir,
        &mut report,
        &mut pids_seen,
        &mut files_seen,
    );
    // The processes' logs (`esgm logs`), kept with the run before the state goes.
    if let Err(e) = super::soak::copy_dir(&state.log_dir(), &run_dir.join("logs")) {
        report.failures.push(format!("cannot keep the processes' logs: {e:#}"));
    }
    let stopped = stop(&domain, &mut coordinator, &state);
    if let Err(e) = &ran {
        report.failures.push(format!("{e:#}"));
    }
    if let Err(e) = stopped {
        report.failures.push(format!("esgm down: {e:#}"));
    }
    report.left_behind = super::soak::left_behind_of(&domain, &files_seen, pids_seen);
    report.left_behind.extend(domain_files(&domain));
    judge(&mut report);
    print(&report);
    let json = a.out.join("chaos.json");
    std::fs::write(&json, serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    println!("\nwrote {}", json.display());
    if !report.failures.is_empty() {
        bail!("chaos: {} failures (seed {seed})", report.failures.len());
    }
    Ok(())
}

/// `esgm down`, then the supervisor this command started leaves, and the state goes.
fn stop(
    domain: &str,
    coordinator: &mut std::process::Child,
    state: &StateDir,
) -> anyhow::Result<()> {
    let down = super::down::run(domain);
    let deadline = Instant::now() + Duration::from_secs(20);
    while coordinator.try_wait()?.is_none() {
        if Instant::now() > deadline {
            coordinator.kill().context("cannot kill the coordinator's supervisor")?;
            coordinator.wait()?;
            bail!("the coordinator's supervisor did not leave after esgm down");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Err(e) = std::fs::remove_dir_all(state.path()) {
        if e.kind() != std::io::ErrorKind::NotFound {
            eprintln!("esgm: cannot remove {}: {e}", state.path().display());
        }
    }
    down
}

/// Declares the workers, waits for them, kills at random, and checks.
#[allow(clippy::too_many_arguments)]
fn campaign(
    domain: &str,
    profile: &Profile,
    a: &Args,
    seed: u64,
    run: &Path,
    report: &mut Report,
    pids_seen: &mut BTreeSet<(String, u32)>,
    files_seen: &mut BTreeSet<PathBuf>,
) -> anyhow::Result<()> {
    let control = ControlClient::connect(domain, Duration::from_secs(10))
        .context("cannot reach the coordinator")?;
    let exe = std::env::current_exe().context("cannot find the esgm executable")?;
    for i in 0..profile.processes {
        let spec = ProcessSpec {
            name: worker::name(i),
            program: exe.display().to_string(),
            args: vec![
                "chaos-worker".into(),
                "--run".into(),
                run.display().to_string(),
                "--index".into(),
                i.to_string(),
            ],
            env: Vec::new(),
        };
        control
            .call(&Request::DeclareProcess { spec })
            .with_context(|| format!("cannot declare worker {i}"))?;
    }
    drop(control);
    report.before = settled_footprint(domain, profile.processes, run, pids_seen, files_seen)?;

    let mut rng = seed | 1;
    let deadline = Instant::now() + Duration::from_secs_f64(a.seconds);
    let every = Duration::from_secs_f64(a.kill_every);
    let mut next_print = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        std::thread::sleep(every);
        rng = xorshift(rng);
        let victim = (rng % (profile.processes as u64 + 1)) as usize;
        kill(domain, profile, victim, &mut report.kills, pids_seen);
        if Instant::now() >= next_print {
            let k = &report.kills;
            println!(
                "  {:.0} s left: killed {} workers and the coordinator {} times",
                deadline.saturating_duration_since(Instant::now()).as_secs_f64(),
                k.writer + k.reader + k.writer_and_reader,
                k.coordinator
            );
            next_print += Duration::from_secs(30);
        }
    }
    println!("  killing stopped; waiting for every process to be back");
    report.after = settled_footprint(domain, profile.processes, run, pids_seen, files_seen)?;
    std::fs::write(worker::stop_file(run), b"stop").context("cannot stop the workers")?;
    let stopped_by = Instant::now() + Duration::from_secs(60);
    for i in 0..profile.processes {
        while !worker::stopped_file(run, i).exists() {
            if Instant::now() > stopped_by {
                bail!("worker {i} did not stop adding within 60 s");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    verify(domain, profile, run, report)
}

/// Kills process `victim` of the profile (the coordinator for the one past the last).
fn kill(
    domain: &str,
    profile: &Profile,
    victim: usize,
    kills: &mut Kills,
    pids_seen: &mut BTreeSet<(String, u32)>,
) {
    let Ok(control) = ControlClient::connect(domain, Duration::from_secs(2)) else {
        kills.skipped += 1;
        return;
    };
    if victim == profile.processes {
        if let Ok(Response::Pong { pid, .. }) = control.call(&Request::Ping) {
            drop(control);
            if sigkill(pid) {
                kills.coordinator += 1;
                pids_seen.insert(("coordinator".into(), pid));
                return;
            }
        }
        kills.skipped += 1;
        return;
    }
    let name = worker::name(victim);
    let pid = match control.call(&Request::ListProcesses) {
        Ok(Response::Processes(list)) => {
            list.into_iter().find(|p| p.spec.name == name).and_then(|p| p.status.pid)
        }
        _ => None,
    };
    let Some(pid) = pid.filter(|pid| sigkill(*pid)) else {
        kills.skipped += 1;
        return;
    };
    pids_seen.insert((name, pid));
    match (profile.written_by(victim).next().is_some(), profile.read_by(victim).next().is_some()) {
        (true, true) => kills.writer_and_reader += 1,
        (true, false) => kills.writer += 1,
        _ => kills.reader += 1,
    }
}

/// `kill -9 pid`; false if it is not there.
fn sigkill(pid: u32) -> bool {
    let Ok(pid) = i32::try_from(pid) else { return false };
    // SAFETY: kill(2) with a pid the coordinator reported and a signal number.
    unsafe { libc::kill(pid, libc::SIGKILL) == 0 }
}

/// Waits until the coordinator answers and every worker runs and said ready since its
/// last start; their `(name, pid)`, the coordinator's included.
fn all_back(
    domain: &str,
    workers: usize,
    run: &Path,
    within: Duration,
) -> anyhow::Result<Vec<(String, u32)>> {
    let deadline = Instant::now() + within;
    let mut missing = Vec::new();
    loop {
        missing.clear();
        let answer = ControlClient::connect(domain, Duration::from_secs(2)).and_then(|c| {
            let coordinator = c.call(&Request::Ping)?;
            Ok((coordinator, c.call(&Request::ListProcesses)?))
        });
        match answer {
            Ok((Response::Pong { pid, .. }, Response::Processes(list))) => {
                let mut out = vec![("coordinator".to_owned(), pid)];
                for i in 0..workers {
                    let name = worker::name(i);
                    let record = list.iter().find(|p| p.spec.name == name);
                    let pid = record.and_then(|p| p.status.pid);
                    let ready = std::fs::read_to_string(worker::ready_file(run, i)).ok();
                    match pid {
                        Some(pid)
                            if ready.as_deref().is_some_and(|r| r.trim() == pid.to_string()) =>
                        {
                            out.push((name, pid));
                        }
                        _ => missing.push(format!(
                            "{name} (pid {pid:?}, ready {ready:?}, last exit {:?})",
                            record.and_then(|r| r.status.last_exit.clone())
                        )),
                    }
                }
                if missing.is_empty() {
                    return Ok(out);
                }
            }
            other => missing.push(format!("the coordinator: {other:?}")),
        }
        if Instant::now() > deadline {
            bail!("the processes were not all back within {within:?}: {}", missing.join("; "));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Once every process is back and the domain settled, its footprint; measured again if
/// a process was restarted meanwhile (one that failed to set up after a kill).
fn settled_footprint(
    domain: &str,
    workers: usize,
    run: &Path,
    pids_seen: &mut BTreeSet<(String, u32)>,
    files_seen: &mut BTreeSet<PathBuf>,
) -> anyhow::Result<Footprint> {
    let mut attempts = 0;
    loop {
        let pids = all_back(domain, workers, run, SETUP)?;
        pids_seen.extend(pids.iter().map(|(n, p)| (n.clone(), *p)));
        std::thread::sleep(SETTLE);
        match footprint(&pids, files_seen) {
            Ok(f) => return Ok(f),
            Err(e) if attempts < 3 => {
                attempts += 1;
                println!("  a process went while measured ({e:#}); measuring again");
            }
            Err(e) => return Err(e),
        }
    }
}

/// The domain's `/dev/shm` files mapped by `pids` and their private memory.
fn footprint(
    pids: &[(String, u32)],
    files_seen: &mut BTreeSet<PathBuf>,
) -> anyhow::Result<Footprint> {
    let mut files = BTreeSet::new();
    let mut by_process = BTreeMap::new();
    for (name, pid) in pids {
        files.extend(probe::mapped_shm(*pid)?);
        by_process.insert(name.clone(), probe::resident(*pid)?.anon);
    }
    let shm = probe::usage(&files)?;
    files_seen.extend(files);
    Ok(Footprint {
        shm_files: shm.files,
        shm_bytes: shm.allocated,
        private_bytes: by_process.values().sum(),
        private_by_process: by_process,
    })
}

/// The check, as a process that wrote nothing: acknowledged structures against what
/// each trajectory holds, and the losses counted.
fn verify(domain: &str, profile: &Profile, run: &Path, report: &mut Report) -> anyhow::Result<()> {
    let esgm = esgm_shm::ShmEsgm::builder()
        .domain(domain)
        .host("esgm-chaos")
        .timeout(Duration::from_secs(60))
        .tool()
        .connect()
        .context("cannot connect to check")?;
    let (acks, malformed) = check::read_acks(run, profile.processes)?;
    report.checked.malformed_lines = malformed;
    for t in &profile.trajectories {
        use esgm_core::EntityTrajectoryStructure as _;
        let handle = esgm_core::Esgm::get_entity_trajectory_structure(&esgm, &t.name)
            .with_context(|| format!("cannot read `{}`", t.name))?;
        let held: Vec<i64> = handle
            .get_between(i64::MIN, i64::MAX)
            .with_context(|| format!("cannot query `{}`", t.name))?
            .iter()
            .map(|s| s.structure.valid_time())
            .collect();
        let acked = acks.get(&t.name).map_or(&[][..], Vec::as_slice);
        check::check_one(&t.name, worker::cache_of(t.class), acked, &held, &mut report.checked);
    }
    let stats = esgm.domain_stats().context("cannot collect the trajectories' counters")?;
    for r in stats.trajectories.values() {
        for (cause, n) in &r.stats.dropped {
            *report.losses_by_cause.entry(cause.to_string()).or_default() += n;
        }
    }
    Ok(())
}

/// The caches' data of `profile`: once per trajectory, and once per writer and reader
/// of each.
fn caches_bytes(profile: &Profile) -> anyhow::Result<(u64, u64)> {
    let (mut once, mut total) = (0, 0);
    for t in &profile.trajectories {
        let one = match t.class {
            super::scale::profile::Class::Image => {
                esgm_core::codec::encoded_len(&super::scale::worker::image_of_profile())?
            }
            _ => 256,
        };
        once += (one * worker::cache_of(t.class)) as u64;
        total += (one * worker::cache_of(t.class) * (1 + t.readers.len())) as u64;
    }
    Ok((once, total))
}

/// Adds the failures the report shows.
fn judge(r: &mut Report) {
    let c = &r.checked;
    if !c.lost.is_empty() {
        r.failures.push(format!(
            "{} acknowledged structures lost: {:?}",
            c.lost.len(),
            first(&c.lost)
        ));
    }
    if !c.duplicated.is_empty() {
        r.failures.push(format!(
            "{} structures held twice: {:?}",
            c.duplicated.len(),
            first(&c.duplicated)
        ));
    }
    if !c.unacknowledged.is_empty() {
        r.failures.push(format!(
            "{} structures held that were never added: {:?}",
            c.unacknowledged.len(),
            first(&c.unacknowledged)
        ));
    }
    if c.checked == 0 {
        r.failures.push("nothing was checked: no structure was acknowledged".into());
    }
    let bound = |before: u64| (before as f64 * GROWTH) as u64 + SLACK_BYTES;
    let shm_bound = bound(r.before.shm_bytes) + r.cache_bytes;
    if r.after.shm_bytes > shm_bound {
        r.failures.push(format!(
            "/dev/shm grew from {} to {} bytes once everything was back (bound {shm_bound}: \
             ×{GROWTH} + the caches' data)",
            r.before.shm_bytes, r.after.shm_bytes
        ));
    }
    let private_bound = bound(r.before.private_bytes) + r.caches_bytes;
    if r.after.private_bytes > private_bound {
        r.failures.push(format!(
            "private memory grew from {} to {} bytes once everything was back (bound {private_bound}: \
             ×{GROWTH} + the caches' data)",
            r.before.private_bytes, r.after.private_bytes
        ));
    }
    if !r.left_behind.is_empty() {
        r.failures.push(format!("left behind after esgm down: {:?}", first(&r.left_behind)));
    }
}

fn first(v: &[String]) -> &[String] {
    &v[..v.len().min(5)]
}

/// Files in `/dev/shm` named for `domain` (esgm's own: wake words, kept histories, and
/// any a bridge left), which nobody may leave after `esgm down`.
fn domain_files(domain: &str) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir("/dev/shm") else { return Vec::new() };
    entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(&format!("@{domain}.")) || n.contains(&format!("@{domain}@")))
        .map(|n| format!("file /dev/shm/{n}"))
        .collect()
}

/// Prints the report.
fn print(r: &Report) {
    let k = &r.kills;
    println!(
        "\nkills survived: {} writers-and-readers, {} writers, {} readers, {} coordinators ({} rounds found the victim restarting)",
        k.writer_and_reader, k.writer, k.reader, k.coordinator, k.skipped
    );
    let c = &r.checked;
    println!(
        "acknowledged: {} structures; {} within their cache checked, {} evicted by the policy; \
         {} lost, {} held twice, {} never added; {} added but unlogged (a kill between add and its line)",
        c.acknowledged,
        c.checked,
        c.evicted_by_policy,
        c.lost.len(),
        c.duplicated.len(),
        c.unacknowledged.len(),
        c.unlogged
    );
    if r.losses_by_cause.is_empty() {
        println!("losses counted by the trajectories: none");
    } else {
        let causes: Vec<String> =
            r.losses_by_cause.iter().map(|(cause, n)| format!("{cause} {n}")).collect();
        println!("losses counted by the trajectories, by cause: {}", causes.join(", "));
    }
    println!(
        "/dev/shm: {} files, {} MiB once set up; {} files, {} MiB once everything was back",
        r.before.shm_files,
        r.before.shm_bytes >> 20,
        r.after.shm_files,
        r.after.shm_bytes >> 20
    );
    println!(
        "private memory: {} MiB once set up, {} MiB once everything was back",
        r.before.private_bytes >> 20,
        r.after.private_bytes >> 20
    );
    if r.failures.is_empty() {
        println!("chaos: passed (seed {})", r.seed);
    } else {
        for f in &r.failures {
            println!("FAILED: {f}");
        }
    }
}

/// The next number of a xorshift64 generator (enough to pick victims repeatably).
fn xorshift(mut x: u64) -> u64 {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    x
}
