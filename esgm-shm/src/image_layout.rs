//! Laying out an `Image` entity structure so that a camera writes its pixels once,
//! straight into loaned shared memory, and every reader sees an ordinary, validated
//! `Image` structure (attributes `width`, `height`, `format`, `image_data`, as
//! [`esgm_core::library::Image`] declares them).
//!
//! # How (for now): a verified template
//! An archive's bytes depend on the image's name, size and format and on its two times
//! — but not on the pixel values. So the publisher encodes, once per (name, width,
//! height, format), a *template*: the image with all-zero pixels and two probe times,
//! through the ordinary codec. It then finds, through the archived view the codec
//! returns, where the pixel bytes and the two time fields lie. For each frame it copies
//! only the bytes around the pixels (a few hundred) into the loan, lets the camera fill
//! the pixel range, and at send time writes the two times into their fields.
//!
//! This uses only `esgm_core::codec`'s public API; the one assumption beyond it (an
//! archived `i64` is 8 little-endian bytes) is checked when the template is built, by
//! stamping other times into a copy and reading them back through validated
//! [`codec::access`]. If the check ever fails the publisher refuses with
//! [`ImageError::LayoutUnsupported`] instead of sending a wrong structure.
//!
//! Cost: building a template is one heap encode of a zero image (once per size or name
//! change); each frame costs two small copies and two 8-byte writes.
//!
//! Limitation: the pixel range's place depends on the name (rkyv writes the name's bytes
//! before the pixels), so the template is built for the name the publisher expects
//! (the last one sent). Sending under another name is correct but slow for that frame
//! (see `ImageLoan::send`).
//!
//! # Proposed codec entry point (to replace the template)
//! With one function in `esgm-core/src/codec.rs` the name limitation and the template
//! disappear: put the pixels *first*, right after the envelope, where their place does
//! not depend on anything else, and serialize the rest after them.
//!
//! ```text
//! /// Offset of the pixels in a buffer laid out by [`encode_image_into`].
//! pub const IMAGE_PIXELS_OFFSET: usize = ENVELOPE_LEN;
//!
//! /// Completes an `Image` entity structure around `pixel_len` pixel bytes that the caller
//! /// already wrote at `out[IMAGE_PIXELS_OFFSET..][..pixel_len]` (they are neither read nor
//! /// written): writes the envelope before them and the rest of the archive (name, times,
//! /// width, height, format, the `image_data` vector pointing back at the pixels) after
//! /// them. Returns the bytes used, envelope included; `access` validates the result like
//! /// any other structure. `BufferTooSmall` names the size needed.
//! pub fn encode_image_into(
//!     name: &str,
//!     valid_time: Time,
//!     create_time: Time,
//!     width: i64,
//!     height: i64,
//!     format: i64,
//!     pixel_len: usize,
//!     out: &mut [u8],
//! ) -> Result<usize, CodecError>;
//!
//! /// An upper bound of what `encode_image_into` needs beyond the pixels for a name of
//! /// `name_len` bytes, so a loan can be sized before the name is known.
//! pub fn image_overhead_bound(name_len: usize) -> usize;
//! ```
//!
//! Inside the codec that is `to_bytes_in` with a writer whose position starts at
//! `pixel_len` (so positions stay relative to the archive start) and a wrapper for the
//! octet field whose `serialize_with` returns `VecResolver::from_pos(0)` without writing
//! any bytes. The archived type is unchanged, so readers need nothing new.
//!
//! A second, smaller addition would remove the zeroing of each loan before encoding:
//! `encode_into_uninit(&EntityStructure, &mut [MaybeUninit<u8>]) -> Result<usize,
//! CodecError>` (rkyv's `Buffer` accepts `&mut [MaybeUninit<u8>]`), returning the
//! number of bytes now initialised.

use std::sync::Arc;

use esgm_core::Entity;
use esgm_core::codec::{self, ArchivedValue, CodecError};
use esgm_core::library::Image;
use esgm_core::{Octets, Time};

/// The attribute holding the pixels, as `esgm_core::library::Image` names it.
pub const IMAGE_DATA: &str = "image_data";

// Distinct, asymmetric byte patterns, so that finding them tells both place and order.
const PROBE_VALID_TIME: Time = 0x0123_4567_89ab_cdef;
const PROBE_CREATE_TIME: Time = 0x7edc_ba98_7654_3210;

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
    /// Width or height is negative, or the pixel count overflows; check the sizes.
    #[error("invalid image size {width}×{height}")]
    InvalidSize {
        /// The requested width.
        width: i64,
        /// The requested height.
        height: i64,
    },
    /// The codec's archived layout is not what the in-place writer expects (see the
    /// module docs); publish the image as a structure instead, and report it.
    #[error("in-place image layout unsupported by this codec: {reason}")]
    LayoutUnsupported {
        /// Which check failed.
        reason: &'static str,
    },
    /// The image structure could not be encoded.
    #[error(transparent)]
    Codec(#[from] CodecError),
}

/// Bytes of pixels for an image of this size and format.
pub fn pixel_len(width: i64, height: i64, format: i64) -> Result<usize, ImageError> {
    let bpp = Image::bytes_per_pixel(format).ok_or(ImageError::UnknownFormat { format })?;
    let invalid = ImageError::InvalidSize { width, height };
    let w = usize::try_from(width).map_err(|_| ImageError::InvalidSize { width, height })?;
    let h = usize::try_from(height).map_err(|_| ImageError::InvalidSize { width, height })?;
    w.checked_mul(h).and_then(|n| n.checked_mul(bpp)).ok_or(invalid)
}

/// The bytes of one image archive except its pixels, and where the variable parts go.
pub(crate) struct ImageTemplate {
    name: String,
    width: i64,
    height: i64,
    format: i64,
    /// Archive bytes before the pixels (envelope included).
    prefix: Vec<u8>,
    /// Archive bytes after the pixels.
    suffix: Vec<u8>,
    pixel_len: usize,
    valid_time_at: usize,
    create_time_at: usize,
}

impl std::fmt::Debug for ImageTemplate {
    // The layout, not a dump of the template's bytes.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageTemplate")
            .field("name", &self.name)
            .field("size", &self.size())
            .field("archive_len", &self.archive_len())
            .field("pixels", &self.pixel_range())
            .finish_non_exhaustive()
    }
}

impl ImageTemplate {
    /// Encodes a zero image and locates its pixels and times (see the module docs).
    pub(crate) fn build(
        name: &str,
        width: i64,
        height: i64,
        format: i64,
    ) -> Result<Arc<Self>, ImageError> {
        let pixel_len = pixel_len(width, height, format)?;
        let image = Image { width, height, format, image_data: Octets::from(vec![0u8; pixel_len]) };
        let es = image.to_structure(name, PROBE_VALID_TIME, PROBE_CREATE_TIME);
        let bytes = codec::encode(&es)?;
        let archived = codec::access(&bytes)?;

        let base = bytes.as_ptr() as usize;
        let offset_of = |p: *const u8| (p as usize).wrapping_sub(base);
        let pixels = archived
            .attributes
            .iter()
            .find(|p| p.name.as_str() == IMAGE_DATA)
            .and_then(|p| match &p.value {
                ArchivedValue::OctetSeq(o) => Some(o.as_slice()),
                _ => None,
            })
            .ok_or(ImageError::LayoutUnsupported { reason: "no image_data octet sequence" })?;
        if pixels.len() != pixel_len {
            return Err(ImageError::LayoutUnsupported { reason: "pixel count differs" });
        }
        let pixel_start = offset_of(pixels.as_ptr());
        let pixel_end = pixel_start + pixel_len;
        let valid_time_at = offset_of(std::ptr::addr_of!(archived.valid_time).cast());
        let create_time_at = offset_of(std::ptr::addr_of!(archived.create_time).cast());
        if std::mem::size_of_val(&archived.valid_time) != 8
            || std::mem::size_of_val(&archived.create_time) != 8
        {
            return Err(ImageError::LayoutUnsupported { reason: "archived times are not 8 bytes" });
        }
        for at in [valid_time_at, create_time_at] {
            if at < pixel_end || at + 8 > bytes.len() {
                return Err(ImageError::LayoutUnsupported { reason: "times not after the pixels" });
            }
        }
        if bytes.get(valid_time_at..valid_time_at + 8) != Some(&PROBE_VALID_TIME.to_le_bytes())
            || bytes.get(create_time_at..create_time_at + 8)
                != Some(&PROBE_CREATE_TIME.to_le_bytes())
        {
            return Err(ImageError::LayoutUnsupported {
                reason: "archived times not little-endian",
            });
        }

        let template = Self {
            name: name.to_owned(),
            width,
            height,
            format,
            prefix: bytes[..pixel_start].to_vec(),
            suffix: bytes[pixel_end..].to_vec(),
            pixel_len,
            valid_time_at,
            create_time_at,
        };

        // Prove that stamping times yields a valid archive carrying them.
        let mut copy = bytes.clone();
        template.stamp(&mut copy, -5, 42);
        let stamped = codec::access(&copy)?;
        if stamped.valid_time != -5 || stamped.create_time != 42 {
            return Err(ImageError::LayoutUnsupported { reason: "stamped times read back wrong" });
        }
        Ok(Arc::new(template))
    }

    /// True if this template lays out exactly this image.
    pub(crate) fn fits(&self, name: &str, width: i64, height: i64, format: i64) -> bool {
        self.width == width && self.height == height && self.format == format && self.name == name
    }

    /// The entity name the template was built for.
    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// Width, height, format.
    pub(crate) fn size(&self) -> (i64, i64, i64) {
        (self.width, self.height, self.format)
    }

    /// Bytes of the whole archive, envelope included.
    pub(crate) fn archive_len(&self) -> usize {
        self.prefix.len() + self.pixel_len + self.suffix.len()
    }

    /// Where the pixels go.
    pub(crate) fn pixel_range(&self) -> std::ops::Range<usize> {
        self.prefix.len()..self.prefix.len() + self.pixel_len
    }

    /// The archive bytes before the pixels.
    pub(crate) fn prefix(&self) -> &[u8] {
        &self.prefix
    }

    /// The archive bytes after the pixels.
    pub(crate) fn suffix(&self) -> &[u8] {
        &self.suffix
    }

    /// Writes the two times into an archive laid out by this template. `archive` must
    /// be at least [`Self::archive_len`] bytes; shorter buffers are left untouched.
    pub(crate) fn stamp(&self, archive: &mut [u8], valid_time: Time, create_time: Time) {
        if let Some(b) = archive.get_mut(self.valid_time_at..self.valid_time_at + 8) {
            b.copy_from_slice(&valid_time.to_le_bytes());
        }
        if let Some(b) = archive.get_mut(self.create_time_at..self.create_time_at + 8) {
            b.copy_from_slice(&create_time.to_le_bytes());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::{Block16, blocks_for};

    #[test]
    fn a_template_filled_and_stamped_is_the_image() {
        for name in ["cam", "a_camera_name_longer_than_inline"] {
            let t = ImageTemplate::build(name, 4, 3, Image::FORMAT_RGB8).unwrap();
            assert_eq!(t.pixel_range().len(), 36);
            // Lay a frame out the way a loan does, in a 16-aligned buffer.
            let mut blocks = vec![Block16::default(); blocks_for(t.archive_len())];
            let buf: &mut [u8] = bytemuck::cast_slice_mut(&mut blocks);
            buf[..t.prefix().len()].copy_from_slice(t.prefix());
            let r = t.pixel_range();
            for (i, b) in buf[r.clone()].iter_mut().enumerate() {
                *b = i as u8;
            }
            buf[r.end..t.archive_len()].copy_from_slice(t.suffix());
            t.stamp(buf, 1000, 2000);

            let es = codec::decode(codec::access(&buf[..t.archive_len()]).unwrap()).unwrap();
            assert_eq!((es.name.as_str(), es.valid_time, es.create_time), (name, 1000, 2000));
            let img = Image::from_structure(&es).unwrap();
            assert_eq!((img.width, img.height, img.format), (4, 3, Image::FORMAT_RGB8));
            assert_eq!(&img.image_data[..], &(0..36u8).collect::<Vec<_>>()[..]);
        }
    }

    #[test]
    fn sizes_are_checked() {
        assert!(matches!(pixel_len(2, 2, 99), Err(ImageError::UnknownFormat { format: 99 })));
        assert!(matches!(pixel_len(-1, 2, 0), Err(ImageError::InvalidSize { .. })));
        assert!(matches!(pixel_len(i64::MAX, i64::MAX, 0), Err(ImageError::InvalidSize { .. })));
        assert_eq!(pixel_len(640, 480, Image::FORMAT_RGB8).unwrap(), 921_600);
    }
}
