//! Property tests of the codec: random entity structures round-trip through
//! `encode` / `access` / `decode`, and corrupted buffers never crash the reader.
//!
//! Doubles are drawn from every class, NaN included: a NaN makes `PartialEq` useless,
//! so the round trip is also checked by re-encoding, which compares bits.

// Helpers outside `#[test]` functions: a panic there is a failed test with a message.
#![allow(clippy::unwrap_used)]

use std::io::Write;
use std::ops::DerefMut;

use esgm_core::codec::{self, ARCHIVE_ALIGNMENT, ENVELOPE_LEN, access, decode, encode};
use esgm_core::{
    AttributeValuePair, EntityFrame, EntityStructure, Octets, Pos2, Position, PositionAltitude,
    PositionAltitudeRotation, Rotation, Value, Vec3,
};
use proptest::prelude::*;

/// Short strings over all of Unicode (not only ASCII): the archived form must keep
/// every code point and the validator must check UTF-8 in place.
fn text() -> impl Strategy<Value = String> {
    "\\PC{0,8}"
}

fn double() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1e6f64..1e6,
        1 => any::<f64>(),
        1 => prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(-0.0),
            Just(f64::MIN_POSITIVE / 2.0),
        ],
    ]
}

fn vec3() -> impl Strategy<Value = Vec3> {
    (double(), double(), double()).prop_map(|(x, y, z)| Vec3 { x, y, z })
}

fn pos2() -> impl Strategy<Value = Pos2> {
    (double(), double()).prop_map(|(x, y)| Pos2 { x, y })
}

fn position() -> impl Strategy<Value = Position> {
    (double(), double()).prop_map(|(north, east)| Position { north, east })
}

fn rotation() -> impl Strategy<Value = Rotation> {
    (double(), double(), double()).prop_map(|(roll, pitch, yaw)| Rotation { roll, pitch, yaw })
}

fn short<T: std::fmt::Debug>(s: impl Strategy<Value = T>) -> impl Strategy<Value = Vec<T>> {
    proptest::collection::vec(s, 0..4)
}

fn leaf() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::NoValue),
        any::<i64>().prop_map(Value::Long),
        double().prop_map(Value::Double),
        any::<bool>().prop_map(Value::Bool),
        text().prop_map(Value::String),
        any::<i64>().prop_map(Value::Time),
        text().prop_map(Value::Symbol),
        proptest::collection::vec(any::<u8>(), 0..48)
            .prop_map(|b| Value::OctetSeq(Octets::from(b))),
        short(any::<i64>()).prop_map(Value::LongSeq),
        short(double()).prop_map(Value::DoubleSeq),
        short(text()).prop_map(Value::SymbolSeq),
        vec3().prop_map(Value::Vec),
        short(vec3()).prop_map(Value::VecSeq),
        pos2().prop_map(Value::Pos2),
        short(pos2()).prop_map(Value::Pos2Seq),
        position().prop_map(Value::Position),
        double().prop_map(Value::Altitude),
        rotation().prop_map(Value::Rotation),
        (position(), double()).prop_map(|(position, altitude)| Value::PositionAltitude(
            PositionAltitude { position, altitude }
        )),
        (position(), double(), rotation()).prop_map(|(position, altitude, rotation)| {
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position,
                altitude,
                rotation,
            })
        }),
    ]
}

fn frame_of(value: impl Strategy<Value = Value> + Clone) -> impl Strategy<Value = EntityFrame> {
    (text(), short((text(), value))).prop_map(|(name, attributes)| {
        attributes.into_iter().fold(EntityFrame::new(name), |f, (a, v)| f.with(a, v))
    })
}

/// Values nested up to three levels deep: aggregates, collections, frames and frame
/// sequences holding any value, frames included.
fn value() -> impl Strategy<Value = Value> {
    leaf().prop_recursive(3, 24, 4, |inner| {
        prop_oneof![
            short(inner.clone()).prop_map(Value::Agg),
            short(inner.clone()).prop_map(Value::Collection),
            frame_of(inner.clone()).prop_map(|f| Value::EntityFrame(Box::new(f))),
            short(frame_of(inner)).prop_map(Value::EntityFrameSeq),
        ]
    })
}

fn structure() -> impl Strategy<Value = EntityStructure> {
    (text(), any::<i64>(), any::<i64>(), proptest::collection::vec((text(), value()), 0..6))
        .prop_map(|(name, valid_time, create_time, attributes)| {
            // Duplicate names are kept: the codec must not care what the type checker
            // would say.
            let mut es = EntityStructure::new(name, valid_time, create_time);
            es.attributes.extend(
                attributes.into_iter().map(|(name, value)| AttributeValuePair { name, value }),
            );
            es
        })
}

/// What the helpers below need of the buffer `encode` returns (an aligned vector whose
/// type only the codec names): a fresh one is aligned for the archive, and can be
/// written to and indexed.
trait Buffer: Default + Write + DerefMut<Target = [u8]> {}
impl<B: Default + Write + DerefMut<Target = [u8]>> Buffer for B {}

/// A fresh buffer of the same kind as `like`, holding a copy of `bytes` (the way a
/// reader copies received bytes into memory aligned for the archive).
fn aligned_like<B: Buffer>(_like: &B, bytes: &[u8]) -> B {
    let mut b = B::default();
    b.write_all(bytes).unwrap();
    // An empty buffer has no allocation (a dangling pointer), so nothing to align.
    if !b.is_empty() {
        assert_eq!(b.as_ptr() as usize % ARCHIVE_ALIGNMENT, 0);
    }
    b
}

/// The archive length in the envelope, rewritten to match the buffer: without this, a
/// truncated or extended buffer never gets past the envelope check, and the archive
/// validator itself would not be exercised.
fn fix_envelope(b: &mut [u8]) {
    if b.len() >= ENVELOPE_LEN {
        let archive_len = (b.len() - ENVELOPE_LEN) as u64;
        b[8..16].copy_from_slice(&archive_len.to_le_bytes());
    }
}

/// A corruption of an encoded buffer.
#[derive(Debug, Clone)]
enum Corruption {
    /// XOR the byte at `at` (a fraction of the length) with a non-zero mask.
    Flip { at: f64, mask: u8 },
    /// Keep only a fraction of the bytes.
    Truncate(f64),
    /// Append bytes.
    Extend(Vec<u8>),
}

fn corruption() -> impl Strategy<Value = Corruption> {
    prop_oneof![
        6 => (0.0..1.0f64, 1u8..=255).prop_map(|(at, mask)| Corruption::Flip { at, mask }),
        2 => (0.0..1.0f64).prop_map(Corruption::Truncate),
        2 => proptest::collection::vec(any::<u8>(), 1..32).prop_map(Corruption::Extend),
    ]
}

fn corrupt<B: Buffer>(bytes: &B, how: &[Corruption], fix: bool) -> B {
    let mut v = bytes.to_vec();
    for c in how {
        match c {
            Corruption::Flip { at, mask } if !v.is_empty() => {
                let i = ((v.len() as f64 * at) as usize).min(v.len() - 1);
                v[i] ^= mask;
            }
            Corruption::Flip { .. } => {}
            Corruption::Truncate(keep) => v.truncate((v.len() as f64 * keep) as usize),
            Corruption::Extend(more) => v.extend_from_slice(more),
        }
    }
    let mut b = aligned_like(bytes, &v);
    if fix {
        fix_envelope(&mut b);
    }
    b
}

proptest! {
    #[test]
    fn structures_round_trip(es in structure()) {
        let bytes = encode(&es).unwrap();
        prop_assert_eq!(bytes.as_ptr() as usize % ARCHIVE_ALIGNMENT, 0);
        let archived = access(&bytes).unwrap();
        prop_assert_eq!(archived.valid_time, es.valid_time);
        prop_assert_eq!(archived.create_time, es.create_time);
        prop_assert_eq!(archived.name.as_str(), es.name.as_str());
        prop_assert_eq!(archived.attributes.len(), es.attributes.len());
        let back = decode(archived).unwrap();
        // Bit-exact (NaN included): the same structure encodes to the same bytes.
        let again = encode(&back).unwrap();
        prop_assert_eq!(again.as_slice(), bytes.as_slice());
        // Self-equality fails only with a NaN somewhere; otherwise compare values.
        #[allow(clippy::eq_op)]
        let comparable = es == es;
        if comparable {
            prop_assert_eq!(&back, &es);
        }
        // A copy in another aligned buffer (what a reader of shared memory sees)
        // reads the same.
        let copy = aligned_like(&bytes, &bytes);
        let from_copy = encode(&decode(access(&copy).unwrap()).unwrap()).unwrap();
        prop_assert_eq!(from_copy.as_slice(), bytes.as_slice());
        // encode_into writes the same bytes into a caller's aligned slice.
        let mut out = aligned_like(&bytes, &vec![0u8; bytes.len()]);
        let n = codec::encode_into(&es, &mut out).unwrap();
        prop_assert_eq!(&out[..n], bytes.as_slice());
    }

    #[test]
    fn corrupted_buffers_are_rejected_or_readable(
        es in structure(),
        how in proptest::collection::vec(corruption(), 1..4),
        fix in any::<bool>(),
    ) {
        let bytes = encode(&es).unwrap();
        let bad = corrupt(&bytes, &how, fix);
        // Never a panic: either an error, or a structure decode can read in full.
        if let Ok(archived) = access(&bad) {
            let decoded = decode(archived);
            prop_assert!(decoded.is_ok(), "accepted but not decodable: {:?}", decoded.err());
        }
    }

    #[test]
    fn random_bytes_are_rejected_or_readable(
        body in proptest::collection::vec(any::<u8>(), 0..256),
        fix in any::<bool>(),
    ) {
        // A valid envelope in front of garbage, so the archive validator sees it.
        let mut v = b"ESGM".to_vec();
        v.extend_from_slice(&codec::FORMAT_VERSION.to_le_bytes());
        v.extend_from_slice(&[0u8; 8]);
        v.extend_from_slice(&body);
        let template = encode(&EntityStructure::default()).unwrap();
        let mut b = aligned_like(&template, &v);
        if fix {
            fix_envelope(&mut b);
        }
        if let Ok(archived) = access(&b) {
            prop_assert!(decode(archived).is_ok());
        }
    }
}
