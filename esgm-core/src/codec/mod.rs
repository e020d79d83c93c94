//! The codec: the one place that turns entity structures into bytes and back (P1).
//!
//! The archived form is rkyv's: a reader in another process uses
//! [`ArchivedEntityStructure`] in place, without deserializing, so an image in shared
//! memory is read where its producer wrote it. Nobody outside this module names rkyv's
//! functions; everything goes through [`encode`], [`encode_into`],
//! [`encode_into_uninit`], [`encoded_len`], [`encode_image_into`], [`restamp`],
//! [`access`], [`access_unchecked`], [`decode`] and [`decode_holding`]; a structure's
//! lineage through [`encode_lineage_into`] and [`decode_lineage`] (`lineage.rs`).
//!
//! Bytes that come from another process must go through [`access`], which validates
//! them (bounds, alignment, enum tags, UTF-8) before any field is read. The unchecked
//! path is only for bytes this process wrote itself or a setup that trusts every peer.
//!
//! # Written bytes are initialised bytes
//! rkyv writes an archive front to back through its writer, one `write` after the
//! other with no gaps: alignment padding is written as zeros, and every archived object
//! is zeroed before its fields are filled in, so padding inside structures is zero too.
//! That is what lets [`encode_into_uninit`] promise that the `n` bytes it reports are
//! initialised (a test encodes over two different backgrounds and compares).
//!
//! # Files
//! `octets.rs` archives octet sequences (and lets the image writer point one at pixels
//! already in place), `writer.rs` holds the counting writer, `image.rs` the in-place
//! image layout, `restamp.rs` the in-place change of an archive's times.

mod image;
mod lineage;
mod restamp;
mod writer;

use std::mem::MaybeUninit;
use std::sync::Arc;

use rkyv::Portable;
use rkyv::rancor::{BoxedError, Failure};
use rkyv::ser::writer::Buffer;
use rkyv::util::AlignedVec;

pub use crate::nesting::{ArchivedNest, MAX_NESTING, Nest, NestingContext};
pub use crate::octets::archive::{HoldOctets, PlaceOctets, SharedBytes, SharedBytesResolver};
use crate::octets::{Octets, OctetsHolder};
use crate::value::frame::EntityStructure;
pub use crate::value::frame::{
    ArchivedAttributeValuePair, ArchivedEntityFrame, ArchivedEntityStructure,
};
pub use crate::value::{ArchivedOctets, ArchivedValue, ArchivedValueSort};
pub use image::{
    IMAGE_NAME_MAX, IMAGE_OVERHEAD_MAX, IMAGE_PIXELS_MAX, IMAGE_PIXELS_OFFSET, encode_image_into,
};
pub use lineage::{
    LINEAGE_VERSION, MAX_LINEAGE_INPUTS, MAX_LINEAGE_NAME, decode_lineage, encode_lineage,
    encode_lineage_into, lineage_len,
};
pub use restamp::restamp;
use writer::CountingWriter;

/// Alignment the archived form needs from its buffer. Shared-memory payloads are laid
/// out on this boundary.
pub const ARCHIVE_ALIGNMENT: usize = 16;

/// A heap buffer aligned for the archived form, as [`encode`] returns one.
pub type ArchiveBuffer = AlignedVec<ARCHIVE_ALIGNMENT>;

/// Encoding or decoding failed; the message says which check failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CodecError {
    /// The bytes are not a valid archived entity structure (truncated, corrupted, or
    /// misaligned): they were rejected before any field was read.
    #[error("malformed entity structure bytes ({len} bytes): {reason}")]
    Malformed {
        /// Length of the rejected buffer.
        len: usize,
        /// What the validator found.
        reason: String,
    },
    /// The buffer handed to [`encode_into`] is too small; retry with `needed` bytes.
    #[error("buffer of {available} bytes is too small, {needed} needed")]
    BufferTooSmall {
        /// Bytes available.
        available: usize,
        /// Bytes the archive needs.
        needed: usize,
    },
    /// The entity name is too long for [`encode_image_into`]'s names region; shorten
    /// it, or publish the image as an ordinary structure.
    #[error("entity name of {len} bytes is too long for an in-place image (at most {max})")]
    NameTooLong {
        /// Bytes in the rejected name.
        len: usize,
        /// [`IMAGE_NAME_MAX`].
        max: usize,
    },
    /// The data is more than the archived format can address (32-bit relative
    /// pointers); split it.
    #[error("{len} bytes exceed the archived format's limit of {max}")]
    TooLarge {
        /// Bytes asked for.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// Serialization failed.
    #[error("could not encode entity structure: {0}")]
    Encode(String),
}

/// Bytes before the archive: magic, format version and archive length.
///
/// rkyv puts an archive's root at its end, so a truncated buffer can validate as some
/// other object that happens to end at the cut. The envelope makes a buffer of the
/// wrong length, or from something that is not esgm, fail before rkyv looks at it, and
/// lets the format evolve.
pub const ENVELOPE_LEN: usize = 16;
const MAGIC: [u8; 4] = *b"ESGM";
/// The archived format's version; bump it with any change to the archived types.
pub const FORMAT_VERSION: u32 = 2;

fn envelope(archive_len: usize) -> [u8; ENVELOPE_LEN] {
    let mut e = [0u8; ENVELOPE_LEN];
    e[..4].copy_from_slice(&MAGIC);
    e[4..8].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    e[8..16].copy_from_slice(&(archive_len as u64).to_le_bytes());
    e
}

fn write_envelope(out: &mut [u8], archive_len: usize) {
    out[..ENVELOPE_LEN].copy_from_slice(&envelope(archive_len));
}

fn malformed(bytes: &[u8], reason: impl Into<String>) -> CodecError {
    CodecError::Malformed { len: bytes.len(), reason: reason.into() }
}

/// Archives an entity structure into a fresh aligned buffer (envelope + archive).
pub fn encode(es: &EntityStructure) -> Result<AlignedVec<ARCHIVE_ALIGNMENT>, CodecError> {
    let mut out = AlignedVec::<ARCHIVE_ALIGNMENT>::new();
    out.extend_from_slice(&[0u8; ENVELOPE_LEN]);
    // Positions inside an archive are relative, and 16 is a multiple of every archived
    // alignment, so the archive written after the envelope is valid on its own.
    let mut out = rkyv::api::high::to_bytes_in::<_, BoxedError>(es, out)
        .map_err(|e| CodecError::Encode(e.to_string()))?;
    let archive_len = out.len() - ENVELOPE_LEN;
    write_envelope(&mut out, archive_len);
    Ok(out)
}

/// Archives an entity structure into `out` (e.g. a loaned shared-memory slice) and
/// returns the number of bytes written, envelope included. `out` must start on an
/// [`ARCHIVE_ALIGNMENT`] boundary; on [`CodecError::BufferTooSmall`] retry with the
/// size it names.
pub fn encode_into(es: &EntityStructure, out: &mut [u8]) -> Result<usize, CodecError> {
    let available = out.len();
    let Some((envelope, body)) = out.split_at_mut_checked(ENVELOPE_LEN) else {
        return Err(CodecError::BufferTooSmall { available, needed: encoded_len(es)? });
    };
    let archive_len = encode_body(es, Buffer::from(body), available)?;
    write_envelope(envelope, archive_len);
    Ok(ENVELOPE_LEN + archive_len)
}

/// [`encode_into`] for memory not yet initialised (a fresh shared-memory loan), so the
/// caller need not zero it first. On success `out[..n]` is initialised (see the module
/// docs) and the rest untouched; on error nothing in `out` may be assumed initialised.
pub fn encode_into_uninit(
    es: &EntityStructure,
    out: &mut [MaybeUninit<u8>],
) -> Result<usize, CodecError> {
    let available = out.len();
    let Some((head, body)) = out.split_at_mut_checked(ENVELOPE_LEN) else {
        return Err(CodecError::BufferTooSmall { available, needed: encoded_len(es)? });
    };
    let archive_len = encode_body(es, Buffer::from(body), available)?;
    for (to, byte) in head.iter_mut().zip(envelope(archive_len)) {
        to.write(byte);
    }
    Ok(ENVELOPE_LEN + archive_len)
}

/// Serializes `es` into `body`, returning the archive's length.
fn encode_body(
    es: &EntityStructure,
    body: Buffer<'_>,
    available: usize,
) -> Result<usize, CodecError> {
    match rkyv::api::high::to_bytes_in::<_, BoxedError>(es, body) {
        Ok(written) => Ok(written.len()),
        // The buffer's overflow error is not distinguishable from others by type;
        // measuring tells which it was.
        Err(e) => match encoded_len(es)? {
            needed if needed > available => Err(CodecError::BufferTooSmall { available, needed }),
            _ => Err(CodecError::Encode(e.to_string())),
        },
    }
}

/// The number of bytes [`encode_into`] needs for `es`, envelope included.
///
/// Measured by serializing into a writer that only counts: no allocation, and octet
/// sequences are counted, not copied, so an image costs what its few fields cost.
pub fn encoded_len(es: &EntityStructure) -> Result<usize, CodecError> {
    let counted = rkyv::api::high::to_bytes_in::<_, BoxedError>(es, CountingWriter::default())
        .map_err(|e| CodecError::Encode(e.to_string()))?;
    Ok(ENVELOPE_LEN + counted.len())
}

fn archive_body(bytes: &[u8]) -> Result<&[u8], CodecError> {
    if bytes.len() < ENVELOPE_LEN || bytes[..4] != MAGIC {
        return Err(malformed(bytes, "not an esgm entity structure (bad magic)"));
    }
    let mut v = [0u8; 4];
    v.copy_from_slice(&bytes[4..8]);
    let version = u32::from_le_bytes(v);
    if version != FORMAT_VERSION {
        return Err(malformed(
            bytes,
            format!("format version {version}, this build reads {FORMAT_VERSION}"),
        ));
    }
    let mut l = [0u8; 8];
    l.copy_from_slice(&bytes[8..16]);
    let len = u64::from_le_bytes(l);
    if len != (bytes.len() - ENVELOPE_LEN) as u64 {
        return Err(malformed(
            bytes,
            format!("envelope says {len} archive bytes, {} present", bytes.len() - ENVELOPE_LEN),
        ));
    }
    Ok(&bytes[ENVELOPE_LEN..])
}

/// Validates `bytes` (envelope and archive) and returns the archived structure inside
/// them, read in place.
///
/// Use this for every buffer written by another process.
///
/// Validation runs with rkyv's cheapest error type, which says only *that* a check
/// failed (it costs nothing on the way, where a descriptive error's trace costs a
/// tenth of the validation); a buffer that fails is validated a second time to say
/// *what* failed. Malformed bytes are the rare case, and their cost is the one paid
/// twice.
pub fn access(bytes: &[u8]) -> Result<&ArchivedEntityStructure, CodecError> {
    let body = archive_body(bytes)?;
    if let Ok(archived) = validate::<Failure>(body) {
        return Ok(archived);
    }
    validate::<BoxedError>(body).map_err(|e| malformed(bytes, e.to_string()))
}

/// Validates an archive (no envelope) with errors of type `E`.
fn validate<E: rkyv::rancor::Source>(body: &[u8]) -> Result<&ArchivedEntityStructure, E> {
    rkyv::api::access_with_context::<ArchivedEntityStructure, _, E>(
        body,
        &mut crate::nesting::Validator::new(body),
    )
}

/// Returns the archived structure in `bytes` checking only the envelope.
///
/// # Safety
/// `bytes` must be exactly what [`encode`] or [`encode_into`] produced (same length,
/// same alignment), unmodified. Only use it for buffers this process wrote, or when
/// every writer is trusted and the validation cost matters.
pub unsafe fn access_unchecked(bytes: &[u8]) -> Result<&ArchivedEntityStructure, CodecError> {
    let body = archive_body(bytes)?;
    // SAFETY: forwarded to the caller, see above.
    Ok(unsafe { rkyv::access_unchecked::<ArchivedEntityStructure>(body) })
}

/// Validates and decodes codec bytes (envelope + archive) wherever they sit: bytes
/// that do not start on an [`ARCHIVE_ALIGNMENT`] boundary (a request payload, a file)
/// are copied to an aligned buffer first.
pub fn decode_bytes(bytes: &[u8]) -> Result<EntityStructure, CodecError> {
    if (bytes.as_ptr() as usize) % ARCHIVE_ALIGNMENT == 0 {
        return decode(access(bytes)?);
    }
    let mut aligned = AlignedVec::<ARCHIVE_ALIGNMENT>::with_capacity(bytes.len());
    aligned.extend_from_slice(bytes);
    decode(access(&aligned)?)
}

/// Turns an archived structure back into an owned one (copies every field, including
/// image bytes: use it only where an owned copy is wanted).
pub fn decode(archived: &ArchivedEntityStructure) -> Result<EntityStructure, CodecError> {
    deserialize(archived, &mut rkyv::de::Pool::new())
}

/// Turns one archived value back into an owned one (octets copied): what a typed view
/// ([`crate::entity_view`]) does for a compound field.
pub fn decode_value(archived: &ArchivedValue) -> Result<crate::value::Value, CodecError> {
    rkyv::api::deserialize_using::<crate::value::Value, _, BoxedError>(
        archived,
        &mut rkyv::de::Pool::new(),
    )
    .map_err(|e| CodecError::Malformed { len: 0, reason: e.to_string() })
}

/// Deserializes with `octets` deciding where octet sequences go ([`HoldOctets`]).
fn deserialize<D: HoldOctets>(
    archived: &ArchivedEntityStructure,
    octets: &mut D,
) -> Result<EntityStructure, CodecError> {
    rkyv::api::deserialize_using::<EntityStructure, _, BoxedError>(archived, octets)
        .map_err(|e| CodecError::Malformed { len: 0, reason: e.to_string() })
}

/// Like [`decode`], but an octet sequence whose bytes lie in `holder`'s bytes is kept
/// there ([`Octets::held`]) instead of copied: an image received in shared memory
/// stays in shared memory, borrowed until the last value pointing into it is dropped.
///
/// `archived` must be inside `holder.bytes()` for anything to be held (octets outside
/// it are copied, so a wrong holder costs a copy, never a dangling value).
pub fn decode_holding(
    archived: &ArchivedEntityStructure,
    holder: &Arc<dyn OctetsHolder>,
) -> Result<EntityStructure, CodecError> {
    deserialize(archived, &mut Holding { holder })
}

/// [`decode_holding`]'s deserializer: holds octets that lie in its holder's bytes.
struct Holding<'a> {
    holder: &'a Arc<dyn OctetsHolder>,
}

impl HoldOctets for Holding<'_> {
    fn hold(&mut self, bytes: &[u8]) -> Option<Octets> {
        let base = self.holder.bytes().as_ptr() as usize;
        let start = (bytes.as_ptr() as usize).checked_sub(base)?;
        Octets::held(Arc::clone(self.holder), start..start + bytes.len())
    }
}

// The archived forms are plain data; make sure of it at compile time.
const _: fn() = || {
    fn portable<T: Portable>() {}
    portable::<ArchivedEntityStructure>();
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::frame::EntityFrame;
    use crate::value::{Octets, Value};

    fn sample() -> EntityStructure {
        let blob = EntityFrame::new("b1").with("x", 1i64).with("y", 2i64).with("size", 3i64);
        EntityStructure::new("cam", 100, 101)
            .with("width", 4i64)
            .with("image_data", Octets::from(vec![7u8; 64]))
            .with("items", vec![blob.clone(), blob])
            .with("label", "hello")
            .with("nested", Value::Agg(vec![Value::Double(1.5), Value::Bool(true)]))
    }

    #[test]
    fn round_trip_and_in_place_read() {
        let es = sample();
        let bytes = encode(&es).unwrap();
        let archived = access(&bytes).unwrap();
        assert_eq!(archived.valid_time, 100);
        assert_eq!(archived.name.as_str(), "cam");
        let img = archived.attributes.iter().find(|p| p.name == "image_data").unwrap();
        match &img.value {
            ArchivedValue::OctetSeq(o) => assert_eq!(o.as_slice(), &[7u8; 64][..]),
            other => panic!("unexpected {other:?}"),
        }
        assert_eq!(decode(archived).unwrap(), es);
    }

    #[test]
    fn decode_holding_keeps_octets_in_the_holders_buffer() {
        struct Buffer(AlignedVec<ARCHIVE_ALIGNMENT>);
        impl OctetsHolder for Buffer {
            fn bytes(&self) -> &[u8] {
                &self.0
            }
        }
        let es = sample();
        let holder: Arc<dyn OctetsHolder> = Arc::new(Buffer(encode(&es).unwrap()));
        let decoded = decode_holding(access(holder.bytes()).unwrap(), &holder).unwrap();
        assert_eq!(decoded, es);
        let pixels = decoded.get("image_data").and_then(Value::as_octets).unwrap();
        assert!(pixels.is_held(), "the image stays in the archive's buffer");
        let inside = holder.bytes().as_ptr_range();
        assert!(inside.contains(&pixels.as_ptr()));
        assert_eq!(Arc::strong_count(&holder), 2, "held by the decoded image");
        drop(decoded);
        assert_eq!(Arc::strong_count(&holder), 1, "released with it");

        // Octets outside the holder's bytes are copied, never pointed at.
        let elsewhere: Arc<dyn OctetsHolder> = Arc::new(Buffer(AlignedVec::new()));
        let archive = encode(&es).unwrap();
        let copied = decode_holding(access(&archive).unwrap(), &elsewhere).unwrap();
        assert!(!copied.get("image_data").and_then(Value::as_octets).unwrap().is_held());
        assert_eq!(copied, es);
    }

    #[test]
    fn encode_into_a_slice() {
        let es = sample();
        let mut buf = AlignedVec::<ARCHIVE_ALIGNMENT>::with_capacity(4096);
        buf.resize(4096, 0);
        let n = encode_into(&es, &mut buf).unwrap();
        assert_eq!(decode(access(&buf[..n]).unwrap()).unwrap(), es);

        let mut small = AlignedVec::<ARCHIVE_ALIGNMENT>::with_capacity(16);
        small.resize(16, 0);
        assert!(matches!(
            encode_into(&es, &mut small),
            Err(CodecError::BufferTooSmall { available: 16, .. })
        ));
    }

    #[test]
    fn encode_into_uninit_initialises_exactly_what_it_reports() {
        let es = sample();
        let reference = encode(&es).unwrap();
        assert_eq!(encoded_len(&es).unwrap(), reference.len());
        // Over two different backgrounds: a byte the encoder skipped would differ.
        for background in [0xAAu8, 0x55] {
            let mut buf = AlignedVec::<ARCHIVE_ALIGNMENT>::with_capacity(4096);
            buf.resize(4096, background);
            // SAFETY: `u8` and `MaybeUninit<u8>` have one layout, and only initialised
            // bytes are written through the view.
            let uninit = unsafe {
                std::slice::from_raw_parts_mut(buf.as_mut_ptr().cast::<MaybeUninit<u8>>(), 4096)
            };
            let n = encode_into_uninit(&es, uninit).unwrap();
            assert_eq!(&buf[..n], &reference[..]);
            assert!(buf[n..].iter().all(|b| *b == background), "wrote past its length");
        }
        let mut small = [MaybeUninit::<u8>::uninit(); 8];
        assert!(matches!(
            encode_into_uninit(&es, &mut small),
            Err(CodecError::BufferTooSmall { available: 8, needed }) if needed == reference.len()
        ));
    }

    #[test]
    fn encoded_len_counts_without_copying_octets() {
        let es = EntityStructure::new("cam", 1, 2).with("px", Octets::from(vec![1u8; 100_000]));
        assert_eq!(encoded_len(&es).unwrap(), encode(&es).unwrap().len());
        assert_eq!(encoded_len(&EntityStructure::default()).unwrap(), ENVELOPE_LEN + 32);
    }

    #[test]
    fn malformed_bytes_are_rejected_not_read() {
        let bytes = encode(&sample()).unwrap();
        // Truncations of every length are rejected, never a crash.
        for cut in 0..bytes.len() {
            let mut buf = AlignedVec::<ARCHIVE_ALIGNMENT>::new();
            buf.extend_from_slice(&bytes[..cut]);
            assert!(access(&buf).is_err(), "cut at {cut} accepted");
        }
        // Garbage is rejected.
        let mut junk = AlignedVec::<ARCHIVE_ALIGNMENT>::new();
        junk.extend_from_slice(&[0xff; 256]);
        assert!(matches!(access(&junk), Err(CodecError::Malformed { len: 256, .. })));
    }
}
