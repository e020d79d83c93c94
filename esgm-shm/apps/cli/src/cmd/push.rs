//! `esgm push TRAJ attr=value … [--valid-time T]`: adds one structure to a primitive
//! trajectory by hand. The values are read as the trajectory's type says (a Long
//! attribute takes `3`, a Double `0.5`, a sequence `1,2,3`, any sort its JSON form),
//! checked against the type here, and added through the writer's gate with the blocking
//! add, so the answer is the gate's outcome: added, held for reordering, or the policy
//! violation that dropped it.

use anyhow::{Context, bail};
use esgm_core::time::Time;
use esgm_core::types::EntityStructureType;
use esgm_core::value::{Value, ValueSort};
use esgm_core::{AddError, AddOutcome, EntityStructure, EntityTrajectoryStructure, Esgm};
use serde_json::json;

use crate::session::connect_tool as connect;
use crate::time_arg::TimeArg;

/// `esgm push` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The trajectory (primitive).
    pub trajectory: String,
    /// Attribute values, `name=value`, one per attribute of the trajectory's type.
    #[arg(value_name = "ATTR=VALUE")]
    pub values: Vec<String>,
    /// Valid time: nanoseconds, RFC 3339, or relative to the latest sample (`+1s`);
    /// default now.
    #[arg(long, allow_hyphen_values = true)]
    pub valid_time: Option<TimeArg>,
    /// The structure's entity name (default: the trajectory's name).
    #[arg(long)]
    pub name: Option<String>,
}

/// Builds, checks and adds the structure; prints the gate's outcome. A violation is an
/// error (exit 1) naming the constraint.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    // The history matters only to a valid time relative to the latest sample: an
    // absolute one adds at once.
    let t = match &a.valid_time {
        Some(TimeArg::Relative(_)) => crate::session::trajectory(&esgm, &a.trajectory)?,
        _ => esgm.get_entity_trajectory_structure(&a.trajectory)?,
    };
    let entity_type = t.entity_type()?;
    let now = esgm.local().clock().now();
    let valid_time = match &a.valid_time {
        // Empty has no latest; a relative time then says it needs one.
        Some(arg) => arg.resolve(t.get_latest_vtime().ok().map(|s| s.valid_time()))?,
        None => now,
    };
    let name = a.name.clone().unwrap_or_else(|| a.trajectory.clone());
    let mut es = EntityStructure::named(name).valid_at(valid_time).created_at(now);
    for pair in &a.values {
        let (attr, text) =
            pair.split_once('=').with_context(|| format!("`{pair}` is not attr=value"))?;
        es.set(attr, parse_value(&entity_type, attr, text)?);
    }
    let outcome = t.add_blocking(es);
    let (word, detail) = match outcome {
        Ok(AddOutcome::Added) => ("added", String::new()),
        Ok(AddOutcome::Held { release_at }) => {
            ("held", format!("held for reordering until {release_at}"))
        }
        Ok(other) => ("sent", format!("{other:?}")),
        Err(AddError::PolicyViolation(v)) => {
            if json {
                println!(
                    "{}",
                    json!({ "outcome": "violation", "constraint": v.constraint.to_string(),
                            "valid_time": v.valid_time, "detail": v.detail })
                );
            }
            bail!("dropped by the {} constraint: {}", v.constraint, v.detail);
        }
        Err(e) => return Err(e).context(format!("cannot add to `{}`", a.trajectory)),
    };
    if json {
        println!("{}", json!({ "outcome": word, "valid_time": valid_time, "detail": detail }));
    } else if detail.is_empty() {
        println!("{word} to `{}` valid at {valid_time}", a.trajectory);
    } else {
        println!("{word} to `{}` valid at {valid_time}: {detail}", a.trajectory);
    }
    Ok(())
}

/// `text` read as the value of `attr` in `entity_type`.
fn parse_value(entity_type: &EntityStructureType, attr: &str, text: &str) -> anyhow::Result<Value> {
    let Some(a) = entity_type.attributes.iter().find(|a| a.name == attr) else {
        let names: Vec<&str> = entity_type.attributes.iter().map(|a| a.name.as_str()).collect();
        bail!("`{}` has no attribute `{attr}` (it has {})", entity_type.name, names.join(", "));
    };
    let bad = |what: &str| anyhow::anyhow!("`{attr}` is a {:?}: `{text}` is not {what}", a.sort);
    let list = |t: &str| -> Vec<String> {
        let t = t.trim().trim_start_matches('[').trim_end_matches(']');
        t.split(',').map(|s| s.trim().to_owned()).filter(|s| !s.is_empty()).collect()
    };
    Ok(match a.sort {
        ValueSort::Long => Value::Long(text.trim().parse().map_err(|_| bad("an integer"))?),
        ValueSort::Double => Value::Double(text.trim().parse().map_err(|_| bad("a number"))?),
        ValueSort::Altitude => Value::Altitude(text.trim().parse().map_err(|_| bad("a number"))?),
        ValueSort::Bool => Value::Bool(text.trim().parse().map_err(|_| bad("true or false"))?),
        ValueSort::Time => {
            Value::Time(text.trim().parse::<Time>().map_err(|_| bad("nanoseconds"))?)
        }
        ValueSort::String => Value::String(text.to_owned()),
        ValueSort::Symbol => Value::Symbol(text.to_owned()),
        ValueSort::LongSeq => Value::LongSeq(
            list(text)
                .iter()
                .map(|s| s.parse())
                .collect::<Result<_, _>>()
                .map_err(|_| bad("integers"))?,
        ),
        ValueSort::DoubleSeq => Value::DoubleSeq(
            list(text)
                .iter()
                .map(|s| s.parse())
                .collect::<Result<_, _>>()
                .map_err(|_| bad("numbers"))?,
        ),
        ValueSort::SymbolSeq => Value::SymbolSeq(list(text)),
        // Any other sort in its JSON form, e.g. {"Pos2":{"x":1.0,"y":2.0}}.
        _ => serde_json::from_str(text)
            .map_err(|e| anyhow::anyhow!("`{attr}` is a {:?}: give it as JSON ({e})", a.sort))?,
    })
}
