//! `esgm type list|show|rm`.

use esgm_core::Esgm;
use serde_json::json;

use crate::session::connect;

/// `esgm type` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum TypeCommand {
    /// Every registered type.
    List,
    /// One type's attributes.
    Show {
        /// Type name.
        name: String,
    },
    /// Destroy a type.
    Rm {
        /// Type name.
        name: String,
    },
}

/// Runs an `esgm type` subcommand.
pub fn run(domain: &str, json: bool, c: &TypeCommand) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    match c {
        TypeCommand::List => {
            for n in esgm.entity_structure_type_names() {
                if json {
                    println!("{}", json!({ "type": n }));
                } else {
                    println!("{n}");
                }
            }
        }
        TypeCommand::Show { name } => {
            let t = esgm.get_entity_structure_type(name)?;
            if json {
                println!("{}", serde_json::to_string(&t)?);
            } else {
                println!("{}", serde_json::to_string_pretty(&t)?);
            }
        }
        TypeCommand::Rm { name } => {
            esgm.destroy_entity_structure_type(name)?;
            println!("destroyed type `{name}`");
        }
    }
    Ok(())
}
