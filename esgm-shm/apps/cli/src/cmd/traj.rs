//! `esgm traj list|show|create|rm`.

use esgm_core::{Clock as _, EntityTrajectoryStructure, Esgm};
use serde_json::json;
use std::io::Write as _;

use anyhow::bail;
use esgm_shm::control::{Request, Response};

use crate::config::apply::SYSTEM_HOST;
use crate::config::decl::TrajectoryDecl;
use crate::session::{connect_tool as connect, trajectory};

/// `esgm traj` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum TrajCommand {
    /// Every trajectory: name, kind, type, source.
    List,
    /// One trajectory: its description, policy and statistics.
    Show {
        /// Trajectory name.
        name: String,
    },
    /// Create a trajectory: exactly one of --primitive, --sampled, --computed, --sync,
    /// --merge, and any policy settings.
    Create(Box<TrajectoryDecl>),
    /// Destroy a trajectory.
    Rm {
        /// Trajectory name.
        name: String,
    },
}

/// Runs an `esgm traj` subcommand.
pub fn run(domain: &str, json: bool, c: &TrajCommand) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    match c {
        TrajCommand::List => {
            let list = esgm.trajectories()?;
            // One write for the whole table, not one per line (a domain may hold
            // thousands of trajectories).
            let mut out = std::io::BufWriter::new(std::io::stdout().lock());
            if !json {
                writeln!(out, "{:<20} {:<10} {:<18} source", "trajectory", "kind", "type")?;
            }
            for i in list {
                if json {
                    writeln!(out, "{}", serde_json::to_string(&i)?)?;
                    continue;
                }
                let source = match (&i.source, i.inputs.as_slice()) {
                    (Some(s), []) => s.clone(),
                    (Some(s), inputs) => format!("{s}({})", inputs.join(", ")),
                    (None, []) => "pushed".to_owned(),
                    (None, inputs) => inputs.join(", "),
                };
                writeln!(out, "{:<20} {:<10} {:<18} {source}", i.name, i.kind.name(), i.type_name)?;
            }
            out.flush()?;
        }
        TrajCommand::Show { name } => {
            let t = trajectory(&esgm, name)?;
            let info = esgm.trajectories()?.into_iter().find(|i| i.name == *name);
            let stats = t.stats()?;
            if json {
                println!("{}", json!({ "info": info, "stats": stats }));
            } else {
                if let Some(i) = info {
                    println!("{}", serde_json::to_string_pretty(&i)?);
                }
                println!("{}", serde_json::to_string_pretty(&stats)?);
            }
        }
        TrajCommand::Create(decl) => {
            let mut spec = decl.to_spec()?;
            if decl.align {
                spec = crate::config::decl::aligned(spec, esgm_core::SystemClock.now());
            }
            // The command line does not stay to write what it creates: primitive, sync
            // and merge trajectories are written by the system's own process (or the
            // named writer); sampled and computed ones where their sensor or unit runs.
            let host = decl.writer.clone().unwrap_or_else(|| SYSTEM_HOST.to_owned());
            let record = match esgm.control(Request::CreateTrajectory { spec, host })? {
                Response::Trajectory(r) => r,
                Response::Error(e) => return Err(e.into()),
                other => bail!("unexpected answer from the coordinator: {other:?}"),
            };
            if json {
                println!("{}", serde_json::to_string(&record.info)?);
            } else {
                println!(
                    "created {} trajectory `{}` of {}, written by {}",
                    record.info.kind.name(),
                    record.info.name,
                    record.info.type_name,
                    record.writer
                );
            }
        }
        TrajCommand::Rm { name } => {
            esgm.destroy_entity_trajectory_structure(name)?;
            println!("destroyed trajectory `{name}`");
        }
    }
    Ok(())
}
