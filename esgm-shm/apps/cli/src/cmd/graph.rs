//! `esgm graph`: the dataflow — sensors and trajectories feeding units feeding
//! trajectories — with what flows along each edge: the rate of the stream it carries
//! and the delay its stage adds. As text, Graphviz DOT, JSON, or a PNG laid out here
//! (`--png`, no Graphviz needed).
//!
//! A node shows its trajectory's rate and median add delay (valid time → added: how
//! old its data is when it arrives). An edge's rate is its source trajectory's (a
//! sensor's edge: the sampled trajectory's). Its delay is the stage's own latency:
//! how much later, at the median, the target's structures are added after their valid
//! time than its input's are, unit and hops included (a computed structure keeps its
//! input's valid time). Only a single-input stage has one: the output of a unit with
//! several inputs keeps the valid time of one of them, and a generator's are its own,
//! so for those the target's add delay on the node is the figure to read. Medians come
//! from log-scaled histograms, so a stage faster than their resolution shows +0.0 ms.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use esgm_chart::graph::{Edge as DrawnEdge, Node as DrawnNode, NodeShape, draw};
use esgm_core::esgm::TrajectoryInfo;
use esgm_core::{EntityTrajectoryStructure, Esgm, Time, TrajectoryStats};
use serde_json::json;

use crate::session::{connect_tool as connect, trajectory};

/// `esgm graph` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print Graphviz DOT (pipe into `dot -Tpng`).
    #[arg(long)]
    pub dot: bool,
    /// Draw the graph into this PNG file, laid out by esgm itself.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
}

/// One edge of the dataflow.
struct Flow {
    from: String,
    to: String,
    /// The unit computing `to`, if any.
    unit: Option<String>,
    rate_hz: Option<f64>,
    delay: Option<Time>,
}

/// Prints (or draws) the graph.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let list = esgm.trajectories()?;
    let mut stats: BTreeMap<String, TrajectoryStats> = BTreeMap::new();
    for info in &list {
        match trajectory(&esgm, &info.name).and_then(|t| Ok(t.stats()?)) {
            Ok(s) => {
                stats.insert(info.name.clone(), s);
            }
            Err(e) => eprintln!("esgm: no statistics of `{}`: {e:#}", info.name),
        }
    }
    let flows = flows(&list, &stats);
    if let Some(path) = &a.png {
        draw_png(&list, &stats, &flows, path)?;
        println!("wrote {}", path.display());
        return Ok(());
    }
    if json {
        for i in &list {
            let s = stats.get(&i.name);
            let inputs: Vec<_> = flows
                .iter()
                .filter(|f| f.to == i.name)
                .map(|f| json!({"from": f.from, "rate_hz": f.rate_hz, "delay_ns": f.delay}))
                .collect();
            println!(
                "{}",
                json!({"trajectory": i.name, "kind": i.kind.name(), "source": i.source,
                       "inputs": inputs, "type": i.type_name,
                       "rate_hz": s.map(|s| s.rate_hz), "add_delay_p50_ns": s.and_then(|s| s.add_delay_p50)})
            );
        }
        return Ok(());
    }
    if a.dot {
        print_dot(&list, &stats, &flows);
        return Ok(());
    }
    for i in &list {
        let into: Vec<&Flow> = flows.iter().filter(|f| f.to == i.name).collect();
        let from = match (&i.source, i.inputs.as_slice()) {
            (Some(s), []) => format!("sensor {s}"),
            (Some(u), inputs) => format!("{u}({})", inputs.join(", ")),
            (None, []) => "pushed".to_owned(),
            (None, inputs) => format!("{}({})", i.kind.name(), inputs.join(", ")),
        };
        let flow: Vec<String> = into.iter().filter_map(|f| edge_label(f)).collect();
        let flow = if flow.is_empty() { String::new() } else { format!("  {}", flow.join("; ")) };
        println!(
            "{from} -> {} [{}{}]{flow}",
            i.name,
            i.type_name,
            node_figures(stats.get(&i.name), ", ")
        );
    }
    Ok(())
}

/// Every edge with its rate and stage delay.
fn flows(list: &[TrajectoryInfo], stats: &BTreeMap<String, TrajectoryStats>) -> Vec<Flow> {
    let delay_of = |name: &str| stats.get(name).and_then(|s| s.add_delay_p50);
    let mut out = Vec::new();
    for i in list {
        let to_delay = delay_of(&i.name);
        match (&i.source, i.inputs.as_slice()) {
            (Some(sensor), []) => out.push(Flow {
                from: format!("sensor:{sensor}"),
                to: i.name.clone(),
                unit: None,
                rate_hz: stats.get(&i.name).map(|s| s.rate_hz),
                // Sampling: the sensor's reading time plus the hop (valid = sample time).
                delay: to_delay,
            }),
            (unit, inputs) => {
                let stage = matches!(
                    i.kind,
                    esgm_core::esgm::TrajectoryKind::Computed
                        | esgm_core::esgm::TrajectoryKind::Merge
                ) && inputs.len() == 1;
                for input in inputs {
                    let delay = match (to_delay, delay_of(input)) {
                        (Some(to), Some(from)) if stage => Some((to - from).max(0)),
                        _ => None,
                    };
                    out.push(Flow {
                        from: input.clone(),
                        to: i.name.clone(),
                        unit: unit.clone(),
                        rate_hz: stats.get(input).map(|s| s.rate_hz),
                        delay,
                    });
                }
            }
        }
    }
    out
}

/// `, 4.0 Hz, p50 delay 90.0 ms`: a trajectory's figures, each after `sep`.
fn node_figures(s: Option<&TrajectoryStats>, sep: &str) -> String {
    let Some(s) = s else { return String::new() };
    let delay = s.add_delay_p50.map(|d| format!("{sep}p50 delay {:.1} ms", d as f64 / 1e6));
    format!("{sep}{:.1} Hz{}", s.rate_hz, delay.unwrap_or_default())
}

fn ms(t: Time) -> String {
    format!("{:+.1} ms", t as f64 / 1e6)
}

/// `unit, 4.0 Hz, +0.4 ms`: what an edge carries.
fn edge_label(f: &Flow) -> Option<String> {
    let parts: Vec<String> =
        [f.unit.clone(), f.rate_hz.map(|r| format!("{r:.1} Hz")), f.delay.map(ms)]
            .into_iter()
            .flatten()
            .collect();
    (!parts.is_empty())
        .then(|| format!("{}: {}", f.from.trim_start_matches("sensor:"), parts.join(", ")))
}

fn print_dot(list: &[TrajectoryInfo], stats: &BTreeMap<String, TrajectoryStats>, flows: &[Flow]) {
    println!("digraph esgm {{\n  rankdir=LR;");
    for i in list {
        let figures = node_figures(stats.get(&i.name), "\\n");
        println!("  \"{}\" [shape=box, label=\"{}\\n{}{figures}\"];", i.name, i.name, i.type_name);
    }
    for f in flows {
        if let Some(sensor) = f.from.strip_prefix("sensor:") {
            println!("  \"{}\" [shape=ellipse, label=\"{sensor}\"];", f.from);
        }
        let label: Vec<String> =
            [f.unit.clone(), f.rate_hz.map(|r| format!("{r:.1} Hz")), f.delay.map(ms)]
                .into_iter()
                .flatten()
                .collect();
        println!("  \"{}\" -> \"{}\" [label=\"{}\"];", f.from, f.to, label.join("\\n"));
    }
    println!("}}");
}

fn draw_png(
    list: &[TrajectoryInfo],
    stats: &BTreeMap<String, TrajectoryStats>,
    flows: &[Flow],
    path: &std::path::Path,
) -> anyhow::Result<()> {
    let mut nodes: Vec<DrawnNode> = list
        .iter()
        .map(|i| {
            let mut lines = vec![i.name.clone(), format!("{} · {}", i.type_name, i.kind.name())];
            if let Some(s) = stats.get(&i.name) {
                lines.push(format!("{:.1} Hz, {} stored", s.rate_hz, s.stored));
                if let Some(d) = s.add_delay_p50 {
                    lines.push(format!("p50 delay {:.1} ms", d as f64 / 1e6));
                }
            }
            DrawnNode { id: i.name.clone(), shape: NodeShape::Stream, lines }
        })
        .collect();
    for f in flows {
        if let Some(sensor) = f.from.strip_prefix("sensor:") {
            if !nodes.iter().any(|n| n.id == f.from) {
                nodes.push(DrawnNode {
                    id: f.from.clone(),
                    shape: NodeShape::Source,
                    lines: vec![sensor.to_owned(), "sensor".to_owned()],
                });
            }
        }
    }
    let edges: Vec<DrawnEdge> = flows
        .iter()
        .map(|f| DrawnEdge {
            from: f.from.clone(),
            to: f.to.clone(),
            lines: [f.unit.clone(), f.rate_hz.map(|r| format!("{r:.1} Hz")), f.delay.map(ms)]
                .into_iter()
                .flatten()
                .collect(),
        })
        .collect();
    draw(&nodes, &edges, path).with_context(|| format!("cannot draw {}", path.display()))
}
