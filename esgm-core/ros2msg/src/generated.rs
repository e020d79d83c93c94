//! Generated messages: an entity structure type with no standard ROS 2 counterpart is
//! exported as the message `esgm_msgs/msg/<Type>`, whose definition
//! `esgm ros2 msg <Type>` prints (with one for every nested frame type), so a ROS
//! workspace can build it and its nodes read esgm's topics with their own types.
//!
//! A message starts with the structure's `std_msgs/Header` (valid time, name). A type
//! nested as a frame (an `EntityFrame<T>` attribute) is another message with the same
//! attributes after a `string name` instead of the header, so it has a name of its own,
//! `esgm_msgs/msg/<T>Frame` ([`frame_message`]): one ROS 2 type name, one definition,
//! whichever of a type's forms a workspace, a recording or a bag carries. Then each
//! attribute, in declaration order:
//!
//! | esgm sort | field |
//! |---|---|
//! | `Long`, `Double`, `Bool` | `int64`, `float64`, `bool` |
//! | `String`, `Symbol` | `string` |
//! | `Time` | `builtin_interfaces/Time` |
//! | `OctetSeq`, `LongSeq`, `DoubleSeq`, `SymbolSeq` | `uint8[]`, `int64[]`, `float64[]`, `string[]` |
//! | `Vec`, `VecSeq` | `geometry_msgs/Vector3`, `geometry_msgs/Vector3[]` |
//! | `Pos2`, `Pos2Seq` | `geometry_msgs/Point` (`z = 0`), `geometry_msgs/Point[]` |
//! | `Position`, `PositionAltitude` | `geometry_msgs/Point` (`x` east, `y` north, `z` altitude) |
//! | `Altitude` | `float64` |
//! | `Rotation` | `geometry_msgs/Vector3` (`x` roll, `y` pitch, `z` yaw, radians) |
//! | `PositionAltitudeRotation` | `geometry_msgs/Pose` (orientation from roll, pitch, yaw) |
//! | `EntityFrame<T>`, `EntityFrameSeq<T>` | `esgm_msgs/T`, `esgm_msgs/T[]` |
//!
//! `Agg`, `Collection` and `AnyValue` have no fixed layout and are refused, naming the
//! attribute; so are names ROS 2 does not allow (a type must be CamelCase, a field
//! snake_case). An attribute without a value is sent as its zero.

use std::collections::BTreeMap;
use std::sync::Arc;

use esgm_core::value::{Pos2, Position, PositionAltitude, Rotation, Vec3};
use esgm_core::{Attr, EntityStructure, EntityStructureType, Value, ValueSort};
use serde::ser::{Error as _, SerializeSeq, SerializeStruct};
use serde::{Serialize, Serializer};

use crate::mapping::{MappingError, ros_time};

/// The ROS 2 package of generated messages.
pub const PACKAGE: &str = "esgm_msgs";

/// What a type's frame message is named after it: `Blob` nested in `BlobSeq` is
/// `esgm_msgs/msg/BlobFrame`, while a `Blob` structure is `esgm_msgs/msg/Blob`.
pub const FRAME_SUFFIX: &str = "Frame";

/// The message name (without package) of `ty`'s frame form.
pub fn frame_message(ty: &str) -> String {
    format!("{ty}{FRAME_SUFFIX}")
}

/// A type and every type it nests, checked to map.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    root: String,
    types: BTreeMap<String, EntityStructureType>,
    /// The types nested as frames (the root too, if it nests itself).
    frames: std::collections::BTreeSet<String>,
}

fn refused(field: &'static str, value: impl std::fmt::Display, why: &'static str) -> MappingError {
    MappingError::Unconvertible { field, value: value.to_string(), why }
}

fn is_message_name(name: &str) -> bool {
    name.chars().next().is_some_and(|c| c.is_ascii_uppercase())
        && name.chars().all(|c| c.is_ascii_alphanumeric())
}

fn is_field_name(name: &str) -> bool {
    name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !name.ends_with('_')
        && !name.contains("__")
}

impl Schema {
    /// The schema of `root`, whose definitions (its own and every nested type's) `lookup`
    /// gives; refused if a name or a sort does not map.
    pub fn new(
        root: &str,
        mut lookup: impl FnMut(&str) -> Option<EntityStructureType>,
    ) -> Result<Self, MappingError> {
        let mut types = BTreeMap::new();
        let mut frames = std::collections::BTreeSet::new();
        let mut todo = vec![root.to_owned()];
        while let Some(name) = todo.pop() {
            if types.contains_key(&name) {
                continue;
            }
            if !is_message_name(&name) {
                return Err(refused(
                    "type",
                    &name,
                    "a ROS 2 message name is CamelCase letters and digits",
                ));
            }
            let t = lookup(&name)
                .ok_or_else(|| refused("type", &name, "its definition is not registered"))?;
            for a in &t.attributes {
                if !is_field_name(&a.name) || a.name == "header" {
                    return Err(refused(
                        "attribute",
                        &a.name,
                        "a ROS 2 field name is snake_case (and not `header`)",
                    ));
                }
                field_type(a)?;
                if let Some(element) = &a.element_type {
                    frames.insert(element.clone());
                    todo.push(element.clone());
                }
            }
            types.insert(name, t);
        }
        if let Some(nested) = frames.iter().find(|f| frame_message(f) == root) {
            return Err(refused(
                "type",
                format!("{root} (also the frame message of `{nested}`, which it nests)"),
                "a type must not be named like the frame message (<Type>Frame) of a type it nests; rename one",
            ));
        }
        Ok(Self { root: root.to_owned(), types, frames })
    }

    /// The root type's name.
    pub fn root(&self) -> &str {
        &self.root
    }

    /// The definition of `name`: the root or a type it nests.
    pub fn get(&self, name: &str) -> Option<&EntityStructureType> {
        self.types.get(name)
    }

    /// Each message definition, `(Message, .msg text)`: the root's first, under the
    /// root's name, then each type nested as a frame under its frame name
    /// ([`frame_message`]).
    pub fn msg_files(&self) -> Vec<(String, String)> {
        let text = |t: &EntityStructureType, top: bool| {
            let mut out = String::new();
            out.push_str(if top {
                "# esgm entity structure: valid time and name\nstd_msgs/Header header\n"
            } else {
                "# esgm entity frame: its entity's name\nstring name\n"
            });
            for a in &t.attributes {
                if let Ok(ty) = field_type(a) {
                    out.push_str(&format!("{ty} {}\n", a.name));
                }
            }
            out
        };
        let mut files = Vec::new();
        if let Some(t) = self.types.get(&self.root) {
            files.push((self.root.clone(), text(t, true)));
        }
        for name in &self.frames {
            if let Some(t) = self.types.get(name) {
                files.push((frame_message(name), text(t, false)));
            }
        }
        files
    }
}

/// An attribute's field type in a `.msg` file.
fn field_type(a: &Attr) -> Result<String, MappingError> {
    let element = || {
        a.element_type
            .clone()
            .ok_or_else(|| refused("attribute", &a.name, "a frame attribute names no element type"))
    };
    Ok(match a.sort {
        ValueSort::Long => "int64".into(),
        ValueSort::Double | ValueSort::Altitude => "float64".into(),
        ValueSort::Bool => "bool".into(),
        ValueSort::String | ValueSort::Symbol => "string".into(),
        ValueSort::Time => "builtin_interfaces/Time".into(),
        ValueSort::OctetSeq => "uint8[]".into(),
        ValueSort::LongSeq => "int64[]".into(),
        ValueSort::DoubleSeq => "float64[]".into(),
        ValueSort::SymbolSeq => "string[]".into(),
        ValueSort::Vec | ValueSort::Rotation => "geometry_msgs/Vector3".into(),
        ValueSort::VecSeq => "geometry_msgs/Vector3[]".into(),
        ValueSort::Pos2 | ValueSort::Position | ValueSort::PositionAltitude => {
            "geometry_msgs/Point".into()
        }
        ValueSort::Pos2Seq => "geometry_msgs/Point[]".into(),
        ValueSort::PositionAltitudeRotation => "geometry_msgs/Pose".into(),
        ValueSort::EntityFrame => format!("{PACKAGE}/{}", frame_message(&element()?)),
        ValueSort::EntityFrameSeq => format!("{PACKAGE}/{}[]", frame_message(&element()?)),
        other => {
            return Err(MappingError::Unconvertible {
                field: "attribute",
                value: format!("{} ({other:?})", a.name),
                why: "this sort has no fixed message layout",
            });
        }
    })
}

/// A structure as its generated message, ready for `ros2-client` to encode.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The structure.
    pub structure: Arc<EntityStructure>,
    /// Its type's schema.
    pub schema: Arc<Schema>,
}

impl Serialize for Generated {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        GeneratedRef { structure: &self.structure, schema: &self.schema }.serialize(s)
    }
}

/// A borrowed structure as its generated message (a recording encodes one per
/// structure it writes, without sharing it).
#[derive(Debug, Clone, Copy)]
pub struct GeneratedRef<'a> {
    /// The structure.
    pub structure: &'a EntityStructure,
    /// Its type's schema.
    pub schema: &'a Schema,
}

impl Serialize for GeneratedRef<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let es = self.structure;
        let Some(t) = self.schema.types.get(&self.schema.root) else {
            return Err(S::Error::custom("the schema lost its root type"));
        };
        let mut st = s.serialize_struct("Message", t.attributes.len() + 1)?;
        let stamp = ros_time(es.valid_time).map_err(S::Error::custom)?;
        st.serialize_field("header", &(stamp, &es.name))?;
        for a in &t.attributes {
            let value = es.get(&a.name).unwrap_or(&Value::NoValue);
            st.serialize_field("field", &Field { attr: a, value, schema: self.schema })?;
        }
        st.end()
    }
}

/// One nested frame.
struct Frame<'a> {
    name: &'a str,
    attributes: &'a [esgm_core::AttributeValuePair],
    ty: &'a EntityStructureType,
    schema: &'a Schema,
}

impl Serialize for Frame<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Frame", self.ty.attributes.len() + 1)?;
        st.serialize_field("name", self.name)?;
        for a in &self.ty.attributes {
            let value = self
                .attributes
                .iter()
                .find(|p| p.name == a.name)
                .map_or(&Value::NoValue, |p| &p.value);
            st.serialize_field("field", &Field { attr: a, value, schema: self.schema })?;
        }
        st.end()
    }
}

struct Field<'a> {
    attr: &'a Attr,
    value: &'a Value,
    schema: &'a Schema,
}

/// `geometry_msgs/Point` or `Vector3`.
#[derive(Serialize)]
struct Xyz(f64, f64, f64);

fn quaternion(r: &Rotation) -> (f64, f64, f64, f64) {
    let (sr, cr) = (r.roll / 2.0).sin_cos();
    let (sp, cp) = (r.pitch / 2.0).sin_cos();
    let (sy, cy) = (r.yaw / 2.0).sin_cos();
    (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )
}

fn point(p: &Position, z: f64) -> Xyz {
    Xyz(p.east, p.north, z)
}

impl Serialize for Field<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let zero = Value::NoValue;
        let v = if self.value.sort() == self.attr.sort { self.value } else { &zero };
        match (self.attr.sort, v) {
            (ValueSort::Long, Value::Long(x)) => s.serialize_i64(*x),
            (ValueSort::Long, _) => s.serialize_i64(0),
            (ValueSort::Double, Value::Double(x)) | (ValueSort::Altitude, Value::Altitude(x)) => {
                s.serialize_f64(*x)
            }
            (ValueSort::Double | ValueSort::Altitude, _) => s.serialize_f64(0.0),
            (ValueSort::Bool, Value::Bool(x)) => s.serialize_bool(*x),
            (ValueSort::Bool, _) => s.serialize_bool(false),
            (ValueSort::String, Value::String(x)) | (ValueSort::Symbol, Value::Symbol(x)) => {
                s.serialize_str(x)
            }
            (ValueSort::String | ValueSort::Symbol, _) => s.serialize_str(""),
            (ValueSort::Time, v) => {
                let t = if let Value::Time(t) = v { *t } else { 0 };
                ros_time(t).map_err(S::Error::custom)?.serialize(s)
            }
            (ValueSort::OctetSeq, Value::OctetSeq(o)) => s.serialize_bytes(o.as_ref()),
            (ValueSort::OctetSeq, _) => s.serialize_bytes(&[]),
            (ValueSort::LongSeq, Value::LongSeq(x)) => x.serialize(s),
            (ValueSort::DoubleSeq, Value::DoubleSeq(x)) => x.serialize(s),
            (ValueSort::SymbolSeq, Value::SymbolSeq(x)) => x.serialize(s),
            (ValueSort::LongSeq | ValueSort::DoubleSeq | ValueSort::SymbolSeq, _) => {
                s.serialize_seq(Some(0))?.end()
            }
            (ValueSort::Vec, v) => {
                let Vec3 { x, y, z } = if let Value::Vec(p) = v { *p } else { Vec3::default() };
                Xyz(x, y, z).serialize(s)
            }
            (ValueSort::Rotation, v) => {
                let r = if let Value::Rotation(r) = v { *r } else { Rotation::default() };
                Xyz(r.roll, r.pitch, r.yaw).serialize(s)
            }
            (ValueSort::VecSeq, v) => {
                let empty = Vec::new();
                let items = if let Value::VecSeq(x) = v { x } else { &empty };
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for p in items {
                    seq.serialize_element(&Xyz(p.x, p.y, p.z))?;
                }
                seq.end()
            }
            (ValueSort::Pos2, v) => {
                let Pos2 { x, y } = if let Value::Pos2(p) = v { *p } else { Pos2::default() };
                Xyz(x, y, 0.0).serialize(s)
            }
            (ValueSort::Pos2Seq, v) => {
                let empty = Vec::new();
                let items = if let Value::Pos2Seq(x) = v { x } else { &empty };
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for p in items {
                    seq.serialize_element(&Xyz(p.x, p.y, 0.0))?;
                }
                seq.end()
            }
            (ValueSort::Position, v) => {
                let p = if let Value::Position(p) = v { *p } else { Position::default() };
                point(&p, 0.0).serialize(s)
            }
            (ValueSort::PositionAltitude, v) => {
                let p = if let Value::PositionAltitude(p) = v {
                    *p
                } else {
                    PositionAltitude::default()
                };
                point(&p.position, p.altitude).serialize(s)
            }
            (ValueSort::PositionAltitudeRotation, v) => {
                let p = if let Value::PositionAltitudeRotation(p) = v {
                    *p
                } else {
                    Default::default()
                };
                let (x, y, z, w) = quaternion(&p.rotation);
                (point(&p.position, p.altitude), (x, y, z, w)).serialize(s)
            }
            (ValueSort::EntityFrame, v) => {
                let ty = self.element::<S>()?;
                match v {
                    Value::EntityFrame(f) => {
                        Frame { name: &f.name, attributes: &f.attributes, ty, schema: self.schema }
                            .serialize(s)
                    }
                    _ => Frame { name: "", attributes: &[], ty, schema: self.schema }.serialize(s),
                }
            }
            (ValueSort::EntityFrameSeq, v) => {
                let ty = self.element::<S>()?;
                let empty = Vec::new();
                let items = if let Value::EntityFrameSeq(x) = v { x } else { &empty };
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for f in items {
                    seq.serialize_element(&Frame {
                        name: &f.name,
                        attributes: &f.attributes,
                        ty,
                        schema: self.schema,
                    })?;
                }
                seq.end()
            }
            // Refused when the schema was made.
            (other, _) => Err(S::Error::custom(format!("sort {other:?} has no message layout"))),
        }
    }
}

impl Field<'_> {
    fn element<S: Serializer>(&self) -> Result<&EntityStructureType, S::Error> {
        self.attr
            .element_type
            .as_ref()
            .and_then(|e| self.schema.types.get(e))
            .ok_or_else(|| S::Error::custom(format!("no element type for `{}`", self.attr.name)))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]
    use super::*;

    fn library(name: &str) -> Option<EntityStructureType> {
        esgm_core::TypeRegistry::with_library()
            .get_entity_structure_type(name)
            .ok()
            .map(|t| (*t).clone())
    }

    #[test]
    fn a_blob_seq_prints_as_two_message_files() {
        let schema = Schema::new("BlobSeq", library).unwrap();
        let files = schema.msg_files();
        assert_eq!(files[0].0, "BlobSeq");
        assert!(
            files[0].1.contains("std_msgs/Header header\nesgm_msgs/BlobFrame[] items\n"),
            "{}",
            files[0].1
        );
        assert_eq!(files[1].0, "BlobFrame");
        assert!(
            files[1].1.contains("string name\nint64 x\nint64 y\nint64 size\n"),
            "{}",
            files[1].1
        );
    }

    /// A structure type and the frame form of the same type never share a name: the
    /// two definitions of `Blob` (`esgm ros2 msg Blob`, `esgm ros2 msg BlobSeq`) are two
    /// messages.
    #[test]
    fn a_type_and_its_frame_form_are_two_message_names() {
        let blob = Schema::new("Blob", library).unwrap().msg_files();
        let seq = Schema::new("BlobSeq", library).unwrap().msg_files();
        assert_eq!(blob.len(), 1);
        let mut names: Vec<&str> = blob.iter().chain(&seq).map(|(n, _)| n.as_str()).collect();
        names.sort_unstable();
        assert_eq!(names, ["Blob", "BlobFrame", "BlobSeq"]);
        assert!(blob[0].1.starts_with("# esgm entity structure"));
        // A type nesting itself has both forms; one named like a nested frame is refused.
        let tree = EntityStructureType::new("Tree").frame_seq("children", "Tree");
        let files = Schema::new("Tree", |_| Some(tree.clone())).unwrap().msg_files();
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["Tree", "TreeFrame"]);
        assert!(files[0].1.contains("esgm_msgs/TreeFrame[] children"), "{}", files[0].1);
        let clash = EntityStructureType::new("BlobFrame").frame("inner", "Blob");
        let e = Schema::new("BlobFrame", |n| {
            if n == "BlobFrame" { Some(clash.clone()) } else { library(n) }
        })
        .unwrap_err();
        assert!(e.to_string().contains("BlobFrame"), "{e}");
    }

    #[test]
    fn unmappable_sorts_and_names_are_refused_naming_the_attribute() {
        let agg = EntityStructureType::new("Odd").attr("parts", ValueSort::Agg);
        let e = Schema::new("Odd", |_| Some(agg.clone())).unwrap_err();
        assert!(e.to_string().contains("parts"), "{e}");
        let caps = EntityStructureType::new("Odd").attr("Speed", ValueSort::Double);
        let e = Schema::new("Odd", |_| Some(caps.clone())).unwrap_err();
        assert!(e.to_string().contains("Speed"), "{e}");
        let e =
            Schema::new("odd_type", |_| Some(EntityStructureType::new("odd_type"))).unwrap_err();
        assert!(e.to_string().contains("CamelCase"), "{e}");
    }
}
