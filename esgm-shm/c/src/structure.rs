//! Building an entity structure (M3) to add: a name, a valid and a create time, and
//! attribute/value pairs set one by one with typed setters; frames nest (a frame is
//! built the same way and handed to its parent). An image's pixels come from a loan
//! ([`crate::image`]) and are handed over as they are.
//!
//! A structure is checked against its trajectory's type when it is added (M4): a
//! missing attribute or one of the wrong sort is `ESGM_INVALID_TYPE`, naming the
//! attribute, its expected and its actual sort. Setting an attribute again replaces
//! its value.

use std::ffi::c_char;

use esgm_shm::prelude::*;
use parking_lot::Mutex;

use crate::handles::{self, handle};
use crate::image::esgm_image_loan_t;
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{put, slice, text, texts};

/// A structure being built.
#[derive(Debug, Default)]
pub(crate) struct Builder {
    pub(crate) frame: EntityFrame,
    pub(crate) valid_time: Time,
    pub(crate) create_time: Time,
}

impl Builder {
    /// The finished structure.
    pub(crate) fn into_structure(self) -> EntityStructure {
        EntityStructure::from_frame(self.frame, self.valid_time, self.create_time)
    }
}

/// An entity structure (or a nested frame) being built: add it to a trajectory,
/// return it from a unit or sensor, or set it as a frame of another. Each of those
/// takes it: its handle is freed then, whether the call succeeded or not.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_structure_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_structure_t => Mutex<Builder>);

/// A 3-D vector (`ESGM_SORT_VEC`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_vec3_t {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

/// A 2-D point (`ESGM_SORT_POS2`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_pos2_t {
    /// x coordinate.
    pub x: f64,
    /// y coordinate.
    pub y: f64,
}

/// A horizontal world position in metres (`ESGM_SORT_POSITION`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_position_t {
    /// Metres north of the origin.
    pub north: f64,
    /// Metres east of the origin.
    pub east: f64,
}

/// An orientation in radians (`ESGM_SORT_ROTATION`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_rotation_t {
    /// About the forward axis.
    pub roll: f64,
    /// About the lateral axis.
    pub pitch: f64,
    /// About the vertical axis (heading).
    pub yaw: f64,
}

/// A position with an altitude (`ESGM_SORT_POSITION_ALTITUDE`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_position_altitude_t {
    /// Horizontal position.
    pub position: esgm_position_t,
    /// Altitude in metres.
    pub altitude: f64,
}

/// A full pose (`ESGM_SORT_POSITION_ALTITUDE_ROTATION`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_pose_t {
    /// Horizontal position.
    pub position: esgm_position_t,
    /// Altitude in metres.
    pub altitude: f64,
    /// Orientation.
    pub rotation: esgm_rotation_t,
}

impl From<esgm_vec3_t> for Vec3 {
    fn from(v: esgm_vec3_t) -> Self {
        Vec3 { x: v.x, y: v.y, z: v.z }
    }
}
impl From<Vec3> for esgm_vec3_t {
    fn from(v: Vec3) -> Self {
        Self { x: v.x, y: v.y, z: v.z }
    }
}
impl From<esgm_pos2_t> for Pos2 {
    fn from(p: esgm_pos2_t) -> Self {
        Pos2 { x: p.x, y: p.y }
    }
}
impl From<Pos2> for esgm_pos2_t {
    fn from(p: Pos2) -> Self {
        Self { x: p.x, y: p.y }
    }
}
impl From<esgm_position_t> for Position {
    fn from(p: esgm_position_t) -> Self {
        Position { north: p.north, east: p.east }
    }
}
impl From<Position> for esgm_position_t {
    fn from(p: Position) -> Self {
        Self { north: p.north, east: p.east }
    }
}
impl From<esgm_rotation_t> for Rotation {
    fn from(r: esgm_rotation_t) -> Self {
        Rotation { roll: r.roll, pitch: r.pitch, yaw: r.yaw }
    }
}
impl From<Rotation> for esgm_rotation_t {
    fn from(r: Rotation) -> Self {
        Self { roll: r.roll, pitch: r.pitch, yaw: r.yaw }
    }
}

/// A new structure `name`, valid at `valid_time` and created at `create_time`
/// (nanoseconds; `esgm_now()` for now), without attributes yet.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_new(
    name: *const c_char,
    valid_time: i64,
    create_time: i64,
    out: *mut esgm_structure_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        crate::strings::writable(out, "out")?;
        let b = Builder { frame: EntityFrame::new(name), valid_time, create_time };
        let h = handles::insert(Mutex::new(b));
        unsafe { put(out, "out", h) }
    })
}

/// A new frame `name` to nest in a structure (`esgm_structure_set_frame`,
/// `esgm_structure_push_frame`): a structure whose times are not used.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_frame_new(name: *const c_char, out: *mut esgm_structure_t) -> esgm_status {
    esgm_structure_new(name, 0, 0, out)
}

/// Frees a structure not handed to esgm. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_free(s: esgm_structure_t) -> esgm_status {
    guard(|| handles::free(s))
}

/// Renames the structure.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_name(s: esgm_structure_t, name: *const c_char) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        handles::get(s)?.lock().frame.name = name.to_owned();
        Ok(())
    })
}

/// Sets its valid and create times (nanoseconds).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_times(
    s: esgm_structure_t,
    valid_time: i64,
    create_time: i64,
) -> esgm_status {
    guard(|| {
        let b = handles::get(s)?;
        let mut b = b.lock();
        b.valid_time = valid_time;
        b.create_time = create_time;
        Ok(())
    })
}

/// Sets attribute `attribute` of `s` to `value`.
fn set(s: esgm_structure_t, attribute: *const c_char, value: Result<Value>) -> esgm_status {
    guard(|| {
        let name = unsafe { text(attribute, "attribute") }?;
        let value = value?;
        handles::with(s, |b| {
            b.lock().frame.set(name, value);
            Ok(())
        })
    })
}

/// Sets a `Long` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_long(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: i64,
) -> esgm_status {
    set(s, attribute, Ok(Value::Long(value)))
}

/// Sets a `Double` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_double(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: f64,
) -> esgm_status {
    set(s, attribute, Ok(Value::Double(value)))
}

/// Sets a `Bool` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_bool(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: bool,
) -> esgm_status {
    set(s, attribute, Ok(Value::Bool(value)))
}

/// Sets a `Time` attribute (nanoseconds).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_time(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: i64,
) -> esgm_status {
    set(s, attribute, Ok(Value::Time(value)))
}

/// Sets an `Altitude` attribute (metres).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_altitude(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: f64,
) -> esgm_status {
    set(s, attribute, Ok(Value::Altitude(value)))
}

/// Sets a `String` attribute (UTF-8, copied).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_string(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: *const c_char,
) -> esgm_status {
    let v = unsafe { text(value, "value") }.map(|t| Value::String(t.to_owned()));
    set(s, attribute, v)
}

/// Sets a `Symbol` attribute (UTF-8, copied).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_symbol(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: *const c_char,
) -> esgm_status {
    let v = unsafe { text(value, "value") }.map(|t| Value::Symbol(t.to_owned()));
    set(s, attribute, v)
}

/// Sets an `OctetSeq` attribute to a copy of `len` bytes at `data`. An image to be
/// read in place by other processes is written into a loan instead
/// (`esgm_structure_set_image`), which is not copied.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_octets(
    s: esgm_structure_t,
    attribute: *const c_char,
    data: *const u8,
    len: usize,
) -> esgm_status {
    let v = unsafe { slice(data, len, "data") }.map(|b| Value::OctetSeq(Octets::from(b)));
    set(s, attribute, v)
}

/// Sets an `OctetSeq` attribute to the pixels written into `loan`, which it takes:
/// the pixels are handed over where they are (the trajectory's shared memory), never
/// copied; the loan's handle is freed.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_image(
    s: esgm_structure_t,
    attribute: *const c_char,
    loan: esgm_image_loan_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(attribute, "attribute") }?;
        let b = handles::get(s)?;
        let octets = crate::image::take(loan)?;
        b.lock().frame.set(name, Value::OctetSeq(octets));
        Ok(())
    })
}

/// Sets a `LongSeq` attribute to a copy of `n` integers at `values`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_long_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
    values: *const i64,
    n: usize,
) -> esgm_status {
    let v = unsafe { slice(values, n, "values") }.map(|v| Value::LongSeq(v.to_vec()));
    set(s, attribute, v)
}

/// Sets a `DoubleSeq` attribute to a copy of `n` floats at `values`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_double_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
    values: *const f64,
    n: usize,
) -> esgm_status {
    let v = unsafe { slice(values, n, "values") }.map(|v| Value::DoubleSeq(v.to_vec()));
    set(s, attribute, v)
}

/// Sets a `SymbolSeq` attribute to copies of `n` strings at `values`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_symbol_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
    values: *const *const c_char,
    n: usize,
) -> esgm_status {
    let v = unsafe { texts(values, n, "values") }
        .map(|v| Value::SymbolSeq(v.into_iter().map(str::to_owned).collect()));
    set(s, attribute, v)
}

/// Sets a `Vec` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_vec(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_vec3_t,
) -> esgm_status {
    set(s, attribute, Ok(Value::Vec(value.into())))
}

/// Sets a `VecSeq` attribute to a copy of `n` vectors at `values`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_vec_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
    values: *const esgm_vec3_t,
    n: usize,
) -> esgm_status {
    let v = unsafe { slice(values, n, "values") }
        .map(|v| Value::VecSeq(v.iter().map(|x| Vec3::from(*x)).collect()));
    set(s, attribute, v)
}

/// Sets a `Pos2` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_pos2(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_pos2_t,
) -> esgm_status {
    set(s, attribute, Ok(Value::Pos2(value.into())))
}

/// Sets a `Pos2Seq` attribute to a copy of `n` points at `values`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_pos2_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
    values: *const esgm_pos2_t,
    n: usize,
) -> esgm_status {
    let v = unsafe { slice(values, n, "values") }
        .map(|v| Value::Pos2Seq(v.iter().map(|x| Pos2::from(*x)).collect()));
    set(s, attribute, v)
}

/// Sets a `Position` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_position(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_position_t,
) -> esgm_status {
    set(s, attribute, Ok(Value::Position(value.into())))
}

/// Sets a `Rotation` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_rotation(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_rotation_t,
) -> esgm_status {
    set(s, attribute, Ok(Value::Rotation(value.into())))
}

/// Sets a `PositionAltitude` attribute.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_position_altitude(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_position_altitude_t,
) -> esgm_status {
    let v = PositionAltitude { position: value.position.into(), altitude: value.altitude };
    set(s, attribute, Ok(Value::PositionAltitude(v)))
}

/// Sets a `PositionAltitudeRotation` attribute (a pose).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_pose(
    s: esgm_structure_t,
    attribute: *const c_char,
    value: esgm_pose_t,
) -> esgm_status {
    let v = PositionAltitudeRotation {
        position: value.position.into(),
        altitude: value.altitude,
        rotation: value.rotation.into(),
    };
    set(s, attribute, Ok(Value::PositionAltitudeRotation(v)))
}

/// Sets an attribute to no value (`NoValue`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_no_value(
    s: esgm_structure_t,
    attribute: *const c_char,
) -> esgm_status {
    set(s, attribute, Ok(Value::NoValue))
}

/// Sets an attribute of any sort from esgm's JSON form of a value (`{"Long": 5}`,
/// `{"Agg": [{"Double": 1.5}, {"String": "a"}]}`): the way to set `Agg` and
/// `Collection` values, which have no typed setter.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_json(
    s: esgm_structure_t,
    attribute: *const c_char,
    json: *const c_char,
) -> esgm_status {
    let v = unsafe { text(json, "json") }.and_then(|j| {
        serde_json::from_str::<Value>(j).map_err(|e| {
            Error::new(esgm_status::ESGM_INVALID_TYPE, format!("`{j}` is not a value: {e}"))
        })
    });
    set(s, attribute, v)
}

/// The frame `frame` holds, taking its handle (freed whether this succeeds or not).
pub(crate) fn take_frame(frame: esgm_structure_t) -> Result<EntityFrame> {
    let b = handles::take(frame)?;
    Ok(std::mem::take(&mut b.lock().frame))
}

/// Sets an `EntityFrame` attribute to `frame` (made with `esgm_frame_new`), which it
/// takes.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_frame(
    s: esgm_structure_t,
    attribute: *const c_char,
    frame: esgm_structure_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(attribute, "attribute") }?;
        let parent = handles::get(s)?;
        if frame == s {
            return Err(Error::argument("a structure cannot be a frame of itself"));
        }
        let child = take_frame(frame)?;
        parent.lock().frame.set(name, Value::EntityFrame(Box::new(child)));
        Ok(())
    })
}

/// Appends `frame` (which it takes) to the `EntityFrameSeq` attribute `attribute`,
/// which a first push creates; an attribute of another sort is `ESGM_INVALID_TYPE`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_push_frame(
    s: esgm_structure_t,
    attribute: *const c_char,
    frame: esgm_structure_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(attribute, "attribute") }?;
        let parent = handles::get(s)?;
        if frame == s {
            return Err(Error::argument("a structure cannot be a frame of itself"));
        }
        let child = take_frame(frame)?;
        let mut parent = parent.lock();
        let frames = &mut parent.frame;
        match frames.attributes.iter_mut().find(|a| a.name == name) {
            Some(a) => match &mut a.value {
                Value::EntityFrameSeq(seq) => seq.push(child),
                other => {
                    return Err(Error::new(
                        esgm_status::ESGM_INVALID_TYPE,
                        format!(
                            "attribute `{name}` is {}, not EntityFrameSeq: frames cannot be \
                             pushed to it",
                            other.sort()
                        ),
                    ));
                }
            },
            None => frames.set(name, Value::EntityFrameSeq(vec![child])),
        }
        Ok(())
    })
}

/// Sets an `EntityFrameSeq` attribute to the empty sequence (a `BlobSeq` of no blobs).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_structure_set_empty_frame_seq(
    s: esgm_structure_t,
    attribute: *const c_char,
) -> esgm_status {
    set(s, attribute, Ok(Value::EntityFrameSeq(Vec::new())))
}

/// The structure `s` holds, taking its handle (freed whether the caller succeeds or
/// not).
pub(crate) fn take(s: esgm_structure_t) -> Result<EntityStructure> {
    let b = handles::take(s)?;
    let built = std::mem::take(&mut *b.lock());
    Ok(built.into_structure())
}
