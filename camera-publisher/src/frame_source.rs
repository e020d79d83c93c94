//! The camera abstraction: something that yields an RGB8 frame for a time.

use esgm_core::Time;
use esgm_core::library::Image;

/// The largest width or height a frame source accepts, in pixels.
///
/// Far above any camera, and small enough that a frame's pixel count fits in a `u32`
/// (what a blob detector labels with) and its byte length in any `usize`.
pub const MAX_DIMENSION: u32 = 16_384;

/// Bytes per pixel of the frames every source produces ([`Image::FORMAT_RGB8`]).
pub const RGB8_BYTES_PER_PIXEL: usize = 3;

/// A frame could not be written into the caller's buffer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The buffer is not exactly one frame long: size it with
    /// [`FrameSource::frame_len`].
    #[error("frame buffer holds {actual} bytes, a frame needs exactly {expected}")]
    WrongBufferLength {
        /// The length a frame needs (`width × height × 3`).
        expected: usize,
        /// The length given.
        actual: usize,
    },
}

/// A camera: an RGB8 frame of fixed size for any time.
///
/// The size never changes over a source's life, so a publisher can size its
/// shared-memory samples once.
pub trait FrameSource {
    /// Frame width in pixels.
    fn width(&self) -> u32;

    /// Frame height in pixels.
    fn height(&self) -> u32;

    /// Length in bytes of one frame: `width × height × 3`.
    fn frame_len(&self) -> usize {
        self.width() as usize * self.height() as usize * RGB8_BYTES_PER_PIXEL
    }

    /// Writes the frame for time `t` into `out` as packed RGB8, row-major, without
    /// allocating: the way a camera fills a shared-memory sample in place.
    fn render_into(&self, t: Time, out: &mut [u8]) -> Result<(), RenderError>;

    /// The frame for time `t` as an [`Image`] (allocates the pixels, or shares them when
    /// the source already holds the frame).
    fn frame(&self, t: Time) -> Image;
}

/// Checks that `out` is exactly one frame of `source` long.
pub(crate) fn check_buffer(expected: usize, out: &[u8]) -> Result<(), RenderError> {
    if out.len() == expected {
        Ok(())
    } else {
        Err(RenderError::WrongBufferLength { expected, actual: out.len() })
    }
}
