//! Any structure as JSON with a JSON Schema, so Foxglove can plot its attributes.
//!
//! A structure becomes one JSON object:
//!
//! ```json
//! {"valid_time": {"sec": 1, "nsec": 500000000}, "create_time": {"sec": 1, "nsec": 600000000},
//!  "name": "robot1", "x": 1.5, "y": -2.0, "dir": 90.0}
//! ```
//!
//! - Times (`valid_time`, `create_time` and `Time` attributes) are Foxglove time objects
//!   `{"sec", "nsec"}`, floored seconds and non-negative nanoseconds.
//! - `Long` is an integer; `Double` and `Altitude` are numbers, with non-finite values
//!   as `null` (JSON has no NaN). `Bool`, `String` and `Symbol` are what they say.
//! - Geometric values are objects with the fields of esgm-core's structs: `Vec`
//!   `{x, y, z}`, `Pos2` `{x, y}`, `Position` `{north, east}`, `Rotation`
//!   `{roll, pitch, yaw}`, `PositionAltitude` `{position, altitude}` and
//!   `PositionAltitudeRotation` `{position, altitude, rotation}`.
//! - Sequences are arrays; a nested frame is an object `{name, <its attributes>}` and a
//!   frame sequence an array of them; `Agg` and `Collection` are arrays of their values.
//! - An octet sequence is `{"length": n}`: pixels do not belong in JSON.
//! - [`Value::NoValue`] is `null`, so every property's schema admits `null`.
//!
//! An attribute named like one of the keys esgm adds (`valid_time`, `create_time` and
//! `name` at the top, `name` in a nested frame) gets a `_` appended to its key, more than
//! one if that name is taken too; schema and messages agree on it.

use std::collections::HashSet;

use esgm_core::{
    AttributeValuePair, EntityFrame, EntityStructure, EntityStructureType, Pos2, Position,
    Rotation, Time, Value, ValueSort, Vec3,
};
use serde::ser::{Serialize, SerializeMap, SerializeSeq, Serializer};
use serde_json::{Value as Json, json};

use super::{ViewError, ViewSchema};

/// How deep a schema follows nested frame types; deeper frames (and recursive types)
/// are described as objects of any shape.
pub const MAX_SCHEMA_DEPTH: usize = 8;

const TOP_RESERVED: &[&str] = &["valid_time", "create_time", "name"];
const FRAME_RESERVED: &[&str] = &["name"];

/// The JSON Schema of `ty`'s JSON view (MCAP schema encoding `jsonschema`, message
/// encoding `json`), named for the type.
///
/// `lookup` resolves the element types that frame attributes name (normally the type
/// registry); a type it cannot resolve is described as an object of any shape.
pub fn json_schema(
    ty: &EntityStructureType,
    lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
) -> ViewSchema {
    let mut properties = serde_json::Map::new();
    properties.insert("valid_time".into(), time_schema());
    properties.insert("create_time".into(), time_schema());
    properties.insert("name".into(), json!({"type": "string"}));
    add_attribute_schemas(&mut properties, ty, TOP_RESERVED, lookup, 0);
    let schema = json!({
        "title": ty.name,
        "description": format!("esgm entity structures of type {}", ty.name),
        "type": "object",
        "properties": properties,
    });
    ViewSchema {
        name: ty.name.clone(),
        encoding: "jsonschema",
        message_encoding: "json",
        data: schema.to_string().into_bytes(),
    }
}

fn add_attribute_schemas(
    properties: &mut serde_json::Map<String, Json>,
    ty: &EntityStructureType,
    reserved: &[&str],
    lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
    depth: usize,
) {
    let names: Vec<&str> = ty.attributes.iter().map(|a| a.name.as_str()).collect();
    let keys = renamed_keys(&names, reserved);
    for (i, a) in ty.attributes.iter().enumerate() {
        let key = keys.as_ref().map_or(a.name.as_str(), |k| k[i].as_str());
        let schema = sort_schema(a.sort, a.element_type.as_deref(), lookup, depth);
        properties.insert(key.to_owned(), schema);
    }
}

/// The keys of attributes `names` when some collide with `reserved`; `None` (keys are
/// the names) in the usual case that none does.
fn renamed_keys(names: &[&str], reserved: &[&str]) -> Option<Vec<String>> {
    if !names.iter().any(|n| reserved.contains(n)) {
        return None;
    }
    let taken: HashSet<&str> = names.iter().chain(reserved).copied().collect();
    let mut used = HashSet::new();
    let keys = names
        .iter()
        .map(|&n| {
            let mut key = n.to_owned();
            if reserved.contains(&n) {
                // Names that are not reserved keep their key, so only suffixed keys
                // can meet each other or another attribute's name.
                while taken.contains(key.as_str()) || used.contains(&key) {
                    key.push('_');
                }
                used.insert(key.clone());
            }
            key
        })
        .collect();
    Some(keys)
}

fn nullable(ty: &str) -> Json {
    json!({"type": [ty, "null"]})
}

fn time_schema() -> Json {
    json!({
        "type": ["object", "null"],
        "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
    })
}

fn numbers_object(fields: &[&str]) -> Json {
    let properties: serde_json::Map<String, Json> =
        fields.iter().map(|f| ((*f).to_owned(), nullable("number"))).collect();
    json!({"type": ["object", "null"], "properties": properties})
}

fn position_schema() -> Json {
    numbers_object(&["north", "east"])
}

fn rotation_schema() -> Json {
    numbers_object(&["roll", "pitch", "yaw"])
}

fn array_of(items: Json) -> Json {
    json!({"type": ["array", "null"], "items": items})
}

fn sort_schema(
    sort: ValueSort,
    element_type: Option<&str>,
    lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
    depth: usize,
) -> Json {
    match sort {
        ValueSort::Long => nullable("integer"),
        ValueSort::Double | ValueSort::Altitude => nullable("number"),
        ValueSort::Bool => nullable("boolean"),
        ValueSort::String | ValueSort::Symbol => nullable("string"),
        ValueSort::Time => time_schema(),
        ValueSort::Vec => numbers_object(&["x", "y", "z"]),
        ValueSort::Pos2 => numbers_object(&["x", "y"]),
        ValueSort::Position => position_schema(),
        ValueSort::Rotation => rotation_schema(),
        ValueSort::PositionAltitude => json!({
            "type": ["object", "null"],
            "properties": {"position": position_schema(), "altitude": nullable("number")},
        }),
        ValueSort::PositionAltitudeRotation => json!({
            "type": ["object", "null"],
            "properties": {
                "position": position_schema(),
                "altitude": nullable("number"),
                "rotation": rotation_schema(),
            },
        }),
        ValueSort::LongSeq => array_of(json!({"type": "integer"})),
        ValueSort::DoubleSeq => array_of(nullable("number")),
        ValueSort::SymbolSeq => array_of(json!({"type": "string"})),
        ValueSort::VecSeq => array_of(numbers_object(&["x", "y", "z"])),
        ValueSort::Pos2Seq => array_of(numbers_object(&["x", "y"])),
        ValueSort::OctetSeq => json!({
            "type": ["object", "null"],
            "description": "an octet sequence: its length only",
            "properties": {"length": {"type": "integer"}},
        }),
        ValueSort::EntityFrame => frame_schema(element_type, lookup, depth),
        ValueSort::EntityFrameSeq => array_of(frame_schema(element_type, lookup, depth)),
        ValueSort::Agg | ValueSort::Collection => json!({"type": ["array", "null"]}),
        ValueSort::AnyValue | ValueSort::UnknownValue => json!({}),
        ValueSort::NoValue => json!({"type": "null"}),
    }
}

fn frame_schema(
    element_type: Option<&str>,
    lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
    depth: usize,
) -> Json {
    let ty = element_type.filter(|_| depth < MAX_SCHEMA_DEPTH).and_then(lookup);
    let Some(ty) = ty else {
        return json!({"type": ["object", "null"]});
    };
    let mut properties = serde_json::Map::new();
    properties.insert("name".into(), json!({"type": "string"}));
    add_attribute_schemas(&mut properties, &ty, FRAME_RESERVED, lookup, depth + 1);
    json!({"title": ty.name, "type": ["object", "null"], "properties": properties})
}

/// Appends the JSON view of `es` to `out` (see the [module docs](self) for the shape).
///
/// ```
/// let es = esgm_core::EntityStructure::new("robot1", 1_500_000_000, 0).with("x", 2.5);
/// let mut out = Vec::new();
/// esgm_recording::view::encode_json(&es, &mut out)?;
/// let text = std::str::from_utf8(&out)?;
/// assert_eq!(text, r#"{"valid_time":{"sec":1,"nsec":500000000},"create_time":{"sec":0,"nsec":0},"name":"robot1","x":2.5}"#);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn encode_json(es: &EntityStructure, out: &mut Vec<u8>) -> Result<(), ViewError> {
    serde_json::to_writer(out, &StructureJson(es))?;
    Ok(())
}

struct StructureJson<'a>(&'a EntityStructure);

impl Serialize for StructureJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let es = self.0;
        let mut map = s.serialize_map(Some(3 + es.attributes.len()))?;
        map.serialize_entry("valid_time", &TimeJson(es.valid_time))?;
        map.serialize_entry("create_time", &TimeJson(es.create_time))?;
        map.serialize_entry("name", &es.name)?;
        attribute_entries(&mut map, &es.attributes, TOP_RESERVED)?;
        map.end()
    }
}

fn attribute_entries<M: SerializeMap>(
    map: &mut M,
    attributes: &[AttributeValuePair],
    reserved: &[&str],
) -> Result<(), M::Error> {
    let keys = if attributes.iter().any(|a| reserved.contains(&a.name.as_str())) {
        let names: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
        renamed_keys(&names, reserved)
    } else {
        None
    };
    for (i, a) in attributes.iter().enumerate() {
        let key = keys.as_ref().map_or(a.name.as_str(), |k| k[i].as_str());
        map.serialize_entry(key, &ValueJson(&a.value))?;
    }
    Ok(())
}

struct FrameJson<'a>(&'a EntityFrame);

impl Serialize for FrameJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let f = self.0;
        let mut map = s.serialize_map(Some(1 + f.attributes.len()))?;
        map.serialize_entry("name", &f.name)?;
        attribute_entries(&mut map, &f.attributes, FRAME_RESERVED)?;
        map.end()
    }
}

/// A Foxglove time: floored seconds and non-negative nanoseconds.
struct TimeJson(Time);

impl Serialize for TimeJson {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(2))?;
        map.serialize_entry("sec", &self.0.div_euclid(1_000_000_000))?;
        map.serialize_entry("nsec", &self.0.rem_euclid(1_000_000_000))?;
        map.end()
    }
}

/// A double, `null` when not finite.
struct F64(f64);

impl Serialize for F64 {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.0.is_finite() { s.serialize_f64(self.0) } else { s.serialize_unit() }
    }
}

fn numbers<S: Serializer>(s: S, fields: &[(&str, f64)]) -> Result<S::Ok, S::Error> {
    let mut map = s.serialize_map(Some(fields.len()))?;
    for (k, v) in fields {
        map.serialize_entry(k, &F64(*v))?;
    }
    map.end()
}

struct Vec3Json<'a>(&'a Vec3);
impl Serialize for Vec3Json<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        numbers(s, &[("x", self.0.x), ("y", self.0.y), ("z", self.0.z)])
    }
}

struct Pos2Json<'a>(&'a Pos2);
impl Serialize for Pos2Json<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        numbers(s, &[("x", self.0.x), ("y", self.0.y)])
    }
}

struct PositionJson<'a>(&'a Position);
impl Serialize for PositionJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        numbers(s, &[("north", self.0.north), ("east", self.0.east)])
    }
}

struct RotationJson<'a>(&'a Rotation);
impl Serialize for RotationJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        numbers(s, &[("roll", self.0.roll), ("pitch", self.0.pitch), ("yaw", self.0.yaw)])
    }
}

fn seq<'a, S: Serializer, T, J: Serialize>(
    s: S,
    items: &'a [T],
    f: impl Fn(&'a T) -> J,
) -> Result<S::Ok, S::Error> {
    let mut seq = s.serialize_seq(Some(items.len()))?;
    for item in items {
        seq.serialize_element(&f(item))?;
    }
    seq.end()
}

struct ValueJson<'a>(&'a Value);

impl Serialize for ValueJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Value::NoValue => s.serialize_unit(),
            Value::Long(v) => s.serialize_i64(*v),
            Value::Double(v) | Value::Altitude(v) => F64(*v).serialize(s),
            Value::Bool(v) => s.serialize_bool(*v),
            Value::String(v) | Value::Symbol(v) => s.serialize_str(v),
            Value::Time(t) => TimeJson(*t).serialize(s),
            Value::OctetSeq(o) => {
                let mut map = s.serialize_map(Some(1))?;
                map.serialize_entry("length", &o.len())?;
                map.end()
            }
            Value::LongSeq(v) => v.serialize(s),
            Value::DoubleSeq(v) => seq(s, v, |d| F64(*d)),
            Value::SymbolSeq(v) => v.serialize(s),
            Value::Vec(v) => Vec3Json(v).serialize(s),
            Value::VecSeq(v) => seq(s, v, Vec3Json),
            Value::Pos2(v) => Pos2Json(v).serialize(s),
            Value::Pos2Seq(v) => seq(s, v, Pos2Json),
            Value::Position(v) => PositionJson(v).serialize(s),
            Value::Rotation(v) => RotationJson(v).serialize(s),
            Value::PositionAltitude(v) => {
                let mut map = s.serialize_map(Some(2))?;
                map.serialize_entry("position", &PositionJson(&v.position))?;
                map.serialize_entry("altitude", &F64(v.altitude))?;
                map.end()
            }
            Value::PositionAltitudeRotation(v) => {
                let mut map = s.serialize_map(Some(3))?;
                map.serialize_entry("position", &PositionJson(&v.position))?;
                map.serialize_entry("altitude", &F64(v.altitude))?;
                map.serialize_entry("rotation", &RotationJson(&v.rotation))?;
                map.end()
            }
            Value::Agg(v) | Value::Collection(v) => seq(s, v, ValueJson),
            Value::EntityFrame(f) => FrameJson(f).serialize(s),
            Value::EntityFrameSeq(v) => seq(s, v, FrameJson),
        }
    }
}

#[cfg(test)]
mod tests {
    use esgm_core::library::{BlobSeq, Image, RobotState, Twist};
    use esgm_core::{Entity, EntityStructureType, PositionAltitude, PositionAltitudeRotation};
    use serde_json::json;

    use super::*;

    fn to_json(es: &EntityStructure) -> Json {
        let mut out = Vec::new();
        encode_json(es, &mut out).unwrap();
        serde_json::from_slice(&out).unwrap()
    }

    fn schema_of(ty: &EntityStructureType) -> Json {
        let lookup = |name: &str| {
            esgm_core::library::predefined_types().into_iter().find(|t| t.name == name)
        };
        let schema = json_schema(ty, &lookup);
        assert_eq!((schema.encoding, schema.message_encoding), ("jsonschema", "json"));
        assert_eq!(schema.name, ty.name);
        serde_json::from_slice(&schema.data).unwrap()
    }

    /// A small structural check that `value` fits `schema` as this module writes them
    /// (types, properties, items); the independent Python reader validates fully.
    fn assert_fits(schema: &Json, value: &Json, path: &str) {
        let types: Vec<&str> = match &schema["type"] {
            Json::String(t) => vec![t.as_str()],
            Json::Array(ts) => ts.iter().filter_map(Json::as_str).collect(),
            _ => return, // any value
        };
        let kind = match value {
            Json::Null => "null",
            Json::Bool(_) => "boolean",
            Json::Number(n) if n.is_i64() || n.is_u64() => "integer",
            Json::Number(_) => "number",
            Json::String(_) => "string",
            Json::Array(_) => "array",
            Json::Object(_) => "object",
        };
        let fits = types.contains(&kind) || (kind == "integer" && types.contains(&"number"));
        assert!(fits, "{path}: {value} is not {types:?}");
        if let (Json::Object(props), Json::Object(fields)) = (&schema["properties"], value) {
            for (k, v) in fields {
                let sub = props.get(k).unwrap_or_else(|| panic!("{path}.{k} not in schema"));
                assert_fits(sub, v, &format!("{path}.{k}"));
            }
        }
        if let Json::Array(items) = value {
            for (i, v) in items.iter().enumerate() {
                assert_fits(&schema["items"], v, &format!("{path}[{i}]"));
            }
        }
    }

    #[test]
    fn robot_state_is_plottable_numbers_with_foxglove_times() {
        let es =
            RobotState { x: 1.5, y: -2.0, dir: f64::NAN }.to_structure("robot1", -1, 2_000_000_001);
        let v = to_json(&es);
        assert_eq!(
            v,
            json!({"valid_time": {"sec": -1, "nsec": 999_999_999},
                   "create_time": {"sec": 2, "nsec": 1},
                   "name": "robot1", "x": 1.5, "y": -2.0, "dir": null})
        );
        let schema = schema_of(&RobotState::entity_structure_type());
        assert_eq!(schema["title"], "RobotState");
        assert_eq!(schema["properties"]["x"], json!({"type": ["number", "null"]}));
        assert_fits(&schema, &v, "");
    }

    #[test]
    fn images_give_their_length_not_their_pixels() {
        let es = Image { width: 2, height: 1, format: 1, image_data: vec![1, 2].into() }
            .to_structure("cam", 0, 0);
        let v = to_json(&es);
        assert_eq!(v["image_data"], json!({"length": 2}));
        assert_eq!(v["width"], 2);
        assert_fits(&schema_of(&Image::entity_structure_type()), &v, "");
    }

    #[test]
    fn nested_frames_follow_their_element_type() {
        let seq = BlobSeq { items: vec![esgm_core::library::Blob { x: 1, y: 2, size: 3 }] };
        let v = to_json(&seq.to_structure("blobs", 5, 6));
        assert_eq!(v["items"], json!([{"name": "Blob", "x": 1, "y": 2, "size": 3}]));
        let schema = schema_of(&BlobSeq::entity_structure_type());
        let blob = &schema["properties"]["items"]["items"];
        assert_eq!(blob["title"], "Blob");
        assert_eq!(blob["properties"]["size"], json!({"type": ["integer", "null"]}));
        assert_fits(&schema, &v, "");
    }

    #[test]
    fn every_sort_encodes_to_what_its_schema_says() {
        let frame = EntityFrame::new("inner").with("k", 1i64);
        let values = vec![
            Value::Long(-3),
            Value::Double(0.25),
            Value::Bool(true),
            Value::String("s".into()),
            Value::Time(1_000_000_000),
            Value::Symbol("sym".into()),
            Value::OctetSeq(vec![0u8; 7].into()),
            Value::LongSeq(vec![1, 2]),
            Value::DoubleSeq(vec![0.5, f64::INFINITY]),
            Value::SymbolSeq(vec!["a".into()]),
            Value::Vec(Vec3 { x: 1.0, y: 2.0, z: 3.0 }),
            Value::VecSeq(vec![Vec3::default()]),
            Value::Pos2(Pos2 { x: 1.0, y: 2.0 }),
            Value::Pos2Seq(vec![Pos2::default()]),
            Value::Position(Position { north: 1.0, east: 2.0 }),
            Value::Altitude(10.0),
            Value::Rotation(Rotation { roll: 0.1, pitch: 0.2, yaw: 0.3 }),
            Value::PositionAltitude(PositionAltitude::default()),
            Value::PositionAltitudeRotation(PositionAltitudeRotation::default()),
            Value::Agg(vec![Value::Long(1), Value::String("x".into())]),
            Value::Collection(vec![Value::Bool(false)]),
            Value::EntityFrame(Box::new(frame.clone())),
            Value::EntityFrameSeq(vec![frame]),
        ];
        let mut ty = EntityStructureType::new("Everything");
        let mut es = EntityStructure::new("e", 0, 0);
        let mut none = EntityStructure::new("e", 0, 0);
        for (i, v) in values.into_iter().enumerate() {
            ty = ty.attr(format!("a{i}"), v.sort());
            es.set(format!("a{i}"), v);
            none.set(format!("a{i}"), Value::NoValue);
        }
        let schema = schema_of(&ty);
        let v = to_json(&es);
        assert_fits(&schema, &v, "");
        assert_fits(&schema, &to_json(&none), "");
        assert_eq!(v["a4"], json!({"sec": 1, "nsec": 0}));
        assert_eq!(v["a8"], json!([0.5, null]));
        assert_eq!(
            v["a18"],
            json!({"position": {"north": 0.0, "east": 0.0}, "altitude": 0.0,
                                     "rotation": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0}})
        );
        assert_eq!(v["a21"], json!({"name": "inner", "k": 1}));
        for sort in ValueSort::ALL {
            assert!(sort_schema(sort, None, &|_| None, 0).is_object(), "{sort}");
        }
    }

    #[test]
    fn geometric_field_names_are_esgm_cores() {
        // The JSON view and esgm-core's own serde names agree.
        let par = PositionAltitudeRotation::default();
        let ours = to_json(
            &EntityStructure::new("p", 0, 0).with("p", Value::PositionAltitudeRotation(par)),
        );
        assert_eq!(ours["p"], serde_json::to_value(par).unwrap());
        let t = Twist { linear: Vec3::default(), angular: Vec3::default() }.to_structure("t", 0, 0);
        assert_eq!(to_json(&t)["linear"], serde_json::to_value(Vec3::default()).unwrap());
    }

    #[test]
    fn attributes_named_like_esgm_keys_get_an_underscore() {
        let ty = EntityStructureType::new("Clash")
            .attr("name", ValueSort::String)
            .attr("name_", ValueSort::Long)
            .attr("valid_time", ValueSort::Time);
        let es = EntityStructure::new("entity", 0, 0)
            .with("name", "attr")
            .with("name_", 1i64)
            .with("valid_time", Value::Time(5));
        let v = to_json(&es);
        assert_eq!(v["name"], "entity");
        assert_eq!(v["name__"], "attr");
        assert_eq!(v["name_"], 1);
        assert_eq!(v["valid_time_"], json!({"sec": 0, "nsec": 5}));
        let schema = schema_of(&ty);
        assert_eq!(schema["properties"]["name__"], json!({"type": ["string", "null"]}));
        assert_fits(&schema, &v, "");
    }

    #[test]
    fn recursive_types_stop_at_the_depth_bound() {
        let node = EntityStructureType::new("Node").frame("next", "Node");
        let lookup = |n: &str| (n == "Node").then(|| node.clone());
        let schema: Json = serde_json::from_slice(&json_schema(&node, &lookup).data).unwrap();
        let mut s = &schema["properties"]["next"];
        let mut depth = 0;
        while s.get("properties").is_some() {
            s = &s["properties"]["next"];
            depth += 1;
        }
        assert_eq!(depth, MAX_SCHEMA_DEPTH);
        assert_eq!(s, &json!({"type": ["object", "null"]}));
    }
}
