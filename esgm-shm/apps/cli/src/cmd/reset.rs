//! `esgm reset [TRAJ]`: empties a trajectory (T5) — in its writer and every process
//! that reads it — or, without a name, every trajectory of the system (E7). Returns
//! once every connected reader has forgotten.

use anyhow::Context;
use esgm_core::{EntityTrajectoryStructure, Esgm};
use serde_json::json;

use crate::session::connect_tool as connect;

/// `esgm reset` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The trajectory to empty; every trajectory if left out.
    pub trajectory: Option<String>,
}

/// Resets and says what was reset.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    match &a.trajectory {
        Some(name) => {
            let t = esgm.get_entity_trajectory_structure(name)?;
            t.reset_blocking().with_context(|| format!("cannot reset `{name}`"))?;
        }
        None => esgm.reset_domain().context("cannot reset the system")?,
    }
    let what = a.trajectory.as_deref().unwrap_or("*");
    if json {
        println!("{}", json!({ "reset": what }));
    } else {
        match &a.trajectory {
            Some(name) => println!("reset `{name}` in its writer and every reader"),
            None => println!("reset every trajectory in every process"),
        }
    }
    Ok(())
}
