//! Mutations of bytes: what a corrupt or hostile writer could do to a valid input.
//!
//! Besides bit flips, byte sets, truncation, extension, insertion, deletion and
//! splicing, the mutations aim at the fields that decide where a decoder reads:
//! 4- and 8-byte little-endian words (rkyv's relative offsets and lengths are 32-bit,
//! the envelope's and the header's lengths 64-bit) are overwritten with boundary
//! values (0, -1, the largest, the input's length and one off it) and with offsets that
//! point elsewhere in the input, at its end, or just past it.

use crate::rng::Rng;

/// The most bytes a mutation grows an input to.
pub const MAX_LEN: usize = 1 << 20;

const U32S: [u32; 22] = [
    0,
    1,
    2,
    4,
    7,
    8,
    15,
    16,
    17,
    63,
    64,
    65,
    127,
    128,
    255,
    256,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_fff0,
    0xffff_ffff,
];

const U64S: [u64; 10] =
    [0, 1, 16, 64, 1 << 31, 1 << 32, 1 << 48, i64::MAX as u64, 1 << 63, u64::MAX];

/// A 32-bit boundary value for a field at `pos` of an input of `len` bytes: a constant,
/// the length and one off it, or a relative offset from `pos` to the start, the end,
/// just past the end, or anywhere.
fn interesting_u32(rng: &mut Rng, pos: usize, len: usize) -> u32 {
    let len32 = len as u32;
    let here = pos as i64;
    match rng.below(6) {
        0 | 1 => *rng.pick(&U32S),
        2 => len32.wrapping_add(rng.below(3) as u32).wrapping_sub(1),
        3 => (-here) as u32,
        4 => (len as i64 - here + rng.below(3) as i64 - 1) as u32,
        _ => (rng.below(len + 1) as i64 - here) as u32,
    }
}

fn interesting_u64(rng: &mut Rng, len: usize) -> u64 {
    match rng.below(3) {
        0 => *rng.pick(&U64S),
        1 => (len as u64).wrapping_add(rng.below(3) as u64).wrapping_sub(1),
        _ => u64::from(*rng.pick(&U32S)),
    }
}

/// A position for a `width`-byte field, on a multiple of `width` three times in four
/// (archived fields are aligned).
fn field_at(rng: &mut Rng, len: usize, width: usize) -> Option<usize> {
    let last = len.checked_sub(width)?;
    let pos = rng.below(last + 1);
    Some(if rng.chance(75) { pos - pos % width } else { pos })
}

/// Applies one to eight random mutations to `data`; `others` are inputs to splice from.
pub fn mutate(rng: &mut Rng, data: &mut Vec<u8>, others: &[Vec<u8>]) {
    for _ in 0..1 + rng.below(8) {
        mutate_once(rng, data, others);
    }
    data.truncate(MAX_LEN);
}

/// Applies one random mutation to `data`.
pub fn mutate_once(rng: &mut Rng, data: &mut Vec<u8>, others: &[Vec<u8>]) {
    let len = data.len();
    match rng.below(14) {
        0 if len > 0 => {
            let at = rng.below(len);
            data[at] ^= 1 << rng.below(8);
        }
        1 if len > 0 => {
            let at = rng.below(len);
            data[at] = *rng.pick(&[0u8, 1, 0x7f, 0x80, 0xfe, 0xff]);
        }
        2 if len > 0 => {
            let at = rng.below(len);
            data[at] = rng.next_u64() as u8;
        }
        3..=5 => {
            if let Some(at) = field_at(rng, len, 4) {
                let v = interesting_u32(rng, at, len);
                data[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        6 => {
            if let Some(at) = field_at(rng, len, 8) {
                let v = interesting_u64(rng, len);
                data[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        7 => {
            if let Some(at) = field_at(rng, len, 4) {
                let mut w = [0u8; 4];
                w.copy_from_slice(&data[at..at + 4]);
                let delta = 1 + rng.below(16) as u32;
                let v = u32::from_le_bytes(w);
                let v = if rng.chance(50) { v.wrapping_add(delta) } else { v.wrapping_sub(delta) };
                data[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        8 => data.truncate(rng.below(len + 1)),
        9 => {
            let n = rng.len(4096);
            if rng.chance(50) {
                data.resize(len + n, 0);
            } else {
                data.extend(rng.bytes(n));
            }
        }
        10 => {
            let at = rng.below(len + 1);
            let n = 1 + rng.below(16);
            let bytes = rng.bytes(n);
            data.splice(at..at, bytes);
        }
        11 if len > 0 => {
            let at = rng.below(len);
            let n = 1 + rng.below((len - at).min(64));
            data.drain(at..at + n);
        }
        12 if len > 1 => {
            // A piece of the input copied over another place of it.
            let from = rng.below(len);
            let n = 1 + rng.below((len - from).min(256));
            let to = rng.below(len);
            let piece = data[from..from + n].to_vec();
            let end = (to + n).min(len);
            data[to..end].copy_from_slice(&piece[..end - to]);
        }
        _ if !others.is_empty() => {
            // Splice: a head of this input and a tail of another.
            let other = rng.pick(others);
            let cut = rng.below(len + 1);
            let from = rng.below(other.len() + 1);
            data.truncate(cut);
            data.extend_from_slice(&other[from..]);
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_change_inputs_and_stay_bounded() {
        let seed: Vec<u8> = (0..200u8).collect();
        let mut changed = 0;
        for i in 0..2_000 {
            let mut rng = Rng::for_case(3, i);
            let mut data = seed.clone();
            mutate(&mut rng, &mut data, std::slice::from_ref(&seed));
            assert!(data.len() <= MAX_LEN);
            changed += usize::from(data != seed);
        }
        assert!(changed > 1_800, "only {changed} of 2000 mutated");
    }
}
