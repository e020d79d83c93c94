//! `esgm ps`: the processes the system keeps running (declared by `esgm apply`,
//! supervised by `esgm up`), with their pid, restarts and last exit.

use anyhow::bail;
use esgm_shm::ShmEsgm;
use esgm_shm::control::{ProcessRecord, Request, Response, SaveHealth};

use crate::session::connect_tool as connect;

/// The declared processes of `domain`, as the supervisor last reported them.
pub fn processes(domain: &str) -> anyhow::Result<Vec<ProcessRecord>> {
    listed(&connect(domain)?)
}

/// The declared processes, as the supervisor last reported them.
pub fn listed(esgm: &ShmEsgm) -> anyhow::Result<Vec<ProcessRecord>> {
    match esgm.control(Request::ListProcesses)? {
        Response::Processes(p) => Ok(p),
        other => bail!("unexpected answer from the coordinator: {other:?}"),
    }
}

/// Prints one line (or JSON object) per process, and a warning if the coordinator
/// failed to save its registry.
pub fn run(domain: &str, json: bool) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    print(&listed(&esgm)?, json)?;
    warn_of_unsaved(&esgm, json)
}

/// Says, after a listing, that the coordinator failed to save its registry (each
/// failure refused and undid a change): on stdout below a table, on stderr beside
/// JSON lines (which stay one shape).
pub fn warn_of_unsaved(esgm: &ShmEsgm, json: bool) -> anyhow::Result<()> {
    let Response::Pong { saves, .. } = esgm.control(Request::Ping)? else {
        bail!("the coordinator did not answer a ping");
    };
    if let Some(line) = unsaved_line(&saves) {
        match json {
            true => eprintln!("esgm: {line}"),
            false => println!("\n{line}"),
        }
    }
    Ok(())
}

/// The warning for `saves`, if any save failed.
fn unsaved_line(saves: &SaveHealth) -> Option<String> {
    let n = saves.failures;
    (n > 0).then(|| match &saves.failing {
        Some(reason) => format!(
            "the coordinator CANNOT SAVE its registry ({n} failed saves; changes are refused \
             until one succeeds): {reason}"
        ),
        None => format!(
            "the coordinator failed to save its registry {n} times (those changes were \
             refused); it saves again"
        ),
    })
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_saves_are_shown_until_and_after_they_recover() {
        assert_eq!(unsaved_line(&SaveHealth::default()), None);
        let failing = SaveHealth { failures: 2, failing: Some("disk full".into()) };
        let line = unsaved_line(&failing).unwrap_or_default();
        assert!(line.contains("CANNOT SAVE") && line.contains("disk full"), "{line}");
        let recovered = SaveHealth { failures: 2, failing: None };
        assert!(unsaved_line(&recovered).unwrap_or_default().contains("2 times"));
    }
}
