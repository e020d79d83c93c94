//! `esgm sensor list` and `esgm unit list`.

use esgm_core::Esgm;
use serde_json::json;

use crate::session::connect_tool as connect;

/// Subcommands of registries that are only listed from the command line (sensors and
/// units are registered by the processes that serve them).
#[derive(Debug, clap::Subcommand)]
pub enum ListOnly {
    /// Every registered one.
    List,
}

/// `esgm sensor list`.
pub fn sensors(domain: &str, json: bool, _c: &ListOnly) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    for (name, type_name) in esgm.sensors()? {
        if json {
            println!("{}", json!({ "sensor": name, "type": type_name }));
        } else {
            println!("{name:<20} {type_name}");
        }
    }
    Ok(())
}

/// `esgm unit list`.
pub fn units(domain: &str, json: bool, _c: &ListOnly) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    for (name, type_name, inputs) in esgm.comp_units()? {
        if json {
            println!("{}", json!({ "unit": name, "type": type_name, "inputs": inputs }));
        } else {
            let inputs: Vec<String> = inputs.iter().map(ToString::to_string).collect();
            println!("{name:<20} {type_name:<18} ({})", inputs.join(", "));
        }
    }
    Ok(())
}
