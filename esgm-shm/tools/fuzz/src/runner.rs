//! The child process: runs one target's cases for a time budget, catches panics,
//! watches for hangs, saves failing inputs, and reports on stdout ([`Event`]).
//!
//! A panic is caught and the run goes on. A hang cannot be stopped from inside (the
//! case's thread cannot be killed), so the watchdog thread saves the input, reports it
//! and ends the process with [`HANG_EXIT`]; an abort ends it without a word. Both are
//! picked up by the parent ([`crate::supervise`]), which carries on after the case.

use std::collections::HashMap;
use std::io::Write;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::event::{Event, Finding, Kind};
use crate::rng::Rng;
use crate::target::{RESET_EVERY, Target};

/// The exit code of a child whose watchdog saw a hang.
pub const HANG_EXIT: i32 = 3;

/// What one child runs.
#[derive(Debug, Clone)]
pub struct Cases {
    /// The run's seed.
    pub seed: u64,
    /// The first case's index.
    pub from: u64,
    /// How long to run cases.
    pub budget: Duration,
    /// Stop after this many cases, if given.
    pub max_cases: Option<u64>,
    /// One case running longer than this is a hang.
    pub hang: Duration,
    /// Where failing inputs are saved.
    pub findings: PathBuf,
    /// Report every case before running it (to find the one that kills the process).
    pub trace: bool,
    /// Check the target's seeds first.
    pub check_seeds: bool,
}

/// The file a failing input is saved to.
pub fn finding_file(dir: &Path, target: &str, kind: Kind, seed: u64, index: u64) -> PathBuf {
    dir.join(format!("{target}-{kind}-{seed:016x}-{index}.bin"))
}

/// Saves `input` as a finding; the path, or an empty one (and the reason in
/// `message`) if it could not be written.
pub fn save(file: PathBuf, input: &[u8], message: &mut String) -> PathBuf {
    let written = file
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|()| std::fs::write(&file, input));
    match written {
        Ok(()) => file,
        Err(e) => {
            message.push_str(&format!(" (input not saved to {}: {e})", file.display()));
            PathBuf::new()
        }
    }
}

fn emit(event: &Event) {
    let mut out = std::io::stdout().lock();
    // A parent that went away ends this run at the next case: nothing to report to.
    if writeln!(out, "{event}").and_then(|()| out.flush()).is_err() {
        std::process::exit(1);
    }
}

/// The last panic's message, kept by the hook instead of printed.
static LAST_PANIC: Mutex<Option<String>> = Mutex::new(None);

fn keep_panic_messages() {
    std::panic::set_hook(Box::new(|info| {
        *LAST_PANIC.lock().unwrap_or_else(PoisonError::into_inner) = Some(info.to_string());
    }));
}

fn last_panic() -> String {
    LAST_PANIC
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .take()
        .unwrap_or_else(|| "panic without a message".to_owned())
}

/// Which case is running, and since when (0: none), for the watchdog.
#[derive(Debug, Default)]
struct Running {
    started_ns: AtomicU64,
    case: AtomicU64,
    over: AtomicBool,
}

/// Marks a seed's number in [`Running::case`].
const SEED_BIT: u64 = 1 << 63;

fn input_of(target: &dyn Target, seed: u64, case: u64) -> Vec<u8> {
    if case & SEED_BIT != 0 {
        let n = (case & !SEED_BIT) as usize;
        target.seeds().get(n).cloned().unwrap_or_default()
    } else {
        target.input(&mut Rng::for_case(seed, case))
    }
}

fn watchdog(target: Arc<dyn Target>, cases: Cases, running: Arc<Running>, clock: Instant) {
    let tick = (cases.hang / 4).clamp(Duration::from_millis(1), Duration::from_millis(50));
    while !running.over.load(Ordering::Acquire) {
        std::thread::sleep(tick);
        let started = running.started_ns.load(Ordering::Acquire);
        let case = running.case.load(Ordering::Acquire);
        let now = clock.elapsed().as_nanos() as u64;
        let same = running.started_ns.load(Ordering::Acquire) == started;
        if started == 0 || !same || now.saturating_sub(started) < cases.hang.as_nanos() as u64 {
            continue;
        }
        let input = input_of(target.as_ref(), cases.seed, case);
        let index = case & !SEED_BIT;
        let mut message = format!(
            "{}case ran over {} ms",
            if case & SEED_BIT != 0 { "seed " } else { "" },
            cases.hang.as_millis()
        );
        let file = finding_file(&cases.findings, target.name(), Kind::Hang, cases.seed, index);
        let file = save(file, &input, &mut message);
        emit(&Event::Found(Finding { kind: Kind::Hang, index, file, message }));
        std::process::exit(HANG_EXIT);
    }
}

/// How many inputs are saved for findings alike (same kind, same start of message,
/// where a panic's location is): a bug that fires on every case fills no disk.
pub const SAVED_ALIKE: u32 = 3;

/// What a child runs its cases with.
struct Child<'a> {
    target: &'a dyn Target,
    cases: &'a Cases,
    running: &'a Running,
    clock: Instant,
    /// Findings so far, by [`alike`] key.
    seen: HashMap<String, u32>,
    /// Findings so far.
    found: u64,
}

/// The key of findings alike: kind and the message's first 80 characters.
fn alike(kind: Kind, message: &str) -> String {
    format!("{kind} {}", message.chars().take(80).collect::<String>())
}

impl Child<'_> {
    /// Runs one case under `catch_unwind`, reporting a panic or a broken promise.
    fn case(
        &mut self,
        case: u64,
        input: &[u8],
        run: impl FnOnce() -> Result<(), crate::target::Broken>,
    ) {
        let (target, cases, running, clock) = (self.target, self.cases, self.running, self.clock);
        running.case.store(case, Ordering::Release);
        running.started_ns.store(clock.elapsed().as_nanos() as u64 + 1, Ordering::Release);
        let outcome = catch_unwind(AssertUnwindSafe(run));
        running.started_ns.store(0, Ordering::Release);
        let (kind, mut message) = match outcome {
            Ok(Ok(())) => return,
            Ok(Err(broken)) => (Kind::Broken, broken.to_string()),
            Err(_) => (Kind::Panic, last_panic()),
        };
        // State a failure left behind would fail every later case alike; a run that
        // makes the case again from the last reset resets here too.
        target.reset();
        let index = case & !SEED_BIT;
        if case & SEED_BIT != 0 {
            message = format!("seed {index}: {message}");
        }
        let seen = self.seen.entry(alike(kind, &message)).or_default();
        *seen += 1;
        let file = if *seen <= SAVED_ALIKE {
            let file = finding_file(&cases.findings, target.name(), kind, cases.seed, index);
            save(file, input, &mut message)
        } else {
            PathBuf::new()
        };
        self.found += 1;
        emit(&Event::Found(Finding { kind, index, file, message }));
    }
}

/// Runs `target`'s cases as `cases` says, reporting on stdout; returns how many
/// findings it reported (a hang ends the process instead).
pub fn run(target: Arc<dyn Target>, cases: Cases) -> u64 {
    keep_panic_messages();
    let clock = Instant::now();
    let running = Arc::new(Running::default());
    let dog = {
        let (target, cases, running) = (Arc::clone(&target), cases.clone(), Arc::clone(&running));
        std::thread::spawn(move || watchdog(target, cases, running, clock))
    };
    let t = target.as_ref();
    let mut child = Child {
        target: t,
        cases: &cases,
        running: &running,
        clock,
        seen: HashMap::new(),
        found: 0,
    };
    if cases.check_seeds {
        for (n, seed) in t.seeds().iter().enumerate() {
            child.case(n as u64 | SEED_BIT, seed, || t.accepts(seed));
        }
        t.reset();
    }
    let mut done = 0u64;
    let mut case = cases.from;
    while clock.elapsed() < cases.budget && cases.max_cases.is_none_or(|max| done < max) {
        if case % RESET_EVERY == 0 {
            t.reset();
            emit(&Event::Progress { next: case, cases: done });
        }
        let input = t.input(&mut Rng::for_case(cases.seed, case));
        if cases.trace {
            emit(&Event::Case { index: case });
        }
        child.case(case, &input, || t.run(&input));
        case += 1;
        done += 1;
    }
    running.over.store(true, Ordering::Release);
    if dog.join().is_err() {
        eprintln!("esgm-fuzz: the watchdog thread panicked");
    }
    emit(&Event::Done { cases: done, millis: clock.elapsed().as_millis() as u64 });
    child.found
}
