//! `esgm log-level LEVEL [--process P]`: changes the log filter of the system's running
//! processes (E7 `set_log_level`), or of one process by name (as `esgm ps` lists it).
//! A process that logs through `esgm_shm::process::init_logging` (every esgm program)
//! replaces its tracing filter at once.

use anyhow::{Context, bail};
use esgm_core::esgm::LogLevel;
use serde_json::json;

use crate::session::connect_tool as connect;

/// `esgm log-level` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// error, warn, info, debug or trace.
    pub level: String,
    /// Only this process (its name in `esgm ps`, or its host name in the registry).
    #[arg(long)]
    pub process: Option<String>,
}

/// Sets the level and lists the processes that took it.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let Some(level) = LogLevel::parse(&a.level) else {
        bail!("`{}` is not a log level: give error, warn, info, debug or trace", a.level);
    };
    let esgm = connect(domain)?;
    let applied =
        esgm.set_log_level_of(a.process.as_deref(), level).context("cannot set the log level")?;
    // The CLI's own connection takes it too; it is not one of the system's processes.
    let own = esgm.host().to_owned();
    let applied: Vec<String> = applied.into_iter().filter(|h| *h != own).collect();
    if json {
        println!("{}", json!({ "level": a.level.to_ascii_lowercase(), "processes": applied }));
    } else if applied.is_empty() {
        println!("log level {}: no other process is connected", a.level.to_ascii_lowercase());
    } else {
        println!("log level {} in {}", a.level.to_ascii_lowercase(), applied.join(", "));
    }
    Ok(())
}
