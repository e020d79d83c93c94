//! `esgm load FILE`: recorded trajectories made queryable in a running system.
//!
//! The command line does not stay: the trajectories are created placed on the
//! system's own process in `esgm up` ([`SYSTEM_HOST`]), which writes them, and the
//! structures are added through it; when this command exits, they remain and answer
//! `esgm latest`, `between`, `at` and `approx`.

use std::path::PathBuf;

use anyhow::Context;
use esgm_core::Esgm;
use esgm_core::esgm::{CreateError, LookupError, Peer, Unreachable};
use esgm_recording::{LoadOptions, LoadReport, Recording, load_with};
use esgm_shm::control::{ControlClientError, ControlError, Request, Response};

use crate::config::apply::SYSTEM_HOST;
use crate::session::connect;

/// `esgm load` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The recording (`.mcap`).
    pub file: PathBuf,
    /// Load only these trajectories.
    #[arg(long, num_args = 1..)]
    pub only: Vec<String>,
    /// Re-create trajectories whose names exist instead of refusing.
    #[arg(long)]
    pub replace: bool,
}

/// Loads the recording into the domain and prints what happened to each trajectory.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let rec =
        Recording::open(&a.file).with_context(|| format!("cannot read {}", a.file.display()))?;
    let esgm = connect(domain)?;
    let options = LoadOptions::new().only(a.only.iter().cloned()).replace(a.replace);
    let report = load_with(&esgm, &rec, &options, |esgm, spec| {
        let name = spec.name.clone();
        let created =
            esgm.control(Request::CreateTrajectory { spec, host: SYSTEM_HOST.to_owned() });
        match created {
            Ok(Response::Trajectory(_)) => {}
            Ok(Response::Error(ControlError::Create(e)))
            | Err(ControlClientError::Remote(ControlError::Create(e))) => return Err(e),
            Ok(other) => {
                return Err(CreateError::Unavailable {
                    reason: Unreachable::malformed(Peer::Coordinator, format!("{other:?}")),
                });
            }
            Err(e) => return Err(CreateError::Unavailable { reason: e.into() }),
        }
        esgm.get_entity_trajectory_structure(&name).map_err(|e| match e {
            LookupError::Unavailable { reason } => CreateError::Unavailable { reason },
            e => CreateError::Unavailable { reason: Unreachable::refused(Peer::Coordinator, e) },
        })
    })
    .with_context(|| format!("cannot load {} into `{domain}`", a.file.display()))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(domain, &report);
    }
    Ok(())
}

fn print_report(domain: &str, r: &LoadReport) {
    println!("loaded {} into `{domain}`, written by {SYSTEM_HOST}", r.path.display());
    if !r.types_registered.is_empty() {
        println!("types registered: {}", r.types_registered.join(", "));
    }
    println!(
        "{:<22} {:<18} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "trajectory", "type", "offered", "added", "dropped", "evicted", "stored"
    );
    for t in &r.trajectories {
        let dropped: u64 = t.dropped.values().sum();
        println!(
            "{:<22} {:<18} {:>8} {:>8} {:>8} {:>8} {:>8}",
            t.name, t.type_name, t.offered, t.added, dropped, t.evicted, t.stored
        );
    }
    for t in &r.trajectories {
        if t.replaced {
            println!("{}: replaced the trajectory of that name", t.name);
        }
        for relaxed in &t.relaxed {
            println!("{}: {relaxed}", t.name);
        }
        for (cause, n) in &t.dropped {
            println!("{}: {n} dropped by its policy ({cause})", t.name);
        }
        if t.evicted > 0 {
            println!(
                "{}: {} evicted by its recorded cache bound; {} stay queryable",
                t.name, t.evicted, t.stored
            );
        }
    }
}
