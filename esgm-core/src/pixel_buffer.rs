//! Image pixels written where they will be read.
//!
//! A camera renders each frame into a buffer; if the buffer is the trajectory's own
//! shared memory (a loan from its publisher), the frame is never copied again: the
//! transport sends the loan, and every reader in every process reads the camera's
//! pixels in place. A trajectory that can offer such buffers has an
//! [`OctetsAllocator`] (the shared-memory runtime installs one on each image
//! trajectory it publishes); elsewhere the buffer is on the heap. A sensor that asks
//! for its buffer this way ([`crate::SensorInterface::get_current_value_with`]) writes
//! its frames in place on every runtime, with the same code.

use std::fmt;

use crate::library::Image;
use crate::octets::Octets;

/// Where a writable image buffer lives until it becomes the pixels of a structure.
pub trait PixelStorage: Send {
    /// The pixels, to write the frame into (initialised: zeroed or written before).
    fn pixels_mut(&mut self) -> &mut [u8];
    /// The finished pixels, as the octet sequence of an `Image` structure.
    fn freeze(self: Box<Self>) -> Octets;
}

/// A writable buffer for one image's pixels: on the heap, or in a trajectory's shared
/// memory ([`OctetsAllocator`]). Fill [`PixelBuffer::pixels_mut`], then put
/// [`PixelBuffer::into_octets`] into the structure's `image_data`.
pub struct PixelBuffer {
    storage: Box<dyn PixelStorage>,
}

impl fmt::Debug for PixelBuffer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("PixelBuffer")
    }
}

/// The heap storage: a vector.
struct Heap(Vec<u8>);

impl PixelStorage for Heap {
    fn pixels_mut(&mut self) -> &mut [u8] {
        &mut self.0
    }
    fn freeze(self: Box<Self>) -> Octets {
        Octets::from(self.0)
    }
}

impl PixelBuffer {
    /// A zeroed buffer of `len` bytes on the heap.
    pub fn heap(len: usize) -> Self {
        Self { storage: Box::new(Heap(vec![0; len])) }
    }

    /// A heap buffer for a `width` × `height` image of `format`; `None` for an unknown
    /// format or a size that does not fit in memory.
    pub fn heap_image(width: i64, height: i64, format: i64) -> Option<Self> {
        let bpp = Image::bytes_per_pixel(format)?;
        // A negative side is an impossible size: `None`, as documented.
        let w = usize::try_from(width).ok()?;
        let h = usize::try_from(height).ok()?;
        Some(Self::heap(w.checked_mul(h)?.checked_mul(bpp)?))
    }

    /// A buffer in `storage` (a transport's shared memory).
    pub fn new(storage: Box<dyn PixelStorage>) -> Self {
        Self { storage }
    }

    /// The pixels to write.
    pub fn pixels_mut(&mut self) -> &mut [u8] {
        self.storage.pixels_mut()
    }

    /// The finished pixels, for the structure's `image_data`.
    pub fn into_octets(self) -> Octets {
        self.storage.freeze()
    }
}

/// Hands out image buffers in a trajectory's own memory (see the module docs).
pub trait OctetsAllocator: Send + Sync + fmt::Debug {
    /// A buffer for a `width` × `height` image of `format`, or `None` if this
    /// allocator cannot give one now (no room, an unknown format): the caller then
    /// uses the heap ([`PixelBuffer::heap_image`]).
    fn image(&self, width: i64, height: i64, format: i64) -> Option<PixelBuffer>;
}

/// The allocator of a trajectory without shared memory: every buffer on the heap.
#[derive(Debug, Clone, Copy, Default)]
pub struct HeapAllocator;

impl OctetsAllocator for HeapAllocator {
    fn image(&self, width: i64, height: i64, format: i64) -> Option<PixelBuffer> {
        PixelBuffer::heap_image(width, height, format)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heap_buffers_become_the_octets_written() {
        let mut b = HeapAllocator.image(2, 2, Image::FORMAT_RGB8).unwrap();
        assert_eq!(b.pixels_mut().len(), 12);
        b.pixels_mut()[11] = 7;
        let o = b.into_octets();
        assert_eq!((o.len(), o[11]), (12, 7));
        assert!(HeapAllocator.image(2, 2, 99).is_none(), "unknown format");
        assert!(HeapAllocator.image(-1, 2, Image::FORMAT_RGB8).is_none());
    }
}
