//! What one Zenoh message of a bridged trajectory carries: a small header, then the
//! codec bytes (envelope + archive) exactly as the writer put them in shared memory.
//!
//! ```text
//! offset  size  field
//!      0     4  magic "ESGZ"
//!      4     2  wire version (1)
//!      6     2  header length (64 + type name, padded to 16)
//!      8     8  exporter session: random per run of the exporting bridge
//!     16     8  writer: the writer's publisher in the exporting domain (its sequence
//!               numbers count per publisher)
//!     24     8  sequence: the writer's number of this sample
//!     32     8  add time in the exporting domain (ns)
//!     40     8  skipped: samples of this writer the exporter chose not to send so far
//!               (`--latest-only`, `--max-rate`), so the importer tells them from losses
//!     48     8  type hash: of the type's definition (see [`type_hash`])
//!     56     2  type name length
//!     58     1  kind: 0 a structure, 1 a reset of the trajectory (no codec bytes)
//!     59     1  reserved (zero)
//!     60     4  lineage length: bytes of the structure's lineage (0: none)
//!     64     n  type name (UTF-8), zero-padded to a multiple of 16
//!  64+n'     l  lineage ([`esgm_core::codec::decode_lineage`]'s bytes), zero-padded to a
//!               multiple of 16
//!     …      …  codec bytes
//! ```
//!
//! Integers are little-endian. Everything here is plain integers and a name: a
//! corrupt header is rejected by comparison, and the codec bytes behind it are
//! validated with [`esgm_core::codec::access`] (through `decode_bytes`) before use,
//! like any bytes from another process.

use esgm_core::codec::{self, CodecError};
use esgm_core::{CacheConstraint, EntityStructure, EntityStructureType};

/// The first bytes of every message.
pub const MAGIC: [u8; 4] = *b"ESGZ";
/// This build's wire version; a message of another is refused.
pub const WIRE_VERSION: u16 = 1;
/// Bytes before the type name.
pub const FIXED_LEN: usize = 64;
/// The longest type name a header carries.
pub const MAX_TYPE_NAME: usize = 1024;

/// What an exporter says about a trajectory (`?esgm=meta`, JSON): enough for an
/// importer to register the type and create the trajectory.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Meta {
    /// The exporting domain.
    pub domain: String,
    /// The trajectory.
    pub trajectory: String,
    /// Its type's name.
    pub type_name: String,
    /// Its type and every element type it names.
    pub types: Vec<(String, EntityStructureType)>,
    /// [`type_hash`] of `types`.
    pub type_hash: u64,
    /// The exporter's cache constraint (the importer keeps the same).
    pub cache: CacheConstraint,
    /// The exporting bridge's session ([`Header::session`]).
    pub session: u64,
}

/// The header of one message (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// Random per run of the exporting bridge.
    pub session: u64,
    /// The writer's publisher in the exporting domain.
    pub writer: u64,
    /// The writer's sequence number of this sample.
    pub sequence: u64,
    /// The add time in the exporting domain.
    pub add_time: i64,
    /// Samples the exporter chose not to send so far (rate limit, latest only).
    pub skipped: u64,
    /// Hash of the type's definition ([`type_hash`]).
    pub type_hash: u64,
    /// The type's name.
    pub type_name: String,
    /// What the message carries.
    pub kind: Kind,
    /// The input structures it was made from, in the exporting domain (a produced
    /// structure's; see [`esgm_core::lineage`]).
    pub lineage: Option<esgm_core::Lineage>,
}

/// What a message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kind {
    /// An entity structure.
    #[default]
    Structure,
    /// The writer reset the trajectory (T5): forget what came before.
    Reset,
}

/// Where the `skipped` count sits in a message, so a message made early can be
/// brought up to date when it is sent ([`set_skipped`]).
const SKIPPED_AT: usize = 40;

/// Sets the `skipped` count of an encoded message.
pub fn set_skipped(message: &mut [u8], skipped: u64) {
    if message.len() >= FIXED_LEN {
        message[SKIPPED_AT..SKIPPED_AT + 8].copy_from_slice(&skipped.to_le_bytes());
    }
}

/// True if an encoded message is a reset.
pub fn is_reset(message: &[u8]) -> bool {
    message.len() >= FIXED_LEN && message[58] == 1
}

/// A message that is not a bridged sample.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WireError {
    /// Too short, wrong magic or version, or a length that does not add up: not a
    /// message of this wire version (or damaged on the way).
    #[error("malformed bridge message ({len} bytes): {reason}")]
    Header {
        /// Bytes received.
        len: usize,
        /// What was wrong.
        reason: String,
    },
    /// The header is fine but the structure behind it is not a valid archive.
    #[error("malformed entity structure in a bridge message: {0}")]
    Codec(#[from] CodecError),
}

fn header_len(type_name: &str) -> usize {
    FIXED_LEN + type_name.len().next_multiple_of(16)
}

/// The message of `header` and `codec_bytes` (envelope + archive, as in shared memory).
///
/// A lineage that cannot be encoded (more inputs than [`esgm_core::codec::MAX_LINEAGE_INPUTS`])
/// is left out, and the structure crosses without it.
pub fn encode(header: &Header, codec_bytes: &[u8]) -> Vec<u8> {
    let hlen = header_len(&header.type_name);
    let lineage =
        header.lineage.as_ref().and_then(|l| codec::encode_lineage(l).ok()).unwrap_or_default();
    let mut out = Vec::with_capacity(hlen + lineage.len() + 16 + codec_bytes.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&WIRE_VERSION.to_le_bytes());
    out.extend_from_slice(&(hlen as u16).to_le_bytes());
    out.extend_from_slice(&header.session.to_le_bytes());
    out.extend_from_slice(&header.writer.to_le_bytes());
    out.extend_from_slice(&header.sequence.to_le_bytes());
    out.extend_from_slice(&header.add_time.to_le_bytes());
    out.extend_from_slice(&header.skipped.to_le_bytes());
    out.extend_from_slice(&header.type_hash.to_le_bytes());
    out.extend_from_slice(&(header.type_name.len() as u16).to_le_bytes());
    out.push(match header.kind {
        Kind::Structure => 0,
        Kind::Reset => 1,
    });
    out.push(0);
    out.extend_from_slice(&(lineage.len() as u32).to_le_bytes());
    out.extend_from_slice(header.type_name.as_bytes());
    out.resize(hlen, 0);
    out.extend_from_slice(&lineage);
    out.resize(hlen + lineage.len().next_multiple_of(16), 0);
    out.extend_from_slice(codec_bytes);
    out
}

fn bad(bytes: &[u8], reason: impl Into<String>) -> WireError {
    WireError::Header { len: bytes.len(), reason: reason.into() }
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(b)
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// Splits a message into its header and codec bytes, checking the header only.
pub fn split(bytes: &[u8]) -> Result<(Header, &[u8]), WireError> {
    if bytes.len() < FIXED_LEN {
        return Err(bad(bytes, format!("shorter than the {FIXED_LEN}-byte header")));
    }
    if bytes[..4] != MAGIC {
        return Err(bad(bytes, "not an esgm bridge message (bad magic)"));
    }
    let version = u16_at(bytes, 4);
    if version != WIRE_VERSION {
        return Err(bad(
            bytes,
            format!("wire version {version}, this bridge reads {WIRE_VERSION}"),
        ));
    }
    let hlen = usize::from(u16_at(bytes, 6));
    let name_len = usize::from(u16_at(bytes, 56));
    if name_len > MAX_TYPE_NAME || hlen != FIXED_LEN + name_len.next_multiple_of(16) {
        return Err(bad(bytes, format!("header length {hlen} for a type name of {name_len}")));
    }
    if bytes.len() < hlen {
        return Err(bad(bytes, format!("header of {hlen} bytes in a shorter message")));
    }
    let type_name = std::str::from_utf8(&bytes[FIXED_LEN..FIXED_LEN + name_len])
        .map_err(|_| bad(bytes, "type name is not UTF-8"))?
        .to_owned();
    let kind = match bytes[58] {
        0 => Kind::Structure,
        1 => Kind::Reset,
        k => return Err(bad(bytes, format!("unknown message kind {k}"))),
    };
    let lineage_len = u32::from_le_bytes([bytes[60], bytes[61], bytes[62], bytes[63]]) as usize;
    let body_at = hlen
        .checked_add(lineage_len.next_multiple_of(16))
        .filter(|end| *end <= bytes.len())
        .ok_or_else(|| {
            bad(bytes, format!("a lineage of {lineage_len} bytes in a shorter message"))
        })?;
    let lineage = match lineage_len {
        0 => None,
        n => Some(codec::decode_lineage(&bytes[hlen..hlen + n])?),
    };
    let header = Header {
        kind,
        session: u64_at(bytes, 8),
        writer: u64_at(bytes, 16),
        sequence: u64_at(bytes, 24),
        add_time: u64_at(bytes, 32) as i64,
        skipped: u64_at(bytes, 40),
        type_hash: u64_at(bytes, 48),
        type_name,
        lineage,
    };
    Ok((header, &bytes[body_at..]))
}

/// Splits a message and validates and decodes its structure
/// ([`codec::decode_bytes`]: `access` first, so malformed bytes are rejected before
/// any field is read). A reset carries none.
pub fn decode(bytes: &[u8]) -> Result<(Header, Option<EntityStructure>), WireError> {
    let (header, body) = split(bytes)?;
    if header.kind == Kind::Reset {
        if !body.is_empty() {
            return Err(bad(bytes, "a reset with a body"));
        }
        return Ok((header, None));
    }
    let es = codec::decode_bytes(body)?;
    Ok((header, Some(es)))
}

/// A stable hash of a type's definition and those of the element types it names
/// (FNV-1a over their JSON form, as [`esgm_shm::type_id()`] hashes names): equal on both
/// hosts exactly when the definitions are.
pub fn type_hash(definitions: &[(String, EntityStructureType)]) -> u64 {
    let mut sorted: Vec<&(String, EntityStructureType)> = definitions.iter().collect();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    // Serializing plain strings, enums and vectors cannot fail.
    let json = serde_json::to_string(&sorted).unwrap_or_default();
    esgm_shm::type_id(&json)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn header() -> Header {
        Header {
            session: 7,
            writer: 9,
            sequence: 42,
            add_time: -5,
            skipped: 3,
            type_hash: 0xdead_beef,
            type_name: "RobotState".into(),
            kind: Kind::Structure,
            lineage: None,
        }
    }

    #[test]
    fn a_message_round_trips() {
        let es = EntityStructure::new("robot1", 10, 11).with("x", 1.5);
        let bytes = encode(&header(), &codec::encode(&es).unwrap());
        let (h, back) = decode(&bytes).unwrap();
        assert_eq!(h, header());
        assert_eq!(back, Some(es));
        let reset = Header { kind: Kind::Reset, ..header() };
        assert_eq!(decode(&encode(&reset, &[])).unwrap(), (reset, None));
    }

    #[test]
    fn damaged_messages_are_errors_not_panics() {
        let es = EntityStructure::new("robot1", 10, 11).with("x", 1.5);
        let good = encode(&header(), &codec::encode(&es).unwrap());
        for cut in [0, 3, 10, 63, 64, 79, 80, 100, good.len() - 1] {
            assert!(decode(&good[..cut]).is_err(), "cut at {cut}");
        }
        let mut version = good;
        version[4] = 9;
        assert!(matches!(decode(&version), Err(WireError::Header { .. })));
    }

    #[test]
    fn a_lineage_crosses_and_a_damaged_one_is_an_error() {
        let es = EntityStructure::new("robot1", 10, 11).with("x", 1.5);
        let lineage = esgm_core::Lineage::of(vec![esgm_core::InputRef {
            trajectory: "camera".into(),
            generation: 4,
            valid_time: 9,
            add_time: 10,
        }]);
        let with = Header { lineage: Some(lineage), ..header() };
        let bytes = encode(&with, &codec::encode(&es).unwrap());
        assert_eq!(decode(&bytes).unwrap(), (with, Some(es)));
        let mut long = bytes.clone();
        long[60..64].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(&long).unwrap_err().to_string().contains("a lineage of"));
        let mut bad = bytes;
        bad[FIXED_LEN + 16] = 7;
        assert!(matches!(decode(&bad), Err(WireError::Codec(_))), "a wrong lineage version");
    }
}
