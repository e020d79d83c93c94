//! The bytes of a [`Lineage`] where it crosses a process or a file: a sample's
//! trailer in shared memory, a bridged or recorded structure's metadata.
//!
//! A lineage is a handful of small records, read once per received sample and never
//! queried in place, so its form is a flat little-endian layout that is parsed with a
//! bounds check at every step, not an archive:
//!
//! | bytes | field |
//! |---|---|
//! | 1 | version ([`LINEAGE_VERSION`]) |
//! | 1 | complete (0 or 1) |
//! | 2 | zero |
//! | 4 | input count (at most [`MAX_LINEAGE_INPUTS`]) |
//! | per input: 8, 8, 8 | generation, valid time, add time |
//! | per input: 2, n | name length (at most [`MAX_LINEAGE_NAME`]), name (UTF-8) |

use crate::lineage::{InputRef, Lineage};

use super::CodecError;

/// The layout's version; another is refused as malformed.
pub const LINEAGE_VERSION: u8 = 1;

/// At most this many inputs in one lineage: more than any unit, sync or generator
/// reads, and a bound on what malformed bytes can make a reader allocate.
pub const MAX_LINEAGE_INPUTS: usize = 4096;

/// At most this many bytes in one input's trajectory name.
pub const MAX_LINEAGE_NAME: usize = 1024;

const HEAD: usize = 8;
const PER_INPUT: usize = 26;

/// How many bytes [`encode_lineage_into`] writes for `lineage`.
pub fn lineage_len(lineage: &Lineage) -> usize {
    HEAD + lineage.inputs.iter().map(|i| PER_INPUT + i.trajectory.len()).sum::<usize>()
}

/// Writes `lineage` at the start of `out` and returns how many bytes it took.
pub fn encode_lineage_into(lineage: &Lineage, out: &mut [u8]) -> Result<usize, CodecError> {
    let needed = lineage_len(lineage);
    if out.len() < needed {
        return Err(CodecError::BufferTooSmall { available: out.len(), needed });
    }
    if lineage.inputs.len() > MAX_LINEAGE_INPUTS {
        return Err(CodecError::TooLarge { len: lineage.inputs.len(), max: MAX_LINEAGE_INPUTS });
    }
    if let Some(long) = lineage.inputs.iter().find(|i| i.trajectory.len() > MAX_LINEAGE_NAME) {
        return Err(CodecError::TooLarge { len: long.trajectory.len(), max: MAX_LINEAGE_NAME });
    }
    let mut at = 0;
    let mut put = |bytes: &[u8]| {
        out[at..at + bytes.len()].copy_from_slice(bytes);
        at += bytes.len();
    };
    put(&[LINEAGE_VERSION, u8::from(lineage.complete), 0, 0]);
    put(&(lineage.inputs.len() as u32).to_le_bytes());
    for input in &lineage.inputs {
        put(&input.generation.to_le_bytes());
        put(&input.valid_time.to_le_bytes());
        put(&input.add_time.to_le_bytes());
        put(&(input.trajectory.len() as u16).to_le_bytes());
        put(input.trajectory.as_bytes());
    }
    Ok(at)
}

/// `lineage` as bytes.
pub fn encode_lineage(lineage: &Lineage) -> Result<Vec<u8>, CodecError> {
    let mut out = vec![0; lineage_len(lineage)];
    encode_lineage_into(lineage, &mut out)?;
    Ok(out)
}

/// Reads a lineage from bytes another process or a file wrote: every length is
/// checked against the bytes there are and against the limits, so malformed bytes are
/// an error, never a panic or an unbounded allocation. Bytes after the lineage are
/// ignored (a trailer sits in zero-filled slack).
pub fn decode_lineage(bytes: &[u8]) -> Result<Lineage, CodecError> {
    let bad = |reason: String| CodecError::Malformed { len: bytes.len(), reason };
    let mut r = Reader { bytes, at: 0 };
    let head = r.take(HEAD).ok_or_else(|| bad("lineage: shorter than its header".into()))?;
    if head[0] != LINEAGE_VERSION {
        return Err(bad(format!(
            "lineage: version {} (this reader knows {LINEAGE_VERSION})",
            head[0]
        )));
    }
    let complete = match head[1] {
        0 => false,
        1 => true,
        other => return Err(bad(format!("lineage: complete flag {other}"))),
    };
    let count = u32::from_le_bytes([head[4], head[5], head[6], head[7]]) as usize;
    if count > MAX_LINEAGE_INPUTS {
        return Err(bad(format!("lineage: {count} inputs (at most {MAX_LINEAGE_INPUTS})")));
    }
    let mut inputs = Vec::with_capacity(count.min(bytes.len() / PER_INPUT));
    for k in 0..count {
        let short = || bad(format!("lineage: input {k} of {count} is cut short"));
        let fixed = r.take(PER_INPUT).ok_or_else(short)?;
        let u64_at = |o: usize| {
            let mut b = [0; 8];
            b.copy_from_slice(&fixed[o..o + 8]);
            b
        };
        let name_len = usize::from(u16::from_le_bytes([fixed[24], fixed[25]]));
        if name_len > MAX_LINEAGE_NAME {
            return Err(bad(format!("lineage: input {k}'s name of {name_len} bytes")));
        }
        let name = r.take(name_len).ok_or_else(short)?;
        let trajectory = std::str::from_utf8(name)
            .map_err(|e| bad(format!("lineage: input {k}'s name is not UTF-8: {e}")))?;
        inputs.push(InputRef {
            trajectory: trajectory.to_owned(),
            generation: u64::from_le_bytes(u64_at(0)),
            valid_time: i64::from_le_bytes(u64_at(8)),
            add_time: i64::from_le_bytes(u64_at(16)),
        });
    }
    Ok(Lineage { inputs, complete })
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let out = self.bytes.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Lineage {
        Lineage {
            inputs: vec![
                InputRef {
                    trajectory: "camera".into(),
                    generation: 3,
                    valid_time: -5,
                    add_time: 7,
                },
                InputRef {
                    trajectory: "odométrie".into(),
                    generation: u64::MAX,
                    valid_time: i64::MAX,
                    add_time: i64::MIN,
                },
            ],
            complete: false,
        }
    }

    #[test]
    fn a_lineage_comes_back_as_it_went() {
        let bytes = encode_lineage(&sample()).unwrap();
        assert_eq!(bytes.len(), lineage_len(&sample()));
        assert_eq!(decode_lineage(&bytes).unwrap(), sample());
        let mut padded = bytes.clone();
        padded.extend([0; 40]);
        assert_eq!(decode_lineage(&padded).unwrap(), sample(), "slack after it is ignored");
        let empty = Lineage::of(Vec::new());
        assert_eq!(decode_lineage(&encode_lineage(&empty).unwrap()).unwrap(), empty);
    }

    #[test]
    fn malformed_lineage_bytes_are_errors_that_say_what() {
        let good = encode_lineage(&sample()).unwrap();
        let why = |bytes: &[u8]| match decode_lineage(bytes) {
            Err(CodecError::Malformed { reason, .. }) => reason,
            other => panic!("accepted {bytes:?}: {other:?}"),
        };
        assert!(why(&good[..3]).contains("header"));
        for cut in [HEAD, HEAD + 5, good.len() - 1] {
            assert!(why(&good[..cut]).contains("cut short"), "cut at {cut}");
        }
        let mut bytes = good.clone();
        bytes[0] = 9;
        assert!(why(&bytes).contains("version 9"));
        let mut bytes = good.clone();
        bytes[1] = 2;
        assert!(why(&bytes).contains("complete flag"));
        let mut bytes = good.clone();
        bytes[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(why(&bytes).contains("inputs (at most"));
        let mut bytes = good.clone();
        bytes[HEAD + 26] = 0xff;
        assert!(why(&bytes).contains("UTF-8"));
        let mut bytes = good;
        bytes[HEAD + 24..HEAD + 26].copy_from_slice(&u16::MAX.to_le_bytes());
        assert!(why(&bytes).contains("name of"));
    }

    #[test]
    fn a_lineage_too_large_is_refused_when_written() {
        let long = Lineage::of(vec![InputRef {
            trajectory: "x".repeat(MAX_LINEAGE_NAME + 1),
            generation: 0,
            valid_time: 0,
            add_time: 0,
        }]);
        assert!(matches!(encode_lineage(&long), Err(CodecError::TooLarge { .. })));
        let mut small = [0u8; 4];
        assert!(matches!(
            encode_lineage_into(&sample(), &mut small),
            Err(CodecError::BufferTooSmall { .. })
        ));
    }
}
