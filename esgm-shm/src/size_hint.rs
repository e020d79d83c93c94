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
//! vector header is 8 bytes, an archived `Value` at most 64 (its largest variant, a
//! 6-DoF pose, is 56 bytes plus the tag), and every out-of-line object may need up to
//! 15 bytes of alignment padding.

use esgm_core::codec::ENVELOPE_LEN;
use esgm_core::{AttributeValuePair, EntityFrame, EntityStructure, Value};

/// Root object of a structure (name, two times, attribute vector) plus padding.
const STRUCTURE_ROOT: usize = 48;
/// An attribute/value pair in the pair array (name header + value + padding).
const PAIR: usize = 96;
/// A value inside an `Agg` or `Collection` array.
const NESTED_VALUE: usize = 80;
/// A frame inside a frame sequence (name header + attribute vector + padding).
const NESTED_FRAME: usize = 32;
/// Alignment padding and header slack for one out-of-line object.
const SLACK: usize = 16;

/// An upper bound (in practice) of the bytes `codec::encode_into_uninit` writes for `es`,
/// envelope included.
pub fn archived_size_hint(es: &EntityStructure) -> usize {
    ENVELOPE_LEN + STRUCTURE_ROOT + string(&es.name) + pairs(&es.attributes)
}

fn string(s: &str) -> usize {
    s.len() + SLACK
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
        // Fixed-size values live inside the archived `Value` itself.
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::codec::encoded_len;
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
