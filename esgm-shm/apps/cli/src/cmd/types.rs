//! `esgm type list|show|add|rm`.

use esgm_core::Esgm;
use serde_json::json;

use crate::config::decl::TypeDecl;
use crate::session::connect_tool as connect;

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
    /// Register a type: `esgm type add Pose x:Double y:Double`.
    Add(TypeDecl),
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
            for n in esgm.entity_structure_type_names()? {
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
        TypeCommand::Add(decl) => {
            esgm.create_entity_structure_type(&decl.name, decl.to_type()?)?;
            println!("created type `{}`", decl.name);
        }
        TypeCommand::Rm { name } => {
            esgm.destroy_entity_structure_type(name)?;
            println!("destroyed type `{name}`");
        }
    }
    Ok(())
}
