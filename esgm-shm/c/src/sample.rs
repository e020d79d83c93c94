//! Reading a sample (M3): its name and times, and its attributes by name or by index,
//! typed, through nested frames and sequences.
//!
//! Nothing is decoded or copied to read (P7): a sample from another process is the
//! archive its writer put in shared memory, checked once when it arrived, and every
//! read here is a lookup in it, in place; a string, a sequence or an image's pixels is
//! lent as a pointer into it, valid while the caller holds a handle on the sample (or
//! a frame's of it), which keeps the writer's chunk mapped and borrowed whatever the
//! writer does meanwhile (exits, crashes, resets the trajectory). The Rust path reads
//! the same way, through `esgm_core::ValueRef`: C takes no step it does not.
//!
//! A missing attribute is `ESGM_NO_SUCH_ATTRIBUTE` (the message lists those there
//! are); one of another sort `ESGM_INVALID_TYPE` (it names both sorts).

use std::ffi::c_char;
use std::sync::Arc;

use esgm_shm::prelude::*;

use crate::handles::{self, handle};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{copy_out, esgm_str_t, put, text};
use crate::types::sort_to_c;
use crate::values::esgm_value_t;

/// One step from a structure into a frame nested in it.
#[derive(Debug, Clone, Copy)]
enum Step {
    /// The `EntityFrame` attribute at this index.
    Frame(usize),
    /// Item `.1` of the `EntityFrameSeq` attribute at index `.0`.
    Item(usize, usize),
}

/// A sample, or a frame nested in one: the sample (shared, never copied) and the way
/// down to the frame.
#[derive(Debug, Clone)]
pub(crate) struct View {
    sample: Sample,
    path: Vec<Step>,
}

impl View {
    /// The whole sample.
    pub(crate) fn of(sample: Sample) -> Self {
        Self { sample, path: Vec::new() }
    }

    /// The frame's name and attributes, read in place.
    pub(crate) fn frame(&self) -> (&str, Attributes<'_>) {
        let mut name = self.sample.structure.name();
        let mut attributes = self.sample.structure.attributes();
        for step in &self.path {
            // Every step was checked when the view was made, and a sample never
            // changes: each resolves.
            let frame = match *step {
                Step::Frame(i) => attributes.clone().nth(i).and_then(|(_, v)| v.as_frame()),
                Step::Item(i, j) => {
                    attributes.clone().nth(i).and_then(|(_, v)| v.as_frames()?.get(j))
                }
            };
            let Some(f) = frame else { return (name, Attributes::none()) };
            name = f.name();
            attributes = f.attributes();
        }
        (name, attributes)
    }

    /// The attribute `name` and its index.
    fn find(&self, name: &str) -> Result<(usize, ValueRef<'_>)> {
        let (frame, attributes) = self.frame();
        attributes
            .clone()
            .enumerate()
            .find(|(_, (n, _))| *n == name)
            .map(|(i, (_, v))| (i, v))
            .ok_or_else(|| {
                let there: Vec<&str> = attributes.map(|(n, _)| n).collect();
                Error::new(
                    esgm_status::ESGM_NO_SUCH_ATTRIBUTE,
                    format!(
                        "`{frame}` has no attribute `{name}`; it has {}",
                        if there.is_empty() { "none".to_owned() } else { there.join(", ") }
                    ),
                )
            })
    }

    /// The attribute at `index`, with its name.
    fn at(&self, index: usize) -> Result<(&str, ValueRef<'_>)> {
        let (frame, attributes) = self.frame();
        let count = attributes.len();
        attributes.clone().nth(index).ok_or_else(|| {
            Error::new(
                esgm_status::ESGM_OUT_OF_RANGE,
                format!("`{frame}` has {count} attributes; there is no index {index}"),
            )
        })
    }

    /// The view one step further down.
    fn down(&self, step: Step) -> Self {
        let mut path = self.path.clone();
        path.push(step);
        Self { sample: self.sample.clone(), path }
    }
}

/// A sample (an entity structure as stored, with its add and query time), or a frame
/// nested in one. Everything read from it is valid while it lives.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_sample_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_sample_t => View);

/// The samples a query returned, in valid-time order.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_sample_list_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_sample_list_t => Vec<Sample>);

/// A sample's name and times.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_sample_info_t {
    /// The structure's (or frame's) name.
    pub name: esgm_str_t,
    /// When it is valid (ns).
    pub valid_time: i64,
    /// When it was created (ns).
    pub create_time: i64,
    /// When it entered the trajectory (ns).
    pub add_time: i64,
    /// When the query it answers was asked (ns; a subscriber's: the add time).
    pub query_time: i64,
    /// Its number of attributes.
    pub attribute_count: usize,
}

/// The view `s` names.
pub(crate) fn view(s: esgm_sample_t) -> Result<Arc<View>> {
    handles::get(s)
}

/// A handle on `sample`, written to `out`.
pub(crate) fn give(sample: Sample, out: *mut esgm_sample_t) -> Result<()> {
    crate::strings::writable(out, "out")?;
    let h: esgm_sample_t = handles::insert(View::of(sample));
    unsafe { put(out, "out", h) }
}

/// Its name and times.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_info(s: esgm_sample_t, out: *mut esgm_sample_info_t) -> esgm_status {
    guard(|| {
        let info = handles::with(s, |v| {
            let (name, attributes) = v.frame();
            Ok(esgm_sample_info_t {
                name: esgm_str_t::of(name),
                valid_time: v.sample.structure.valid_time(),
                create_time: v.sample.structure.create_time(),
                add_time: v.sample.add_time,
                query_time: v.sample.query_time,
                attribute_count: attributes.len(),
            })
        })?;
        // The name lives in the sample, which the handle keeps.
        unsafe { put(out, "out", info) }
    })
}

/// The attribute `attribute` as a value of whatever sort it is.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_value(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut esgm_value_t,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let name = unsafe { text(attribute, "attribute") }?;
            let (_, value) = v.find(name)?;
            let read = esgm_value_t::of(name, value)?;
            unsafe { put(out, "out", read) }
        })
    })
}

/// The attribute at `index` (0 to its count − 1, in the structure's order), with its
/// name.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_value_at(
    s: esgm_sample_t,
    index: usize,
    out: *mut esgm_value_t,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let (name, value) = v.at(index)?;
            let read = esgm_value_t::of(name, value)?;
            unsafe { put(out, "out", read) }
        })
    })
}

/// Item `index` of the sequence attribute `attribute` (a symbol, vector, point or
/// value of a `SymbolSeq`, `VecSeq`, `Pos2Seq`, `Agg` or `Collection`; an integer or
/// float of a `LongSeq` or `DoubleSeq`). A frame sequence's items are frames:
/// `esgm_sample_frame_at`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_item(
    s: esgm_sample_t,
    attribute: *const c_char,
    index: usize,
    out: *mut esgm_value_t,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let name = unsafe { text(attribute, "attribute") }?;
            let (_, value) = v.find(name)?;
            let sort = value.sort();
            let len = match sort {
                ValueSort::EntityFrameSeq => {
                    return Err(Error::new(
                        esgm_status::ESGM_INVALID_TYPE,
                        format!(
                            "attribute `{name}` is EntityFrameSeq: read its frames with esgm_sample_frame_at"
                        ),
                    ));
                }
                ValueSort::OctetSeq => None,
                _ => value.seq_len(),
            };
            let Some(len) = len else {
                return Err(Error::new(
                    esgm_status::ESGM_INVALID_TYPE,
                    format!("attribute `{name}` is {sort}, not a sequence"),
                ));
            };
            if index >= len {
                return Err(Error::new(
                    esgm_status::ESGM_OUT_OF_RANGE,
                    format!("attribute `{name}` has {len} items; there is no index {index}"),
                ));
            }
            let item = match sort {
                ValueSort::SymbolSeq => {
                    let mut read = esgm_value_t::of_value("", &Value::NoValue);
                    read.sort = sort_to_c(ValueSort::Symbol);
                    read.text = esgm_str_t::of(value.symbol_at(index).unwrap_or_default());
                    read
                }
                ValueSort::Agg | ValueSort::Collection => match value.elements() {
                    Some(mut items) => match items.nth(index) {
                        Some(item) => esgm_value_t::of("", item)?,
                        None => esgm_value_t::of_value("", &Value::NoValue),
                    },
                    None => esgm_value_t::of_value("", &Value::NoValue),
                },
                ValueSort::VecSeq => esgm_value_t::of_value(
                    "",
                    &value.vec3_at(index).map_or(Value::NoValue, Value::Vec),
                ),
                ValueSort::Pos2Seq => esgm_value_t::of_value(
                    "",
                    &value.pos2_at(index).map_or(Value::NoValue, Value::Pos2),
                ),
                ValueSort::LongSeq => esgm_value_t::of_value(
                    "",
                    &value
                        .as_long_seq()
                        .and_then(|x| x.get(index).copied())
                        .map_or(Value::NoValue, Value::Long),
                ),
                ValueSort::DoubleSeq => esgm_value_t::of_value(
                    "",
                    &value
                        .as_double_seq()
                        .and_then(|x| x.get(index).copied())
                        .map_or(Value::NoValue, Value::Double),
                ),
                _ => esgm_value_t::of_value("", &Value::NoValue),
            };
            unsafe { put(out, "out", item) }
        })
    })
}

/// The value of `attribute`, which must be of `sort` (a wrong one is named).
fn typed<'a>(v: &'a View, attribute: *const c_char, sort: ValueSort) -> Result<ValueRef<'a>> {
    let name = unsafe { text(attribute, "attribute") }?;
    let (_, value) = v.find(name)?;
    if value.sort() != sort {
        let (frame, _) = v.frame();
        return Err(Error::new(
            esgm_status::ESGM_INVALID_TYPE,
            format!("attribute `{name}` of `{frame}` is {}, not {sort}", value.sort()),
        ));
    }
    Ok(value)
}

/// A number read from a value `typed` checked: its sort has one.
fn checked<T>(read: Option<T>) -> Result<T> {
    read.ok_or_else(|| {
        Error::new(esgm_status::ESGM_INVALID_TYPE, "the attribute has no such value")
    })
}

/// Reads a `Long` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_long(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut i64,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let x = checked(typed(v, attribute, ValueSort::Long)?.as_long())?;
            unsafe { put(out, "out", x) }
        })
    })
}

/// Reads a `Double` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_double(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut f64,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let x = checked(typed(v, attribute, ValueSort::Double)?.as_double())?;
            unsafe { put(out, "out", x) }
        })
    })
}

/// Reads a `Bool` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_bool(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut bool,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let x = checked(typed(v, attribute, ValueSort::Bool)?.as_bool())?;
            unsafe { put(out, "out", x) }
        })
    })
}

/// Reads a `Time` attribute (ns).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_time(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut i64,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let x = checked(typed(v, attribute, ValueSort::Time)?.as_long())?;
            unsafe { put(out, "out", x) }
        })
    })
}

/// Reads a `String` attribute, lent while the sample lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_string(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut esgm_str_t,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let x = checked(typed(v, attribute, ValueSort::String)?.as_str())?;
            unsafe { put(out, "out", esgm_str_t::of(x)) }
        })
    })
}

/// Reads an `OctetSeq` attribute (an image's pixels): `len` bytes at `data`, in the
/// writer's shared memory where it was written there, valid while the sample lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_octets(
    s: esgm_sample_t,
    attribute: *const c_char,
    data: *mut *const u8,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(data, "data")?;
        crate::strings::writable(len, "len")?;
        handles::with(s, |v| {
            let o = checked(typed(v, attribute, ValueSort::OctetSeq)?.as_bytes())?;
            unsafe {
                put(data, "data", o.as_ptr())?;
                put(len, "len", o.len())
            }
        })
    })
}

/// Writes true to `out` if the `OctetSeq` attribute's bytes are read in place in
/// another process's shared memory (a held image), false if on this process's heap.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_octets_are_shared(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut bool,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let shared = typed(v, attribute, ValueSort::OctetSeq)?.octets_are_shared();
            unsafe { put(out, "out", shared) }
        })
    })
}

/// Reads a `LongSeq` attribute: `len` integers at `data`, valid while the sample lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_long_seq(
    s: esgm_sample_t,
    attribute: *const c_char,
    data: *mut *const i64,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(data, "data")?;
        crate::strings::writable(len, "len")?;
        handles::with(s, |v| {
            let x = lent(checked(typed(v, attribute, ValueSort::LongSeq)?.as_long_seq())?)?;
            unsafe {
                put(data, "data", x.as_ptr())?;
                put(len, "len", x.len())
            }
        })
    })
}

/// Reads a `DoubleSeq` attribute: `len` floats at `data`, valid while the sample lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_get_double_seq(
    s: esgm_sample_t,
    attribute: *const c_char,
    data: *mut *const f64,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(data, "data")?;
        crate::strings::writable(len, "len")?;
        handles::with(s, |v| {
            let x = lent(checked(typed(v, attribute, ValueSort::DoubleSeq)?.as_double_seq())?)?;
            unsafe {
                put(data, "data", x.as_ptr())?;
                put(len, "len", x.len())
            }
        })
    })
}

/// Numbers lent where they lie in the sample; numbers that had to be converted (an
/// archive read on a big-endian host) cannot be lent past this call.
pub(crate) fn lent<T: Clone>(numbers: std::borrow::Cow<'_, [T]>) -> Result<&[T]> {
    match numbers {
        std::borrow::Cow::Borrowed(x) => Ok(x),
        std::borrow::Cow::Owned(_) => Err(Error::new(
            esgm_status::ESGM_INVALID_TYPE,
            "this host's byte order differs from the archive's: read the items one by one \
             (esgm_sample_item)",
        )),
    }
}

/// The `EntityFrame` attribute `attribute`, as a new handle (to free) that reads like
/// a sample.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_frame(
    s: esgm_sample_t,
    attribute: *const c_char,
    out: *mut esgm_sample_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let v = view(s)?;
        let name = unsafe { text(attribute, "attribute") }?;
        let (index, value) = v.find(name)?;
        if value.as_frame().is_none() {
            return Err(Error::new(
                esgm_status::ESGM_INVALID_TYPE,
                format!("attribute `{name}` is {}, not EntityFrame", value.sort()),
            ));
        }
        let h: esgm_sample_t = handles::insert(v.down(Step::Frame(index)));
        unsafe { put(out, "out", h) }
    })
}

/// Frame `index` of the `EntityFrameSeq` attribute `attribute` (its count is the
/// value's `len`), as a new handle (to free) that reads like a sample.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_frame_at(
    s: esgm_sample_t,
    attribute: *const c_char,
    index: usize,
    out: *mut esgm_sample_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let v = view(s)?;
        let name = unsafe { text(attribute, "attribute") }?;
        let (at, value) = v.find(name)?;
        let Some(seq) = value.as_frames() else {
            return Err(Error::new(
                esgm_status::ESGM_INVALID_TYPE,
                format!("attribute `{name}` is {}, not EntityFrameSeq", value.sort()),
            ));
        };
        if index >= seq.len() {
            return Err(Error::new(
                esgm_status::ESGM_OUT_OF_RANGE,
                format!("attribute `{name}` has {} frames; there is no index {index}", seq.len()),
            ));
        }
        let h: esgm_sample_t = handles::insert(v.down(Step::Item(at, index)));
        unsafe { put(out, "out", h) }
    })
}

/// The sample (or frame) as JSON, for printing: name, times and attributes (an image's
/// bytes as its length only), copied into `buf` as `esgm_stats_json` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_to_json(
    s: esgm_sample_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        handles::with(s, |v| {
            let (name, attributes) = v.frame();
            let mut fields = serde_json::Map::new();
            for (attribute, value) in attributes {
                // For printing: values converted (an image to its length).
                fields.insert(attribute.to_owned(), json_value(&value.to_value()));
            }
            let text = serde_json::json!({
                "name": name,
                "valid_time": v.sample.structure.valid_time(),
                "create_time": v.sample.structure.create_time(),
                "add_time": v.sample.add_time,
                "attributes": fields,
            })
            .to_string();
            unsafe { copy_out(&text, buf, capacity, len) }
        })
    })
}

/// A value as plain JSON (numbers, strings, arrays, objects); bytes as their count.
fn json_value(value: &Value) -> serde_json::Value {
    use serde_json::json;
    match value {
        Value::NoValue => serde_json::Value::Null,
        Value::Long(x) | Value::Time(x) => json!(x),
        Value::Double(x) | Value::Altitude(x) => json!(x),
        Value::Bool(b) => json!(b),
        Value::String(s) | Value::Symbol(s) => json!(s),
        Value::OctetSeq(o) => json!({ "octets": o.len() }),
        Value::LongSeq(x) => json!(x),
        Value::DoubleSeq(x) => json!(x),
        Value::SymbolSeq(x) => json!(x),
        Value::Agg(x) | Value::Collection(x) => x.iter().map(json_value).collect(),
        Value::EntityFrame(f) => frame_json(f),
        Value::EntityFrameSeq(seq) => seq.iter().map(frame_json).collect(),
        other => serde_json::to_value(other).unwrap_or(serde_json::Value::Null),
    }
}

fn frame_json(f: &EntityFrame) -> serde_json::Value {
    let mut fields = serde_json::Map::new();
    fields.insert("name".into(), serde_json::json!(f.name));
    for a in &f.attributes {
        fields.insert(a.name.clone(), json_value(&a.value));
    }
    serde_json::Value::Object(fields)
}

/// Another handle on the same sample (or frame), to free separately: keep an input of
/// a unit's callback beyond the call this way.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_clone(s: esgm_sample_t, out: *mut esgm_sample_t) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let v = view(s)?;
        let h: esgm_sample_t = handles::insert_arc(v);
        unsafe { put(out, "out", h) }
    })
}

/// Frees a sample's handle; its memory (an image's shared memory chunk) goes when no
/// handle or process holds it. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_free(s: esgm_sample_t) -> esgm_status {
    guard(|| handles::free(s))
}

/// The number of samples in `list`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_list_len(list: esgm_sample_list_t, out: *mut usize) -> esgm_status {
    guard(|| {
        let n = handles::get(list)?.len();
        unsafe { put(out, "out", n) }
    })
}

/// Sample `index` of `list`, as a new handle to free.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_list_get(
    list: esgm_sample_list_t,
    index: usize,
    out: *mut esgm_sample_t,
) -> esgm_status {
    guard(|| {
        let l = handles::get(list)?;
        let sample = l.get(index).cloned().ok_or_else(|| {
            Error::new(
                esgm_status::ESGM_OUT_OF_RANGE,
                format!("the list has {} samples; there is no index {index}", l.len()),
            )
        })?;
        give(sample, out)
    })
}

/// Frees a list (samples taken from it stay). Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sample_list_free(list: esgm_sample_list_t) -> esgm_status {
    guard(|| handles::free(list))
}
