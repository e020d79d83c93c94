//! Re-stamping an archive in place: new valid and create times without encoding again.
//!
//! A producer that prepares a structure ahead of time (encodes it into a shared-memory
//! loan while nothing is urgent) learns the structure's times only when it sends —
//! a reply to a request, a sample taken on a tick. rkyv puts the root object at the end
//! of the archive, so the times sit at a fixed distance from the archive's end, and
//! changing them is two 8-byte writes; nothing else in the archive refers to them.

use std::mem::{offset_of, size_of};

use super::{ArchivedEntityStructure, CodecError, ENVELOPE_LEN, archive_body, malformed};
use crate::time::Time;

/// Rewrites the valid and create times of the archive in `bytes` (envelope + archive,
/// as [`super::encode_into`] wrote it), in place.
///
/// Only the envelope is checked (magic, version, length) and the archive must be big
/// enough to hold a root; the two times are the only bytes written. Used on bytes this
/// process encoded, it leaves an archive that decodes to the same structure with the
/// new times; on bytes that are not an archive it writes sixteen bytes of nonsense into
/// nonsense, which validation on the reading side still rejects.
pub fn restamp(bytes: &mut [u8], valid_time: Time, create_time: Time) -> Result<(), CodecError> {
    let archive_len = archive_body(bytes)?.len();
    let Some(root) = archive_len.checked_sub(size_of::<ArchivedEntityStructure>()) else {
        return Err(malformed(bytes, "archive too short to hold an entity structure"));
    };
    let root = ENVELOPE_LEN + root;
    for (field, time) in [
        (offset_of!(ArchivedEntityStructure, valid_time), valid_time),
        (offset_of!(ArchivedEntityStructure, create_time), create_time),
    ] {
        // rkyv archives integers little-endian.
        bytes[root + field..root + field + size_of::<Time>()].copy_from_slice(&time.to_le_bytes());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{access, decode, encode};
    use crate::value::Octets;
    use crate::value::frame::{EntityFrame, EntityStructure};

    #[test]
    fn a_restamped_archive_is_the_structure_with_new_times() {
        let shapes = [
            EntityStructure::default(),
            EntityStructure::new("robot", 1, 2).with("x", 1.5).with("y", -2.0),
            EntityStructure::new("cam", 3, 4)
                .with("image_data", Octets::from(vec![9u8; 300]))
                .with("blobs", vec![EntityFrame::new("b").with("size", 3i64)]),
        ];
        for es in shapes {
            let mut bytes = encode(&es).unwrap();
            restamp(&mut bytes, -7, i64::MAX).unwrap();
            let mut expected = es.clone();
            expected.valid_time = -7;
            expected.create_time = i64::MAX;
            assert_eq!(decode(access(&bytes).unwrap()).unwrap(), expected);
        }
    }

    #[test]
    fn bytes_that_are_not_an_archive_are_refused_untouched() {
        let mut junk = vec![0xAB; 64];
        assert!(matches!(restamp(&mut junk, 1, 1), Err(CodecError::Malformed { len: 64, .. })));
        assert!(junk.iter().all(|b| *b == 0xAB));
        let mut empty = Vec::new();
        assert!(restamp(&mut empty, 1, 1).is_err());
    }
}
