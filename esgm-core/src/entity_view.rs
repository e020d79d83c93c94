//! Typed views (M5): `#[derive(Entity)]` also generates `<Type>View<'a>`, which reads
//! the attributes of a structure in place, by name checked once, without decoding it.
//! `RobotState::view(archived)?.x()` reads an `f64` from an archive in shared memory;
//! `Image::view(archived)?.image_data()` is the pixels as `&[u8]` where the writer put
//! them.
//!
//! A view is made from a [`ViewSource`]: an archived structure (what
//! `esgm_shm`'s received samples give, read in place), or an owned structure or sample
//! (the in-process runtime's answers, whose pixels are already shared, never copied).
//! Numbers and booleans are copied out, strings and octets are borrowed, and compound
//! values (points, poses, sequences, nested frames) are decoded when the view is made:
//! they are small, and a field accessor then costs a copy of the value.
//!
//! ```
//! use esgm_core::library::RobotState;
//! use esgm_core::{Entity, codec};
//!
//! let es = RobotState { x: 1.0, y: 2.0, dir: 90.0 }.to_structure("robot1", 10, 10);
//! let bytes = codec::encode(&es).unwrap();
//! let view = RobotState::view(codec::access(&bytes).unwrap()).unwrap();
//! assert_eq!((view.x(), view.dir()), (1.0, 90.0));
//! ```

use std::sync::Arc;

use crate::codec::{ArchivedEntityStructure, ArchivedValue, decode_value};
use crate::entity::AttributeField;
use crate::sample::Sample;
use crate::structure::{SharedStructure, StructureForm};
use crate::value::frame::{EntityFrame, EntityStructure};
use crate::value::{
    Octets, Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort,
    Vec3,
};

/// A field type as a typed view reads it.
pub trait ViewField: AttributeField {
    /// What the view returns for the field: a copy for numbers, a borrow for text and
    /// octets, the decoded value for compound values.
    type View<'a>: Clone;
    /// The field from its archived value, or `None` if the value has another sort.
    fn view_archived(value: &ArchivedValue) -> Option<Self::View<'_>>;
    /// The field from an owned value, or `None` if the value has another sort.
    fn view_value(value: &Value) -> Option<Self::View<'_>>;
}

/// Where a typed view reads from.
#[derive(Debug, Clone, Copy)]
pub enum ViewSource<'a> {
    /// An archived structure, read in place (shared memory, a file, a network buffer).
    Archived(&'a ArchivedEntityStructure),
    /// An owned structure.
    Structure(&'a EntityStructure),
}

impl<'a> From<&'a ArchivedEntityStructure> for ViewSource<'a> {
    fn from(a: &'a ArchivedEntityStructure) -> Self {
        Self::Archived(a)
    }
}

impl<'a> From<&'a EntityStructure> for ViewSource<'a> {
    fn from(s: &'a EntityStructure) -> Self {
        Self::Structure(s)
    }
}

impl<'a> From<&'a SharedStructure> for ViewSource<'a> {
    fn from(s: &'a SharedStructure) -> Self {
        match s.form() {
            StructureForm::Owned(es) => Self::Structure(es),
            StructureForm::Archived { structure, .. } => Self::Archived(structure),
        }
    }
}

impl<'a> From<&'a Sample> for ViewSource<'a> {
    fn from(s: &'a Sample) -> Self {
        (&s.structure).into()
    }
}

/// A structure that a typed view cannot read as its type.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ViewError {
    /// The structure has no attribute of that name.
    #[error("a `{type_name}` view needs attribute `{attribute}`, which the structure lacks")]
    MissingAttribute {
        /// The view's type.
        type_name: &'static str,
        /// The attribute.
        attribute: &'static str,
    },
    /// The attribute has another sort than the view's field.
    #[error("a `{type_name}` view reads `{attribute}` as {expected:?}, but it is {found:?}")]
    WrongSort {
        /// The view's type.
        type_name: &'static str,
        /// The attribute.
        attribute: &'static str,
        /// The field's sort.
        expected: ValueSort,
        /// The value's sort.
        found: ValueSort,
    },
}

/// Reads field `attribute` of a `type_name` view from `source` (the derive's code
/// calls this once per field when a view is made).
pub fn view_field<'a, T: ViewField>(
    source: ViewSource<'a>,
    type_name: &'static str,
    attribute: &'static str,
) -> Result<T::View<'a>, ViewError> {
    let missing = ViewError::MissingAttribute { type_name, attribute };
    let wrong =
        |found: ValueSort| ViewError::WrongSort { type_name, attribute, expected: T::SORT, found };
    match source {
        ViewSource::Archived(a) => {
            let pair = a.attributes.iter().find(|p| p.name.as_str() == attribute).ok_or(missing)?;
            T::view_archived(&pair.value).ok_or_else(|| wrong(archived_sort(&pair.value)))
        }
        ViewSource::Structure(s) => {
            let value = s.get(attribute).ok_or(missing)?;
            T::view_value(value).ok_or_else(|| wrong(value.sort()))
        }
    }
}

use crate::structure::value_ref_sort as archived_sort;

/// Numbers and booleans: copied out of the archive.
macro_rules! copied {
    ($t:ty, $variant:ident) => {
        impl ViewField for $t {
            type View<'a> = $t;
            fn view_archived(value: &ArchivedValue) -> Option<$t> {
                match value {
                    ArchivedValue::$variant(x) => Some((*x).into()),
                    _ => None,
                }
            }
            fn view_value(value: &Value) -> Option<$t> {
                match value {
                    Value::$variant(x) => Some(*x),
                    _ => None,
                }
            }
        }
    };
}

copied!(i64, Long);
copied!(f64, Double);
copied!(bool, Bool);

impl ViewField for String {
    type View<'a> = &'a str;
    fn view_archived(value: &ArchivedValue) -> Option<&str> {
        match value {
            ArchivedValue::String(s) => Some(s.as_str()),
            _ => None,
        }
    }
    fn view_value(value: &Value) -> Option<&str> {
        match value {
            Value::String(s) => Some(s.as_str()),
            _ => None,
        }
    }
}

impl ViewField for Octets {
    type View<'a> = &'a [u8];
    fn view_archived(value: &ArchivedValue) -> Option<&[u8]> {
        match value {
            ArchivedValue::OctetSeq(o) => Some(o.as_slice()),
            _ => None,
        }
    }
    fn view_value(value: &Value) -> Option<&[u8]> {
        match value {
            Value::OctetSeq(o) => Some(&o[..]),
            _ => None,
        }
    }
}

/// Compound values: decoded when the view is made.
macro_rules! decoded {
    ($($t:ty),* $(,)?) => {$(
        impl ViewField for $t {
            type View<'a> = $t;
            fn view_archived(value: &ArchivedValue) -> Option<$t> {
                // A checked archive decodes; if not, the field reads as absent, like a wrong sort.
                decode_value(value).ok().and_then(|v| <$t as AttributeField>::from_value(&v))
            }
            fn view_value(value: &Value) -> Option<$t> {
                <$t as AttributeField>::from_value(value)
            }
        }
    )*};
}

decoded!(
    Vec<i64>,
    Vec<f64>,
    Vec<String>,
    Vec3,
    Vec<Vec3>,
    Pos2,
    Vec<Pos2>,
    Position,
    Rotation,
    PositionAltitude,
    PositionAltitudeRotation,
    Vec<EntityFrame>,
    Vec<Value>,
    EntityFrame,
    Value,
);

/// Typed entities nested in a sequence: decoded once, shared by the accessor's copies
/// (an `Arc`, so the entity type need not be `Clone`).
impl<T: crate::entity::Entity> ViewField for Vec<T> {
    type View<'a> = Arc<[T]>;
    fn view_archived(value: &ArchivedValue) -> Option<Arc<[T]>> {
        // A checked archive decodes; if not, the field reads as absent, like a wrong sort.
        decode_value(value).ok().and_then(|v| Self::view_value(&v))
    }
    fn view_value(value: &Value) -> Option<Arc<[T]>> {
        <Vec<T> as AttributeField>::from_value(value).map(Arc::from)
    }
}

/// A typed entity nested as a frame, for the derive's `ViewField` impl: decoded once
/// and shared, as [`Vec<T>`]'s elements are.
pub fn view_nested<T: crate::entity::Entity + AttributeField>(value: &Value) -> Option<Arc<T>> {
    T::from_value(value).map(Arc::new)
}

/// [`view_nested`] from an archived value.
pub fn view_nested_archived<T: crate::entity::Entity + AttributeField>(
    value: &ArchivedValue,
) -> Option<Arc<T>> {
    // A checked archive decodes; if not, the field reads as absent, like a wrong sort.
    decode_value(value).ok().and_then(|v| view_nested(&v))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::codec;
    use crate::entity::Entity;
    use crate::library::{BlobSeq, Image, RobotState};

    fn archive(es: &EntityStructure) -> impl std::ops::Deref<Target = [u8]> + use<> {
        codec::encode(es).unwrap()
    }

    #[test]
    fn a_view_reads_an_archive_in_place_and_an_owned_structure_alike() {
        let es = RobotState { x: 1.5, y: -2.0, dir: 90.0 }.to_structure("robot1", 10, 11);
        let bytes = archive(&es);
        let archived = codec::access(&bytes).unwrap();
        let v = RobotState::view(archived).unwrap();
        assert_eq!((v.x(), v.y(), v.dir()), (1.5, -2.0, 90.0));
        let owned = RobotState::view(&es).unwrap();
        assert_eq!((owned.x(), owned.y(), owned.dir()), (1.5, -2.0, 90.0));
    }

    #[test]
    fn pixels_are_borrowed_from_the_archive() {
        let img = Image { width: 4, height: 2, format: 1, image_data: vec![7u8; 24].into() };
        let bytes = archive(&img.to_structure("cam", 1, 1));
        let v = Image::view(codec::access(&bytes).unwrap()).unwrap();
        assert!(bytes.as_ptr_range().contains(&v.image_data().as_ptr()), "copied");
        assert_eq!(v.image_data(), &[7u8; 24][..]);
        assert_eq!((v.width(), v.height(), v.format()), (4, 2, 1));
    }

    #[test]
    fn nested_entities_are_decoded_once_and_shared() {
        let blobs = crate::library::Blob { x: 1, y: 2, size: 3 };
        let seq = BlobSeq { items: vec![blobs, blobs] };
        let bytes = archive(&seq.to_structure("blobs", 1, 1));
        let v = BlobSeq::view(codec::access(&bytes).unwrap()).unwrap();
        assert_eq!(v.items().len(), 2);
        assert_eq!(v.items()[1].size, 3);
    }

    #[test]
    fn a_structure_of_another_shape_is_refused_naming_the_attribute() {
        let es = EntityStructure::new("r", 1, 1).with("x", 1.0).with("y", "north");
        let bytes = archive(&es);
        let e = RobotState::view(codec::access(&bytes).unwrap()).err().unwrap();
        assert_eq!(
            e,
            ViewError::WrongSort {
                type_name: "RobotState",
                attribute: "y",
                expected: ValueSort::Double,
                found: ValueSort::String,
            }
        );
        let e = RobotState::view(&EntityStructure::new("r", 1, 1).with("x", 1.0)).err().unwrap();
        assert!(e.to_string().contains("`y`"), "{e}");
    }
}
