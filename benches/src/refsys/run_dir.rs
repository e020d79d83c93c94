//! How the node programs a coordinator starts take part in a run's window. The runner
//! speaks the run's protocol ([`super::processes`]) with the coordinator's process on
//! its standard streams; the node programs are the coordinator's workers, started by
//! its supervisor with no standard input of the runner's, so the coordinator's process
//! relays the protocol to them through files in the run's directory, which their
//! environment names ([`RUN_ENV`], inherited from the coordinator's process):
//! 1. a worker, once it serves what it was declared for, writes `workers/NAME.ready`
//!    holding its pid (NAME: the sensor or unit it serves);
//! 2. the coordinator's process, told `go START UNTIL`, writes `workers/go` (written
//!    whole, then renamed into place, so a worker never reads half of it);
//! 3. each worker runs the window, writes its node's report (`NAME.txt`, which the
//!    runner reads with every other system's) and then `workers/NAME.done`.
//!
//! Every wait has a deadline, and a late worker is named with the end of its log.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use super::report::NodeReport;

/// The environment variable naming the run's directory, for the workers of a measured
/// run (unset: a system run by hand, not measured).
pub const RUN_ENV: &str = "ESGM_REFSYS_RUN";
/// The environment variable giving every processing node's work, the number
/// cruncher's limit (unset: none, upstream's `BenchmarkCPUUsage` timing).
pub const CRUNCH_ENV: &str = "ESGM_REFSYS_CRUNCH";

/// How often a file waited for is looked for.
const POLL: Duration = Duration::from_millis(20);

/// A stage a worker says it reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// It serves what it was declared for.
    Ready,
    /// It ran the window and wrote its report.
    Done,
}

impl Stage {
    fn word(self) -> &'static str {
        match self {
            Stage::Ready => "ready",
            Stage::Done => "done",
        }
    }
}

/// A worker of the run: the sensor or unit it serves, and its process's name (its log
/// is `state/logs/PROCESS.log` in the run's directory).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Worker {
    /// What it serves.
    pub serves: String,
    /// Its process.
    pub process: String,
}

/// A run's directory.
#[derive(Debug, Clone)]
pub struct RunDir {
    dir: PathBuf,
}

impl RunDir {
    /// The run's directory `dir`.
    pub fn new(dir: &Path) -> Self {
        Self { dir: dir.to_path_buf() }
    }

    /// The run this worker takes part in, if the environment names one.
    pub fn from_env() -> Option<Self> {
        std::env::var_os(RUN_ENV).map(|d| Self { dir: PathBuf::from(d) })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The directory the coordinator's domain keeps its registry and logs in.
    pub fn state(&self) -> PathBuf {
        self.dir.join("state")
    }

    fn workers(&self) -> PathBuf {
        self.dir.join("workers")
    }

    fn marker(&self, name: &str, stage: Stage) -> PathBuf {
        self.workers().join(format!("{name}.{}", stage.word()))
    }

    /// Writes `path` whole, then puts it in place.
    fn write(&self, path: &Path, text: &str) -> anyhow::Result<()> {
        std::fs::create_dir_all(self.workers())
            .with_context(|| format!("cannot make {}", self.workers().display()))?;
        let partial = path.with_extension("partial");
        std::fs::write(&partial, text)
            .and_then(|()| std::fs::rename(&partial, path))
            .with_context(|| format!("cannot write {}", path.display()))
    }

    /// A worker serving `name` is ready (step 1).
    pub fn ready(&self, name: &str) -> anyhow::Result<()> {
        self.write(&self.marker(name, Stage::Ready), &std::process::id().to_string())
    }

    /// The coordinator's process opens the window from `start` to `until` (step 2).
    pub fn go(&self, start: u64, until: u64) -> anyhow::Result<()> {
        self.write(&self.workers().join("go"), &format!("{start} {until}"))
    }

    /// Waits for [`Self::go`] until `deadline`; `START UNTIL`.
    pub fn wait_for_go(&self, deadline: Instant) -> anyhow::Result<(u64, u64)> {
        let path = self.workers().join("go");
        loop {
            match std::fs::read_to_string(&path) {
                Ok(text) => {
                    let words: Vec<&str> = text.split_whitespace().collect();
                    let (Some(start), Some(until)) = (words.first(), words.get(1)) else {
                        bail!("{} holds {text:?}, not `START UNTIL`", path.display());
                    };
                    return Ok((start.parse()?, until.parse()?));
                }
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
            }
            if Instant::now() >= deadline {
                bail!("no `go` from the coordinator's process in time ({})", path.display());
            }
            std::thread::sleep(POLL);
        }
    }

    /// A worker serving `name` ran the window and reports `report` (step 3).
    pub fn done(&self, name: &str, report: &NodeReport) -> anyhow::Result<()> {
        let path = self.dir.join(format!("{name}.txt"));
        std::fs::write(&path, report.to_text())
            .with_context(|| format!("cannot write {}", path.display()))?;
        self.write(&self.marker(name, Stage::Done), "")
    }

    /// Waits until every one of `workers` reached `stage`, up to `deadline`; their pids
    /// (for [`Stage::Ready`]; 0 for [`Stage::Done`]). `given_up` is asked while waiting: a reason to stop
    /// waiting at once (the coordinator stopped).
    pub fn wait_for(
        &self,
        stage: Stage,
        workers: &[Worker],
        deadline: Instant,
        given_up: &mut dyn FnMut() -> Option<String>,
    ) -> anyhow::Result<Vec<u32>> {
        let mut pids = vec![None; workers.len()];
        loop {
            for (i, w) in workers.iter().enumerate() {
                if pids[i].is_some() {
                    continue;
                }
                match std::fs::read_to_string(self.marker(&w.serves, stage)) {
                    Ok(text) => {
                        pids[i] = Some(match stage {
                            Stage::Ready => text.trim().parse::<u32>().with_context(|| {
                                format!("{}'s ready marker holds {text:?}, not a pid", w.serves)
                            })?,
                            Stage::Done => 0,
                        });
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    Err(e) => {
                        return Err(e)
                            .with_context(|| format!("cannot read {}'s marker", w.serves));
                    }
                }
            }
            let late: Vec<&Worker> =
                workers.iter().zip(&pids).filter(|(_, p)| p.is_none()).map(|(w, _)| w).collect();
            let Some(first) = late.first() else { break };
            let why = given_up();
            if why.is_some() || Instant::now() >= deadline {
                let names: Vec<&str> = late.iter().map(|w| w.serves.as_str()).collect();
                bail!(
                    "{} of {} workers not {} ({}){}; the log of `{}` (process {}) ends:\n{}",
                    late.len(),
                    workers.len(),
                    stage.word(),
                    names.join(", "),
                    why.map(|w| format!(": {w}")).unwrap_or_else(|| " in time".into()),
                    first.serves,
                    first.process,
                    self.log_tail(&first.process)
                );
            }
            std::thread::sleep(POLL);
        }
        Ok(pids.into_iter().map(|p| p.unwrap_or(0)).collect())
    }

    /// The last lines of worker process `process`'s log.
    pub fn log_tail(&self, process: &str) -> String {
        let path = self.state().join("logs").join(format!("{process}.log"));
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                let lines: Vec<&str> = text.lines().collect();
                lines[lines.len().saturating_sub(15)..].join("\n")
            }
            Err(e) => format!("({}: {e})", path.display()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workers_and_the_coordinator_meet_through_the_run_directory() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunDir::new(dir.path());
        let workers = [
            Worker { serves: "A".into(), process: "unit-A".into() },
            Worker { serves: "B".into(), process: "unit-B".into() },
        ];
        run.ready("A").unwrap();
        let soon = Instant::now() + Duration::from_millis(100);
        let e = run.wait_for(Stage::Ready, &workers, soon, &mut || None).unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("1 of 2 workers not ready (B) in time") && e.contains("unit-B"), "{e}");
        let stopped = run
            .wait_for(Stage::Ready, &workers, soon, &mut || Some("the coordinator stopped".into()))
            .unwrap_err();
        assert!(format!("{stopped:#}").contains(": the coordinator stopped"), "{stopped:#}");
        run.ready("B").unwrap();
        let later = Instant::now() + Duration::from_secs(10);
        let pids = run.wait_for(Stage::Ready, &workers, later, &mut || None).unwrap();
        assert_eq!(pids, [std::process::id(); 2]);

        assert!(run.wait_for_go(Instant::now()).is_err(), "no go yet");
        run.go(600, 1_200).unwrap();
        assert_eq!(run.wait_for_go(later).unwrap(), (600, 1_200));
        run.done("A", &NodeReport::new("A")).unwrap();
        run.done("B", &NodeReport::new("B")).unwrap();
        run.wait_for(Stage::Done, &workers, later, &mut || None).unwrap();
        assert!(dir.path().join("A.txt").exists());
    }
}
