//! The codec: the one place that turns entity structures into bytes and back (P1).
//!
//! The archived form is rkyv's: a reader in another process uses
//! [`ArchivedEntityStructure`] in place, without deserializing, so an image in shared
//! memory is read where its producer wrote it. Nobody outside this module names rkyv's
//! functions; everything goes through [`encode`], [`encode_into`], [`access`],
//! [`access_unchecked`] and [`decode`].
//!
//! Bytes that come from another process must go through [`access`], which validates
//! them (bounds, alignment, enum tags, UTF-8) before any field is read. The unchecked
//! path is only for bytes this process wrote itself or a setup that trusts every peer.

use std::sync::Arc;

use rkyv::rancor::{BoxedError, Fallible};
use rkyv::ser::{Allocator, Writer};
use rkyv::util::AlignedVec;
use rkyv::vec::{ArchivedVec, VecResolver};
use rkyv::with::{ArchiveWith, DeserializeWith, SerializeWith};
use rkyv::{Place, Portable};

use crate::frame::EntityStructure;
pub use crate::frame::{ArchivedAttributeValuePair, ArchivedEntityFrame, ArchivedEntityStructure};
pub use crate::value::{ArchivedOctets, ArchivedValue, ArchivedValueSort};

/// Alignment the archived form needs from its buffer. Shared-memory payloads are laid
/// out on this boundary.
pub const ARCHIVE_ALIGNMENT: usize = 16;

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
pub const FORMAT_VERSION: u32 = 1;

fn write_envelope(out: &mut [u8], archive_len: usize) {
    out[..4].copy_from_slice(&MAGIC);
    out[4..8].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    out[8..16].copy_from_slice(&(archive_len as u64).to_le_bytes());
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
    if out.len() < ENVELOPE_LEN {
        return Err(CodecError::BufferTooSmall { available: out.len(), needed: encoded_len(es)? });
    }
    let (envelope, body) = out.split_at_mut(ENVELOPE_LEN);
    let written = match rkyv::api::high::to_bytes_in::<_, BoxedError>(
        es,
        rkyv::ser::writer::Buffer::from(&mut *body),
    ) {
        Ok(written) => written.len(),
        Err(_) => {
            let needed = encoded_len(es)?;
            return Err(CodecError::BufferTooSmall { available: out.len(), needed });
        }
    };
    write_envelope(envelope, written);
    Ok(ENVELOPE_LEN + written)
}

/// The number of bytes [`encode_into`] needs for `es`.
pub fn encoded_len(es: &EntityStructure) -> Result<usize, CodecError> {
    Ok(encode(es)?.len())
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
pub fn access(bytes: &[u8]) -> Result<&ArchivedEntityStructure, CodecError> {
    let body = archive_body(bytes)?;
    rkyv::access::<ArchivedEntityStructure, BoxedError>(body)
        .map_err(|e| malformed(bytes, e.to_string()))
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

/// Turns an archived structure back into an owned one (copies every field, including
/// image bytes: use it only where an owned copy is wanted).
pub fn decode(archived: &ArchivedEntityStructure) -> Result<EntityStructure, CodecError> {
    rkyv::deserialize::<EntityStructure, BoxedError>(archived)
        .map_err(|e| CodecError::Malformed { len: 0, reason: e.to_string() })
}

/// Archives an `Arc<[u8]>` as a plain byte vector: the archived form has no shared
/// pointer bookkeeping, and readers see a `&[u8]` in place.
#[derive(Debug)]
pub struct SharedBytes;

impl ArchiveWith<Arc<[u8]>> for SharedBytes {
    type Archived = ArchivedVec<u8>;
    type Resolver = VecResolver;

    fn resolve_with(field: &Arc<[u8]>, resolver: Self::Resolver, out: Place<Self::Archived>) {
        ArchivedVec::resolve_from_len(field.len(), resolver, out);
    }
}

impl<S: Fallible + Allocator + Writer + ?Sized> SerializeWith<Arc<[u8]>, S> for SharedBytes {
    fn serialize_with(field: &Arc<[u8]>, serializer: &mut S) -> Result<VecResolver, S::Error> {
        ArchivedVec::<u8>::serialize_from_slice(field, serializer)
    }
}

impl<D: Fallible + ?Sized> DeserializeWith<ArchivedVec<u8>, Arc<[u8]>, D> for SharedBytes {
    fn deserialize_with(field: &ArchivedVec<u8>, _: &mut D) -> Result<Arc<[u8]>, D::Error> {
        Ok(Arc::from(field.as_slice()))
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
    use crate::frame::EntityFrame;
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
