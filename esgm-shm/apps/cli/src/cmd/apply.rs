//! `esgm apply <file.toml>`: declare a system — types, sensors, units, robots and
//! trajectories with their policies — from a configuration file (format: see
//! `crate::config` and the commented `tutorial.toml`).

use std::path::PathBuf;

use crate::config::{self, Plan};

/// `esgm apply` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The configuration file.
    pub file: PathBuf,
    /// Check the file (and its names against the running system) without changing
    /// anything.
    #[arg(long)]
    pub dry_run: bool,
}

/// Runs `esgm apply`.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let plan = config::load(&a.file)?;
    if a.dry_run {
        for (line, kind, name) in plan.items() {
            if json {
                println!("{}", serde_json::json!({ "kind": kind, "name": name, "line": line }));
            } else {
                println!("{:>5}  {kind:<10} {name}", format!("{line}:"));
            }
        }
        return Ok(());
    }
    apply_plan(domain, &plan, json)
}

/// Applies a checked plan, printing each outcome (as JSON lines with `json`).
pub fn apply_plan(domain: &str, plan: &Plan, json: bool) -> anyhow::Result<()> {
    // A large file takes a while (every declaration is a coordinator round trip).
    let progress = crate::progress::ApplyProgress::start(json, plan.items().len());
    let result = config::apply::apply(domain, plan, &mut |o| {
        let line = if json {
            // Plain strings and numbers: serializing cannot fail.
            serde_json::to_string(&o).unwrap_or_default()
        } else {
            format!("{:<10} {:<20} {:<10} (line {})", o.kind, o.name, o.change, o.line)
        };
        progress.println(&line);
    });
    progress.finish();
    result
}
