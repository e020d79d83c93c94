//! How samples and tables look on the terminal and in `--json`.

use esgm_core::frame::{AttributeValuePair, EntityFrame};
use esgm_core::{Sample, Value};
use serde_json::{Map, json};

use crate::time_arg::display;

/// A value as JSON; byte sequences (image pixels) as their length, not their bytes.
pub fn value_json(v: &Value) -> serde_json::Value {
    match v {
        Value::NoValue => serde_json::Value::Null,
        Value::Long(v) => json!(v),
        Value::Double(v) => json!(v),
        Value::Bool(v) => json!(v),
        Value::Time(v) => json!(v),
        Value::String(v) | Value::Symbol(v) => json!(v),
        Value::LongSeq(v) => json!(v),
        Value::DoubleSeq(v) => json!(v),
        Value::SymbolSeq(v) => json!(v),
        Value::OctetSeq(o) => json!({ "octets": o.len() }),
        Value::Agg(vs) | Value::Collection(vs) => vs.iter().map(value_json).collect(),
        Value::EntityFrame(f) => frame_json(f),
        Value::EntityFrameSeq(fs) => fs.iter().map(frame_json).collect(),
        other => serde_json::to_value(other).unwrap_or(serde_json::Value::Null),
    }
}

fn attributes_json(attributes: &[AttributeValuePair]) -> serde_json::Value {
    let mut m = Map::new();
    for a in attributes {
        m.insert(a.name.clone(), value_json(&a.value));
    }
    serde_json::Value::Object(m)
}

fn frame_json(f: &EntityFrame) -> serde_json::Value {
    json!({ "name": f.name, "attributes": attributes_json(&f.attributes) })
}

/// A sample as one JSON object.
pub fn sample_json(trajectory: &str, s: &Sample) -> serde_json::Value {
    let mut v = json!({
        "trajectory": trajectory,
        "name": s.structure.name,
        "valid_time": s.structure.valid_time,
        "create_time": s.structure.create_time,
        "add_time": s.add_time,
        "attributes": attributes_json(&s.structure.attributes),
    });
    if let Some(held) = &s.not_interpolated {
        v["not_interpolated"] = json!(held.as_ref());
    }
    v
}

/// A sample as one line of text: valid time, entity, attributes, add delay.
pub fn sample_line(s: &Sample) -> String {
    let attrs: Vec<String> = s
        .structure
        .attributes
        .iter()
        .map(|a| format!("{}={}", a.name, value_json(&a.value)))
        .collect();
    let held = match &s.not_interpolated {
        Some(held) => format!("  (not interpolated, most recent value: {})", held.join(", ")),
        None => String::new(),
    };
    format!(
        "{}  {}  {}  (add delay {:.3} ms){held}",
        display(s.structure.valid_time),
        s.structure.name,
        attrs.join(" "),
        s.add_delay() as f64 / 1e6
    )
}

/// Prints a sample in the chosen format.
pub fn print_sample(json: bool, trajectory: &str, s: &Sample) {
    if json {
        println!("{}", sample_json(trajectory, s));
    } else {
        println!("{}", sample_line(s));
    }
}

/// Milliseconds for a table cell.
pub fn ms(t: Option<i64>) -> String {
    t.map_or_else(|| "-".to_owned(), |t| format!("{:.2}", t as f64 / 1e6))
}
