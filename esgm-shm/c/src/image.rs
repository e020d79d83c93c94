//! Image loans: pixels written once, by their producer, where every reader reads them
//! (P1). A producer asks a trajectory it writes for a loan of its shared memory
//! (`esgm_trajectory_image_loan`; a sensor asks its context,
//! `esgm_sensor_image_loan`), renders or DMA-copies a frame into the loan's pixels, and
//! sets the loan as the structure's `image_data` (`esgm_structure_set_image`), which
//! hands the pixels over where they are. A loan dropped without being added
//! (`esgm_image_loan_free`) goes back to the trajectory's pool.
//!
//! Where the trajectory offers no shared memory (an in-process ESGM, a trajectory this
//! process does not write), the loan is on the heap, and the same code works.

use esgm_shm::prelude::*;
use parking_lot::Mutex;

use crate::handles::{self, handle};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::put;

/// A loan and the size of its image.
#[derive(Debug)]
pub(crate) struct Loan {
    buffer: Option<PixelBuffer>,
    /// Where the pixels are: a trajectory's shared memory, or the heap.
    in_shared_memory: bool,
}

/// A writable buffer for one image's pixels, in the trajectory's shared memory:
/// write the frame into `esgm_image_loan_pixels`, then hand it to a structure with
/// `esgm_structure_set_image` (or free it unused).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_image_loan_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_image_loan_t => Mutex<Loan>);

/// The image formats of `esgm_trajectory_image_loan`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_image_format {
    /// 8-bit red, green, blue per pixel (3 bytes).
    ESGM_IMAGE_RGB8 = 0,
    /// 8-bit grey per pixel (1 byte).
    ESGM_IMAGE_MONO8 = 1,
}

/// A loan of `width` × `height` pixels of `format` from `allocator` (its shared
/// memory), or from the heap when it has none to give.
pub(crate) fn lend(
    allocator: Option<&dyn OctetsAllocator>,
    width: i64,
    height: i64,
    format: i64,
) -> Result<esgm_image_loan_t> {
    let bytes_per_pixel = library::Image::bytes_per_pixel(format).ok_or_else(|| {
        Error::argument(format!(
            "image format {format} is neither ESGM_IMAGE_RGB8 (0) nor ESGM_IMAGE_MONO8 (1)"
        ))
    })?;
    let size = usize::try_from(width)
        .ok()
        .zip(usize::try_from(height).ok())
        .and_then(|(w, h)| w.checked_mul(h)?.checked_mul(bytes_per_pixel));
    if size.is_none() || width == 0 || height == 0 {
        return Err(Error::argument(format!("an image of {width} × {height} pixels cannot be")));
    }
    let lent = allocator.and_then(|a| a.image(width, height, format));
    let in_shared_memory = lent.is_some();
    let buffer = match lent {
        Some(b) => b,
        None => PixelBuffer::heap_image(width, height, format).ok_or_else(|| {
            Error::new(
                esgm_status::ESGM_LIMIT_REACHED,
                format!("no memory for an image of {width} × {height}"),
            )
        })?,
    };
    Ok(handles::insert(Mutex::new(Loan { buffer: Some(buffer), in_shared_memory })))
}

/// The writable pixels of `loan`: `len` bytes at `data` (row by row, `width` ×
/// bytes per pixel each), valid until the loan is added or freed.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_image_loan_pixels(
    loan: esgm_image_loan_t,
    data: *mut *mut u8,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(data, "data")?;
        crate::strings::writable(len, "len")?;
        let l = handles::get(loan)?;
        let mut l = l.lock();
        let buffer = l
            .buffer
            .as_mut()
            .ok_or_else(|| Error::argument("this image loan was added already"))?;
        let pixels = buffer.pixels_mut();
        // The pixels stay where they are while the loan lives: a shared-memory chunk,
        // or a heap buffer the loan owns and never resizes.
        let (ptr, n) = (pixels.as_mut_ptr(), pixels.len());
        unsafe {
            put(data, "data", ptr)?;
            put(len, "len", n)
        }
    })
}

/// Writes true to `out` if the loan's pixels are in the trajectory's shared memory
/// (other processes will read them in place), false if on the heap.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_image_loan_is_shared(
    loan: esgm_image_loan_t,
    out: *mut bool,
) -> esgm_status {
    guard(|| {
        let shared = handles::get(loan)?.lock().in_shared_memory;
        unsafe { put(out, "out", shared) }
    })
}

/// Gives an unused loan back. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_image_loan_free(loan: esgm_image_loan_t) -> esgm_status {
    guard(|| handles::free(loan))
}

/// The finished pixels of `loan`, taking its handle.
pub(crate) fn take(loan: esgm_image_loan_t) -> Result<Octets> {
    let l = handles::take(loan)?;
    let buffer = l.lock().buffer.take();
    buffer
        .map(PixelBuffer::into_octets)
        .ok_or_else(|| Error::argument("this image loan was added already"))
}
