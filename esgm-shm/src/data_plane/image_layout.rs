//! Where an image's pixels go in a loaned sample, and how big the loan is.
//!
//! The codec lays an in-place `Image` out as: envelope, a fixed region for the entity
//! name, the pixels at [`IMAGE_PIXELS_OFFSET`], then the attribute pairs and the root
//! ([`esgm_core::codec::encode_image_into`], whose docs say why the name must come
//! first). The pixels' offset does not depend on the name, the times or the size, so a
//! camera fills them before it has decided any of those, and
//! [`crate::ImageLoan::send`] only completes the structure around them: no template,
//! no copy, any name up to [`IMAGE_NAME_MAX`] bytes.
//!
//! A loan is sized `pixel_len + IMAGE_OVERHEAD_MAX` (a bound, at most a few dozen
//! bytes over; the header carries the exact archive length and the rest is zeroed).

use esgm_core::codec::{CodecError, IMAGE_OVERHEAD_MAX, IMAGE_PIXELS_MAX};
use esgm_core::library::Image;

use crate::data_plane::payload::BLOCK_LEN;

pub use esgm_core::codec::{IMAGE_NAME_MAX, IMAGE_PIXELS_OFFSET};

// Pixels start on a block boundary, so a camera's aligned writes stay aligned.
const _: () = assert!(IMAGE_PIXELS_OFFSET % BLOCK_LEN == 0);

/// An image could not be loaned or laid out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageError {
    /// The pixel format is not one whose bytes per pixel are known
    /// ([`Image::bytes_per_pixel`]); use a known format.
    #[error("unknown image format {format}")]
    UnknownFormat {
        /// The rejected format.
        format: i64,
    },
    /// Width or height is negative, or the image is larger than a sample can hold;
    /// check the sizes.
    #[error("invalid image size {width}×{height}")]
    InvalidSize {
        /// The requested width.
        width: i64,
        /// The requested height.
        height: i64,
    },
    /// A frame handed to [`crate::ImageLoan::write_pixels`] is not the loan's pixel
    /// length; pass exactly one frame of the loaned size and format.
    #[error("frame of {found} bytes for an image of {expected} pixel bytes")]
    FrameLength {
        /// The loan's pixel length.
        expected: usize,
        /// The frame's length.
        found: usize,
    },
    /// The image structure could not be encoded.
    #[error(transparent)]
    Codec(#[from] CodecError),
}

/// Bytes of pixels for an image of this size and format.
pub fn pixel_len(width: i64, height: i64, format: i64) -> Result<usize, ImageError> {
    let bpp = Image::bytes_per_pixel(format).ok_or(ImageError::UnknownFormat { format })?;
    let invalid = || ImageError::InvalidSize { width, height };
    let w = usize::try_from(width).map_err(|_| invalid())?;
    let h = usize::try_from(height).map_err(|_| invalid())?;
    w.checked_mul(h)
        .and_then(|n| n.checked_mul(bpp))
        .filter(|n| *n <= IMAGE_PIXELS_MAX)
        .ok_or_else(invalid)
}

/// Payload bytes to loan for an image of `pixel_len` bytes (at most
/// [`IMAGE_PIXELS_MAX`], as [`pixel_len`] returns).
pub fn image_loan_len(pixel_len: usize) -> usize {
    pixel_len + IMAGE_OVERHEAD_MAX
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data_plane::payload::{Block16, blocks_for};
    use esgm_core::codec::{self, encode_image_into};
    use esgm_core::{Entity, Octets};

    #[test]
    fn a_loan_holds_the_image_for_any_accepted_name() {
        for name in ["", "cam", "a_camera_name_longer_than_inline", &"ü".repeat(115)] {
            assert!(name.len() <= IMAGE_NAME_MAX);
            for (w, h, f) in [(0, 0, Image::FORMAT_RGB8), (4, 3, Image::FORMAT_RGB8), (5, 1, 1)] {
                let len = pixel_len(w, h, f).unwrap();
                // Laid out the way a loan is: whole 16-byte blocks.
                let mut blocks = vec![Block16::default(); blocks_for(image_loan_len(len))];
                let buf: &mut [u8] = bytemuck::cast_slice_mut(&mut blocks);
                for (i, b) in buf[IMAGE_PIXELS_OFFSET..][..len].iter_mut().enumerate() {
                    *b = i as u8;
                }
                let n = encode_image_into(name, 1000, 2000, w, h, f, len, buf).unwrap();
                let es = codec::decode(codec::access(&buf[..n]).unwrap()).unwrap();
                let pixels: Vec<u8> = (0..len).map(|i| i as u8).collect();
                let image =
                    Image { width: w, height: h, format: f, image_data: Octets::from(pixels) };
                assert_eq!(es, image.to_structure(name, 1000, 2000));
            }
        }
    }

    #[test]
    fn sizes_are_checked() {
        assert!(matches!(pixel_len(2, 2, 99), Err(ImageError::UnknownFormat { format: 99 })));
        assert!(matches!(pixel_len(-1, 2, 0), Err(ImageError::InvalidSize { .. })));
        assert!(matches!(pixel_len(i64::MAX, i64::MAX, 0), Err(ImageError::InvalidSize { .. })));
        assert!(matches!(pixel_len(1 << 20, 1 << 20, 0), Err(ImageError::InvalidSize { .. })));
        assert_eq!(pixel_len(640, 480, Image::FORMAT_RGB8).unwrap(), 921_600);
    }
}
