//! An `Image` entity structure completed around pixels that are already in the output
//! buffer, so that a camera writes each pixel once, where every reader reads it.
//!
//! # Layout
//! ```text
//! 0                16            n+10                256           256+pixel_len
//! | envelope       | name | "image_data" | zeros     | pixels      | pad | 4 attribute pairs | root |
//!                  |<- names region, IMAGE_NAME_MAX + 10 bytes ->|
//! ```
//! The pixels sit at the fixed [`IMAGE_PIXELS_OFFSET`], whatever the entity's name, so
//! a producer can fill them before it knows the name, and the archive is an ordinary
//! archived [`EntityStructure`] (format version unchanged): [`super::access`]
//! validates it and readers need nothing new.
//!
//! # Why the names come first
//! rkyv's validator walks an archive in field order and requires every object it
//! reaches to lie after the previous one (and before its parent). In an
//! `ArchivedEntityStructure` the entity name comes before the attributes, and in the
//! `image_data` pair the attribute's name comes before the pixels. Names longer than 8
//! bytes are stored out of line, so their bytes must precede the pixels, or a valid-
//! looking archive is rejected. Putting the pixels right after the envelope would make
//! every image fail validation; a fixed region for the names keeps the pixels' offset
//! independent of the name, at the price of a longest name, [`IMAGE_NAME_MAX`].
//!
//! # How
//! rkyv writes an archive front to back, children before parents and the root last.
//! [`encode_image_into`] serializes the real structure — `library::Image { .. }
//! .to_structure(name, ..)` with an empty placeholder for `image_data` — through a
//! writer that starts at the names region. When the placeholder is serialized, the
//! octet field wrapper ([`super::octets`]) asks the writer where its bytes are; this
//! writer zeroes the rest of the names region, jumps over the pixels (neither reading
//! nor writing them) and answers with their position and length. The attribute pairs
//! and the root follow the pixels, aligned relative to the archive start as usual.

use std::mem::size_of;
use std::ops::Range;

use rkyv::rancor::{BoxedError, Source};
use rkyv::ser::{Positional, Writer};

use super::{
    ARCHIVE_ALIGNMENT, ArchivedAttributeValuePair, ArchivedEntityStructure, CodecError,
    ENVELOPE_LEN, write_envelope,
};
use crate::octets::archive::{ArchiveTooLarge, MAX_ARCHIVE_LEN, PlaceOctets};
use crate::time::Time;
use crate::value::Octets;
use crate::value::frame::EntityStructure;

/// Offset of the pixel bytes in a buffer written by [`encode_image_into`]: after the
/// envelope and the region for the names (see the module docs). A multiple of
/// [`ARCHIVE_ALIGNMENT`], so pixels start 16-aligned in an aligned buffer.
pub const IMAGE_PIXELS_OFFSET: usize = 256;
const _: () = assert!(IMAGE_PIXELS_OFFSET % ARCHIVE_ALIGNMENT == 0);

/// The pixels' attribute, as [`Image`] names it; its name's bytes share the names
/// region with the entity name.
const IMAGE_DATA: &str = "image_data";

/// Longest entity name, in UTF-8 bytes, that [`encode_image_into`] accepts: the entity
/// name and `"image_data"` must fit before the pixels.
pub const IMAGE_NAME_MAX: usize = IMAGE_PIXELS_OFFSET - ENVELOPE_LEN - IMAGE_DATA.len();

/// Attributes of an [`Image`] structure (pinned by a test).
const IMAGE_ATTRIBUTES: usize = 4;

/// Upper bound of the bytes [`encode_image_into`] uses besides the pixels (envelope,
/// names region, attribute pairs, root, alignment), for any accepted name: size a
/// buffer or loan `pixel_len + IMAGE_OVERHEAD_MAX`.
pub const IMAGE_OVERHEAD_MAX: usize = IMAGE_PIXELS_OFFSET
    + (ARCHIVE_ALIGNMENT - 1)
    + IMAGE_ATTRIBUTES * size_of::<ArchivedAttributeValuePair>()
    + (ARCHIVE_ALIGNMENT - 1)
    + size_of::<ArchivedEntityStructure>();

/// Largest `pixel_len` the archived format can address (relative pointers are 32-bit).
pub const IMAGE_PIXELS_MAX: usize = MAX_ARCHIVE_LEN - IMAGE_OVERHEAD_MAX;

/// Completes an `Image` entity structure (attributes `width`, `height`, `format`,
/// `image_data`, as [`crate::library::Image`] declares them) around `pixel_len` bytes already present
/// at `out[IMAGE_PIXELS_OFFSET..][..pixel_len]`, which are neither read nor written.
/// Returns the bytes used, envelope included; every byte of `out[..n]` outside the
/// pixels is written (padding as zeros), so nothing stale is left in the archive.
///
/// The result is an ordinary archive: [`super::access`] validates it and
/// [`super::decode`] gives exactly `Image { width, height, format, image_data: pixels }
/// .to_structure(name, valid_time, create_time)`. The codec does not check that
/// `pixel_len` matches width, height and format; the caller sized the pixels.
///
/// `out` must start on an [`ARCHIVE_ALIGNMENT`] boundary to be read in place.
///
/// # Errors
/// [`CodecError::NameTooLong`] if `name` is longer than [`IMAGE_NAME_MAX`] bytes,
/// [`CodecError::TooLarge`] if `pixel_len` exceeds [`IMAGE_PIXELS_MAX`], and
/// [`CodecError::BufferTooSmall`] (with the exact size) if `out` cannot hold the
/// archive; at most `pixel_len + IMAGE_OVERHEAD_MAX` is ever needed.
#[allow(clippy::too_many_arguments, reason = "the attributes of `Image`, then the buffer")]
pub fn encode_image_into(
    name: &str,
    valid_time: Time,
    create_time: Time,
    width: i64,
    height: i64,
    format: i64,
    pixel_len: usize,
    out: &mut [u8],
) -> Result<usize, CodecError> {
    if name.len() > IMAGE_NAME_MAX {
        return Err(CodecError::NameTooLong { len: name.len(), max: IMAGE_NAME_MAX });
    }
    if pixel_len > IMAGE_PIXELS_MAX {
        return Err(CodecError::TooLarge { len: pixel_len, max: IMAGE_PIXELS_MAX });
    }
    // `Image`'s attributes in its type's order (a test holds the two together), built
    // here without the typed struct: the codec sits under the typed layer.
    let image = EntityStructure::new(name, valid_time, create_time)
        .with("width", width)
        .with("height", height)
        .with("format", format)
        .with("image_data", Octets::default());
    let too_small = |out: &[u8]| -> CodecError {
        match measure(&image, pixel_len) {
            Ok(needed) => CodecError::BufferTooSmall { available: out.len(), needed },
            Err(e) => e,
        }
    };
    if out.len() < IMAGE_PIXELS_OFFSET + pixel_len {
        return Err(too_small(out));
    }
    let (envelope, body) = out.split_at_mut(ENVELOPE_LEN);
    let mut writer = ImageWriter::new(Some(body), pixel_len);
    let serialized = rkyv::api::high::to_bytes_in::<_, BoxedError>(&image, &mut writer).map(|_| ());
    match (serialized, writer.failure) {
        (Ok(_), None) if writer.placed => {}
        (_, Some(Failure::OutOfSpace)) => return Err(too_small(out)),
        (Err(e), _) => return Err(CodecError::Encode(e.to_string())),
        (Ok(_), _) => {
            return Err(CodecError::Encode("image structure without its pixels".into()));
        }
    }
    let archive_len = writer.pos;
    write_envelope(envelope, archive_len);
    Ok(ENVELOPE_LEN + archive_len)
}

/// The exact bytes [`encode_image_into`] uses for `image` (placeholder pixels).
fn measure(image: &EntityStructure, pixel_len: usize) -> Result<usize, CodecError> {
    let mut writer = ImageWriter::new(None, pixel_len);
    rkyv::api::high::to_bytes_in::<_, BoxedError>(image, &mut writer)
        .map_err(|e| CodecError::Encode(e.to_string()))?;
    Ok(ENVELOPE_LEN + writer.pos)
}

/// Why the image writer stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Failure {
    /// The names did not fit before the pixels.
    NamesOverflow,
    /// The buffer ended.
    OutOfSpace,
}

#[derive(Debug, thiserror::Error)]
#[error("{0:?} while writing an image archive")]
struct ImageWriteError(Failure);

/// Writes an archive body whose octet placeholder stands for pixels at a fixed place
/// (see the module docs). Without a buffer it only counts, for the exact length.
struct ImageWriter<'a> {
    body: Option<&'a mut [u8]>,
    pos: usize,
    /// Archive positions of the pixels.
    pixels: Range<usize>,
    placed: bool,
    failure: Option<Failure>,
}

impl<'a> ImageWriter<'a> {
    fn new(body: Option<&'a mut [u8]>, pixel_len: usize) -> Self {
        let start = IMAGE_PIXELS_OFFSET - ENVELOPE_LEN;
        Self { body, pos: 0, pixels: start..start + pixel_len, placed: false, failure: None }
    }

    fn fail<E: Source>(&mut self, failure: Failure) -> E {
        self.failure = Some(failure);
        E::new(ImageWriteError(failure))
    }
}

impl Positional for ImageWriter<'_> {
    fn pos(&self) -> usize {
        self.pos
    }
}

impl<E: Source> Writer<E> for ImageWriter<'_> {
    fn write(&mut self, bytes: &[u8]) -> Result<(), E> {
        let end = self.pos + bytes.len();
        if !self.placed && end > self.pixels.start {
            return Err(self.fail(Failure::NamesOverflow));
        }
        if end > MAX_ARCHIVE_LEN {
            return Err(E::new(ArchiveTooLarge));
        }
        if let Some(body) = self.body.as_deref_mut() {
            match body.get_mut(self.pos..end) {
                Some(to) => to.copy_from_slice(bytes),
                None => return Err(self.fail(Failure::OutOfSpace)),
            }
        }
        self.pos = end;
        Ok(())
    }
}

impl<E: Source> PlaceOctets<E> for ImageWriter<'_> {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        if self.placed {
            return Ok(None);
        }
        if let Some(body) = self.body.as_deref_mut() {
            // The rest of the names region: zeros, never stale bytes. `write` kept
            // `pos` at or before the pixels, and the caller checked the body covers them.
            match body.get_mut(self.pos..self.pixels.start) {
                Some(gap) => gap.fill(0),
                None => return Err(self.fail(Failure::OutOfSpace)),
            }
        }
        self.placed = true;
        self.pos = self.pixels.end;
        Ok(Some((self.pixels.start, self.pixels.len())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::entity::Entity;
    use crate::library::Image;
    use rkyv::util::AlignedVec;

    use crate::codec::{access, decode, encode};

    fn aligned(len: usize, background: u8) -> AlignedVec<ARCHIVE_ALIGNMENT> {
        let mut buf = AlignedVec::with_capacity(len);
        buf.resize(len, background);
        buf
    }

    fn expected(name: &str, pixels: &[u8]) -> EntityStructure {
        Image { width: 3, height: 2, format: 7, image_data: Octets::from(pixels) }
            .to_structure(name, -4, 9)
    }

    #[test]
    fn image_attributes_are_pinned() {
        let t = Image::entity_structure_type();
        assert_eq!(t.attributes.len(), IMAGE_ATTRIBUTES);
        assert_eq!(t.attributes[IMAGE_ATTRIBUTES - 1].name, IMAGE_DATA);
    }

    #[test]
    fn completes_a_valid_image_around_pixels_it_never_touches() {
        let names =
            ["", "cam", "exactly8", "nine_char", "kamera_ü_ñ_日本", &"n".repeat(IMAGE_NAME_MAX)];
        for name in names {
            for pixel_len in [0usize, 1, 7, 15, 16, 17, 33, 1000] {
                let pixels: Vec<u8> = (0..pixel_len).map(|i| (i * 31 + 5) as u8).collect();
                let mut runs = Vec::new();
                // Two different backgrounds: every archive byte outside the pixels is
                // written, so both give the same archive.
                for background in [0xAAu8, 0x55] {
                    let mut buf = aligned(pixel_len + IMAGE_OVERHEAD_MAX, background);
                    buf[IMAGE_PIXELS_OFFSET..][..pixel_len].copy_from_slice(&pixels);
                    let n = encode_image_into(name, -4, 9, 3, 2, 7, pixel_len, &mut buf).unwrap();
                    assert!(n <= pixel_len + IMAGE_OVERHEAD_MAX, "{name:?} {pixel_len}");
                    assert_eq!(&buf[IMAGE_PIXELS_OFFSET..][..pixel_len], &pixels[..]);
                    let archived = access(&buf[..n]).unwrap();
                    let es = decode(archived).unwrap();
                    assert_eq!(es, expected(name, &pixels), "{name:?} {pixel_len}");
                    // The same structure as the ordinary encoder's, field for field.
                    assert_eq!(decode(access(&encode(&es).unwrap()).unwrap()).unwrap(), es);
                    runs.push(buf[..n].to_vec());
                }
                assert_eq!(runs[0], runs[1], "{name:?} {pixel_len}: unwritten bytes");
            }
        }
    }

    #[test]
    fn buffer_size_names_and_limits_are_checked() {
        let mut buf = aligned(100 + IMAGE_OVERHEAD_MAX, 0);
        let n = encode_image_into("cam", 1, 2, 10, 10, 1, 100, &mut buf).unwrap();
        // Exactly `n` bytes suffice; one fewer names `n`.
        let mut exact = aligned(n, 0);
        assert_eq!(encode_image_into("cam", 1, 2, 10, 10, 1, 100, &mut exact).unwrap(), n);
        let mut short = aligned(n - 1, 0);
        assert!(matches!(
            encode_image_into("cam", 1, 2, 10, 10, 1, 100, &mut short),
            Err(CodecError::BufferTooSmall { needed, .. }) if needed == n
        ));
        // Too small even for the pixels.
        let mut tiny = aligned(IMAGE_PIXELS_OFFSET, 0);
        assert!(matches!(
            encode_image_into("cam", 1, 2, 10, 10, 1, 100, &mut tiny),
            Err(CodecError::BufferTooSmall { needed, .. }) if needed == n
        ));
        let long = "x".repeat(IMAGE_NAME_MAX + 1);
        assert!(matches!(
            encode_image_into(&long, 1, 2, 10, 10, 1, 100, &mut buf),
            Err(CodecError::NameTooLong { len, max: IMAGE_NAME_MAX }) if len == IMAGE_NAME_MAX + 1
        ));
        assert!(matches!(
            encode_image_into("cam", 1, 2, 10, 10, 1, IMAGE_PIXELS_MAX + 1, &mut buf),
            Err(CodecError::TooLarge { .. })
        ));
    }
}
