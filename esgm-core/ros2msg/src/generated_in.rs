//! Generated messages read back: an `esgm_msgs/msg/<Type>` message (from a ROS 2 node
//! built with the definitions `esgm ros2 msg <Type>` prints) as the entity structure
//! it stands for, field for field as [`crate::generated`] writes them. The layout is
//! the type's, known only at run time, so the message is read through a
//! [`DeserializeSeed`] made from its [`Schema`].
//!
//! The header's stamp is the valid time and its frame id the structure's name; a
//! nested frame's `name` is its entity's. A `geometry_msgs/Pose`'s orientation comes
//! back as roll, pitch and yaw.

use std::fmt;

use esgm_core::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Vec3,
};
use esgm_core::{
    Attr, AttributeValuePair, EntityFrame, EntityStructure, EntityStructureType, Time, Value,
    ValueSort,
};
use serde::Deserialize;
use serde::de::{DeserializeSeed, Deserializer, Error as _, SeqAccess, Visitor};

use crate::generated::Schema;
use crate::mapping::esgm_time;
use crate::msgs;

/// Reads one message of `schema`'s root type as its structure, created at
/// `received` ([`crate::generated`] for the layout).
#[derive(Debug, Clone, Copy)]
pub struct GeneratedSeed<'a> {
    /// The message's type and the types it nests.
    pub schema: &'a Schema,
    /// The structure's create time (when the message was received).
    pub received: Time,
}

impl<'de> DeserializeSeed<'de> for GeneratedSeed<'_> {
    type Value = EntityStructure;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<EntityStructure, D::Error> {
        let ty = self
            .schema
            .get(self.schema.root())
            .ok_or_else(|| D::Error::custom("the schema lost its root type"))?;
        let fields = ty.attributes.len() + 1;
        d.deserialize_tuple(fields, Message { schema: self.schema, ty, received: self.received })
    }
}

struct Message<'a> {
    schema: &'a Schema,
    ty: &'a EntityStructureType,
    received: Time,
}

impl<'de> Visitor<'de> for Message<'_> {
    type Value = EntityStructure;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "an {}/msg/{} message", crate::generated::PACKAGE, self.ty.name)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<EntityStructure, A::Error> {
        let (stamp, name): (msgs::Time, String) =
            seq.next_element()?.ok_or_else(|| A::Error::custom("the message has no header"))?;
        let mut es = EntityStructure::new(name, esgm_time(stamp), self.received);
        es.attributes = fields(&mut seq, self.ty, self.schema)?;
        Ok(es)
    }
}

/// Each attribute of `ty`, in order, from `seq`.
fn fields<'de, A: SeqAccess<'de>>(
    seq: &mut A,
    ty: &EntityStructureType,
    schema: &Schema,
) -> Result<Vec<AttributeValuePair>, A::Error> {
    ty.attributes
        .iter()
        .map(|attr| {
            let value = seq
                .next_element_seed(FieldSeed { attr, schema })?
                .ok_or_else(|| A::Error::custom(format!("field `{}` is missing", attr.name)))?;
            Ok(AttributeValuePair::new(attr.name.clone(), value))
        })
        .collect()
}

/// One attribute's field.
#[derive(Clone, Copy)]
struct FieldSeed<'a> {
    attr: &'a Attr,
    schema: &'a Schema,
}

impl FieldSeed<'_> {
    fn element<E: serde::de::Error>(&self) -> Result<&EntityStructureType, E> {
        self.attr
            .element_type
            .as_deref()
            .and_then(|e| self.schema.get(e))
            .ok_or_else(|| E::custom(format!("no element type for `{}`", self.attr.name)))
    }
}

/// `geometry_msgs/Point` or `Vector3`.
type Xyz = (f64, f64, f64);

/// Roll, pitch and yaw of a unit quaternion `(x, y, z, w)` (the inverse of what the
/// writer sends).
fn rotation((x, y, z, w): (f64, f64, f64, f64)) -> Rotation {
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    Rotation { roll, pitch, yaw }
}

impl<'de> DeserializeSeed<'de> for FieldSeed<'_> {
    type Value = Value;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        let position = |(east, north, _): Xyz| Position { north, east };
        Ok(match self.attr.sort {
            ValueSort::Long => Value::Long(i64::deserialize(d)?),
            ValueSort::Double => Value::Double(f64::deserialize(d)?),
            ValueSort::Altitude => Value::Altitude(f64::deserialize(d)?),
            ValueSort::Bool => Value::Bool(bool::deserialize(d)?),
            ValueSort::String => Value::String(String::deserialize(d)?),
            ValueSort::Symbol => Value::Symbol(String::deserialize(d)?),
            ValueSort::Time => Value::Time(esgm_time(msgs::Time::deserialize(d)?)),
            ValueSort::OctetSeq => Value::OctetSeq(Vec::<u8>::deserialize(d)?.into()),
            ValueSort::LongSeq => Value::LongSeq(Vec::deserialize(d)?),
            ValueSort::DoubleSeq => Value::DoubleSeq(Vec::deserialize(d)?),
            ValueSort::SymbolSeq => Value::SymbolSeq(Vec::deserialize(d)?),
            ValueSort::Vec => {
                let (x, y, z) = Xyz::deserialize(d)?;
                Value::Vec(Vec3 { x, y, z })
            }
            ValueSort::Rotation => {
                let (roll, pitch, yaw) = Xyz::deserialize(d)?;
                Value::Rotation(Rotation { roll, pitch, yaw })
            }
            ValueSort::VecSeq => Value::VecSeq(
                Vec::<Xyz>::deserialize(d)?.into_iter().map(|(x, y, z)| Vec3 { x, y, z }).collect(),
            ),
            ValueSort::Pos2 => {
                let (x, y, _) = Xyz::deserialize(d)?;
                Value::Pos2(Pos2 { x, y })
            }
            ValueSort::Pos2Seq => Value::Pos2Seq(
                Vec::<Xyz>::deserialize(d)?.into_iter().map(|(x, y, _)| Pos2 { x, y }).collect(),
            ),
            ValueSort::Position => Value::Position(position(Xyz::deserialize(d)?)),
            ValueSort::PositionAltitude => {
                let p = Xyz::deserialize(d)?;
                Value::PositionAltitude(PositionAltitude { position: position(p), altitude: p.2 })
            }
            ValueSort::PositionAltitudeRotation => {
                let (p, q) = <(Xyz, (f64, f64, f64, f64))>::deserialize(d)?;
                Value::PositionAltitudeRotation(PositionAltitudeRotation {
                    position: position(p),
                    altitude: p.2,
                    rotation: rotation(q),
                })
            }
            ValueSort::EntityFrame => {
                let ty = self.element()?;
                let frame = FrameSeed { ty, schema: self.schema }.deserialize(d)?;
                Value::EntityFrame(Box::new(frame))
            }
            ValueSort::EntityFrameSeq => {
                let ty = self.element()?;
                Value::EntityFrameSeq(d.deserialize_seq(Frames { ty, schema: self.schema })?)
            }
            other => {
                return Err(D::Error::custom(format!(
                    "attribute `{}`: sort {other:?} has no message layout",
                    self.attr.name
                )));
            }
        })
    }
}

/// A nested frame: its entity's name, then its attributes.
#[derive(Clone, Copy)]
struct FrameSeed<'a> {
    ty: &'a EntityStructureType,
    schema: &'a Schema,
}

impl<'de> DeserializeSeed<'de> for FrameSeed<'_> {
    type Value = EntityFrame;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<EntityFrame, D::Error> {
        d.deserialize_tuple(self.ty.attributes.len() + 1, self)
    }
}

impl<'de> Visitor<'de> for FrameSeed<'_> {
    type Value = EntityFrame;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "an {}/{} frame",
            crate::generated::PACKAGE,
            crate::generated::frame_message(&self.ty.name)
        )
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<EntityFrame, A::Error> {
        let name: String =
            seq.next_element()?.ok_or_else(|| A::Error::custom("the frame has no name"))?;
        let attributes = fields(&mut seq, self.ty, self.schema)?;
        Ok(EntityFrame { name, attributes })
    }
}

/// A sequence of nested frames.
struct Frames<'a> {
    ty: &'a EntityStructureType,
    schema: &'a Schema,
}

impl<'de> Visitor<'de> for Frames<'_> {
    type Value = Vec<EntityFrame>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "a sequence of {}/{} frames",
            crate::generated::PACKAGE,
            crate::generated::frame_message(&self.ty.name)
        )
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<EntityFrame>, A::Error> {
        // The length comes from the wire: never trusted for an allocation.
        let mut frames = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1024));
        while let Some(frame) =
            seq.next_element_seed(FrameSeed { ty: self.ty, schema: self.schema })?
        {
            frames.push(frame);
        }
        Ok(frames)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::generated::GeneratedRef;
    use esgm_core::library::{Blob, BlobSeq};
    use esgm_core::{Entity, TypeRegistry};

    fn library(name: &str) -> Option<EntityStructureType> {
        TypeRegistry::with_library().get_entity_structure_type(name).ok().map(|t| (*t).clone())
    }

    fn round_trip(es: &EntityStructure, schema: &Schema) -> EntityStructure {
        let mut bytes = Vec::new();
        crate::cdr::encode_into(&GeneratedRef { structure: es, schema }, &mut bytes).unwrap();
        crate::cdr::decode_seed(&bytes, GeneratedSeed { schema, received: 7 }).unwrap()
    }

    #[test]
    fn a_blob_seq_comes_back_as_it_went() {
        let schema = Schema::new("BlobSeq", library).unwrap();
        let seq =
            BlobSeq { items: vec![Blob { x: 1, y: -2, size: 30 }, Blob { x: 4, y: 5, size: 60 }] };
        let es = seq.to_structure("camera", 1_700_000_000_123_456_789, 7);
        let back = round_trip(&es, &schema);
        assert_eq!(back, es);
        assert_eq!(BlobSeq::from_structure(&back).unwrap(), seq);
    }

    #[test]
    fn every_sort_with_a_layout_comes_back() {
        let t = EntityStructureType::new("Everything")
            .attr("count", ValueSort::Long)
            .attr("ratio", ValueSort::Double)
            .attr("on", ValueSort::Bool)
            .attr("label", ValueSort::String)
            .attr("when", ValueSort::Time)
            .attr("bytes", ValueSort::OctetSeq)
            .attr("longs", ValueSort::LongSeq)
            .attr("doubles", ValueSort::DoubleSeq)
            .attr("words", ValueSort::SymbolSeq)
            .attr("velocity", ValueSort::Vec)
            .attr("where2", ValueSort::Pos2)
            .attr("path", ValueSort::Pos2Seq)
            .attr("pose", ValueSort::PositionAltitudeRotation);
        let schema = Schema::new("Everything", |_| Some(t.clone())).unwrap();
        let mut es = EntityStructure::new("thing", 5_000_000_001, 7);
        es.set("count", -3_i64);
        es.set("ratio", 0.5);
        es.set("on", true);
        es.set("label", "hello");
        es.set("when", Value::Time(2_000_000_003));
        es.set("bytes", Value::OctetSeq(vec![1_u8, 2, 3].into()));
        es.set("longs", Value::LongSeq(vec![1, -1]));
        es.set("doubles", Value::DoubleSeq(vec![0.25]));
        es.set("words", Value::SymbolSeq(vec!["a".into(), "b".into()]));
        es.set("velocity", Value::Vec(Vec3 { x: 1.0, y: 2.0, z: 3.0 }));
        es.set("where2", Value::Pos2(Pos2 { x: -1.0, y: 1.0 }));
        es.set("path", Value::Pos2Seq(vec![Pos2 { x: 0.0, y: 1.0 }]));
        let pose = PositionAltitudeRotation {
            position: Position { north: 3.0, east: 4.0 },
            altitude: 5.0,
            rotation: Rotation { roll: 0.1, pitch: -0.2, yaw: 0.3 },
        };
        es.set("pose", Value::PositionAltitudeRotation(pose));
        let back = round_trip(&es, &schema);
        for pair in &es.attributes {
            let got = back.get(&pair.name).unwrap();
            match (got, &pair.value) {
                (Value::PositionAltitudeRotation(g), Value::PositionAltitudeRotation(w)) => {
                    assert_eq!((g.position, g.altitude), (w.position, w.altitude));
                    for (a, b) in [
                        (g.rotation.roll, w.rotation.roll),
                        (g.rotation.pitch, w.rotation.pitch),
                        (g.rotation.yaw, w.rotation.yaw),
                    ] {
                        assert!((a - b).abs() < 1e-12, "{a} {b}");
                    }
                }
                (g, w) => assert_eq!(g, w, "{}", pair.name),
            }
        }
        assert_eq!((back.name.as_str(), back.valid_time), ("thing", 5_000_000_001));
    }

    #[test]
    fn a_short_message_is_an_error_not_a_panic() {
        let schema = Schema::new("BlobSeq", library).unwrap();
        let es = BlobSeq { items: vec![Blob { x: 1, y: 2, size: 3 }] }.to_structure("c", 1, 1);
        let mut bytes = Vec::new();
        crate::cdr::encode_into(&GeneratedRef { structure: &es, schema: &schema }, &mut bytes)
            .unwrap();
        for cut in [0, 4, 9, bytes.len() - 1] {
            let seed = GeneratedSeed { schema: &schema, received: 0 };
            assert!(crate::cdr::decode_seed(&bytes[..cut], seed).is_err(), "{cut}");
        }
    }
}
