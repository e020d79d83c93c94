//! `esgm ps`: the processes the system keeps running (declared by `esgm apply`,
//! supervised by `esgm up`), with their pid, restarts and last exit.

use anyhow::bail;
use esgm_shm::control::{ProcessRecord, Request, Response};

use crate::session::connect_tool as connect;

/// The declared processes, as the supervisor last reported them.
pub fn processes(domain: &str) -> anyhow::Result<Vec<ProcessRecord>> {
    let esgm = connect(domain)?;
    match esgm.control(Request::ListProcesses)? {
        Response::Processes(p) => Ok(p),
        other => bail!("unexpected answer from the coordinator: {other:?}"),
    }
}

/// Prints one line (or JSON object) per process.
pub fn run(domain: &str, json: bool) -> anyhow::Result<()> {
    print(&processes(domain)?, json)
}

/// Prints `list` as a table (or JSON lines).
pub fn print(list: &[ProcessRecord], json: bool) -> anyhow::Result<()> {
    if !json {
        println!("{:<28} {:>8} {:>8}  {:<24} command", "process", "pid", "restarts", "last exit");
    }
    for p in list {
        if json {
            println!("{}", serde_json::to_string(&p)?);
            continue;
        }
        let pid = p.status.pid.map_or_else(|| "-".to_owned(), |p| p.to_string());
        let command = std::iter::once(p.spec.program.rsplit('/').next().unwrap_or_default())
            .chain(p.spec.args.iter().map(String::as_str))
            .collect::<Vec<_>>()
            .join(" ");
        println!(
            "{:<28} {:>8} {:>8}  {:<24} {command}",
            p.spec.name,
            pid,
            p.status.restarts,
            p.status.last_exit.as_deref().unwrap_or("-")
        );
    }
    Ok(())
}
