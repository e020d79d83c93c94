//! A produced trajectory's trace as a Foxglove channel (`/<trajectory>/trace`, issue
//! 42): for each structure, the tree of inputs it was made from
//! ([`esgm_core::esgm::trace_with`]), flattened to its hops, with the end-to-end
//! latency and each stage's share of it. Plotted in Foxglove
//! (`/driving_direction/trace.stages_ms.blobs`), it shows live where a pipeline's
//! latency goes; the Raw Messages panel shows one structure's whole trace.

use esgm_core::Time;
use esgm_core::esgm::{Found, TraceNode};
use serde_json::{Value, json};

/// The schema's name.
pub const SCHEMA_NAME: &str = "esgm.Trace";

/// The channel's topic for `trajectory`.
pub fn topic(trajectory: &str) -> String {
    format!("/{trajectory}/trace")
}

/// The JSON Schema of every message.
pub fn schema() -> Vec<u8> {
    let hop = json!({
        "type": "object",
        "properties": {
            "trajectory": { "type": "string" },
            "depth": { "type": "integer", "description": "0: the structure traced; 1: its inputs; …" },
            "valid_time": { "type": "integer", "description": "ns since the epoch" },
            "add_time": { "type": "integer", "description": "ns since the epoch" },
            "hop_ms": { "type": ["number", "null"], "description": "its add time minus its latest input's" },
            "found": { "type": "string", "enum": ["stored", "evicted", "no_trajectory", "cut_off"] },
            "complete": { "type": "boolean", "description": "false: a unit, which may have read more than its inputs" },
        },
    });
    let schema = json!({
        "title": SCHEMA_NAME,
        "type": "object",
        "properties": {
            "trajectory": { "type": "string" },
            "valid_time": { "type": "integer" },
            "end_to_end_ms": { "type": ["number", "null"], "description": "from the earliest source entering to this structure entering" },
            "source": { "type": ["string", "null"], "description": "that source's trajectory" },
            "stages_ms": {
                "type": "object",
                "description": "each produced trajectory's hop, the longest where it appears twice",
                "additionalProperties": { "type": "number" },
            },
            "hops": { "type": "array", "items": hop },
        },
    });
    schema.to_string().into_bytes()
}

fn ms(ns: Time) -> f64 {
    ns as f64 / 1e6
}

/// The message for `tree`, appended to `out`.
pub fn encode(tree: &TraceNode, out: &mut Vec<u8>) -> serde_json::Result<()> {
    let (latency, source) = match tree.end_to_end() {
        Some((latency, first)) => (Some(ms(latency)), Some(first.trajectory.as_str())),
        None => (None, None),
    };
    let stages: serde_json::Map<String, Value> =
        tree.stage_times().into_iter().map(|(t, hop)| (t.to_owned(), json!(ms(hop)))).collect();
    let hops: Vec<Value> = tree
        .walk()
        .into_iter()
        .map(|(depth, n)| {
            json!({
                "trajectory": n.trajectory,
                "depth": depth,
                "valid_time": n.valid_time,
                "add_time": n.add_time,
                "hop_ms": n.hop.map(ms),
                "found": found(n.found),
                "complete": n.complete,
            })
        })
        .collect();
    let message = json!({
        "trajectory": tree.trajectory,
        "valid_time": tree.valid_time,
        "end_to_end_ms": latency,
        "source": source,
        "stages_ms": stages,
        "hops": hops,
    });
    serde_json::to_writer(out, &message)
}

fn found(f: Found) -> &'static str {
    match f {
        Found::Stored => "stored",
        Found::Evicted => "evicted",
        Found::NoTrajectory => "no_trajectory",
        Found::CutOff => "cut_off",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(name: &str, add: Time, hop: Option<Time>, inputs: Vec<TraceNode>) -> TraceNode {
        TraceNode {
            trajectory: name.into(),
            generation: None,
            valid_time: 7,
            add_time: add,
            hop,
            found: Found::Stored,
            complete: hop.is_none(),
            inputs,
        }
    }

    #[test]
    fn a_trace_message_splits_the_latency_by_stage() {
        let camera = node("images", 1_000_000, None, vec![]);
        let blobs = node("blobs", 4_000_000, Some(3_000_000), vec![camera]);
        let top = node("direction", 4_500_000, Some(500_000), vec![blobs]);
        let mut out = Vec::new();
        encode(&top, &mut out).unwrap();
        let v: Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["end_to_end_ms"], 3.5);
        assert_eq!(v["source"], "images");
        assert_eq!(v["stages_ms"], json!({ "direction": 0.5, "blobs": 3.0 }));
        assert_eq!(v["hops"].as_array().map(Vec::len), Some(3));
        assert_eq!(v["hops"][2]["depth"], 2);
        let schema: Value = serde_json::from_slice(&schema()).unwrap();
        assert_eq!(schema["title"], SCHEMA_NAME);
    }
}
