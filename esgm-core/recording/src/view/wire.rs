//! The protobuf wire format, as far as the views need it: varints, tags,
//! length-delimited and fixed-width fields, and a reader that reports offsets.

use super::DecodeError;

/// Wire type of varint fields (int32, int64, bool, enums).
pub(crate) const VARINT: u8 = 0;
/// Wire type of 64-bit fixed fields.
pub(crate) const I64: u8 = 1;
/// Wire type of length-delimited fields (strings, bytes, messages).
pub(crate) const LEN: u8 = 2;
/// Wire type of 32-bit fixed fields (fixed32, float).
pub(crate) const I32: u8 = 5;

/// Appends `v` as a base-128 varint.
pub(crate) fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The number of bytes [`put_varint`] writes for `v`.
pub(crate) fn varint_len(v: u64) -> usize {
    // 1 byte per started group of 7 bits; 0 still takes a byte.
    (64 - (v | 1).leading_zeros() as usize).div_ceil(7)
}

/// Appends a field's tag.
pub(crate) fn put_tag(out: &mut Vec<u8>, field: u32, wire_type: u8) {
    put_varint(out, (u64::from(field) << 3) | u64::from(wire_type));
}

/// Appends a length-delimited field holding `bytes`; returns where `bytes` landed.
pub(crate) fn put_len(out: &mut Vec<u8>, field: u32, bytes: &[u8]) -> std::ops::Range<usize> {
    put_tag(out, field, LEN);
    put_varint(out, bytes.len() as u64);
    let start = out.len();
    out.extend_from_slice(bytes);
    start..out.len()
}

/// Appends a fixed32 field.
pub(crate) fn put_fixed32(out: &mut Vec<u8>, field: u32, v: u32) {
    put_tag(out, field, I32);
    out.extend_from_slice(&v.to_le_bytes());
}

/// Appends a varint field.
pub(crate) fn put_varint_field(out: &mut Vec<u8>, field: u32, v: u64) {
    put_tag(out, field, VARINT);
    put_varint(out, v);
}

/// A field's payload as read from the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Payload {
    /// A varint's value.
    Varint(u64),
    /// A 64-bit fixed value.
    I64(u64),
    /// The byte range of a length-delimited field's contents.
    Len(usize, usize),
    /// A 32-bit fixed value.
    I32(u32),
}

impl Payload {
    pub(crate) fn wire_type(self) -> u8 {
        match self {
            Payload::Varint(_) => VARINT,
            Payload::I64(_) => I64,
            Payload::Len(..) => LEN,
            Payload::I32(_) => I32,
        }
    }
}

/// One field read: its number, its payload and where its tag started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Field {
    pub(crate) number: u64,
    pub(crate) payload: Payload,
    pub(crate) offset: usize,
}

impl Field {
    /// An error for a field whose wire type is not `expected`.
    pub(crate) fn wrong_wire_type(&self, expected: u8) -> DecodeError {
        DecodeError::WrongWireType {
            field: self.number,
            expected,
            found: self.payload.wire_type(),
            offset: self.offset,
        }
    }
}

/// Reads the fields of `bytes[start..end]` one after another. Offsets are into `bytes`,
/// so errors inside a nested message name their place in the whole message.
#[derive(Debug)]
pub(crate) struct FieldReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    end: usize,
}

impl<'a> FieldReader<'a> {
    /// A reader over `bytes[start..end]`; the caller guarantees the range is in bounds.
    pub(crate) fn new(bytes: &'a [u8], start: usize, end: usize) -> Self {
        FieldReader { bytes, pos: start, end }
    }

    fn varint(&mut self) -> Result<u64, DecodeError> {
        let start = self.pos;
        let mut value = 0u64;
        for i in 0..10 {
            let Some(&b) = self.bytes[..self.end].get(self.pos) else {
                return Err(DecodeError::Truncated { offset: start, needed: 1 });
            };
            self.pos += 1;
            value |= u64::from(b & 0x7f) << (7 * i);
            if b < 0x80 {
                return Ok(value);
            }
        }
        Err(DecodeError::VarintTooLong { offset: start })
    }

    fn take(&mut self, n: usize, item_offset: usize) -> Result<usize, DecodeError> {
        let left = self.end - self.pos;
        if n > left {
            return Err(DecodeError::Truncated { offset: item_offset, needed: n - left });
        }
        let start = self.pos;
        self.pos += n;
        Ok(start)
    }

    /// The next field, or `None` at the end.
    pub(crate) fn next_field(&mut self) -> Result<Option<Field>, DecodeError> {
        if self.pos >= self.end {
            return Ok(None);
        }
        let offset = self.pos;
        let tag = self.varint()?;
        let number = tag >> 3;
        let wire_type = (tag & 7) as u8;
        if number == 0 {
            return Err(DecodeError::FieldZero { offset });
        }
        let payload = match wire_type {
            VARINT => Payload::Varint(self.varint()?),
            I64 => {
                let at = self.take(8, offset)?;
                let mut b = [0u8; 8];
                b.copy_from_slice(&self.bytes[at..at + 8]);
                Payload::I64(u64::from_le_bytes(b))
            }
            LEN => {
                let len_offset = self.pos;
                let len = self.varint()?;
                let left = self.end - self.pos;
                let len = match usize::try_from(len) {
                    Ok(len) if len <= left => len,
                    _ => {
                        let needed = usize::try_from(len).unwrap_or(usize::MAX) - left;
                        return Err(DecodeError::Truncated { offset: len_offset, needed });
                    }
                };
                let at = self.take(len, len_offset)?;
                Payload::Len(at, at + len)
            }
            I32 => {
                let at = self.take(4, offset)?;
                let mut b = [0u8; 4];
                b.copy_from_slice(&self.bytes[at..at + 4]);
                Payload::I32(u32::from_le_bytes(b))
            }
            _ => return Err(DecodeError::UnsupportedWireType { field: number, wire_type, offset }),
        };
        Ok(Some(Field { number, payload, offset }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_round_trip_and_have_their_length() {
        for v in [0, 1, 127, 128, 300, 16_383, 16_384, u64::from(u32::MAX), u64::MAX] {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            assert_eq!(out.len(), varint_len(v), "{v}");
            put_varint_field(&mut out, 1, v);
            let mut r = FieldReader::new(&out, varint_len(v), out.len());
            let f = r.next_field().unwrap().unwrap();
            assert_eq!((f.number, f.payload), (1, Payload::Varint(v)));
            assert_eq!(r.next_field().unwrap(), None);
        }
        // The protobuf documentation's example: 150 is 96 01.
        let mut out = Vec::new();
        put_varint(&mut out, 150);
        assert_eq!(out, [0x96, 0x01]);
    }

    #[test]
    fn damaged_input_names_the_offset() {
        // A length-delimited field claiming 5 bytes with 2 present.
        let bytes = [0x0a, 0x05, 1, 2];
        let err = FieldReader::new(&bytes, 0, 4).next_field().unwrap_err();
        assert_eq!(err, DecodeError::Truncated { offset: 1, needed: 3 });
        // Eleven continuation bytes.
        let bytes = [0x08, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01];
        let err = FieldReader::new(&bytes, 0, bytes.len()).next_field().unwrap_err();
        assert_eq!(err, DecodeError::VarintTooLong { offset: 1 });
        // Wire type 3 (start group).
        let bytes = [0x0b];
        let err = FieldReader::new(&bytes, 0, 1).next_field().unwrap_err();
        assert_eq!(err, DecodeError::UnsupportedWireType { field: 1, wire_type: 3, offset: 0 });
        // A fixed32 cut short, and field number 0.
        let err = FieldReader::new(&[0x15, 1, 2], 0, 3).next_field().unwrap_err();
        assert_eq!(err, DecodeError::Truncated { offset: 0, needed: 2 });
        let err = FieldReader::new(&[0x00, 0], 0, 2).next_field().unwrap_err();
        assert_eq!(err, DecodeError::FieldZero { offset: 0 });
    }

    #[test]
    fn a_reader_stops_at_its_end_not_the_buffers() {
        let mut out = Vec::new();
        put_fixed32(&mut out, 2, 7);
        put_fixed32(&mut out, 3, 8);
        let mut r = FieldReader::new(&out, 0, 5);
        assert_eq!(r.next_field().unwrap().unwrap().payload, Payload::I32(7));
        assert_eq!(r.next_field().unwrap(), None);
        // A varint that would continue past the reader's end is truncated there.
        let bytes = [0x08, 0x80, 0x01];
        let err = FieldReader::new(&bytes, 0, 2).next_field().unwrap_err();
        assert_eq!(err, DecodeError::Truncated { offset: 1, needed: 1 });
    }
}
