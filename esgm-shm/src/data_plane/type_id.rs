//! The type id in every sample header: a 64-bit FNV-1a hash of the trajectory's entity
//! structure type name.
//!
//! A reader compares it with the hash of the type it expects and drops a sample of
//! another type without touching the payload. FNV-1a because it is tiny, `const`, has no
//! seed (every process and build computes the same value) and spreads short ASCII names
//! well; it is not a defence against a hostile peer, which [`esgm_core::codec::access`]
//! is. A collision between two type names of one system would only let a mistyped
//! sample through to validation and the type checker, which still catch it.

const FNV_OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// The type id of an entity structure type name (64-bit FNV-1a of its UTF-8 bytes).
pub const fn type_id(type_name: &str) -> u64 {
    let bytes = type_name.as_bytes();
    let mut hash = FNV_OFFSET_BASIS;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(FNV_PRIME);
        i += 1;
    }
    hash
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_reference_vectors() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(type_id(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(type_id("a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(type_id("foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn library_types_are_distinct() {
        let names = ["Image", "Blob", "BlobSeq", "RobotState", "DrivingDirection", "Pose", "Twist"];
        let mut ids: Vec<u64> = names.iter().map(|n| type_id(n)).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), names.len());
    }
}
