//! `esgm graph`: the dataflow — sensors and trajectories feeding units feeding
//! trajectories — as text or Graphviz DOT.

use esgm_core::Esgm;
use serde_json::json;

use crate::session::connect;

/// `esgm graph` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print Graphviz DOT (pipe into `dot -Tpng`).
    #[arg(long)]
    pub dot: bool,
}

/// Prints the graph.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let list = esgm.trajectories();
    if json {
        for i in &list {
            println!(
                "{}",
                json!({"trajectory": i.name, "kind": i.kind.name(), "source": i.source,
                       "inputs": i.inputs, "type": i.type_name})
            );
        }
        return Ok(());
    }
    if a.dot {
        println!("digraph esgm {{\n  rankdir=LR;");
        for i in &list {
            println!("  \"{}\" [shape=box, label=\"{}\\n{}\"];", i.name, i.name, i.type_name);
            match &i.source {
                Some(src) if i.inputs.is_empty() => {
                    println!("  \"sensor:{src}\" [shape=ellipse, label=\"{src}\"];");
                    println!("  \"sensor:{src}\" -> \"{}\";", i.name);
                }
                Some(unit) => {
                    for input in &i.inputs {
                        println!("  \"{input}\" -> \"{}\" [label=\"{unit}\"];", i.name);
                    }
                }
                None => {
                    for input in &i.inputs {
                        println!("  \"{input}\" -> \"{}\";", i.name);
                    }
                }
            }
        }
        println!("}}");
        return Ok(());
    }
    for i in &list {
        let from = match (&i.source, i.inputs.as_slice()) {
            (Some(s), []) => format!("sensor {s}"),
            (Some(u), inputs) => format!("{u}({})", inputs.join(", ")),
            (None, []) => "pushed".to_owned(),
            (None, inputs) => format!("{}({})", i.kind.name(), inputs.join(", ")),
        };
        println!("{from} -> {} [{}]", i.name, i.type_name);
    }
    Ok(())
}
