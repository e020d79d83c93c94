//! Writing an image without a copy: `trajectory.image_buffer(width, height)` lends a
//! buffer of the trajectory's own memory (its shared memory when other processes read
//! it), whose pixels are a writable numpy array; adding it (`"image_data": buffer`)
//! hands those pixels to the trajectory as they are.
//!
//! ```python
//! with images.image_buffer(640, 480) as frame:
//!     frame[:] = camera.read()
//! images.create_at_now("camera", {"width": 640, "height": 480, "format": 0, "image_data": frame_buffer})
//! ```
//!
//! After the add the array is read-only (its memory is the sample's now); the buffer
//! keeps that memory alive as long as the array lives.

use std::sync::Mutex;

use esgm_core::{InProcessTrajectory, Octets, PixelBuffer};
use numpy::PyArray1;
use numpy::ndarray::ArrayViewMut1;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyWeakrefReference};

/// Where the pixels live.
#[derive(Debug)]
enum Pixels {
    /// Lent by the trajectory (its shared memory): handed over as they are.
    Lent(PixelBuffer),
    /// On the heap (an in-process trajectory): copied once when added, and kept here
    /// for the arrays that view them.
    Heap(Box<[u8]>),
    /// Added: the sample's memory, kept for the arrays that view it.
    Added(#[allow(dead_code, reason = "kept alive for the arrays that view it")] Octets),
    /// Added from the heap: the bytes the arrays view, kept (the sample has a copy).
    AddedHeap(#[allow(dead_code, reason = "kept alive for the arrays that view it")] Box<[u8]>),
}

/// A buffer of a trajectory's memory for one image's pixels.
///
/// Its array's base is the buffer (so the memory outlives every view of it); the
/// buffer holds that array only weakly, else the two would form a cycle that Python's
/// collector cannot see through a native class, and every frame would leak (found by
/// the `python-image` benchmark: one frame of resident memory per add).
#[pyclass(frozen, module = "esgm")]
#[derive(Debug)]
pub struct ImageBuffer {
    pixels: Mutex<Pixels>,
    shape: Vec<usize>,
    array: Mutex<Option<Py<PyWeakrefReference>>>,
}

impl ImageBuffer {
    /// A buffer for a `width × height` image of `format` in `trajectory`'s memory.
    pub fn new(t: &InProcessTrajectory, width: i64, height: i64, format: i64) -> PyResult<Self> {
        let bpp = esgm_core::library::Image::bytes_per_pixel(format)
            .ok_or_else(|| PyValueError::new_err(format!("unknown image format {format}")))?;
        let bad = || PyValueError::new_err(format!("an image of {width} × {height} cannot be"));
        let (w, h) = (
            usize::try_from(width).map_err(|_| bad())?,
            usize::try_from(height).map_err(|_| bad())?,
        );
        let len = w.checked_mul(h).and_then(|n| n.checked_mul(bpp)).ok_or_else(bad)?;
        let shared = t.with_store(|s| s.octets_allocator()).ok().flatten();
        let pixels = match shared.and_then(|a| a.image(width, height, format)) {
            Some(lent) => Pixels::Lent(lent),
            None => Pixels::Heap(vec![0_u8; len].into_boxed_slice()),
        };
        let shape = if bpp == 1 { vec![h, w] } else { vec![h, w, bpp] };
        Ok(Self { pixels: Mutex::new(pixels), shape, array: Mutex::new(None) })
    }

    /// The pixels as octets for an add: lent ones as they are, heap ones copied once.
    pub fn take(slf: &Bound<'_, Self>) -> PyResult<Octets> {
        let me = slf.get();
        let mut pixels =
            me.pixels.lock().map_err(|_| PyRuntimeError::new_err("a poisoned buffer"))?;
        let octets = match std::mem::replace(&mut *pixels, Pixels::Added(Octets::default())) {
            Pixels::Lent(buffer) => buffer.into_octets(),
            Pixels::Heap(bytes) => {
                let octets = Octets::new(bytes.to_vec());
                // The arrays keep viewing the heap bytes, which stay here.
                *pixels = Pixels::AddedHeap(bytes);
                return Ok(octets);
            }
            Pixels::Added(_) | Pixels::AddedHeap(_) => {
                return Err(PyRuntimeError::new_err("this image buffer was already added"));
            }
        };
        *pixels = Pixels::Added(octets.clone());
        drop(pixels);
        // The pixels are the sample's now: whoever holds the array may read them only.
        if let Some(array) = Self::live_array(slf)? {
            let flags = PyDict::new(slf.py());
            flags.set_item("write", false)?;
            array.call_method("setflags", (), Some(&flags))?;
        }
        Ok(octets)
    }

    /// The array last made over the pixels, if someone still holds it.
    fn live_array<'py>(slf: &Bound<'py, Self>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let array =
            slf.get().array.lock().map_err(|_| PyRuntimeError::new_err("a poisoned buffer"))?;
        Ok(array.as_ref().and_then(|weak| weak.bind(slf.py()).upgrade()))
    }
}

#[pymethods]
impl ImageBuffer {
    /// The pixels, a writable numpy array `(height, width[, 3])` over the buffer.
    #[getter]
    fn array<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let me = slf.get();
        if let Some(a) = Self::live_array(slf)? {
            return Ok(a);
        }
        let mut pixels =
            me.pixels.lock().map_err(|_| PyRuntimeError::new_err("a poisoned buffer"))?;
        let bytes: &mut [u8] = match &mut *pixels {
            Pixels::Lent(b) => b.pixels_mut(),
            Pixels::Heap(b) => b,
            Pixels::Added(_) | Pixels::AddedHeap(_) => {
                return Err(PyRuntimeError::new_err("this image buffer was already added"));
            }
        };
        let view = ArrayViewMut1::from(bytes);
        // SAFETY: the array views memory this buffer owns (a loan of shared memory, or
        // its heap bytes), which stays where it is while the buffer lives: a loan is
        // handed to the sample as it is, the heap bytes are never freed before the
        // buffer; and the buffer is the array's base, so it lives as long as the array.
        let flat = unsafe { PyArray1::<u8>::borrow_from_array(&view, slf.clone().into_any()) };
        drop(pixels);
        let shaped = flat.call_method1("reshape", (me.shape.clone(),))?;
        *me.array.lock().map_err(|_| PyRuntimeError::new_err("a poisoned buffer"))? =
            Some(PyWeakrefReference::new(&shaped)?.unbind());
        Ok(shaped)
    }

    fn __enter__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        Self::array(slf)
    }

    fn __exit__(
        &self,
        _a: &Bound<'_, PyAny>,
        _b: &Bound<'_, PyAny>,
        _c: &Bound<'_, PyAny>,
    ) -> bool {
        false
    }
}
