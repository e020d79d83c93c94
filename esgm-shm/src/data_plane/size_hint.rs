//! How many payload bytes to loan for a structure, without encoding it first.
//!
//! Two ways to size a loan: this module's [`archived_size_hint`], a walk over the
//! structure adding a generous bound for each node of the archived form, or
//! `esgm_core::codec::encoded_len`, which is exact (a full serialization into a
//! counting writer: no allocation and no copy of octet bytes, but every node is
//! serialized). The publisher uses the hint: measuring exactly and then encoding runs
//! the serializer twice, while an over-estimate costs only zeroing the unused tail of
//! the loan, a few dozen bytes per node — cheaper than a serialization pass at every
//! size. Where the hint is not tight enough to be trusted is the sample-size limit: a
//! hint above the publisher's configured maximum could grow the segment (or fail a
//! fixed-size loan) for a structure that fits, so there the publisher asks
//! `encoded_len` instead (see `publisher.rs`).
//!
//! The bound is meant to be an over-estimate (the unit tests check it against the
//! codec for every value sort); if it is ever short, `encode_into_uninit` reports the
//! size it needs and the publisher retries once with exactly that, so a wrong hint
//! costs time, never correctness.
//!
//! The per-node constants are upper bounds of rkyv 0.8's archived sizes: a string or
//! vector header is 8 bytes (a string of up to 8 bytes lives inside it), an archived
//! `Value` 16 (variants larger than 8 bytes, the geometric ones, are boxed out of
//! line), and every out-of-line object may need up to 7 bytes of alignment padding
//! (nothing in the archive is aligned to more than 8). The hint is kept tight because
//! its excess is zeroed in shared memory on every publish: bytes the reader's core
//! must give up its copy of.

use esgm_core::codec::ENVELOPE_LEN;
use esgm_core::{AttributeValuePair, EntityFrame, EntityStructure, Value};

/// Root object of a structure (name, two times, attribute vector) plus padding.
const STRUCTURE_ROOT: usize = 40;
/// An attribute/value pair in the pair array (name header + value).
const PAIR: usize = 24;
/// A value inside an `Agg` or `Collection` array.
const NESTED_VALUE: usize = 16;
/// A frame inside a frame sequence (name header + attribute vector).
const NESTED_FRAME: usize = 16;
/// Alignment padding for one out-of-line object.
const SLACK: usize = 8;
/// Strings this long or shorter are stored inside their header.
const INLINE_STRING: usize = 8;

/// An upper bound (in practice) of the bytes `codec::encode_into_uninit` writes for `es`,
/// envelope included.
pub fn archived_size_hint(es: &EntityStructure) -> usize {
    ENVELOPE_LEN + STRUCTURE_ROOT + string(&es.name) + pairs(&es.attributes)
}

fn string(s: &str) -> usize {
    if s.len() <= INLINE_STRING { 0 } else { s.len() + SLACK }
}

fn pairs(attributes: &[AttributeValuePair]) -> usize {
    SLACK + attributes.iter().map(|p| PAIR + string(&p.name) + value(&p.value)).sum::<usize>()
}

fn frame(f: &EntityFrame) -> usize {
    string(&f.name) + pairs(&f.attributes)
}

/// Out-of-line bytes of a value (what its archived header points to).
fn value(v: &Value) -> usize {
    match v {
        Value::String(s) | Value::Symbol(s) => string(s),
        Value::OctetSeq(o) => o.len() + SLACK,
        Value::LongSeq(v) => 8 * v.len() + SLACK,
        Value::DoubleSeq(v) => 8 * v.len() + SLACK,
        Value::SymbolSeq(v) => SLACK + v.iter().map(|s| SLACK + string(s)).sum::<usize>(),
        Value::VecSeq(v) => 24 * v.len() + SLACK,
        Value::Pos2Seq(v) => 16 * v.len() + SLACK,
        Value::Agg(v) | Value::Collection(v) => {
            SLACK + v.iter().map(|x| NESTED_VALUE + value(x)).sum::<usize>()
        }
        Value::EntityFrame(f) => NESTED_FRAME + SLACK + frame(f),
        Value::EntityFrameSeq(v) => {
            SLACK + v.iter().map(|f| NESTED_FRAME + frame(f)).sum::<usize>()
        }
        // Boxed out of line: 16 to 48 bytes of doubles.
        Value::Vec(_) | Value::Rotation(_) | Value::PositionAltitude(_) => 24 + SLACK,
        Value::Pos2(_) | Value::Position(_) => 16 + SLACK,
        Value::PositionAltitudeRotation(_) => 48 + SLACK,
        // Up to 8 bytes: inside the archived `Value` itself.
        Value::NoValue
        | Value::Long(_)
        | Value::Double(_)
        | Value::Bool(_)
        | Value::Time(_)
        | Value::Altitude(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::codec::encoded_len;
    use esgm_core::value::{Position, PositionAltitude, Rotation};
    use esgm_core::{Octets, Pos2, PositionAltitudeRotation, Vec3};

    fn every_sort() -> Vec<Value> {
        let frame = EntityFrame::new("blob_with_a_long_name").with("x", 1i64).with("y", 2.5);
        vec![
            Value::NoValue,
            Value::Long(-1),
            Value::Double(1.5),
            Value::Bool(true),
            Value::String("a string longer than the inline limit".into()),
            Value::String("short".into()),
            Value::Time(5),
            Value::Symbol("sym".into()),
            Value::OctetSeq(Octets::from(vec![1u8; 1001])),
            Value::LongSeq(vec![1, 2, 3]),
            Value::DoubleSeq(vec![1.0; 7]),
            Value::SymbolSeq(vec!["a".into(), "a much longer symbol name".into()]),
            Value::Vec(Vec3::default()),
            Value::VecSeq(vec![Vec3::default(); 3]),
            Value::Pos2(Pos2::default()),
            Value::Pos2Seq(vec![Pos2::default(); 5]),
            Value::Altitude(3.0),
            Value::Position(Position::default()),
            Value::Rotation(Rotation::default()),
            Value::PositionAltitude(PositionAltitude::default()),
            Value::PositionAltitudeRotation(PositionAltitudeRotation::default()),
            Value::Agg(vec![Value::Long(1), Value::String("nested string value".into())]),
            Value::Collection(vec![Value::Agg(vec![Value::Bool(false)])]),
            Value::EntityFrame(Box::new(frame.clone())),
            Value::EntityFrameSeq(vec![frame.clone(), frame]),
        ]
    }

    #[test]
    fn hint_bounds_every_sort_alone_and_together() {
        let mut all = EntityStructure::new("entity_name_longer_than_eight", 1, 2);
        for (i, v) in every_sort().into_iter().enumerate() {
            let alone = EntityStructure::new("e", 1, 2).with("attribute", v.clone());
            let hint = archived_size_hint(&alone);
            let actual = encoded_len(&alone).unwrap();
            assert!(hint >= actual, "sort #{i} {v:?}: hint {hint} < actual {actual}");
            all.set(format!("attr_{i}"), v);
        }
        let hint = archived_size_hint(&all);
        let actual = encoded_len(&all).unwrap();
        assert!(hint >= actual, "hint {hint} < actual {actual}");
    }

    #[test]
    fn hint_stays_close_for_a_robot_state() {
        let robot =
            EntityStructure::new("robot1", 1, 2).with("x", 1.0).with("y", 2.0).with("dir", 0.5);
        let hint = archived_size_hint(&robot);
        let actual = encoded_len(&robot).unwrap();
        assert!(hint >= actual && hint - actual <= 32, "hint {hint}, actual {actual}");
    }

    #[test]
    fn hint_stays_close_for_images() {
        let img = EntityStructure::new("cam", 1, 2)
            .with("width", 640i64)
            .with("height", 480i64)
            .with("format", 0i64)
            .with("image_data", Octets::from(vec![0u8; 921_600]));
        let hint = archived_size_hint(&img);
        let actual = encoded_len(&img).unwrap();
        assert!(hint >= actual && hint - actual < 1024, "hint {hint}, actual {actual}");
    }
}
