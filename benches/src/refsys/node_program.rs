//! `esgm-refsys-node`: the program every sensor and unit of the reference system's file
//! (`benches/refsys/refsys.toml`) is served by, one process each, started and
//! supervised by the coordinator as any user's program a system file names. It serves
//! the sensor or unit it was declared for (`ESGM_NAME`, which the file's loader sets)
//! with the node's logic ([`super::served`]), connected through `connect` as the
//! coordinator's environment says.
//!
//! In a measured run ([`RUN_ENV`] names its directory) it takes part in the run's
//! window through that directory ([`super::run_dir`]): ready, `go START UNTIL`, its
//! node's report, done; it leaves with the process that started it. Run by hand
//! (`esgm up --config`), it serves from the start and reports nothing. Either way it
//! leaves when its system is stopped (`esgm down`).
//!
//! `esgm-bench` is this program too when called by its name: the run starts the
//! coordinator with `esgm-bench` under that name first on its `PATH`, so the nodes of
//! a run are always the code it was built with (`cargo run --bin esgm-bench` builds only
//! esgm-bench; a separate `esgm-refsys-node` could be stale).

use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use esgm_shm::attach::serve_while_system_lives;
use esgm_shm::prelude::*;

use super::processes::sleep_until;
use super::run_dir::{CRUNCH_ENV, RUN_ENV, RunDir};
use super::served::serve;
use super::system_file::PROGRAM;
use super::window::{DRAIN, Window};

/// How long a worker waits for its run's `go`: a run's setup (every worker started and
/// registered, every trajectory created) takes seconds; this is what a failed one
/// leaves a worker waiting.
const SETUP: Duration = Duration::from_secs(90);

/// Whether this process was started as the node program (its name, as called).
pub fn called_as_node_program() -> bool {
    std::env::args_os()
        .next()
        .and_then(|arg0| std::path::Path::new(&arg0).file_name().map(|n| n == PROGRAM))
        .unwrap_or(false)
}

/// The node program's `main`.
pub fn main() -> ExitCode {
    init_logging();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{PROGRAM}: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let name = std::env::var(esgm_cli::config::NAME_ENV).with_context(|| {
        format!(
            "{} is not set: {PROGRAM} serves a sensor or unit of the reference system's file \
             (benches/refsys/refsys.toml), started by the coordinator that applies it",
            esgm_cli::config::NAME_ENV
        )
    })?;
    let crunch: u64 = match std::env::var(CRUNCH_ENV) {
        Ok(v) => v.parse().with_context(|| format!("{CRUNCH_ENV}={v} is not a number"))?,
        Err(std::env::VarError::NotPresent) => 0,
        Err(e) => return Err(e).with_context(|| format!("{CRUNCH_ENV} is not unicode")),
    };
    let run = RunDir::from_env();
    if run.is_some() {
        leave_with_parent()?;
    }
    let esgm = ShmEsgm::builder().from_env().connect().context("cannot join the system")?;
    let window = Arc::new(Window::default());
    let served = serve(&esgm, &name, crunch, &window)?;
    match run {
        Some(run) => {
            run.ready(&name)?;
            let (start, until) = run.wait_for_go(Instant::now() + SETUP).with_context(|| {
                format!("{name} of the run in {} ({RUN_ENV})", run.dir().display())
            })?;
            let as_time = |ns: u64| Time::try_from(ns).unwrap_or(Time::MAX);
            window.set(as_time(start), as_time(until));
            sleep_until(until.saturating_add(u64::try_from(DRAIN.as_nanos()).unwrap_or(0)));
            run.done(&name, &served.report())?;
            write_steps(&name);
        }
        None => window.open_for_good(),
    }
    // Serves its trajectories (and answers queries of them) until the system stops.
    serve_while_system_lives(&esgm, None, Duration::from_millis(500));
    Ok(())
}

/// With the hop probes built in (`--features hop-probe`) and [`STEPS_ENV`] naming a
/// directory: this node's hop steps, one line a step ([`crate::hop_steps::lines`]), in
/// `steps-<node>.txt` there, to read beside the run's KPIs.
fn write_steps(name: &str) {
    let Some(dir) = std::env::var_os(STEPS_ENV) else { return };
    let lines = crate::hop_steps::lines(name);
    if lines.is_empty() {
        return;
    }
    let path = std::path::Path::new(&dir).join(format!("steps-{name}.txt"));
    if let Err(e) = std::fs::write(&path, lines.join("\n") + "\n") {
        eprintln!("{PROGRAM}: cannot write {}: {e}", path.display());
    }
}

/// The directory the node writes its hop steps to (`--features hop-probe`).
pub const STEPS_ENV: &str = "ESGM_REFSYS_STEPS";

/// A worker of a measured run leaves when the process that started it (the run's
/// coordinator) dies, so a run that fails and kills its coordinator leaves no worker
/// behind. Not by hand: there a worker outlives a crashed coordinator, which adopts it
/// when it comes back (`esgm up --supervise`).
fn leave_with_parent() -> anyhow::Result<()> {
    #[cfg(target_os = "linux")]
    {
        let parent = std::os::unix::process::parent_id();
        // SAFETY: PR_SET_PDEATHSIG takes a signal number and changes only what the
        // kernel sends this process when its parent ends; no memory is passed.
        let set = unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) };
        if set != 0 {
            eprintln!(
                "{PROGRAM}: cannot leave with the coordinator ({}); a failed run may leave \
                 this worker behind",
                std::io::Error::last_os_error()
            );
        }
        // The parent may have ended before the request: then nothing would be sent.
        if std::os::unix::process::parent_id() != parent {
            anyhow::bail!("the coordinator that started this worker is gone");
        }
    }
    Ok(())
}
