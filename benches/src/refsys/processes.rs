//! Running a system's processes together: every node process (and the in-process
//! system's one) speaks the same small protocol on its standard streams, so the runner
//! starts them all, lets the topology run for the same window in each, and measures
//! them alike.
//!
//! 1. The process sets itself up (connects, declares its trajectories or topics,
//!    subscribes) and prints `ready`. Before it, a process that started others of the
//!    system (a coordinator, its workers) names each with a line `pid N`: they are
//!    measured with it.
//! 2. Once every process is ready, the runner writes `go START UNTIL` (ns on the system
//!    clock): sensors and timers start at START, everything stops at UNTIL. START is a
//!    multiple of the topology's common period ([`super::topology::common_period`]), so
//!    a timer that ticks on multiples of its own period ticks at START too.
//! 3. At UNTIL the process writes its nodes' reports into the run's directory
//!    (`NODE.txt`) and prints `done`, then waits for `exit` (or the end of its input) and
//!    leaves. Between `go` and `done` the runner measures the CPU and memory of every
//!    process ([`super::resources::Meter`]), so setup and teardown are not counted.
//!
//! Everything that waits has a deadline; a process that dies or hangs fails the run,
//! naming it and the end of its log (its stderr, `NAME.log` in the run's directory).

use std::io::{BufRead as _, BufReader, Write as _};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use super::node::now_ns;
use super::report::NodeReport;
use super::resources::{Meter, Usage};
use super::system::RunSettings;

/// How long a process may take to set up.
const SETUP: Duration = Duration::from_secs(90);
/// How long after UNTIL a process may take to report.
const REPORT: Duration = Duration::from_secs(30);
/// The gap between the last `ready` and START, so every process has read `go`.
const LEAD: Duration = Duration::from_millis(500);

/// A process of a system.
struct Running {
    name: String,
    child: Child,
    stdin: Option<ChildStdin>,
}

impl Drop for Running {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _already_gone = self.child.kill();
            let _reaped = self.child.wait();
        }
    }
}

/// The last lines of `name`'s log, for an error.
fn log_tail(dir: &Path, name: &str) -> String {
    let text = std::fs::read_to_string(dir.join(format!("{name}.log"))).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(15)..].join("\n")
}

/// Runs `processes` (a name and a command each, the command not yet spawned) through
/// the protocol; `others` are pids of the system's processes that do not speak it (a
/// coordinator, a rosmaster), measured with them. Returns the reports the processes
/// wrote, what they used between `go` and `done`, and the `note TEXT` lines they
/// printed (for the report).
pub fn run(
    processes: Vec<(String, Command)>,
    others: &[u32],
    settings: &RunSettings,
) -> anyhow::Result<(Vec<NodeReport>, Usage, Vec<String>)> {
    let dir = &settings.dir;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot make {}", dir.display()))?;
    let (lines_tx, lines) = mpsc::channel::<(usize, String)>();
    let mut running = Vec::new();
    for (i, (name, mut command)) in processes.into_iter().enumerate() {
        let log = std::fs::File::create(dir.join(format!("{name}.log")))
            .with_context(|| format!("cannot make {name}'s log"))?;
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .with_context(|| format!("cannot start {name}"))?;
        let stdout = child.stdout.take().context("no stdout")?;
        let tx = lines_tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send((i, line)).is_err() {
                    return;
                }
            }
        });
        let stdin = child.stdin.take();
        running.push(Running { name, child, stdin });
    }
    drop(lines_tx);

    let mut notes = Vec::new();
    // Returns the pids announced meanwhile (`pid N`).
    let mut wait_for =
        |word: &str, running: &mut Vec<Running>, deadline: Instant| -> anyhow::Result<Vec<u32>> {
            let mut said = vec![false; running.len()];
            let mut announced = Vec::new();
            while said.iter().any(|s| !s) {
                let left = deadline.saturating_duration_since(Instant::now());
                match lines.recv_timeout(left.min(Duration::from_millis(200))) {
                    Ok((i, line)) if line.trim() == word => said[i] = true,
                    Ok((i, line)) if line.starts_with("note ") => {
                        notes.push(format!("{}: {}", running[i].name, &line[5..]));
                    }
                    Ok((i, line)) if line.starts_with("pid ") => {
                        let pid = line[4..].trim().parse::<u32>().with_context(|| {
                            format!("{} announced {line:?}, not `pid N`", running[i].name)
                        })?;
                        announced.push(pid);
                    }
                    Ok(_) => {}
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        bail!("every process closed its output before `{word}`");
                    }
                }
                for (i, r) in running.iter_mut().enumerate() {
                    if !said[i] {
                        if let Some(status) = r.child.try_wait()? {
                            bail!(
                                "{} exited ({status}) before `{word}`:\n{}",
                                r.name,
                                log_tail(dir, &r.name)
                            );
                        }
                    }
                }
                if Instant::now() >= deadline {
                    let late: Vec<&str> = running
                        .iter()
                        .zip(&said)
                        .filter(|(_, s)| !**s)
                        .map(|(r, _)| r.name.as_str())
                        .collect();
                    bail!(
                        "no `{word}` from {} in time; {}'s log ends:\n{}",
                        late.join(", "),
                        late[0],
                        log_tail(dir, late[0])
                    );
                }
            }
            Ok(announced)
        };

    let announced = wait_for("ready", &mut running, Instant::now() + SETUP)?;
    let mut pids: Vec<u32> = running.iter().map(|r| r.child.id()).collect();
    pids.extend_from_slice(others);
    pids.extend(announced);
    let meter = Meter::start(pids)?;
    let earliest = now_ns() + u64::try_from(LEAD.as_nanos()).unwrap_or(0);
    let common = u64::try_from(super::topology::common_period().as_nanos()).unwrap_or(1).max(1);
    let start = earliest.div_ceil(common) * common;
    let until = start + u64::try_from(settings.duration.as_nanos()).unwrap_or(u64::MAX);
    for r in &mut running {
        let stdin = r.stdin.as_mut().context("no stdin")?;
        writeln!(stdin, "go {start} {until}")
            .with_context(|| format!("cannot tell {} to go", r.name))?;
        stdin.flush()?;
    }
    wait_for("done", &mut running, Instant::now() + LEAD + settings.duration + REPORT)?;
    let usage = meter.finish()?;
    for r in &mut running {
        if let Some(mut stdin) = r.stdin.take() {
            let _gone_already = writeln!(stdin, "exit");
        }
    }
    let deadline = Instant::now() + REPORT;
    for r in &mut running {
        loop {
            if let Some(status) = r.child.try_wait()? {
                if !status.success() {
                    bail!("{} failed ({status}):\n{}", r.name, log_tail(dir, &r.name));
                }
                break;
            }
            if Instant::now() > deadline {
                bail!("{} did not leave after `exit`:\n{}", r.name, log_tail(dir, &r.name));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    Ok((read_reports(dir)?, usage, notes))
}

/// Every node report in `dir`, those of one node folded into one
/// ([`NodeReport::by_node`]).
pub fn read_reports(dir: &Path) -> anyhow::Result<Vec<NodeReport>> {
    let mut reports = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "txt") {
            let text = std::fs::read_to_string(&path)?;
            reports.push(NodeReport::parse(&text).with_context(|| format!("{}", path.display()))?);
        }
    }
    Ok(NodeReport::by_node(reports))
}

/// A node process's side of the protocol (in Rust: esgm's and ROS 2's processes).
#[derive(Debug)]
pub struct NodeSide {
    input: std::io::StdinLock<'static>,
}

impl NodeSide {
    /// Says `ready` (set up) and waits for `go`; returns START and UNTIL (ns).
    pub fn ready() -> anyhow::Result<(Self, u64, u64)> {
        println!("ready");
        std::io::stdout().flush()?;
        let mut input = std::io::stdin().lock();
        let mut line = String::new();
        input.read_line(&mut line)?;
        let words: Vec<&str> = line.split_whitespace().collect();
        let (Some(&"go"), Some(start), Some(until)) = (words.first(), words.get(1), words.get(2))
        else {
            bail!("expected `go START UNTIL`, got {line:?}");
        };
        Ok((Self { input }, start.parse()?, until.parse()?))
    }

    /// Writes `reports` into `dir`, says `done`, and waits for `exit`.
    pub fn done(mut self, reports: &[NodeReport], dir: &Path) -> anyhow::Result<()> {
        for r in reports {
            std::fs::write(dir.join(format!("{}.txt", r.node)), r.to_text())?;
        }
        println!("done");
        std::io::stdout().flush()?;
        let mut line = String::new();
        // `exit`, or the end of the input: either way, leave.
        let _either = self.input.read_line(&mut line);
        Ok(())
    }
}

/// Sleeps until `ns` on the system clock.
pub fn sleep_until(ns: u64) {
    let now = now_ns();
    if ns > now {
        std::thread::sleep(Duration::from_nanos(ns - now));
    }
}
