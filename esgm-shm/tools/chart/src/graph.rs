//! A dataflow graph as a PNG, laid out here (no Graphviz needed): `esgm graph --png`.
//!
//! The layout is layered, left to right, as Graphviz's `dot` with `rankdir=LR` draws
//! a dataflow. A node with no inputs is in layer 0, and every other node is one layer
//! right of its rightmost input. Within a layer, nodes are ordered by the mean row of
//! their inputs (one barycentre pass, which removes most crossings of a pipeline),
//! then by name. A node without inputs stands just left of its first reader. Edges
//! are arrows from the right side of a node to the left side of the next, labelled at
//! their middle; one that skips layers runs in a lane of its own below the nodes, so
//! it never crosses a box. A cycle cannot occur in a dataflow the
//! ESGM accepts, and a node on one is still placed: layering stops after one pass per
//! node.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::prelude::*;

use crate::{ChartError, FAMILY, color, register_font};

/// What a node is drawn as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeShape {
    /// A source outside the graph (a sensor): pale orange.
    Source,
    /// A stream (a trajectory): pale blue.
    Stream,
}

/// A node: a unique id, its shape, and its label lines (the first in bold size).
#[derive(Debug, Clone)]
pub struct Node {
    /// Unique id, used by edges.
    pub id: String,
    /// How it is drawn.
    pub shape: NodeShape,
    /// Label lines, top to bottom.
    pub lines: Vec<String>,
}

/// An edge from node `from` to node `to`, with a label (may be empty).
#[derive(Debug, Clone)]
pub struct Edge {
    /// The source node's id.
    pub from: String,
    /// The target node's id.
    pub to: String,
    /// Label lines, drawn at the middle of the arrow.
    pub lines: Vec<String>,
}

const NODE_W: i32 = 240;
const LINE_H: i32 = 17;
const COL_GAP: i32 = 170;
const ROW_GAP: i32 = 40;
const MARGIN: i32 = 30;

/// Each node's (layer, row): see the module docs.
pub fn layout(nodes: &[Node], edges: &[Edge]) -> BTreeMap<String, (usize, usize)> {
    let mut layer: BTreeMap<&str, usize> = nodes.iter().map(|n| (n.id.as_str(), 0)).collect();
    for _ in 0..nodes.len() {
        let mut changed = false;
        for e in edges {
            let (Some(&from), Some(&to)) = (layer.get(e.from.as_str()), layer.get(e.to.as_str()))
            else {
                continue;
            };
            if to < from + 1 {
                layer.insert(e.to.as_str(), from + 1);
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    // A source read only further right (a robot's state steering the last stage) is
    // drawn just before its first reader, not in the first column.
    for n in nodes {
        let id = n.id.as_str();
        if edges.iter().any(|e| e.to == id) {
            continue;
        }
        let first_reader =
            edges.iter().filter(|e| e.from == id).filter_map(|e| layer.get(e.to.as_str())).min();
        if let Some(&reader) = first_reader {
            layer.insert(id, reader.saturating_sub(1));
        }
    }
    let layers = layer.values().copied().max().map_or(0, |m| m + 1);
    let mut placed: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for l in 0..layers {
        let mut column: Vec<(f64, &str)> = nodes
            .iter()
            .filter(|n| layer[n.id.as_str()] == l)
            .map(|n| {
                let rows: Vec<f64> = edges
                    .iter()
                    .filter(|e| e.to == n.id)
                    .filter_map(|e| placed.get(&e.from).map(|p| p.1 as f64))
                    .collect();
                let mean = if rows.is_empty() {
                    f64::MAX
                } else {
                    rows.iter().sum::<f64>() / rows.len() as f64
                };
                (mean, n.id.as_str())
            })
            .collect();
        column.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(b.1)));
        for (row, (_, id)) in column.into_iter().enumerate() {
            placed.insert(id.to_owned(), (l, row));
        }
    }
    placed
}

/// Draws the graph into a PNG at `path`.
pub fn draw(nodes: &[Node], edges: &[Edge], path: &Path) -> Result<(), ChartError> {
    register_font()?;
    let places = layout(nodes, edges);
    let lines = nodes.iter().map(|n| n.lines.len()).max().unwrap_or(1).max(1) as i32;
    let node_h = lines * LINE_H + 12;
    let layers = places.values().map(|p| p.0 + 1).max().unwrap_or(1) as i32;
    let rows = places.values().map(|p| p.1 + 1).max().unwrap_or(1) as i32;
    let width = 2 * MARGIN + layers * NODE_W + (layers - 1) * COL_GAP;
    let grid_h = 2 * MARGIN + rows * node_h + (rows - 1) * ROW_GAP;
    let spans = |e: &Edge| match (places.get(&e.from), places.get(&e.to)) {
        (Some(a), Some(b)) => b.0 != a.0 + 1,
        _ => false,
    };
    let long = edges.iter().filter(|e| spans(e)).count() as i32;
    let lane_h = LINE_H * 2 + 6;
    let height = grid_h + long * lane_h;
    let corner = |id: &str| -> Option<(i32, i32)> {
        let (l, r) = places.get(id)?;
        Some((MARGIN + *l as i32 * (NODE_W + COL_GAP), MARGIN + *r as i32 * (node_h + ROW_GAP)))
    };

    let root = BitMapBackend::new(path, (width as u32, height as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(ChartError::draw)?;
    let text = (FAMILY, 14).into_font().color(&BLACK);
    let small = (FAMILY, 13).into_font().color(&RGBColor(90, 90, 90));
    let bold = (FAMILY, 15).into_font().style(FontStyle::Bold).color(&BLACK);

    let mut lane = 0;
    for e in edges {
        let (Some(a), Some(b)) = (corner(&e.from), corner(&e.to)) else { continue };
        let start = (a.0 + NODE_W, a.1 + node_h / 2);
        let end = (b.0, b.1 + node_h / 2);
        let (path, last, label_at) = if spans(e) {
            // Out into the gap, down to its lane, along, up into the gap before the
            // target, then in.
            let y = grid_h - MARGIN / 2 + lane * lane_h;
            lane += 1;
            let (out_x, in_x) = (start.0 + COL_GAP / 3, end.0 - COL_GAP / 3);
            let path = vec![start, (out_x, start.1), (out_x, y), (in_x, y), (in_x, end.1), end];
            let above = LINE_H * e.lines.len() as i32 + 2;
            (path, (in_x, end.1), ((out_x + in_x) / 2 - 60, y - above))
        } else {
            let above = LINE_H * e.lines.len() as i32 + 2;
            let mid = ((start.0 + end.0) / 2 - 60, (start.1 + end.1) / 2 - above);
            (vec![start, end], start, mid)
        };
        root.draw(&PathElement::new(path, color(7).stroke_width(2))).map_err(ChartError::draw)?;
        // The arrowhead: a small triangle along the last segment's direction.
        let start = last;
        let (dx, dy) = ((end.0 - start.0) as f64, (end.1 - start.1) as f64);
        let len = (dx * dx + dy * dy).sqrt().max(1.0);
        let (ux, uy) = (dx / len, dy / len);
        let back = (end.0 as f64 - 10.0 * ux, end.1 as f64 - 10.0 * uy);
        let side = (-uy * 5.0, ux * 5.0);
        let head = vec![
            end,
            ((back.0 + side.0) as i32, (back.1 + side.1) as i32),
            ((back.0 - side.0) as i32, (back.1 - side.1) as i32),
        ];
        root.draw(&Polygon::new(head, color(7).filled())).map_err(ChartError::draw)?;
        for (i, line) in e.lines.iter().enumerate() {
            root.draw_text(line, &small, (label_at.0, label_at.1 + i as i32 * LINE_H))
                .map_err(ChartError::draw)?;
        }
    }
    for n in nodes {
        let Some((x, y)) = corner(&n.id) else { continue };
        let fill = match n.shape {
            NodeShape::Source => RGBColor(255, 229, 204),
            NodeShape::Stream => RGBColor(222, 235, 247),
        };
        root.draw(&Rectangle::new([(x, y), (x + NODE_W, y + node_h)], fill.filled()))
            .map_err(ChartError::draw)?;
        root.draw(&Rectangle::new([(x, y), (x + NODE_W, y + node_h)], BLACK.stroke_width(1)))
            .map_err(ChartError::draw)?;
        for (i, line) in n.lines.iter().enumerate() {
            let style = if i == 0 { &bold } else { &text };
            root.draw_text(line, style, (x + 8, y + 6 + i as i32 * LINE_H))
                .map_err(ChartError::draw)?;
        }
    }
    root.present().map_err(ChartError::draw)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn node(id: &str) -> Node {
        Node { id: id.into(), shape: NodeShape::Stream, lines: vec![id.into()] }
    }

    fn edge(from: &str, to: &str) -> Edge {
        Edge { from: from.into(), to: to.into(), lines: vec!["4.0 Hz".into()] }
    }

    #[test]
    fn a_pipeline_is_laid_out_in_layers_by_its_inputs() {
        let nodes: Vec<Node> =
            ["camera", "images", "blobs", "robot", "steer"].into_iter().map(node).collect();
        let edges = vec![
            edge("camera", "images"),
            edge("images", "blobs"),
            edge("blobs", "steer"),
            edge("robot", "steer"),
        ];
        let p = layout(&nodes, &edges);
        assert_eq!((p["camera"].0, p["images"].0, p["blobs"].0, p["steer"].0), (0, 1, 2, 3));
        assert_eq!(p["robot"].0, 2, "a source stands just left of its first reader");
        assert_ne!(p["robot"], p["blobs"]);
    }

    #[test]
    fn a_cycle_is_still_placed() {
        let nodes = vec![node("a"), node("b")];
        let p = layout(&nodes, &[edge("a", "b"), edge("b", "a")]);
        assert_eq!(p.len(), 2);
    }

    #[test]
    fn the_graph_is_drawn_into_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.png");
        let nodes = vec![
            Node { id: "s".into(), shape: NodeShape::Source, lines: vec!["camera".into()] },
            node("images"),
        ];
        draw(&nodes, &[edge("s", "images")], &path).unwrap();
        // An edge that skips a layer runs in its lane below.
        let nodes = vec![node("a"), node("b"), node("c")];
        let edges = [edge("a", "b"), edge("b", "c"), edge("a", "c")];
        draw(&nodes, &edges, &path).unwrap();
        assert!(std::fs::read(&path).unwrap().starts_with(b"\x89PNG"));
    }
}
