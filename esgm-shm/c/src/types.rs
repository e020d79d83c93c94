//! Entity structure types (E1, M4): a name and typed attributes, made from a list of
//! attributes and sorts, registered, read back and destroyed with the IDL's names.
//!
//! ```c
//! esgm_type_t blob;
//! esgm_type_new("Blob", &blob);
//! esgm_type_add_attribute(blob, "x", ESGM_SORT_LONG, NULL);
//! esgm_type_add_attribute(blob, "y", ESGM_SORT_LONG, NULL);
//! esgm_type_add_attribute(blob, "size", ESGM_SORT_LONG, NULL);
//! esgm_create_entity_structure_type(esgm, "Blob", blob);
//! esgm_type_free(blob);
//! ```

use std::ffi::c_char;

use esgm_shm::prelude::*;
use parking_lot::Mutex;

use crate::connect::{esgm_t, on, runtime};
use crate::handles::{self, handle};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{copy_out, esgm_str_t, optional, put, text};

/// The sorts of values (the seed's `ValueSort`), as C code names them.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_sort {
    /// No value (`NoValue`).
    ESGM_SORT_NO_VALUE = 0,
    /// A 64-bit signed integer (`LONG_TYPE`).
    ESGM_SORT_LONG = 1,
    /// A 64-bit float (`DOUBLE_TYPE`).
    ESGM_SORT_DOUBLE = 2,
    /// A boolean (`BOOL_TYPE`).
    ESGM_SORT_BOOL = 3,
    /// Text (`STRING_TYPE`).
    ESGM_SORT_STRING = 4,
    /// A time-point in nanoseconds (`TIME_TYPE`).
    ESGM_SORT_TIME = 5,
    /// A name of something in the system (`SYMBOL_TYPE`).
    ESGM_SORT_SYMBOL = 6,
    /// Raw bytes, such as an image's pixels, never copied between processes
    /// (`OCTET_SEQ_TYPE`).
    ESGM_SORT_OCTET_SEQ = 7,
    /// Integers (`LONG_SEQ_TYPE`).
    ESGM_SORT_LONG_SEQ = 8,
    /// Floats (`DOUBLE_SEQ_TYPE`).
    ESGM_SORT_DOUBLE_SEQ = 9,
    /// Symbols (`SYMBOL_SEQ_TYPE`).
    ESGM_SORT_SYMBOL_SEQ = 10,
    /// A 3-D vector (`VEC_TYPE`).
    ESGM_SORT_VEC = 11,
    /// 3-D vectors (`VEC_SEQ_TYPE`).
    ESGM_SORT_VEC_SEQ = 12,
    /// A 2-D point (`POS2_TYPE`).
    ESGM_SORT_POS2 = 13,
    /// 2-D points (`POS2_SEQ_TYPE`).
    ESGM_SORT_POS2_SEQ = 14,
    /// A horizontal world position (`POSITION_TYPE`).
    ESGM_SORT_POSITION = 15,
    /// An altitude in metres (`ALTITUDE_TYPE`).
    ESGM_SORT_ALTITUDE = 16,
    /// Roll, pitch, yaw (`ROTATION_TYPE`).
    ESGM_SORT_ROTATION = 17,
    /// A position with an altitude (`POSITION_ALTITUDE_TYPE`).
    ESGM_SORT_POSITION_ALTITUDE = 18,
    /// A full pose (`POSITION_ALTITUDE_ROTATION_TYPE`).
    ESGM_SORT_POSITION_ALTITUDE_ROTATION = 19,
    /// A tuple of values (`AGG_TYPE`).
    ESGM_SORT_AGG = 20,
    /// A collection of values (`COLLECTION_TYPE`).
    ESGM_SORT_COLLECTION = 21,
    /// A nested frame of a named type (`ENTITY_FRAME_TYPE`).
    ESGM_SORT_ENTITY_FRAME = 22,
    /// A sequence of frames of a named type (`ENTITY_FRAME_SEQ_TYPE`).
    ESGM_SORT_ENTITY_FRAME_SEQ = 23,
    /// As an attribute's sort: any value (`ANY_VALUE_TYPE`).
    ESGM_SORT_ANY_VALUE = 24,
    /// `UNKNOWN_VALUE_TYPE`.
    ESGM_SORT_UNKNOWN_VALUE = 25,
}

/// Every sort with its C value, in the C enum's order.
const SORTS: [ValueSort; 26] = [
    ValueSort::NoValue,
    ValueSort::Long,
    ValueSort::Double,
    ValueSort::Bool,
    ValueSort::String,
    ValueSort::Time,
    ValueSort::Symbol,
    ValueSort::OctetSeq,
    ValueSort::LongSeq,
    ValueSort::DoubleSeq,
    ValueSort::SymbolSeq,
    ValueSort::Vec,
    ValueSort::VecSeq,
    ValueSort::Pos2,
    ValueSort::Pos2Seq,
    ValueSort::Position,
    ValueSort::Altitude,
    ValueSort::Rotation,
    ValueSort::PositionAltitude,
    ValueSort::PositionAltitudeRotation,
    ValueSort::Agg,
    ValueSort::Collection,
    ValueSort::EntityFrame,
    ValueSort::EntityFrameSeq,
    ValueSort::AnyValue,
    ValueSort::UnknownValue,
];

/// The sort of a C value, named `what` in the error.
pub(crate) fn sort_from_c(sort: i32, what: &str) -> Result<ValueSort> {
    usize::try_from(sort).ok().and_then(|i| SORTS.get(i).copied()).ok_or_else(|| {
        Error::argument(format!(
            "`{what}` is {sort}, not a sort (ESGM_SORT_NO_VALUE (0) … ESGM_SORT_UNKNOWN_VALUE (25))"
        ))
    })
}

/// The C value of a sort.
pub(crate) fn sort_to_c(sort: ValueSort) -> i32 {
    SORTS.iter().position(|s| *s == sort).map_or(0, |i| i as i32)
}

/// An entity structure type being made, or one read from the system: a name and
/// its attributes, each with a sort (and, for frames, the type of its elements).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_type_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_type_t => Mutex<EntityStructureType>);

/// One attribute of a type, as `esgm_type_attribute` reads it; the texts are valid
/// while the type's handle lives.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_attribute_t {
    /// Its name.
    pub name: esgm_str_t,
    /// Its sort (an `esgm_sort`).
    pub sort: i32,
    /// For a frame or frame sequence, the type of its elements; else empty.
    pub element_type: esgm_str_t,
}

/// A new type called `name`, without attributes yet.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_new(name: *const c_char, out: *mut esgm_type_t) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        crate::strings::writable(out, "out")?;
        let h = handles::insert(Mutex::new(EntityStructureType::new(name)));
        unsafe { put(out, "out", h) }
    })
}

/// Adds the attribute `name` of `sort` (an `esgm_sort`) to `t`; a frame or frame
/// sequence names the registered type of its elements in `element_type` (null for
/// every other sort). A name already in the type, or a frame without its element type,
/// is `ESGM_INVALID_TYPE`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_add_attribute(
    t: esgm_type_t,
    name: *const c_char,
    sort: i32,
    element_type: *const c_char,
) -> esgm_status {
    guard(|| {
        let ty = handles::get(t)?;
        let name = unsafe { text(name, "name") }?;
        let sort = sort_from_c(sort, "sort")?;
        let element = unsafe { optional(element_type, "element_type") }?;
        let mut ty = ty.lock();
        if ty.attribute(name).is_some() {
            return Err(Error::new(
                esgm_status::ESGM_INVALID_TYPE,
                format!("type `{}` has an attribute `{name}` already", ty.name),
            ));
        }
        let is_frame = matches!(sort, ValueSort::EntityFrame | ValueSort::EntityFrameSeq);
        match (is_frame, element) {
            (true, None) => {
                return Err(Error::new(
                    esgm_status::ESGM_INVALID_TYPE,
                    format!(
                        "attribute `{name}` of type `{}`: a frame names the type of its \
                         elements (element_type, e.g. \"Blob\")",
                        ty.name
                    ),
                ));
            }
            (false, Some(e)) => {
                return Err(Error::new(
                    esgm_status::ESGM_INVALID_TYPE,
                    format!(
                        "attribute `{name}` of type `{}` is {sort}, which has no element type \
                         (`{e}`); pass NULL",
                        ty.name
                    ),
                ));
            }
            _ => {}
        }
        ty.attributes.push(Attr {
            name: name.to_owned(),
            sort,
            element_type: element.map(str::to_owned),
        });
        Ok(())
    })
}

/// Frees a type's handle (a registered type stays registered). Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_free(t: esgm_type_t) -> esgm_status {
    guard(|| handles::free(t))
}

/// The type's name, valid while its handle lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_name(t: esgm_type_t, out: *mut esgm_str_t) -> esgm_status {
    guard(|| {
        let ty = handles::get(t)?;
        // The name's bytes stay where they are while the handle lives: attributes
        // added later never move it.
        let name = esgm_str_t::of(&ty.lock().name);
        unsafe { put(out, "out", name) }
    })
}

/// The number of attributes of `t`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_attribute_count(t: esgm_type_t, out: *mut usize) -> esgm_status {
    guard(|| {
        let n = handles::get(t)?.lock().attributes.len();
        unsafe { put(out, "out", n) }
    })
}

/// The attribute at `index` (in declaration order) of `t`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_type_attribute(
    t: esgm_type_t,
    index: usize,
    out: *mut esgm_attribute_t,
) -> esgm_status {
    guard(|| {
        let ty = handles::get(t)?;
        let ty = ty.lock();
        let a = ty.attributes.get(index).ok_or_else(|| {
            Error::new(
                esgm_status::ESGM_OUT_OF_RANGE,
                format!(
                    "type `{}` has {} attributes; there is no index {index}",
                    ty.name,
                    ty.attributes.len()
                ),
            )
        })?;
        let attribute = esgm_attribute_t {
            name: esgm_str_t::of(&a.name),
            sort: sort_to_c(a.sort),
            element_type: esgm_str_t::of(a.element_type.as_deref().unwrap_or("")),
        };
        unsafe { put(out, "out", attribute) }
    })
}

/// The type of `t` (a copy).
pub(crate) fn type_of(t: esgm_type_t) -> Result<EntityStructureType> {
    Ok(handles::get(t)?.lock().clone())
}

/// Registers `t` under `type_name` (E1; the IDL's form, where the registered name may
/// differ from the type's own). `ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS` when the
/// name is taken by another definition.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_entity_structure_type(
    esgm: esgm_t,
    type_name: *const c_char,
    t: esgm_type_t,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(type_name, "type_name") }?;
        let ty = type_of(t)?;
        on!(&*rt, e => e.create_entity_structure_type(name, ty)).map_err(|e| Error::of(&e))
    })
}

/// Registers `t` under its own name.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_type(esgm: esgm_t, t: esgm_type_t) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let ty = type_of(t)?;
        on!(&*rt, e => e.create_type(ty)).map_err(|e| Error::of(&e))
    })
}

/// Removes the type `type_name` (existing trajectories keep theirs).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_destroy_entity_structure_type(
    esgm: esgm_t,
    type_name: *const c_char,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(type_name, "type_name") }?;
        on!(&*rt, e => e.destroy_entity_structure_type(name)).map_err(|e| Error::of(&e))
    })
}

/// The registered type `type_name`, as a new handle to free.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_entity_structure_type(
    esgm: esgm_t,
    type_name: *const c_char,
    out: *mut esgm_type_t,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(type_name, "type_name") }?;
        crate::strings::writable(out, "out")?;
        let ty = on!(&*rt, e => e.get_entity_structure_type(name)).map_err(|e| Error::of(&e))?;
        let h = handles::insert(Mutex::new(ty));
        unsafe { put(out, "out", h) }
    })
}

/// The registered types' names as a JSON array, copied into `buf` as
/// `esgm_stats_json` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_entity_structure_type_names_json(
    esgm: esgm_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let names = on!(&*rt, e => e.entity_structure_type_names()).map_err(|e| Error::of(&e))?;
        let text = crate::connect::json(&names)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}
