//! The parent process: runs each target in a child process of this same executable,
//! so that a case that aborts (a stack overflow, a failed allocation) or hangs costs a
//! child, not the run; then finds that case again and carries on after it.
//!
//! Finding the case that killed a child: the child reports progress at every
//! [`RESET_EVERY`]th case, and a case's input depends on its seed and index alone
//! ([`crate::rng::Rng::for_case`]). So the parent runs the cases from the last
//! progress report again in a child that names each case before running it; the last
//! one named is the culprit, and the parent makes its input again and saves it.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::event::{Event, Finding, Kind};
use crate::rng::Rng;
use crate::runner::{HANG_EXIT, finding_file, save};
use crate::target::RESET_EVERY;
use crate::targets;

/// What a run does.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The total budget, split evenly over the targets.
    pub seconds: f64,
    /// The run's seed.
    pub seed: u64,
    /// The targets, by name.
    pub targets: Vec<String>,
    /// Where failing inputs are saved.
    pub findings: PathBuf,
    /// One case running longer than this is a hang.
    pub hang: Duration,
}

/// How one target did.
#[derive(Debug, Clone)]
pub struct TargetReport {
    /// Its name.
    pub name: String,
    /// Cases run.
    pub cases: u64,
    /// Seconds its children spent running cases.
    pub seconds: f64,
    /// What failed.
    pub findings: Vec<Finding>,
}

/// How a child ended.
#[derive(Debug)]
enum End {
    /// It spent its budget.
    Done,
    /// Its watchdog saw case `index` hang.
    Hang { index: u64 },
    /// It died: `status`, and its last words on stderr.
    Died { status: String },
}

/// What a child reported before it ended.
#[derive(Debug)]
struct ChildRun {
    cases: u64,
    millis: u64,
    next: u64,
    last_case: Option<u64>,
    findings: Vec<Finding>,
    end: End,
}

/// Runs every target of `plan` with this executable, `exe`, as the child.
pub fn run(exe: &Path, plan: &Plan) -> anyhow::Result<Vec<TargetReport>> {
    let budget = Duration::from_secs_f64(plan.seconds / plan.targets.len().max(1) as f64);
    plan.targets.iter().map(|name| run_target(exe, plan, name, budget)).collect()
}

fn run_target(
    exe: &Path,
    plan: &Plan,
    name: &str,
    budget: Duration,
) -> anyhow::Result<TargetReport> {
    let start = Instant::now();
    let mut report =
        TargetReport { name: name.to_owned(), cases: 0, seconds: 0.0, findings: Vec::new() };
    let mut from = 0;
    while let Some(left) = budget.checked_sub(start.elapsed()).filter(|d| !d.is_zero()) {
        let child = run_child(exe, plan, name, from, left, None, false)?;
        report.seconds += child.millis as f64 / 1000.0;
        report.findings.extend(child.findings);
        // Cases run one after the other: a child that ended at case `i` ran those
        // from `from` to `i` (its last progress report may be up to 255 behind).
        let (cases, next) = match child.end {
            End::Done => (child.cases, None),
            End::Hang { index } => (index + 1 - from.min(index + 1), Some(index + 1)),
            End::Died { status } => {
                let (finding, next) = find_abort(exe, plan, name, child.next, status)?;
                report.findings.push(finding);
                (next.saturating_sub(from), Some(next))
            }
        };
        report.cases += cases;
        match next {
            Some(next) => from = next,
            None => break,
        }
    }
    Ok(report)
}

/// Runs the cases from `checkpoint` again, naming each, to find the one that killed a
/// child; returns the finding and the case to go on from.
fn find_abort(
    exe: &Path,
    plan: &Plan,
    name: &str,
    checkpoint: u64,
    status: String,
) -> anyhow::Result<(Finding, u64)> {
    let replay =
        run_child(exe, plan, name, checkpoint, Duration::from_secs(600), Some(RESET_EVERY), true)?;
    let (End::Died { status: again }, Some(index)) = (&replay.end, replay.last_case) else {
        let message = format!(
            "died ({status}) in one of cases {checkpoint}..{}; running them again did not",
            checkpoint + RESET_EVERY
        );
        let finding =
            Finding { kind: Kind::Abort, index: checkpoint, file: PathBuf::new(), message };
        return Ok((finding, checkpoint + RESET_EVERY));
    };
    let target = targets::by_name(name)
        .with_context(|| format!("unknown target {name}"))?
        .map_err(|e| anyhow::anyhow!("target {name} has no seeds: {e}"))?;
    let input = target.input(&mut Rng::for_case(plan.seed, index));
    let mut message = again.clone();
    let file = finding_file(&plan.findings, name, Kind::Abort, plan.seed, index);
    let file = save(file, &input, &mut message);
    Ok((Finding { kind: Kind::Abort, index, file, message }, index + 1))
}

fn describe(status: ExitStatus, stderr: &str) -> String {
    use std::os::unix::process::ExitStatusExt;
    let how = match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit code {code}"),
        (None, Some(signal)) => format!("signal {signal}"),
        (None, None) => status.to_string(),
    };
    let last: String = stderr.lines().rev().take(3).collect::<Vec<_>>().join(" | ");
    if last.is_empty() { how } else { format!("{how}: {last}") }
}

#[allow(clippy::too_many_arguments, reason = "what one child runs")]
fn run_child(
    exe: &Path,
    plan: &Plan,
    name: &str,
    from: u64,
    budget: Duration,
    max_cases: Option<u64>,
    trace: bool,
) -> anyhow::Result<ChildRun> {
    let mut command = Command::new(exe);
    command
        .args(["--child", "--target", name])
        .args(["--seed", &plan.seed.to_string(), "--from", &from.to_string()])
        .args(["--seconds", &budget.as_secs_f64().to_string()])
        .args(["--hang-ms", &plan.hang.as_millis().to_string()])
        .arg("--findings")
        .arg(&plan.findings)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(n) = max_cases {
        command.args(["--max-cases", &n.to_string()]);
    }
    if trace {
        command.arg("--trace");
    }
    let began = Instant::now();
    let mut child = command.spawn().with_context(|| format!("cannot run {}", exe.display()))?;
    let lines = child.stdout.take().context("child without stdout")?;
    let mut stderr = child.stderr.take().context("child without stderr")?;
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(lines).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let errors = std::thread::spawn(move || {
        let mut text = String::new();
        // Only for the message of a child that died; unreadable stderr leaves it out.
        stderr.read_to_string(&mut text).map(|_| text).unwrap_or_default()
    });
    // The child's watchdog catches hangs; this catches a child that hangs anyway.
    let deadline = Instant::now() + budget + plan.hang * 2 + Duration::from_secs(30);
    let mut run = ChildRun {
        cases: 0,
        millis: 0,
        next: from,
        last_case: None,
        findings: Vec::new(),
        end: End::Done,
    };
    let mut done = false;
    let mut hang = None;
    loop {
        match rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            Ok(line) => match Event::parse(&line) {
                Some(Event::Progress { next, cases }) => (run.next, run.cases) = (next, cases),
                Some(Event::Case { index }) => run.last_case = Some(index),
                Some(Event::Done { cases, millis }) => {
                    (run.cases, run.millis, done) = (cases, millis, true);
                }
                Some(Event::Found(f)) => {
                    if f.kind == Kind::Hang {
                        hang = Some(f.index);
                    }
                    run.findings.push(f);
                }
                None => eprintln!("esgm-fuzz: {name}: {line}"),
            },
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                kill(&mut child, name);
                let index = run.last_case.unwrap_or(run.next);
                run.findings.push(Finding {
                    kind: Kind::Hang,
                    index,
                    file: PathBuf::new(),
                    message: "the child stopped answering (its watchdog did not fire)".into(),
                });
                hang = Some(index);
                break;
            }
        }
    }
    let status = child.wait().context("cannot wait for a child")?;
    let stderr = errors.join().unwrap_or_default();
    if !done {
        run.millis = began.elapsed().as_millis() as u64;
    }
    run.end = match hang {
        Some(index) => End::Hang { index },
        None if status.success() && done => End::Done,
        None if status.code() == Some(HANG_EXIT) => End::Hang { index: run.next },
        None => End::Died { status: describe(status, &stderr) },
    };
    Ok(run)
}

fn kill(child: &mut Child, name: &str) {
    if let Err(e) = child.kill() {
        eprintln!("esgm-fuzz: {name}: cannot stop a stuck child: {e}");
    }
}
