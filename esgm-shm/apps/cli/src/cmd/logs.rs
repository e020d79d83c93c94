//! `esgm logs [process]`: what a system's processes wrote. `esgm up` sends each
//! supervised process's output, and a detached coordinator's own, to
//! `<state dir>/logs/<process>.log` (the state directory: `ESGM_STATE_DIR`, else
//! `$XDG_STATE_HOME/esgm/<domain>`); the logs outlive the system, for a post-mortem.

use std::io::Read;

use anyhow::{Context, bail};
use esgm_core::type_registry::closest_name;
use esgm_shm::control::StateDir;

/// `esgm logs` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The process (as `esgm ps` names it, or `coordinator`); without it, every
    /// process's log is listed.
    pub process: Option<String>,
    /// Show the last N lines (0: all).
    #[arg(long, short = 'n', default_value_t = 50)]
    pub lines: usize,
}

/// Lists the logs, or prints one.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let state = StateDir::from_env(domain).context("cannot choose a state directory")?;
    let dir = state.log_dir();
    let mut names = Vec::new();
    match std::fs::read_dir(&dir) {
        Ok(entries) => {
            for entry in entries {
                let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
                let file = entry.file_name().to_string_lossy().into_owned();
                if let Some(name) = file.strip_suffix(".log") {
                    names.push(name.to_owned());
                }
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("no logs for `{domain}` in {} (was it started with `esgm up`?)", dir.display())
        }
        Err(e) => return Err(e).with_context(|| format!("cannot list {}", dir.display())),
    }
    names.sort();
    let Some(process) = &a.process else {
        for name in &names {
            let path = dir.join(format!("{name}.log"));
            let bytes = std::fs::metadata(&path)
                .with_context(|| format!("cannot read {}", path.display()))?
                .len();
            if json {
                let line = serde_json::json!({"process": name, "path": path, "bytes": bytes});
                println!("{line}");
            } else {
                println!("{name:<28} {bytes:>10} bytes  {}", path.display());
            }
        }
        return Ok(());
    };
    if !names.contains(process) {
        let hint = closest_name(process, names.iter().map(String::as_str))
            .map(|s| format!("; did you mean `{s}`?"))
            .unwrap_or_default();
        bail!("no log of process `{process}` in {}{hint}", dir.display());
    }
    let path = dir.join(format!("{process}.log"));
    let mut text = String::new();
    std::fs::File::open(&path)
        .and_then(|mut f| f.read_to_string(&mut text))
        .with_context(|| format!("cannot read {}", path.display()))?;
    let lines: Vec<&str> = text.lines().collect();
    let from = if a.lines == 0 { 0 } else { lines.len().saturating_sub(a.lines) };
    for line in &lines[from..] {
        if json {
            println!("{}", serde_json::json!({"process": process, "line": line}));
        } else {
            println!("{line}");
        }
    }
    Ok(())
}
