//! `esgm trace TRAJ [--latest | --at T]`: the tree of input structures behind one
//! structure, back to the sensors and pushed trajectories it came from, with each
//! hop's writer, times and the time the hop added, so an end-to-end latency is split
//! by stage (issue 42).

use std::collections::HashMap;

use anyhow::Context;
use esgm_core::esgm::{Found, TraceNode, trace_with};
use esgm_core::{EntityTrajectoryStructure, InProcessTrajectory, Sample, Time};
use esgm_shm::ShmEsgm;
use esgm_shm::control::{Request, Response};
use serde_json::json;

use crate::session::{connect_tool as connect, trajectory};
use crate::time_arg::{TimeArg, display};

/// A trajectory, and which of its structures to trace.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The trajectory.
    pub trajectory: String,
    /// The structure valid at this time (ns, RFC 3339, or relative to the latest:
    /// -100ms); the latest if not given.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "latest")]
    pub at: Option<TimeArg>,
    /// The latest structure (the default).
    #[arg(long)]
    pub latest: bool,
}

/// `esgm trace`.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    let sample = pick(&t, a.at.as_ref())?;
    let mut handles: HashMap<String, Option<InProcessTrajectory>> = HashMap::new();
    let open = |name: &str| {
        handles.entry(name.to_owned()).or_insert_with(|| trajectory(&esgm, name).ok()).clone()
    };
    let tree = trace_with(open, &a.trajectory, &sample);
    let writers = writers(&esgm, &tree);
    if json {
        println!("{}", serde_json::to_string_pretty(&node_json(&tree, &writers))?);
    } else {
        print!("{}", render(&tree, &writers));
    }
    Ok(())
}

/// The structure `--at` names (valid exactly then), or the latest.
fn pick(t: &InProcessTrajectory, at: Option<&TimeArg>) -> anyhow::Result<Sample> {
    let name = t.name();
    let latest = t.get_latest().with_context(|| format!("`{name}` holds no structure"))?;
    match at {
        None => Ok(latest),
        Some(at) => {
            let time = at.resolve(Some(latest.valid_time()))?;
            t.get_at(time).with_context(|| format!("`{name}` holds no structure valid at {time}"))
        }
    }
}

/// The writer (process or host) of every trajectory in the tree, as the registry says.
fn writers(esgm: &ShmEsgm, tree: &TraceNode) -> HashMap<String, String> {
    let mut out = HashMap::new();
    for (_, node) in tree.walk() {
        if out.contains_key(&node.trajectory) {
            continue;
        }
        let request = Request::GetEntityTrajectoryStructure { name: node.trajectory.clone() };
        let writer = match esgm.control(request) {
            Ok(Response::Trajectory(record)) => record.writer,
            _ => "gone".to_owned(),
        };
        out.insert(node.trajectory.clone(), writer);
    }
    out
}

fn node_json(node: &TraceNode, writers: &HashMap<String, String>) -> serde_json::Value {
    json!({
        "trajectory": node.trajectory,
        "writer": writers.get(&node.trajectory),
        "generation": node.generation,
        "valid_time": node.valid_time,
        "add_time": node.add_time,
        "hop_ns": node.hop,
        "found": node.found,
        "complete": node.complete,
        "inputs": node.inputs.iter().map(|n| node_json(n, writers)).collect::<Vec<_>>(),
    })
}

/// Milliseconds with three decimals.
fn ms(ns: Time) -> String {
    format!("{:.3} ms", ns as f64 / 1e6)
}

/// The tree as text: one line per structure, then where the time went.
fn render(tree: &TraceNode, writers: &HashMap<String, String>) -> String {
    let mut out = String::new();
    line(&mut out, tree, writers, "", "");
    if let Some((latency, first)) = tree.end_to_end() {
        out.push_str(&format!(
            "end to end: {} from `{}` entering to `{}` entering\n",
            ms(latency),
            first.trajectory,
            tree.trajectory
        ));
    }
    if tree.walk().iter().any(|(_, n)| !n.complete) {
        out.push_str(
            "(*) a unit: the inputs it was handed are listed; reads it made through other handles are not recorded\n",
        );
    }
    out
}

fn line(
    out: &mut String,
    node: &TraceNode,
    writers: &HashMap<String, String>,
    lead: &str,
    branch: &str,
) {
    let writer = writers.get(&node.trajectory).map_or("?", String::as_str);
    let what = match node.found {
        Found::Stored if node.inputs.is_empty() => "source".to_owned(),
        Found::Stored => match node.hop {
            Some(hop) => format!("hop {}", ms(hop)),
            None => String::new(),
        },
        Found::Evicted => "no longer held (evicted or reset)".to_owned(),
        Found::NoTrajectory => "trajectory gone".to_owned(),
        Found::CutOff => "not followed (trace too deep or too wide)".to_owned(),
    };
    let star = if node.complete { "" } else { " (*)" };
    out.push_str(&format!(
        "{lead}{branch}{}{star}  valid {}  added {}  {what}  [{writer}]\n",
        node.trajectory,
        display(node.valid_time),
        display(node.add_time),
    ));
    let child_lead = format!(
        "{lead}{}",
        match branch {
            "" => "",
            "└─ " => "   ",
            _ => "│  ",
        }
    );
    for (k, child) in node.inputs.iter().enumerate() {
        let last = k + 1 == node.inputs.len();
        line(out, child, writers, &child_lead, if last { "└─ " } else { "├─ " });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leaf(name: &str, add: Time) -> TraceNode {
        TraceNode {
            trajectory: name.into(),
            generation: Some(1),
            valid_time: 10,
            add_time: add,
            hop: None,
            found: Found::Stored,
            complete: true,
            inputs: vec![],
        }
    }

    #[test]
    fn the_tree_shows_each_hop_and_the_end_to_end_time() {
        let mid = TraceNode {
            hop: Some(2_000_000),
            complete: false,
            inputs: vec![
                leaf("camera", 1_000_000),
                TraceNode { found: Found::Evicted, ..leaf("odom", 2_000_000) },
            ],
            ..leaf("mid", 4_000_000)
        };
        let top = TraceNode {
            generation: None,
            hop: Some(500_000),
            inputs: vec![mid],
            ..leaf("out", 4_500_000)
        };
        let writers = HashMap::from([("out".to_owned(), "cu-workers".to_owned())]);
        let text = render(&top, &writers);
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[0].starts_with("out  valid") && lines[0].ends_with("hop 0.500 ms  [cu-workers]"),
            "{text}"
        );
        assert!(
            lines[1].starts_with("└─ mid (*)") && lines[1].contains("hop 2.000 ms  [?]"),
            "{text}"
        );
        assert!(lines[2].starts_with("   ├─ camera") && lines[2].contains("source"), "{text}");
        assert!(
            lines[3].starts_with("   └─ odom") && lines[3].contains("no longer held"),
            "{text}"
        );
        assert_eq!(lines[4], "end to end: 3.500 ms from `camera` entering to `out` entering");
        assert!(lines[5].starts_with("(*) a unit"));
        let j = node_json(&top, &writers);
        assert_eq!(j["inputs"][0]["inputs"][1]["found"], "evicted");
        assert_eq!(j["writer"], "cu-workers");
        assert_eq!(j["hop_ns"], 500_000);
    }
}
