//! Attribute values between Python and esgm, guided by the trajectory's type: a Python
//! `int` is a `Long` where the type says `Long` and a `Time` where it says `Time`; a
//! nested frame is a `dict`, a frame sequence a `list` of them. A value that does not fit
//! raises `TypeError` naming the attribute, before anything is added.
//!
//! Octets (images) going out are numpy arrays over esgm's own memory (the writer's
//! shared-memory chunk): no copy, read-only, and they keep that memory alive as long as
//! they live ([`octets_array`]).

use esgm_core::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Vec3,
};
use esgm_core::{
    Attr, AttributeValuePair, EntityFrame, EntityStructureType, FrameRef, Octets, Value, ValueRef,
    ValueSort,
};
use numpy::ndarray::ArrayView1;
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyKeyError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{
    PyBool, PyByteArray, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple,
};

/// How nested frame types are found.
pub type Types<'a> = &'a dyn Fn(&str) -> Option<EntityStructureType>;

fn wrong(attr: &str, expected: &str, got: &Bound<'_, PyAny>) -> PyErr {
    let got = got.get_type().name().map_or_else(|_| "?".to_owned(), |n| n.to_string());
    PyTypeError::new_err(format!("attribute `{attr}` takes {expected}, not {got}"))
}

fn float(attr: &str, v: &Bound<'_, PyAny>) -> PyResult<f64> {
    if v.is_instance_of::<PyBool>()
        || !(v.is_instance_of::<PyFloat>() || v.is_instance_of::<PyInt>())
    {
        return Err(wrong(attr, "a float", v));
    }
    v.extract::<f64>()
}

fn int(attr: &str, v: &Bound<'_, PyAny>) -> PyResult<i64> {
    if v.is_instance_of::<PyBool>() || !v.is_instance_of::<PyInt>() {
        return Err(wrong(attr, "an int", v));
    }
    v.extract::<i64>().map_err(|_| {
        PyTypeError::new_err(format!("attribute `{attr}`: the int does not fit 64 bits"))
    })
}

fn string(attr: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    if !v.is_instance_of::<PyString>() {
        return Err(wrong(attr, "a str", v));
    }
    v.extract::<String>()
}

fn list<'py>(attr: &str, v: &Bound<'py, PyAny>) -> PyResult<Vec<Bound<'py, PyAny>>> {
    if !(v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>()) {
        return Err(wrong(attr, "a list", v));
    }
    v.try_iter()?.collect()
}

/// An image buffer's pixels as they are ([`crate::images`]); bytes, a bytearray or a
/// C-contiguous uint8 numpy array, copied.
fn octets(attr: &str, v: &Bound<'_, PyAny>) -> PyResult<Octets> {
    if let Ok(buffer) = v.cast::<crate::images::ImageBuffer>() {
        return crate::images::ImageBuffer::take(buffer);
    }
    if let Ok(b) = v.cast::<PyBytes>() {
        return Ok(Octets::new(b.as_bytes().to_vec()));
    }
    if let Ok(b) = v.cast::<PyByteArray>() {
        return Ok(Octets::new(b.to_vec()));
    }
    if let Ok(a) = v.cast::<numpy::PyUntypedArray>() {
        let contiguous = a.is_c_contiguous();
        let Ok(typed) = v.cast::<numpy::PyArrayDyn<u8>>() else {
            return Err(PyTypeError::new_err(format!(
                "attribute `{attr}` takes a uint8 array, not one of dtype {}",
                a.dtype()
            )));
        };
        if !contiguous {
            return Err(PyTypeError::new_err(format!(
                "attribute `{attr}`: the array is not contiguous (use numpy.ascontiguousarray)"
            )));
        }
        let read = typed.try_readonly()?;
        return Ok(Octets::new(read.as_slice()?.to_vec()));
    }
    Err(wrong(attr, "bytes, a bytearray or a uint8 numpy array", v))
}

fn xyz(attr: &str, v: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f64>> {
    let items = list(attr, v)?;
    if items.len() != n {
        return Err(PyTypeError::new_err(format!(
            "attribute `{attr}` takes {n} floats, not {}",
            items.len()
        )));
    }
    items.iter().map(|x| float(attr, x)).collect()
}

/// The frame a `dict` describes, of type `ty` (its name under the key `name`).
pub fn frame(
    d: &Bound<'_, PyAny>,
    attr: &str,
    ty: &EntityStructureType,
    types: Types<'_>,
) -> PyResult<EntityFrame> {
    let d = d.cast::<PyDict>().map_err(|_| wrong(attr, "a dict", d))?;
    let name = match d.get_item("name")? {
        Some(n) => string("name", &n)?,
        None => String::new(),
    };
    let mut f = EntityFrame::new(name);
    f.attributes = attributes(d, ty, types, &["name"])?;
    Ok(f)
}

/// The attributes of `d` for type `ty`; `skip` lists keys that are not attributes.
pub fn attributes(
    d: &Bound<'_, PyDict>,
    ty: &EntityStructureType,
    types: Types<'_>,
    skip: &[&str],
) -> PyResult<Vec<AttributeValuePair>> {
    let mut out = Vec::with_capacity(d.len());
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        if skip.contains(&key.as_str()) {
            continue;
        }
        let Some(attr) = ty.attribute(&key) else {
            let known: Vec<&str> = ty.attributes.iter().map(|a| a.name.as_str()).collect();
            return Err(PyKeyError::new_err(format!(
                "type `{}` has no attribute `{key}`; it has {}",
                ty.name,
                known.join(", ")
            )));
        };
        out.push(AttributeValuePair { name: key, value: to_value(&v, attr, types)? });
    }
    Ok(out)
}

/// A Python value as the value `attr` holds.
pub fn to_value(v: &Bound<'_, PyAny>, attr: &Attr, types: Types<'_>) -> PyResult<Value> {
    let name = attr.name.as_str();
    let element = || -> PyResult<EntityStructureType> {
        let e = attr.element_type.as_deref().unwrap_or_default();
        types(e).ok_or_else(|| PyTypeError::new_err(format!("attribute `{name}`: no type `{e}`")))
    };
    Ok(match attr.sort {
        ValueSort::Long => Value::Long(int(name, v)?),
        ValueSort::Time => Value::Time(int(name, v)?),
        ValueSort::Double => Value::Double(float(name, v)?),
        ValueSort::Altitude => Value::Altitude(float(name, v)?),
        ValueSort::Bool => {
            if !v.is_instance_of::<PyBool>() {
                return Err(wrong(name, "a bool", v));
            }
            Value::Bool(v.extract()?)
        }
        ValueSort::String => Value::String(string(name, v)?),
        ValueSort::Symbol => Value::Symbol(string(name, v)?),
        ValueSort::OctetSeq => Value::OctetSeq(octets(name, v)?),
        ValueSort::LongSeq => {
            Value::LongSeq(list(name, v)?.iter().map(|x| int(name, x)).collect::<PyResult<_>>()?)
        }
        ValueSort::DoubleSeq => Value::DoubleSeq(
            list(name, v)?.iter().map(|x| float(name, x)).collect::<PyResult<_>>()?,
        ),
        ValueSort::SymbolSeq => Value::SymbolSeq(
            list(name, v)?.iter().map(|x| string(name, x)).collect::<PyResult<_>>()?,
        ),
        ValueSort::Vec => {
            let p = xyz(name, v, 3)?;
            Value::Vec(Vec3 { x: p[0], y: p[1], z: p[2] })
        }
        ValueSort::Pos2 => {
            let p = xyz(name, v, 2)?;
            Value::Pos2(Pos2 { x: p[0], y: p[1] })
        }
        ValueSort::VecSeq => Value::VecSeq(
            list(name, v)?
                .iter()
                .map(|p| xyz(name, p, 3).map(|p| Vec3 { x: p[0], y: p[1], z: p[2] }))
                .collect::<PyResult<_>>()?,
        ),
        ValueSort::Pos2Seq => Value::Pos2Seq(
            list(name, v)?
                .iter()
                .map(|p| xyz(name, p, 2).map(|p| Pos2 { x: p[0], y: p[1] }))
                .collect::<PyResult<_>>()?,
        ),
        ValueSort::Position => {
            let p = xyz(name, v, 2)?;
            Value::Position(Position { north: p[0], east: p[1] })
        }
        ValueSort::Rotation => {
            let r = xyz(name, v, 3)?;
            Value::Rotation(Rotation { roll: r[0], pitch: r[1], yaw: r[2] })
        }
        ValueSort::PositionAltitude => {
            let p = xyz(name, v, 3)?;
            let position = Position { north: p[0], east: p[1] };
            Value::PositionAltitude(PositionAltitude { position, altitude: p[2] })
        }
        ValueSort::PositionAltitudeRotation => {
            let p = xyz(name, v, 6)?;
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: Position { north: p[0], east: p[1] },
                altitude: p[2],
                rotation: Rotation { roll: p[3], pitch: p[4], yaw: p[5] },
            })
        }
        ValueSort::EntityFrame => Value::EntityFrame(Box::new(frame(v, name, &element()?, types)?)),
        ValueSort::EntityFrameSeq => {
            let ty = element()?;
            Value::EntityFrameSeq(
                list(name, v)?
                    .iter()
                    .map(|f| frame(f, name, &ty, types))
                    .collect::<PyResult<_>>()?,
            )
        }
        // Values of any sort, whose sort a Python value does not say.
        other => {
            return Err(PyTypeError::new_err(format!(
                "attribute `{name}` is of sort {other:?}, whose values have no one Python form; give the type a definite sort"
            )));
        }
    })
}

/// Keeps esgm's memory of octets alive for the numpy arrays that view it.
#[pyclass(frozen, module = "esgm")]
#[derive(Debug)]
pub struct OctetsOwner {
    octets: Octets,
}

/// A read-only numpy array over `octets`, without a copy: its base keeps them alive.
pub fn octets_array<'py>(py: Python<'py>, octets: &Octets) -> PyResult<Bound<'py, PyAny>> {
    let owner = Bound::new(py, OctetsOwner { octets: octets.clone() })?;
    let bytes: &[u8] = owner.get().octets.as_ref();
    let view = ArrayView1::from(bytes);
    // SAFETY: the array views the bytes of `owner.octets`, which `owner` (the array's
    // base) keeps alive and never changes: octets are immutable once made, and the
    // array is made read-only below before any Python code can see it.
    let array = unsafe { PyArray1::<u8>::borrow_from_array(&view, owner.clone().into_any()) };
    let flags = PyDict::new(py);
    flags.set_item("write", false)?;
    array.call_method("setflags", (), Some(&flags))?;
    Ok(array.into_any())
}

/// A value as Python: numbers, strings, lists, dicts for frames, and octets as
/// zero-copy read-only numpy arrays. Read in place: a sample from another process is
/// converted from its archive in shared memory, field by field, and its pixels are
/// not copied (the array's base holds the memory they lie in).
pub fn from_value<'py>(py: Python<'py>, v: ValueRef<'_>) -> PyResult<Bound<'py, PyAny>> {
    let tuple = |xs: &[f64]| PyTuple::new(py, xs).map(Bound::into_any);
    Ok(match v.sort() {
        ValueSort::Long | ValueSort::Time => v.as_long().into_pyobject(py)?.into_any(),
        ValueSort::Double | ValueSort::Altitude => v.as_double().into_pyobject(py)?.into_any(),
        ValueSort::Bool => v.as_bool().into_pyobject(py)?.to_owned().into_any(),
        ValueSort::String | ValueSort::Symbol => {
            PyString::new(py, v.as_str().unwrap_or_default()).into_any()
        }
        ValueSort::OctetSeq => match v.as_octets() {
            Some(o) => octets_array(py, &o)?,
            None => py.None().into_bound(py),
        },
        ValueSort::LongSeq => {
            PyList::new(py, v.as_long_seq().unwrap_or_default().iter())?.into_any()
        }
        ValueSort::DoubleSeq => {
            PyList::new(py, v.as_double_seq().unwrap_or_default().iter())?.into_any()
        }
        ValueSort::SymbolSeq => PyList::new(py, v.symbols().unwrap_or_default())?.into_any(),
        ValueSort::Vec => {
            let p = v.as_vec3().unwrap_or_default();
            tuple(&[p.x, p.y, p.z])?
        }
        ValueSort::Pos2 => {
            let p = v.as_pos2().unwrap_or_default();
            tuple(&[p.x, p.y])?
        }
        ValueSort::VecSeq => {
            let n = v.seq_len().unwrap_or_default();
            let items = (0..n)
                .filter_map(|i| v.vec3_at(i))
                .map(|p| tuple(&[p.x, p.y, p.z]))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        ValueSort::Pos2Seq => {
            let n = v.seq_len().unwrap_or_default();
            let items = (0..n)
                .filter_map(|i| v.pos2_at(i))
                .map(|p| tuple(&[p.x, p.y]))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        ValueSort::Position => {
            let p = v.as_position().unwrap_or_default();
            tuple(&[p.north, p.east])?
        }
        ValueSort::Rotation => {
            let r = v.as_rotation().unwrap_or_default();
            tuple(&[r.roll, r.pitch, r.yaw])?
        }
        ValueSort::PositionAltitude => {
            let p = v.as_position_altitude().unwrap_or_default();
            tuple(&[p.position.north, p.position.east, p.altitude])?
        }
        ValueSort::PositionAltitudeRotation => {
            let p = v.as_pose().unwrap_or_default();
            tuple(&[
                p.position.north,
                p.position.east,
                p.altitude,
                p.rotation.roll,
                p.rotation.pitch,
                p.rotation.yaw,
            ])?
        }
        ValueSort::Agg | ValueSort::Collection => {
            let items = match v.elements() {
                Some(items) => items.map(|x| from_value(py, x)).collect::<PyResult<Vec<_>>>()?,
                None => Vec::new(),
            };
            PyList::new(py, items)?.into_any()
        }
        ValueSort::EntityFrame => match v.as_frame() {
            Some(f) => frame_dict(py, f)?.into_any(),
            None => py.None().into_bound(py),
        },
        ValueSort::EntityFrameSeq => {
            let items = match v.as_frames() {
                Some(fs) => fs.iter().map(|f| frame_dict(py, f)).collect::<PyResult<Vec<_>>>()?,
                None => Vec::new(),
            };
            PyList::new(py, items)?.into_any()
        }
        _ => py.None().into_bound(py),
    })
}

fn frame_dict<'py>(py: Python<'py>, f: FrameRef<'_>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", f.name())?;
    for (name, value) in f.attributes() {
        d.set_item(name, from_value(py, value)?)?;
    }
    Ok(d)
}
