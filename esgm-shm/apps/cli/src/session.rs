//! Connecting to a running system, and reading a trajectory from the command line.

use std::time::{Duration, Instant};

use anyhow::Context;
use esgm_core::{EntityTrajectoryStructure, Esgm, InProcessTrajectory};
use esgm_shm::ShmEsgm;

/// How long a command waits for a trajectory's history to arrive from its writer.
const SETTLE: Duration = Duration::from_millis(500);
/// How long nothing new must arrive before the history counts as received.
const QUIET: Duration = Duration::from_millis(30);

/// Connects to the coordinator of `domain` as the CLI, for a command that stays (a
/// reader such as `esgm echo` or `esgm record`): it counts against the domain's
/// processes and its trajectories' readers like any process.
pub fn connect(domain: &str) -> anyhow::Result<ShmEsgm> {
    connect_with(domain, false)
}

/// Connects as a short-lived command (`esgm latest`, `esgm push`, `esgm stats`…),
/// which may use the room every service keeps beyond its limits: a domain whose
/// limit is reached can still be looked at ([`esgm_shm::DomainLimits`]).
pub fn connect_tool(domain: &str) -> anyhow::Result<ShmEsgm> {
    connect_with(domain, true)
}

fn connect_with(domain: &str, tool: bool) -> anyhow::Result<ShmEsgm> {
    let host = format!("esgm-cli-{}", std::process::id());
    let mut builder = ShmEsgm::builder().domain(domain).host(host).timeout(Duration::from_secs(5));
    if tool {
        builder = builder.tool();
    }
    builder.connect().with_context(|| format!("cannot reach the system `{domain}`"))
}

/// A handle on `name` with the writer's history received: at once when the writer
/// handed it over as the CLI began to read (the usual case); otherwise the CLI is a
/// late reader that waits until samples stop arriving, at most [`SETTLE`].
pub fn trajectory(esgm: &ShmEsgm, name: &str) -> anyhow::Result<InProcessTrajectory> {
    let t = esgm.get_entity_trajectory_structure(name)?;
    if esgm.history_received(name) {
        return Ok(t);
    }
    let deadline = Instant::now() + SETTLE;
    let mut last = (0, Instant::now());
    while Instant::now() < deadline {
        let added = t.stats().map(|s| s.added).unwrap_or(0);
        if added != last.0 {
            last = (added, Instant::now());
        } else if last.1.elapsed() > QUIET {
            // The writer handed the history over when the replica was made (its join);
            // what still comes, comes within a moment. An empty trajectory stays empty.
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(t)
}
