//! Typed structs as entity structures (M5): the [`Entity`] trait that
//! `#[derive(Entity)]` implements, and [`AttributeField`], which maps a Rust field type
//! to a [`ValueSort`].
//!
//! This replaces the seed's hand-written `…Wrapper` classes: a plain struct declares
//! the type once, and converts to and from entity structures without string lookups in
//! user code.
//!
//! ```
//! use esgm_core::{Entity, EntityStructure};
//!
//! #[derive(Entity, Debug, PartialEq)]
//! struct Blob { x: i64, y: i64, size: i64 }
//!
//! let ty = Blob::entity_structure_type();
//! assert_eq!(ty.name, "Blob");
//! let es: EntityStructure = Blob { x: 1, y: 2, size: 3 }.to_structure("blob1", 10, 10);
//! assert_eq!(Blob::from_structure(&es).unwrap(), Blob { x: 1, y: 2, size: 3 });
//! ```

use crate::structure::{Attributes, FrameRef, SharedStructure, ValueRef};
use crate::time::Time;
use crate::types::EntityStructureType;
use crate::value::frame::{AttributeValuePair, EntityFrame, EntityStructure};
use crate::value::{
    Octets, Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort,
    Vec3,
};

pub use esgm_derive::Entity;

/// A structure or frame could not be read as a typed struct.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FromEntityError {
    /// The attribute is absent.
    #[error("attribute `{attribute}` of `{type_name}` is missing")]
    MissingAttribute {
        /// The Rust type being built.
        type_name: &'static str,
        /// The attribute.
        attribute: &'static str,
    },
    /// The attribute has a value of another sort.
    #[error("attribute `{attribute}` of `{type_name}` is {actual}, expected {expected}")]
    WrongSort {
        /// The Rust type being built.
        type_name: &'static str,
        /// The attribute.
        attribute: &'static str,
        /// The sort the field needs.
        expected: ValueSort,
        /// The sort found.
        actual: ValueSort,
    },
}

/// A Rust type usable as one attribute of an [`Entity`] struct.
pub trait AttributeField: Sized {
    /// The attribute's sort.
    const SORT: ValueSort;
    /// For frame-sorted fields: the element type name (see [`crate::types::Attr`]).
    fn element_type() -> Option<&'static str> {
        None
    }
    /// The field as a value.
    fn to_value(&self) -> Value;
    /// The field from a value read in place (owned, or archived where it arrived), or
    /// `None` if the value has another sort.
    fn from_value_ref(value: ValueRef<'_>) -> Option<Self>;
    /// The field from an owned value, or `None` if the value has another sort.
    fn from_value(value: &Value) -> Option<Self> {
        Self::from_value_ref(value.into())
    }
}

/// A plain struct that is an entity structure type. Derive it with
/// `#[derive(Entity)]`; `#[entity(name = "…")]` on the struct sets the type name
/// (default: the struct's name) and `#[entity(rename = "…")]` on a field sets the
/// attribute name.
pub trait Entity: Sized {
    /// The type's registered name.
    const TYPE_NAME: &'static str;

    /// The entity structure type this struct declares.
    fn entity_structure_type() -> EntityStructureType;

    /// The struct's fields as attribute/value pairs, in declaration order.
    fn to_attributes(&self) -> Vec<AttributeValuePair>;

    /// Builds the struct from attribute/value pairs read in place (an owned structure's
    /// or an archived one's): the one conversion the others call.
    fn from_attribute_refs(attributes: Attributes<'_>) -> Result<Self, FromEntityError>;

    /// Builds the struct from attribute/value pairs.
    fn from_attributes(attributes: &[AttributeValuePair]) -> Result<Self, FromEntityError> {
        Self::from_attribute_refs(Attributes::owned(attributes))
    }

    /// The struct as a frame named `name` (to nest it in another structure).
    fn to_frame(&self, name: impl Into<String>) -> EntityFrame {
        EntityFrame { name: name.into(), attributes: self.to_attributes() }
    }

    /// The struct as an entity structure.
    fn to_structure(
        &self,
        name: impl Into<String>,
        valid_time: Time,
        create_time: Time,
    ) -> EntityStructure {
        EntityStructure {
            name: name.into(),
            valid_time,
            create_time,
            attributes: self.to_attributes(),
        }
    }

    /// Reads the struct from a frame.
    fn from_frame(frame: &EntityFrame) -> Result<Self, FromEntityError> {
        Self::from_attributes(&frame.attributes)
    }

    /// Reads the struct from an entity structure.
    fn from_structure(es: &EntityStructure) -> Result<Self, FromEntityError> {
        Self::from_attributes(&es.attributes)
    }

    /// Reads the struct from a structure as a trajectory holds it (a sample's), in
    /// place: an archived one from another process is read without decoding it first.
    fn from_shared(structure: &SharedStructure) -> Result<Self, FromEntityError> {
        Self::from_attribute_refs(structure.attributes())
    }

    /// Reads the struct from a nested frame read in place.
    fn from_frame_ref(frame: FrameRef<'_>) -> Result<Self, FromEntityError> {
        Self::from_attribute_refs(frame.attributes())
    }
}

/// Reads one field; used by the derive macro's generated code.
#[doc(hidden)]
pub fn read_field<T: AttributeField>(
    attributes: &Attributes<'_>,
    type_name: &'static str,
    attribute: &'static str,
) -> Result<T, FromEntityError> {
    let (_, value) = attributes
        .clone()
        .find(|(name, _)| *name == attribute)
        .ok_or(FromEntityError::MissingAttribute { type_name, attribute })?;
    T::from_value_ref(value).ok_or(FromEntityError::WrongSort {
        type_name,
        attribute,
        expected: T::SORT,
        actual: value.sort(),
    })
}

/// A field read by a `ValueRef` accessor, checked to be of exactly the field's sort
/// (`as_long` also reads a `Time`, which an `i64` field does not take).
macro_rules! field {
    ($t:ty, $sort:ident, $variant:ident, |$v:ident| $read:expr) => {
        impl AttributeField for $t {
            const SORT: ValueSort = ValueSort::$sort;
            fn to_value(&self) -> Value {
                Value::$variant(self.clone())
            }
            fn from_value_ref($v: ValueRef<'_>) -> Option<Self> {
                if $v.sort() != ValueSort::$sort {
                    return None;
                }
                $read
            }
        }
    };
}

field!(i64, Long, Long, |v| v.as_long());
field!(f64, Double, Double, |v| v.as_double());
field!(bool, Bool, Bool, |v| v.as_bool());
field!(String, String, String, |v| v.as_str().map(str::to_owned));
field!(Octets, OctetSeq, OctetSeq, |v| v.as_octets());
field!(Vec<i64>, LongSeq, LongSeq, |v| v.as_long_seq().map(|s| s.into_owned()));
field!(Vec<f64>, DoubleSeq, DoubleSeq, |v| v.as_double_seq().map(|s| s.into_owned()));
field!(Vec<String>, SymbolSeq, SymbolSeq, |v| v
    .symbols()
    .map(|s| s.into_iter().map(str::to_owned).collect()));
field!(Vec3, Vec, Vec, |v| v.as_vec3());
field!(Pos2, Pos2, Pos2, |v| v.as_pos2());
field!(Position, Position, Position, |v| v.as_position());
field!(Rotation, Rotation, Rotation, |v| v.as_rotation());
field!(PositionAltitude, PositionAltitude, PositionAltitude, |v| v.as_position_altitude());
field!(PositionAltitudeRotation, PositionAltitudeRotation, PositionAltitudeRotation, |v| v
    .as_pose());
field!(Vec<EntityFrame>, EntityFrameSeq, EntityFrameSeq, |v| v.as_frames().map(|f| f.to_frames()));
field!(Vec<Value>, Agg, Agg, |v| v.elements().map(|e| e.map(ValueRef::to_value).collect()));
field!(Vec<Vec3>, VecSeq, VecSeq, |v| match v.to_value() {
    Value::VecSeq(s) => Some(s),
    _ => None,
});
field!(Vec<Pos2>, Pos2Seq, Pos2Seq, |v| match v.to_value() {
    Value::Pos2Seq(s) => Some(s),
    _ => None,
});

impl AttributeField for EntityFrame {
    const SORT: ValueSort = ValueSort::EntityFrame;
    fn to_value(&self) -> Value {
        Value::EntityFrame(Box::new(self.clone()))
    }
    fn from_value_ref(value: ValueRef<'_>) -> Option<Self> {
        value.as_frame().map(FrameRef::to_frame)
    }
}

impl AttributeField for Value {
    const SORT: ValueSort = ValueSort::AnyValue;
    fn to_value(&self) -> Value {
        self.clone()
    }
    fn from_value_ref(value: ValueRef<'_>) -> Option<Self> {
        Some(value.to_value())
    }
}

/// A sequence of typed entities is a frame sequence whose element type is `T`'s.
impl<T: Entity> AttributeField for Vec<T> {
    const SORT: ValueSort = ValueSort::EntityFrameSeq;
    fn element_type() -> Option<&'static str> {
        Some(T::TYPE_NAME)
    }
    fn to_value(&self) -> Value {
        Value::EntityFrameSeq(self.iter().map(|e| e.to_frame(T::TYPE_NAME)).collect())
    }
    fn from_value_ref(value: ValueRef<'_>) -> Option<Self> {
        // One element of another shape makes the whole value not a `Vec<T>`: `None` says so.
        let frames = value.as_frames()?;
        (0..frames.len()).map(|i| frames.get(i).and_then(|f| T::from_frame_ref(f).ok())).collect()
    }
}
