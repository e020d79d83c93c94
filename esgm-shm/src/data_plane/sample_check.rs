//! The checks a reader runs on a sample another process wrote, as one pure function.
//!
//! [`check_sample`] is what [`crate::TrajectorySubscriber::receive`] runs on every
//! sample, and nothing else: it takes the header and the payload as plain values, so
//! the fuzzer (`esgm-fuzz`) feeds it hostile bytes without shared memory and exercises
//! the very code a reader runs, not a copy of it.
//!
//! Checks, in the order they cost:
//! 1. the header's type id against the reader's type (no payload access);
//! 2. the header's kind, then its archive length against the payload delivered;
//! 3. with [`Validation::InPlace`], the archive itself: envelope, rkyv bytecheck with
//!    the nesting bound, and the header's times against the archive's.

use esgm_core::codec::{self, ArchivedEntityStructure, CodecError, ENVELOPE_LEN};

use crate::data_plane::payload::SampleHeader;
use crate::data_plane::subscriber::{ReceiveError, Validation};

/// A sample that passed [`check_sample`]: what the reader may hand out.
#[derive(Debug)]
#[non_exhaustive]
pub enum SampleVerdict<'a> {
    /// An entity structure: its codec bytes (envelope and archive, `archive_len` of the
    /// payload) and, when it was validated ([`Validation::InPlace`]), the archived
    /// structure read in place. `None` means validation was deferred
    /// ([`Validation::OnAccess`]).
    Structure {
        /// The codec bytes at the start of the payload.
        bytes: &'a [u8],
        /// The validated structure, if validation ran.
        archived: Option<&'a ArchivedEntityStructure>,
    },
    /// A structure kept in the trajectory's kept history: where it is. The reader takes
    /// it from the file and checks it there.
    Kept {
        /// The file's id.
        file_id: u64,
        /// The entry's index.
        index: u64,
        /// The entry's start position in the file's ring.
        start: u64,
        /// The entry's codec bytes' length.
        len: usize,
    },
    /// The writer reset the trajectory (T5); the reader forgets what came before.
    Reset {
        /// The marker's sequence number.
        sequence: u64,
    },
}

/// Checks a sample's header and payload as a reader must before using either.
///
/// `payload` is every byte delivered (the loaned slice, possibly longer than the
/// archive); `expected_type_id` is [`crate::data_plane::type_id::type_id()`] of the reader's type. The
/// errors are [`ReceiveError::TypeMismatch`], [`ReceiveError::UnknownKind`],
/// [`ReceiveError::Truncated`] and [`ReceiveError::Malformed`]; nothing the header or
/// payload holds makes it panic or read out of bounds.
pub fn check_sample<'a>(
    header: &SampleHeader,
    payload: &'a [u8],
    expected_type_id: u64,
    validation: Validation,
) -> Result<SampleVerdict<'a>, ReceiveError> {
    if header.type_id != expected_type_id {
        return Err(ReceiveError::TypeMismatch {
            expected: expected_type_id,
            found: header.type_id,
        });
    }
    if header.kind == SampleHeader::KIND_RESET {
        return Ok(SampleVerdict::Reset { sequence: header.sequence });
    }
    if header.kind == SampleHeader::KIND_KEPT {
        let len = usize::try_from(header.archive_len).ok().filter(|n| *n >= ENVELOPE_LEN);
        let (Some(len), Some(index), Some(id), Some(start)) =
            (len, header.kept.checked_sub(1), payload.get(..8), payload.get(8..16))
        else {
            return Err(ReceiveError::Truncated {
                archive_len: header.archive_len,
                payload_len: payload.len(),
            });
        };
        let word = |b: &[u8]| u64::from_ne_bytes(b.try_into().unwrap_or([0; 8]));
        let (file_id, start) = (word(id), word(start));
        return Ok(SampleVerdict::Kept { file_id, index, start, len });
    }
    if header.kind != SampleHeader::KIND_STRUCTURE {
        return Err(ReceiveError::UnknownKind { kind: header.kind });
    }
    let bytes = match usize::try_from(header.archive_len) {
        Ok(n) if (ENVELOPE_LEN..=payload.len()).contains(&n) => &payload[..n],
        _ => {
            return Err(ReceiveError::Truncated {
                archive_len: header.archive_len,
                payload_len: payload.len(),
            });
        }
    };
    let archived = match validation {
        Validation::InPlace => Some(validate(bytes, header).map_err(ReceiveError::Malformed)?),
        Validation::OnAccess => None,
    };
    Ok(SampleVerdict::Structure { bytes, archived })
}

/// Full validation of `bytes`, and the header's times must be the archive's: filters
/// and time lookups read the header, so a header that lies is as bad as a bad archive.
/// (Also what a sample received with [`Validation::OnAccess`] runs on first access.)
pub(crate) fn validate<'a>(
    bytes: &'a [u8],
    header: &SampleHeader,
) -> Result<&'a ArchivedEntityStructure, CodecError> {
    let archived = codec::access(bytes)?;
    if archived.valid_time != header.valid_time || archived.create_time != header.create_time {
        return Err(CodecError::Malformed {
            len: bytes.len(),
            reason: format!(
                "header times ({}, {}) differ from the archive's ({}, {})",
                header.valid_time, header.create_time, archived.valid_time, archived.create_time
            ),
        });
    }
    Ok(archived)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use esgm_core::EntityStructure;
    use esgm_core::codec::encode;

    use super::*;

    const TYPE: u64 = 0xE56;

    fn header(es: &EntityStructure, archive_len: usize) -> SampleHeader {
        SampleHeader {
            valid_time: es.valid_time,
            create_time: es.create_time,
            archive_len: archive_len as u64,
            type_id: TYPE,
            kind: SampleHeader::KIND_STRUCTURE,
            ..SampleHeader::default()
        }
    }

    #[test]
    fn a_written_sample_passes_and_each_lie_is_named() {
        let es = EntityStructure::new("s", 5, 6).with("x", 1i64);
        let mut aligned = encode(&es).unwrap();
        let n = aligned.len();
        aligned.extend_from_slice(&[0; 15]); // the loaned slice's slack
        let h = header(&es, n);
        match check_sample(&h, &aligned, TYPE, Validation::InPlace).unwrap() {
            SampleVerdict::Structure { bytes, archived: Some(a) } => {
                assert_eq!((bytes.len(), a.valid_time.to_native()), (n, 5));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            check_sample(&h, &aligned, TYPE, Validation::OnAccess),
            Ok(SampleVerdict::Structure { archived: None, .. })
        ));
        assert!(matches!(
            check_sample(&h, &aligned, TYPE + 1, Validation::InPlace),
            Err(ReceiveError::TypeMismatch { .. })
        ));
        let reset = SampleHeader { kind: SampleHeader::KIND_RESET, sequence: 9, ..h };
        assert!(matches!(
            check_sample(&reset, &[][..], TYPE, Validation::InPlace),
            Ok(SampleVerdict::Reset { sequence: 9 })
        ));
        let unknown = SampleHeader { kind: 0, ..h };
        assert!(matches!(
            check_sample(&unknown, &aligned, TYPE, Validation::InPlace),
            Err(ReceiveError::UnknownKind { kind: 0 })
        ));
        for archive_len in [0, ENVELOPE_LEN as u64 - 1, aligned.len() as u64 + 1, u64::MAX] {
            let lying = SampleHeader { archive_len, ..h };
            assert!(matches!(
                check_sample(&lying, &aligned, TYPE, Validation::InPlace),
                Err(ReceiveError::Truncated { .. })
            ));
        }
        let late = SampleHeader { valid_time: 6, ..h };
        assert!(matches!(
            check_sample(&late, &aligned, TYPE, Validation::InPlace),
            Err(ReceiveError::Malformed(_))
        ));
    }
}
