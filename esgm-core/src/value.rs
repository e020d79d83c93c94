//! Values and their sorts (M2): the seed's `ValueSort` list and `Value` union.
//!
//! Names follow `value.idl` so users of the original find their way (`LONG_TYPE` is
//! [`ValueSort::Long`], `OCTET_SEQ_TYPE` is [`ValueSort::OctetSeq`], …). Two deliberate
//! widenings: `long` is 64-bit (a pixel count or a nanosecond time overflows 32 bits),
//! and [`ValueSort::NoValue`] names the sort of the special value [`Value::NoValue`] so
//! that type errors can say "expected Long, found NoValue".
//!
//! The archived `Value` is 16 bytes: the geometric variants (6 to 48 bytes of doubles)
//! are boxed out of line in the archive (rkyv's `AsBox`), so a structure of three
//! doubles archives to 120 bytes instead of 240 — two cache lines to move between
//! cores instead of four — while the in-memory `Value` keeps them inline.
//!
//! Octet sequences (images) are held in an [`Octets`] (see [`crate::octets`]), a shared
//! byte buffer: cloning a value, a frame or a structure never copies pixels in process,
//! and the archived form (see [`crate::codec`]) is a plain byte vector read in place.

use std::fmt;

use rkyv::{Archive, Deserialize, Serialize};

// Frames hold values and a value can hold frames: the two are one module.
pub mod frame;

pub use crate::octets::{ArchivedOctets, Octets, OctetsHolder};
use crate::time::Time;
use frame::EntityFrame;

/// The sort (type) of a [`Value`], as in the seed's `ValueSort` enum.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq, Eq, Clone, Copy), compare(PartialEq))]
pub enum ValueSort {
    /// `AGG_TYPE`: a tuple of values (a structured value, Definition 3.3.2).
    Agg,
    /// `ALTITUDE_TYPE`: an altitude in metres.
    Altitude,
    /// `ANY_VALUE_TYPE`: as an attribute's sort, accepts a value of any sort.
    AnyValue,
    /// `BOOL_TYPE`.
    Bool,
    /// `COLLECTION_TYPE`: an unordered collection of values.
    Collection,
    /// `DOUBLE_TYPE`: a 64-bit float.
    Double,
    /// `DOUBLE_SEQ_TYPE`.
    DoubleSeq,
    /// `ENTITY_FRAME_TYPE`: a nested entity frame (recursive entity structures, Def. 2.4.4).
    EntityFrame,
    /// `ENTITY_FRAME_SEQ_TYPE`: a sequence of entity frames (e.g. the tutorial's BlobSeq).
    EntityFrameSeq,
    /// `LONG_TYPE`: a 64-bit signed integer.
    Long,
    /// `LONG_SEQ_TYPE`.
    LongSeq,
    /// `OCTET_SEQ_TYPE`: raw bytes, e.g. image data; never copied between processes.
    OctetSeq,
    /// `POS2_TYPE`: a 2-D point.
    Pos2,
    /// `POS2_SEQ_TYPE`.
    Pos2Seq,
    /// `POSITION_ALTITUDE_TYPE`.
    PositionAltitude,
    /// `POSITION_ALTITUDE_ROTATION_TYPE`: a full 6-DoF pose.
    PositionAltitudeRotation,
    /// `POSITION_TYPE`: a horizontal world position.
    Position,
    /// `ROTATION_TYPE`: roll, pitch, yaw.
    Rotation,
    /// `STRING_TYPE`.
    String,
    /// `SYMBOL_SEQ_TYPE`.
    SymbolSeq,
    /// `SYMBOL_TYPE`: a name referring to something in the system.
    Symbol,
    /// `TIME_TYPE`: a time-point in nanoseconds.
    Time,
    /// `UNKNOWN_VALUE_TYPE`.
    UnknownValue,
    /// `VEC_TYPE`: a 3-D vector.
    Vec,
    /// `VEC_SEQ_TYPE`.
    VecSeq,
    /// The sort of [`Value::NoValue`] (an esgm addition, for error messages).
    NoValue,
}

impl ValueSort {
    /// Every sort, in declaration order; useful for parsers and exhaustive tests.
    pub const ALL: [ValueSort; 26] = [
        ValueSort::Agg,
        ValueSort::Altitude,
        ValueSort::AnyValue,
        ValueSort::Bool,
        ValueSort::Collection,
        ValueSort::Double,
        ValueSort::DoubleSeq,
        ValueSort::EntityFrame,
        ValueSort::EntityFrameSeq,
        ValueSort::Long,
        ValueSort::LongSeq,
        ValueSort::OctetSeq,
        ValueSort::Pos2,
        ValueSort::Pos2Seq,
        ValueSort::PositionAltitude,
        ValueSort::PositionAltitudeRotation,
        ValueSort::Position,
        ValueSort::Rotation,
        ValueSort::String,
        ValueSort::SymbolSeq,
        ValueSort::Symbol,
        ValueSort::Time,
        ValueSort::UnknownValue,
        ValueSort::Vec,
        ValueSort::VecSeq,
        ValueSort::NoValue,
    ];

    /// The seed's IDL spelling, e.g. `LONG_TYPE`.
    pub fn idl_name(self) -> &'static str {
        match self {
            ValueSort::Agg => "AGG_TYPE",
            ValueSort::Altitude => "ALTITUDE_TYPE",
            ValueSort::AnyValue => "ANY_VALUE_TYPE",
            ValueSort::Bool => "BOOL_TYPE",
            ValueSort::Collection => "COLLECTION_TYPE",
            ValueSort::Double => "DOUBLE_TYPE",
            ValueSort::DoubleSeq => "DOUBLE_SEQ_TYPE",
            ValueSort::EntityFrame => "ENTITY_FRAME_TYPE",
            ValueSort::EntityFrameSeq => "ENTITY_FRAME_SEQ_TYPE",
            ValueSort::Long => "LONG_TYPE",
            ValueSort::LongSeq => "LONG_SEQ_TYPE",
            ValueSort::OctetSeq => "OCTET_SEQ_TYPE",
            ValueSort::Pos2 => "POS2_TYPE",
            ValueSort::Pos2Seq => "POS2_SEQ_TYPE",
            ValueSort::PositionAltitude => "POSITION_ALTITUDE_TYPE",
            ValueSort::PositionAltitudeRotation => "POSITION_ALTITUDE_ROTATION_TYPE",
            ValueSort::Position => "POSITION_TYPE",
            ValueSort::Rotation => "ROTATION_TYPE",
            ValueSort::String => "STRING_TYPE",
            ValueSort::SymbolSeq => "SYMBOL_SEQ_TYPE",
            ValueSort::Symbol => "SYMBOL_TYPE",
            ValueSort::Time => "TIME_TYPE",
            ValueSort::UnknownValue => "UNKNOWN_VALUE_TYPE",
            ValueSort::Vec => "VEC_TYPE",
            ValueSort::VecSeq => "VEC_SEQ_TYPE",
            ValueSort::NoValue => "NO_VALUE",
        }
    }

    /// Parses a sort from its Rust name (`Long`), its IDL name (`LONG_TYPE`) or a
    /// lower-case alias (`long`, `i64`, `f64`, `bytes`, `frame`, `frames`, …), for
    /// config files and the CLI.
    pub fn parse(s: &str) -> Option<ValueSort> {
        let alias = match s {
            "i64" | "int" | "integer" => Some(ValueSort::Long),
            "f64" | "float" | "real" => Some(ValueSort::Double),
            "bytes" | "octets" => Some(ValueSort::OctetSeq),
            "frame" => Some(ValueSort::EntityFrame),
            "frames" => Some(ValueSort::EntityFrameSeq),
            "str" => Some(ValueSort::String),
            _ => None,
        };
        alias.or_else(|| {
            Self::ALL.into_iter().find(|v| {
                let rust = format!("{v:?}");
                rust == s
                    || rust.eq_ignore_ascii_case(s)
                    || v.idl_name() == s
                    || v.idl_name().trim_end_matches("_TYPE").replace('_', "")
                        == s.to_ascii_uppercase().replace('_', "")
            })
        })
    }

    /// True for sorts whose values are numbers or tuples of numbers, which linear
    /// interpolation and averaging work on.
    pub fn is_numeric(self) -> bool {
        matches!(
            self,
            ValueSort::Long
                | ValueSort::Double
                | ValueSort::Time
                | ValueSort::Altitude
                | ValueSort::Pos2
                | ValueSort::Position
                | ValueSort::Rotation
                | ValueSort::Vec
                | ValueSort::PositionAltitude
                | ValueSort::PositionAltitudeRotation
                | ValueSort::LongSeq
                | ValueSort::DoubleSeq
        )
    }
}

impl fmt::Display for ValueSort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

/// A 3-D vector (`Vec` in the seed's common types).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct Vec3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

/// A 2-D point, e.g. in image pixels (`Pos2`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct Pos2 {
    /// x coordinate.
    pub x: f64,
    /// y coordinate.
    pub y: f64,
}

/// A horizontal world position in metres, north and east of the map origin (`Position`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct Position {
    /// Metres north of the origin.
    pub north: f64,
    /// Metres east of the origin.
    pub east: f64,
}

/// An orientation as roll, pitch and yaw in radians (`Rotation`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct Rotation {
    /// Rotation about the forward axis.
    pub roll: f64,
    /// Rotation about the lateral axis.
    pub pitch: f64,
    /// Rotation about the vertical axis (heading).
    pub yaw: f64,
}

/// A world position with an altitude (`PositionAltitude`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct PositionAltitude {
    /// Horizontal position.
    pub position: Position,
    /// Altitude in metres.
    pub altitude: f64,
}

/// A full pose: position, altitude and orientation (`PositionAltitudeRotation`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug, PartialEq), compare(PartialEq))]
pub struct PositionAltitudeRotation {
    /// Horizontal position.
    pub position: Position,
    /// Altitude in metres.
    pub altitude: f64,
    /// Orientation.
    pub rotation: Rotation,
}

/// A value of an attribute: the seed's `Value` union plus `NoValue`.
#[derive(
    Debug,
    Clone,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(serialize_bounds(
    __S: rkyv::ser::Writer + rkyv::ser::Allocator,
    __S::Error: rkyv::rancor::Source,
))]
#[rkyv(deserialize_bounds(__D::Error: rkyv::rancor::Source))]
#[rkyv(bytecheck(bounds(
    __C: rkyv::validation::ArchiveContext + crate::nesting::NestingContext,
    <__C as rkyv::rancor::Fallible>::Error: rkyv::rancor::Source,
)))]
#[rkyv(derive(Debug))]
pub enum Value {
    /// The special value meaning "no value" (Definition 3.3.3).
    #[default]
    NoValue,
    /// `LONG_TYPE`.
    Long(i64),
    /// `DOUBLE_TYPE`.
    Double(f64),
    /// `BOOL_TYPE`.
    Bool(bool),
    /// `STRING_TYPE`.
    String(String),
    /// `TIME_TYPE`.
    Time(Time),
    /// `SYMBOL_TYPE`.
    Symbol(String),
    /// `OCTET_SEQ_TYPE`.
    OctetSeq(Octets),
    /// `LONG_SEQ_TYPE`.
    LongSeq(Vec<i64>),
    /// `DOUBLE_SEQ_TYPE`.
    DoubleSeq(Vec<f64>),
    /// `SYMBOL_SEQ_TYPE`.
    SymbolSeq(Vec<String>),
    /// `VEC_TYPE`.
    Vec(#[rkyv(with = rkyv::with::AsBox)] Vec3),
    /// `VEC_SEQ_TYPE`.
    VecSeq(Vec<Vec3>),
    /// `POS2_TYPE`.
    Pos2(#[rkyv(with = rkyv::with::AsBox)] Pos2),
    /// `POS2_SEQ_TYPE`.
    Pos2Seq(Vec<Pos2>),
    /// `POSITION_TYPE`.
    Position(#[rkyv(with = rkyv::with::AsBox)] Position),
    /// `ALTITUDE_TYPE`.
    Altitude(f64),
    /// `ROTATION_TYPE`.
    Rotation(#[rkyv(with = rkyv::with::AsBox)] Rotation),
    /// `POSITION_ALTITUDE_TYPE`.
    PositionAltitude(#[rkyv(with = rkyv::with::AsBox)] PositionAltitude),
    /// `POSITION_ALTITUDE_ROTATION_TYPE`.
    PositionAltitudeRotation(#[rkyv(with = rkyv::with::AsBox)] PositionAltitudeRotation),
    /// `AGG_TYPE`: a tuple of values.
    Agg(#[rkyv(omit_bounds, with = crate::nesting::Nest)] Vec<Value>),
    /// `COLLECTION_TYPE`: a collection of values.
    Collection(#[rkyv(omit_bounds, with = crate::nesting::Nest)] Vec<Value>),
    /// `ENTITY_FRAME_TYPE`: a nested frame.
    EntityFrame(#[rkyv(omit_bounds, with = crate::nesting::Nest)] Box<EntityFrame>),
    /// `ENTITY_FRAME_SEQ_TYPE`: a sequence of frames.
    EntityFrameSeq(#[rkyv(omit_bounds, with = crate::nesting::Nest)] Vec<EntityFrame>),
}

impl Value {
    /// The sort of this value.
    pub fn sort(&self) -> ValueSort {
        match self {
            Value::NoValue => ValueSort::NoValue,
            Value::Long(_) => ValueSort::Long,
            Value::Double(_) => ValueSort::Double,
            Value::Bool(_) => ValueSort::Bool,
            Value::String(_) => ValueSort::String,
            Value::Time(_) => ValueSort::Time,
            Value::Symbol(_) => ValueSort::Symbol,
            Value::OctetSeq(_) => ValueSort::OctetSeq,
            Value::LongSeq(_) => ValueSort::LongSeq,
            Value::DoubleSeq(_) => ValueSort::DoubleSeq,
            Value::SymbolSeq(_) => ValueSort::SymbolSeq,
            Value::Vec(_) => ValueSort::Vec,
            Value::VecSeq(_) => ValueSort::VecSeq,
            Value::Pos2(_) => ValueSort::Pos2,
            Value::Pos2Seq(_) => ValueSort::Pos2Seq,
            Value::Position(_) => ValueSort::Position,
            Value::Altitude(_) => ValueSort::Altitude,
            Value::Rotation(_) => ValueSort::Rotation,
            Value::PositionAltitude(_) => ValueSort::PositionAltitude,
            Value::PositionAltitudeRotation(_) => ValueSort::PositionAltitudeRotation,
            Value::Agg(_) => ValueSort::Agg,
            Value::Collection(_) => ValueSort::Collection,
            Value::EntityFrame(_) => ValueSort::EntityFrame,
            Value::EntityFrameSeq(_) => ValueSort::EntityFrameSeq,
        }
    }

    /// The value as an integer, if it is a `Long` or a `Time`.
    pub fn as_long(&self) -> Option<i64> {
        match self {
            Value::Long(v) | Value::Time(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a float, if it is a number of any sort (`Long`, `Double`, `Time`,
    /// `Altitude`).
    pub fn as_double(&self) -> Option<f64> {
        match self {
            Value::Double(v) | Value::Altitude(v) => Some(*v),
            Value::Long(v) | Value::Time(v) => Some(*v as f64),
            _ => None,
        }
    }

    /// The value as a bool, if it is one.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a string slice, if it is a `String` or a `Symbol`.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(v) | Value::Symbol(v) => Some(v),
            _ => None,
        }
    }

    /// The bytes of an octet sequence.
    pub fn as_octets(&self) -> Option<&Octets> {
        match self {
            Value::OctetSeq(v) => Some(v),
            _ => None,
        }
    }

    /// The nested frame of an `EntityFrame` value.
    pub fn as_frame(&self) -> Option<&EntityFrame> {
        match self {
            Value::EntityFrame(v) => Some(v),
            _ => None,
        }
    }

    /// The frames of an `EntityFrameSeq` value.
    pub fn as_frames(&self) -> Option<&[EntityFrame]> {
        match self {
            Value::EntityFrameSeq(v) => Some(v),
            _ => None,
        }
    }

    /// True for [`Value::NoValue`].
    pub fn is_no_value(&self) -> bool {
        matches!(self, Value::NoValue)
    }
}

impl Value {
    /// Approximate heap bytes this value holds; octet buffers already in `seen` (by
    /// address) are not counted again, so a shared image counts once.
    pub fn approx_heap_bytes(&self, seen: &mut std::collections::HashSet<usize>) -> usize {
        use std::mem::size_of;
        match self {
            Value::String(s) | Value::Symbol(s) => s.capacity(),
            Value::OctetSeq(o) if seen.insert(o.as_ptr() as usize) => o.len(),
            Value::LongSeq(v) => v.capacity() * size_of::<i64>(),
            Value::DoubleSeq(v) => v.capacity() * size_of::<f64>(),
            Value::SymbolSeq(v) => v.iter().map(|s| s.capacity() + size_of::<String>()).sum(),
            Value::VecSeq(v) => v.capacity() * size_of::<Vec3>(),
            Value::Pos2Seq(v) => v.capacity() * size_of::<Pos2>(),
            Value::Agg(v) | Value::Collection(v) => {
                v.iter().map(|x| size_of::<Value>() + x.approx_heap_bytes(seen)).sum()
            }
            Value::EntityFrame(f) => size_of::<EntityFrame>() + f.approx_heap_bytes(seen),
            Value::EntityFrameSeq(v) => {
                v.iter().map(|f| size_of::<EntityFrame>() + f.approx_heap_bytes(seen)).sum()
            }
            _ => 0,
        }
    }
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Long(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Double(v)
    }
}
impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Value::Bool(v)
    }
}
impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::String(v.to_owned())
    }
}
impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::String(v)
    }
}
impl From<Octets> for Value {
    fn from(v: Octets) -> Self {
        Value::OctetSeq(v)
    }
}
impl From<EntityFrame> for Value {
    fn from(v: EntityFrame) -> Self {
        Value::EntityFrame(Box::new(v))
    }
}
impl From<Vec<EntityFrame>> for Value {
    fn from(v: Vec<EntityFrame>) -> Self {
        Value::EntityFrameSeq(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_parse_from_every_spelling() {
        for s in ValueSort::ALL {
            assert_eq!(ValueSort::parse(&format!("{s:?}")), Some(s));
            assert_eq!(ValueSort::parse(s.idl_name()), Some(s), "{}", s.idl_name());
        }
        assert_eq!(ValueSort::parse("long"), Some(ValueSort::Long));
        assert_eq!(ValueSort::parse("entity_frame_seq"), Some(ValueSort::EntityFrameSeq));
        assert_eq!(ValueSort::parse("f64"), Some(ValueSort::Double));
        assert_eq!(ValueSort::parse("lnog"), None);
    }

    #[test]
    fn value_sorts_match_variants() {
        assert_eq!(Value::from(3i64).sort(), ValueSort::Long);
        assert_eq!(Value::NoValue.sort(), ValueSort::NoValue);
        assert_eq!(Value::from(vec![EntityFrame::new("b")]).sort(), ValueSort::EntityFrameSeq);
        assert_eq!(Value::Time(5).as_double(), Some(5.0));
    }
}
