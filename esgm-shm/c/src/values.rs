//! Values as C reads and writes them, many at once: `esgm_value_t` is one attribute
//! (its name, its sort and the fields that sort uses). A sample's attributes are read
//! into an array in one call (`esgm_sample_values`); a structure is added from an
//! array in one call (`esgm_add_values`), or a builder given one
//! (`esgm_structure_set_values`). One call instead of one per attribute: the C++
//! wrapper's typed structs (`ESGM_ENTITY`) read and write this way.

use std::ffi::c_char;

use esgm_shm::prelude::*;

use crate::add::{esgm_outcome, outcome_of};
use crate::handles;
use crate::image::esgm_image_loan_t;
use crate::sample::esgm_sample_t;
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{esgm_str_t, put, slice, text};
use crate::structure::{esgm_pos2_t, esgm_pose_t, esgm_structure_t, esgm_vec3_t};
use crate::trajectory::{esgm_trajectory_t, traj};
use crate::types::{sort_from_c, sort_to_c};

/// One attribute's value, as C reads and writes it: `sort` says which fields hold it.
///
/// - `ESGM_SORT_LONG`, `ESGM_SORT_TIME`: `long_value`;
/// - `ESGM_SORT_DOUBLE`, `ESGM_SORT_ALTITUDE`: `double_value`;
/// - `ESGM_SORT_BOOL`: `bool_value`;
/// - `ESGM_SORT_STRING`, `ESGM_SORT_SYMBOL`: `text`;
/// - `ESGM_SORT_OCTET_SEQ`: `data` (bytes) and `len`; written: copied, unless `handle`
///   is an `esgm_image_loan_t`'s id, whose pixels are handed over (and the loan taken);
/// - `ESGM_SORT_LONG_SEQ`, `ESGM_SORT_DOUBLE_SEQ`: `data` (`int64_t`s or `double`s),
///   `len`;
/// - `ESGM_SORT_SYMBOL_SEQ`, `ESGM_SORT_VEC_SEQ`, `ESGM_SORT_POS2_SEQ`, `ESGM_SORT_AGG`,
///   `ESGM_SORT_COLLECTION`: read, `len` items (`esgm_sample_item`); written, `data` is
///   `len` `esgm_str_t`s, `esgm_vec3_t`s, `esgm_pos2_t`s or `esgm_value_t`s;
/// - `ESGM_SORT_ENTITY_FRAME_SEQ`: read, `len` frames (`esgm_sample_frame_at`); written,
///   `data` is `len` `esgm_structure_t`s (frames, taken);
/// - `ESGM_SORT_ENTITY_FRAME`: read, nothing here (`esgm_sample_frame`); written,
///   `handle` is an `esgm_structure_t`'s id (a frame, taken);
/// - `ESGM_SORT_VEC`: `vec`; `ESGM_SORT_POS2`: `pos2`;
/// - `ESGM_SORT_POSITION`, `ESGM_SORT_POSITION_ALTITUDE`,
///   `ESGM_SORT_POSITION_ALTITUDE_ROTATION`, `ESGM_SORT_ROTATION`: `pose`'s fields.
///
/// Read, its pointers are into the sample, valid while its handle lives.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_value_t {
    /// The attribute's name (empty for a sequence's item).
    pub name: esgm_str_t,
    /// Its sort (an `esgm_sort`).
    pub sort: i32,
    /// An integer or a time.
    pub long_value: i64,
    /// A float or an altitude.
    pub double_value: f64,
    /// A boolean.
    pub bool_value: bool,
    /// A string or a symbol.
    pub text: esgm_str_t,
    /// Bytes, numbers or items of a sequence.
    pub data: *const std::ffi::c_void,
    /// The number of bytes or items.
    pub len: usize,
    /// A vector.
    pub vec: esgm_vec3_t,
    /// A 2-D point.
    pub pos2: esgm_pos2_t,
    /// A position, altitude and rotation.
    pub pose: esgm_pose_t,
    /// Written: a frame's `esgm_structure_t` or an image's `esgm_image_loan_t` id
    /// (taken); 0 otherwise. Read: 0.
    pub handle: u64,
}

impl esgm_value_t {
    /// `value`, named `name`, lent from its sample: read where it lies (in the writer's
    /// shared memory for a sample from another process), never copied.
    pub(crate) fn of(name: &str, value: ValueRef<'_>) -> Result<Self> {
        let sort = value.sort();
        let mut v = Self {
            name: esgm_str_t::of(name),
            sort: sort_to_c(sort),
            long_value: 0,
            double_value: 0.0,
            bool_value: false,
            text: esgm_str_t::of(""),
            data: std::ptr::null(),
            len: 0,
            vec: esgm_vec3_t::default(),
            pos2: esgm_pos2_t::default(),
            pose: esgm_pose_t::default(),
            handle: 0,
        };
        match sort {
            ValueSort::Long | ValueSort::Time => v.long_value = value.as_long().unwrap_or_default(),
            ValueSort::Double | ValueSort::Altitude => {
                v.double_value = value.as_double().unwrap_or_default()
            }
            ValueSort::Bool => v.bool_value = value.as_bool().unwrap_or_default(),
            ValueSort::String | ValueSort::Symbol => {
                v.text = esgm_str_t::of(value.as_str().unwrap_or_default())
            }
            ValueSort::OctetSeq => {
                if let Some(o) = value.as_bytes() {
                    (v.data, v.len) = (o.as_ptr().cast(), o.len());
                }
            }
            ValueSort::LongSeq => {
                if let Some(x) = value.as_long_seq() {
                    let x = crate::sample::lent(x)?;
                    (v.data, v.len) = (x.as_ptr().cast(), x.len());
                }
            }
            ValueSort::DoubleSeq => {
                if let Some(x) = value.as_double_seq() {
                    let x = crate::sample::lent(x)?;
                    (v.data, v.len) = (x.as_ptr().cast(), x.len());
                }
            }
            ValueSort::SymbolSeq
            | ValueSort::VecSeq
            | ValueSort::Pos2Seq
            | ValueSort::Agg
            | ValueSort::Collection
            | ValueSort::EntityFrameSeq => v.len = value.seq_len().unwrap_or_default(),
            ValueSort::Vec => v.vec = value.as_vec3().unwrap_or_default().into(),
            ValueSort::Pos2 => v.pos2 = value.as_pos2().unwrap_or_default().into(),
            ValueSort::Position => v.pose.position = value.as_position().unwrap_or_default().into(),
            ValueSort::Rotation => v.pose.rotation = value.as_rotation().unwrap_or_default().into(),
            ValueSort::PositionAltitude => {
                let p = value.as_position_altitude().unwrap_or_default();
                v.pose.position = p.position.into();
                v.pose.altitude = p.altitude;
            }
            ValueSort::PositionAltitudeRotation => {
                let p = value.as_pose().unwrap_or_default();
                v.pose.position = p.position.into();
                v.pose.altitude = p.altitude;
                v.pose.rotation = p.rotation.into();
            }
            _ => {}
        }
        Ok(v)
    }

    /// An owned value that holds no bytes to lend (a number, a point, no value), named
    /// `name`.
    pub(crate) fn of_value(name: &str, value: &Value) -> Self {
        // Nothing is lent from a value without bytes, and numbers are never refused.
        Self::of(name, value.into()).unwrap_or_else(|_| Self::of_nothing(name))
    }

    fn of_nothing(name: &str) -> Self {
        Self {
            name: esgm_str_t::of(name),
            sort: sort_to_c(ValueSort::NoValue),
            long_value: 0,
            double_value: 0.0,
            bool_value: false,
            text: esgm_str_t::of(""),
            data: std::ptr::null(),
            len: 0,
            vec: esgm_vec3_t::default(),
            pos2: esgm_pos2_t::default(),
            pose: esgm_pose_t::default(),
            handle: 0,
        }
    }
}

/// Text lent by C as an `esgm_str_t`, checked; `what` names it in an error (made only
/// then: this runs for every attribute of every add).
fn lent_text<'a>(s: &esgm_str_t, what: impl Fn() -> String) -> Result<&'a str> {
    if s.len == 0 {
        return Ok("");
    }
    let bytes = unsafe { slice(s.ptr.cast::<u8>(), s.len, "text") }
        .map_err(|_| Error::argument(format!("`{}` is a null pointer with a length", what())))?;
    std::str::from_utf8(bytes).map_err(|e| {
        Error::argument(format!("`{}` is not UTF-8 (byte {})", what(), e.valid_up_to()))
    })
}

/// The value `v` writes (taking the handles it names), as attribute `what`.
fn value_of(v: &esgm_value_t, what: &str) -> Result<Value> {
    let sort = match usize::try_from(v.sort).ok().filter(|i| *i < 26) {
        Some(_) => sort_from_c(v.sort, "sort")?,
        None => sort_from_c(v.sort, &format!("{what}.sort"))?,
    };
    let items = |size: &str| -> Result<()> {
        if v.len > 0 && v.data.is_null() {
            return Err(Error::argument(format!("`{what}.data` is null but {size} is {}", v.len)));
        }
        Ok(())
    };
    Ok(match sort {
        ValueSort::NoValue => Value::NoValue,
        ValueSort::Long => Value::Long(v.long_value),
        ValueSort::Time => Value::Time(v.long_value),
        ValueSort::Double => Value::Double(v.double_value),
        ValueSort::Altitude => Value::Altitude(v.double_value),
        ValueSort::Bool => Value::Bool(v.bool_value),
        ValueSort::String => Value::String(lent_text(&v.text, || what.to_owned())?.to_owned()),
        ValueSort::Symbol => Value::Symbol(lent_text(&v.text, || what.to_owned())?.to_owned()),
        ValueSort::OctetSeq if v.handle != 0 => {
            Value::OctetSeq(crate::image::take(esgm_image_loan_t { id: v.handle })?)
        }
        ValueSort::OctetSeq => {
            items("len")?;
            Value::OctetSeq(Octets::from(unsafe { slice(v.data.cast::<u8>(), v.len, what) }?))
        }
        ValueSort::LongSeq => {
            items("len")?;
            Value::LongSeq(unsafe { slice(v.data.cast::<i64>(), v.len, what) }?.to_vec())
        }
        ValueSort::DoubleSeq => {
            items("len")?;
            Value::DoubleSeq(unsafe { slice(v.data.cast::<f64>(), v.len, what) }?.to_vec())
        }
        ValueSort::SymbolSeq => {
            items("len")?;
            let texts = unsafe { slice(v.data.cast::<esgm_str_t>(), v.len, what) }?;
            Value::SymbolSeq(
                texts
                    .iter()
                    .map(|t| lent_text(t, || what.to_owned()).map(str::to_owned))
                    .collect::<Result<_>>()?,
            )
        }
        ValueSort::VecSeq => {
            items("len")?;
            let vs = unsafe { slice(v.data.cast::<esgm_vec3_t>(), v.len, what) }?;
            Value::VecSeq(vs.iter().map(|x| Vec3::from(*x)).collect())
        }
        ValueSort::Pos2Seq => {
            items("len")?;
            let ps = unsafe { slice(v.data.cast::<esgm_pos2_t>(), v.len, what) }?;
            Value::Pos2Seq(ps.iter().map(|x| Pos2::from(*x)).collect())
        }
        ValueSort::Agg | ValueSort::Collection => {
            items("len")?;
            let inner = unsafe { slice(v.data.cast::<esgm_value_t>(), v.len, what) }?;
            let values = inner
                .iter()
                .enumerate()
                .map(|(i, x)| value_of(x, &format!("{what}[{i}]")))
                .collect::<Result<Vec<_>>>()?;
            if sort == ValueSort::Agg { Value::Agg(values) } else { Value::Collection(values) }
        }
        ValueSort::Vec => Value::Vec(v.vec.into()),
        ValueSort::Pos2 => Value::Pos2(v.pos2.into()),
        ValueSort::Position => Value::Position(v.pose.position.into()),
        ValueSort::Rotation => Value::Rotation(v.pose.rotation.into()),
        ValueSort::PositionAltitude => Value::PositionAltitude(PositionAltitude {
            position: v.pose.position.into(),
            altitude: v.pose.altitude,
        }),
        ValueSort::PositionAltitudeRotation => {
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: v.pose.position.into(),
                altitude: v.pose.altitude,
                rotation: v.pose.rotation.into(),
            })
        }
        ValueSort::EntityFrame => {
            Value::EntityFrame(Box::new(crate::structure::take_frame(esgm_structure_t {
                id: v.handle,
            })?))
        }
        ValueSort::EntityFrameSeq => {
            items("len")?;
            let frames = unsafe { slice(v.data.cast::<esgm_structure_t>(), v.len, what) }?;
            Value::EntityFrameSeq(
                frames.iter().map(|f| crate::structure::take_frame(*f)).collect::<Result<_>>()?,
            )
        }
        ValueSort::AnyValue | ValueSort::UnknownValue => {
            return Err(Error::argument(format!(
                "`{what}` is of sort {sort}, which is an attribute's sort, not a value's"
            )));
        }
    })
}

/// Frees the handles a value would have taken, when the call failed before it did: a
/// call that takes values takes all of them, whatever happens.
fn release(v: &esgm_value_t) {
    let Ok(sort) = sort_from_c(v.sort, "") else { return };
    match sort {
        ValueSort::EntityFrame => {
            let _gone = handles::free(esgm_structure_t { id: v.handle });
        }
        ValueSort::OctetSeq if v.handle != 0 => {
            let _gone = handles::free(esgm_image_loan_t { id: v.handle });
        }
        ValueSort::EntityFrameSeq if !v.data.is_null() => {
            if let Ok(frames) = unsafe { slice(v.data.cast::<esgm_structure_t>(), v.len, "") } {
                for f in frames {
                    let _gone = handles::free(*f);
                }
            }
        }
        ValueSort::Agg | ValueSort::Collection if !v.data.is_null() => {
            if let Ok(inner) = unsafe { slice(v.data.cast::<esgm_value_t>(), v.len, "") } {
                inner.iter().for_each(release);
            }
        }
        _ => {}
    }
}

/// The attributes `n` values at `values` write, taking their handles (all of them,
/// also when one is wrong).
pub(crate) fn attributes(values: *const esgm_value_t, n: usize) -> Result<Vec<AttributeValuePair>> {
    let values = unsafe { slice(values, n, "values") }?;
    let mut out = Vec::with_capacity(values.len());
    for (i, v) in values.iter().enumerate() {
        let made = lent_text(&v.name, || format!("values[{i}].name")).and_then(|name| {
            Ok(AttributeValuePair { name: name.to_owned(), value: value_of(v, name)? })
        });
        match made {
            Ok(pair) => out.push(pair),
            Err(e) => {
                values[i + 1..].iter().for_each(release);
                return Err(e);
            }
        }
    }
    Ok(out)
}

/// Sets `n` attributes of the structure `s` from `values` at once (frames and loans in
/// them are taken).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_values(
    s: esgm_structure_t,
    values: *const esgm_value_t,
    n: usize,
) -> esgm_status {
    guard(|| {
        let b = handles::get(s);
        let attributes = attributes(values, n)?;
        let b = b?;
        let mut b = b.lock();
        for a in attributes {
            b.frame.set(a.name, a.value);
        }
        Ok(())
    })
}

/// T4 in one call: adds a structure `name`, valid at `valid_time` and created at
/// `create_time`, with the `n` attributes `values` (frames and loans in them taken),
/// to `t`; a policy violation drops it (`ESGM_OUTCOME_DROPPED`). `outcome` may be null.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_add_values(
    t: esgm_trajectory_t,
    name: *const c_char,
    valid_time: i64,
    create_time: i64,
    values: *const esgm_value_t,
    n: usize,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| added(t, name, valid_time, create_time, values, n, false, outcome))
}

/// `esgm_add_values`, waiting for the writer's gate: `ESGM_POLICY_VIOLATION` if it
/// refused the structure.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_add_values_blocking(
    t: esgm_trajectory_t,
    name: *const c_char,
    valid_time: i64,
    create_time: i64,
    values: *const esgm_value_t,
    n: usize,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| added(t, name, valid_time, create_time, values, n, true, outcome))
}

#[allow(clippy::too_many_arguments, reason = "the C function's arguments")]
fn added(
    t: esgm_trajectory_t,
    name: *const c_char,
    valid_time: i64,
    create_time: i64,
    values: *const esgm_value_t,
    n: usize,
    blocking: bool,
    outcome: *mut i32,
) -> Result<()> {
    let attributes = attributes(values, n)?;
    let name = unsafe { text(name, "name") }?;
    let found = traj(t)?;
    let mut es = EntityStructure::new(name, valid_time, create_time);
    es.attributes = attributes;
    let o = if blocking { found.handle.add_blocking(es) } else { found.handle.add(es) }
        .map_err(|e| Error::of(&e))?;
    if outcome.is_null() {
        return Ok(());
    }
    let o: esgm_outcome = outcome_of(&o);
    unsafe { put(outcome, "outcome", o as i32) }
}

/// Reads every attribute of the sample (or frame) `s` at once into `out`, which has
/// room for `capacity` values (read-only views, valid while `s` lives); `count` gets
/// the number of attributes (more than `capacity` when some did not fit).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_values(
    s: esgm_sample_t,
    out: *mut esgm_value_t,
    capacity: usize,
    count: *mut usize,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(count, "count")?;
        if capacity > 0 {
            crate::strings::writable(out, "out")?;
        }
        crate::handles::with(s, |v| {
            let (_, attrs) = v.frame();
            let n = attrs.len();
            for (i, (name, value)) in attrs.take(capacity).enumerate() {
                let read = esgm_value_t::of(name, value)?;
                // SAFETY: `out` has room for `capacity` values (checked not null and
                // aligned above), and `i < capacity`.
                unsafe { out.add(i).write(read) };
            }
            unsafe { put(count, "count", n) }
        })
    })
}
