//! Value approximation and merge rules (T2, G1, seed 3.3.4.1): how a value is estimated
//! at a time-point with no sample, and how several samples at one time-point become one.
//!
//! Numeric attributes (integers, floats, times, and the geometric tuples) are
//! interpolated or averaged component-wise; nested frames recursively; every other
//! attribute takes the most recent value. Angles are interpolated linearly without
//! wrap-around (a heading of 350° to 10° passes through 180°); interpolate a unit
//! vector instead where that matters.

use crate::frame::{AttributeValuePair, EntityFrame, EntityStructure};
use crate::time::Time;
use crate::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, Vec3,
};

/// How to answer "the value at `t`" when no sample has valid time `t` (the seed's
/// `ValueApproximationConstraint`).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub enum ValueApproximation {
    /// No approximation: `ValueNotAvailable` unless a sample is valid exactly at `t`.
    #[default]
    None,
    /// The sample whose valid time is closest to `t`, before or after (before wins a tie).
    Closest,
    /// The sample with the largest valid time before `t` (`get_closest_at_or_before`).
    MostRecent,
    /// These attribute values, valid at `t`, created at the query time.
    Default(Vec<AttributeValuePair>),
    /// Linear interpolation between the closest samples before and after `t`.
    Linear,
}

/// How several samples with one valid time become one value (the seed's merge
/// constraint).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum MergeRule {
    /// The sample created first.
    KeepFirst,
    /// The sample created last.
    #[default]
    KeepLast,
    /// The average of numeric attributes (others from the last created).
    Average,
    /// The median of numeric attributes (others from the last created).
    Median,
}

/// Interpolates between structures `a` (valid before `t`) and `b` (valid after `t`),
/// producing a structure valid at `t` created at `query_time`.
pub fn interpolate(
    a: &EntityStructure,
    b: &EntityStructure,
    t: Time,
    query_time: Time,
) -> EntityStructure {
    // Differences in i128 (extreme i64 times overflow i64), then f64: converting the
    // absolute times first would lose the nanoseconds of wall-clock times (~1.7e18).
    let span = (i128::from(b.valid_time) - i128::from(a.valid_time)) as f64;
    let offset = (i128::from(t) - i128::from(a.valid_time)) as f64;
    let f = if span > 0.0 { offset / span } else { 0.0 };
    EntityStructure {
        name: a.name.clone(),
        valid_time: t,
        create_time: query_time,
        attributes: lerp_attributes(&a.attributes, &b.attributes, f),
    }
}

fn lerp_attributes(
    a: &[AttributeValuePair],
    b: &[AttributeValuePair],
    f: f64,
) -> Vec<AttributeValuePair> {
    a.iter()
        .map(|pa| {
            let value = match b.iter().find(|pb| pb.name == pa.name) {
                Some(pb) => lerp_value(&pa.value, &pb.value, f),
                None => pa.value.clone(),
            };
            AttributeValuePair { name: pa.name.clone(), value }
        })
        .collect()
}

fn l(a: f64, b: f64, f: f64) -> f64 {
    a + (b - a) * f
}

fn li(a: i64, b: i64, f: f64) -> i64 {
    // In f64: `b - a` overflows i64 for far-apart values; `as` saturates.
    (a as f64 + (b as f64 - a as f64) * f).round() as i64
}

fn lpos(a: &Position, b: &Position, f: f64) -> Position {
    Position { north: l(a.north, b.north, f), east: l(a.east, b.east, f) }
}

fn lrot(a: &Rotation, b: &Rotation, f: f64) -> Rotation {
    Rotation { roll: l(a.roll, b.roll, f), pitch: l(a.pitch, b.pitch, f), yaw: l(a.yaw, b.yaw, f) }
}

fn lvec(a: &Vec3, b: &Vec3, f: f64) -> Vec3 {
    Vec3 { x: l(a.x, b.x, f), y: l(a.y, b.y, f), z: l(a.z, b.z, f) }
}

/// Interpolates two values of the same numeric sort at fraction `f` (0 = `a`,
/// 1 = `b`); any other pair yields `a` (the most recent value before `t`).
pub fn lerp_value(a: &Value, b: &Value, f: f64) -> Value {
    match (a, b) {
        (Value::Long(x), Value::Long(y)) => Value::Long(li(*x, *y, f)),
        (Value::Time(x), Value::Time(y)) => Value::Time(li(*x, *y, f)),
        (Value::Double(x), Value::Double(y)) => Value::Double(l(*x, *y, f)),
        (Value::Altitude(x), Value::Altitude(y)) => Value::Altitude(l(*x, *y, f)),
        (Value::Pos2(x), Value::Pos2(y)) => {
            Value::Pos2(Pos2 { x: l(x.x, y.x, f), y: l(x.y, y.y, f) })
        }
        (Value::Position(x), Value::Position(y)) => Value::Position(lpos(x, y, f)),
        (Value::Rotation(x), Value::Rotation(y)) => Value::Rotation(lrot(x, y, f)),
        (Value::Vec(x), Value::Vec(y)) => Value::Vec(lvec(x, y, f)),
        (Value::PositionAltitude(x), Value::PositionAltitude(y)) => {
            Value::PositionAltitude(PositionAltitude {
                position: lpos(&x.position, &y.position, f),
                altitude: l(x.altitude, y.altitude, f),
            })
        }
        (Value::PositionAltitudeRotation(x), Value::PositionAltitudeRotation(y)) => {
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: lpos(&x.position, &y.position, f),
                altitude: l(x.altitude, y.altitude, f),
                rotation: lrot(&x.rotation, &y.rotation, f),
            })
        }
        (Value::LongSeq(x), Value::LongSeq(y)) if x.len() == y.len() => {
            Value::LongSeq(x.iter().zip(y).map(|(a, b)| li(*a, *b, f)).collect())
        }
        (Value::DoubleSeq(x), Value::DoubleSeq(y)) if x.len() == y.len() => {
            Value::DoubleSeq(x.iter().zip(y).map(|(a, b)| l(*a, *b, f)).collect())
        }
        (Value::EntityFrame(x), Value::EntityFrame(y)) => {
            Value::EntityFrame(Box::new(EntityFrame {
                name: x.name.clone(),
                attributes: lerp_attributes(&x.attributes, &y.attributes, f),
            }))
        }
        _ => a.clone(),
    }
}

/// Merges structures that share a valid time (non-empty, in add order) by `rule`.
/// The result keeps the valid time; its create time is that of the sample it was
/// chosen from or, for average and median, the latest create time.
pub fn merge(group: &[&EntityStructure], rule: MergeRule) -> Option<EntityStructure> {
    // Ties in create time go to the later-added sample for KeepLast, the earlier for
    // KeepFirst.
    let first =
        group.iter().enumerate().min_by_key(|(i, e)| (e.create_time, *i)).map(|(_, e)| *e)?;
    let last =
        group.iter().enumerate().max_by_key(|(i, e)| (e.create_time, *i)).map(|(_, e)| *e)?;
    match rule {
        MergeRule::KeepFirst => Some(first.clone()),
        MergeRule::KeepLast => Some(last.clone()),
        MergeRule::Average => {
            // A running mean in floating point (integers are rounded once, at the end):
            // after k samples, mean_k = lerp(mean_{k-1}, x_k, 1/k).
            let mut acc = lift(&group[0].attributes);
            for (k, e) in group.iter().enumerate().skip(1) {
                acc = lerp_attributes(&acc, &lift(&e.attributes), 1.0 / (k as f64 + 1.0));
            }
            let mean = lower(acc, &last.attributes);
            Some(with_attributes(last, fill_non_numeric(mean, &last.attributes)))
        }
        MergeRule::Median => {
            let attributes = last
                .attributes
                .iter()
                .map(|p| {
                    let values: Vec<&Value> = group.iter().filter_map(|e| e.get(&p.name)).collect();
                    AttributeValuePair {
                        name: p.name.clone(),
                        value: median_value(&p.value, &values),
                    }
                })
                .collect();
            Some(with_attributes(last, attributes))
        }
    }
}

/// Integer attributes as floats (recursively), so averaging does not round per step.
fn lift(attributes: &[AttributeValuePair]) -> Vec<AttributeValuePair> {
    attributes
        .iter()
        .map(|p| AttributeValuePair { name: p.name.clone(), value: lift_value(&p.value) })
        .collect()
}

fn lift_value(v: &Value) -> Value {
    match v {
        Value::Long(x) | Value::Time(x) => Value::Double(*x as f64),
        Value::LongSeq(xs) => Value::DoubleSeq(xs.iter().map(|x| *x as f64).collect()),
        Value::EntityFrame(f) => Value::EntityFrame(Box::new(EntityFrame {
            name: f.name.clone(),
            attributes: lift(&f.attributes),
        })),
        other => other.clone(),
    }
}

/// Back to the sorts of `like` after [`lift`], rounding integers once.
fn lower(mean: Vec<AttributeValuePair>, like: &[AttributeValuePair]) -> Vec<AttributeValuePair> {
    mean.into_iter()
        .map(|p| {
            let value = match like.iter().find(|q| q.name == p.name) {
                Some(q) => lower_value(p.value, &q.value),
                None => p.value,
            };
            AttributeValuePair { name: p.name, value }
        })
        .collect()
}

fn lower_value(v: Value, like: &Value) -> Value {
    match (v, like) {
        (Value::Double(x), Value::Long(_)) => Value::Long(x.round() as i64),
        (Value::Double(x), Value::Time(_)) => Value::Time(x.round() as i64),
        (Value::DoubleSeq(xs), Value::LongSeq(_)) => {
            Value::LongSeq(xs.into_iter().map(|x| x.round() as i64).collect())
        }
        (Value::EntityFrame(f), Value::EntityFrame(l)) => {
            Value::EntityFrame(Box::new(EntityFrame {
                name: f.name,
                attributes: lower(f.attributes, &l.attributes),
            }))
        }
        (v, _) => v,
    }
}

fn with_attributes(base: &EntityStructure, attributes: Vec<AttributeValuePair>) -> EntityStructure {
    EntityStructure {
        name: base.name.clone(),
        valid_time: base.valid_time,
        create_time: base.create_time,
        attributes,
    }
}

/// The running mean keeps the first sample's non-numeric values; the merge rule says
/// non-numeric attributes come from the last created sample.
fn fill_non_numeric(
    mean: Vec<AttributeValuePair>,
    last: &[AttributeValuePair],
) -> Vec<AttributeValuePair> {
    mean.into_iter()
        .map(|p| {
            if p.value.sort().is_numeric() {
                p
            } else {
                let value =
                    last.iter().find(|q| q.name == p.name).map_or(p.value, |q| q.value.clone());
                AttributeValuePair { name: p.name, value }
            }
        })
        .collect()
}

fn median_f(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        xs[n / 2]
    } else {
        (xs[n / 2 - 1] + xs[n / 2]) / 2.0
    }
}

/// Median of one attribute over a group; scalars only (tuples and others take the
/// last created value, `last`).
fn median_value(last: &Value, values: &[&Value]) -> Value {
    let nums: Option<Vec<f64>> = values.iter().map(|v| scalar(v, last)).collect();
    match (last, nums) {
        (Value::Long(_), Some(xs)) => Value::Long(median_f(xs).round() as i64),
        (Value::Time(_), Some(xs)) => Value::Time(median_f(xs).round() as i64),
        (Value::Double(_), Some(xs)) => Value::Double(median_f(xs)),
        (Value::Altitude(_), Some(xs)) => Value::Altitude(median_f(xs)),
        _ => last.clone(),
    }
}

fn scalar(v: &Value, like: &Value) -> Option<f64> {
    (v.sort() == like.sort()).then(|| v.as_double()).flatten()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn es(vt: Time, ct: Time, x: f64, n: i64, label: &str) -> EntityStructure {
        EntityStructure::new("r", vt, ct).with("x", x).with("n", n).with("label", label)
    }

    #[test]
    fn interpolation_is_numeric_only() {
        let a = es(0, 0, 0.0, 0, "a");
        let b = es(10, 10, 10.0, 5, "b");
        let m = interpolate(&a, &b, 4, 99);
        assert_eq!((m.valid_time, m.create_time), (4, 99));
        assert_eq!(m.get("x"), Some(&Value::Double(4.0)));
        assert_eq!(m.get("n"), Some(&Value::Long(2)));
        assert_eq!(m.get("label"), Some(&Value::from("a")));
    }

    #[test]
    fn nested_frames_and_tuples_interpolate() {
        let fa = EntityFrame::new("p").with("x", 0.0);
        let fb = EntityFrame::new("p").with("x", 2.0);
        let v = lerp_value(&Value::from(fa), &Value::from(fb), 0.5);
        assert_eq!(v.as_frame().and_then(|f| f.get("x")), Some(&Value::Double(1.0)));
        let p = lerp_value(
            &Value::Pos2(Pos2 { x: 0.0, y: 0.0 }),
            &Value::Pos2(Pos2 { x: 4.0, y: 8.0 }),
            0.25,
        );
        assert_eq!(p, Value::Pos2(Pos2 { x: 1.0, y: 2.0 }));
        // Sequences of different lengths are not interpolated.
        let s = lerp_value(&Value::LongSeq(vec![1]), &Value::LongSeq(vec![1, 2]), 0.5);
        assert_eq!(s, Value::LongSeq(vec![1]));
    }

    #[test]
    fn merge_rules() {
        let a = es(5, 1, 1.0, 10, "a");
        let b = es(5, 3, 3.0, 20, "b");
        let c = es(5, 2, 8.0, 60, "c");
        let g = [&a, &b, &c];
        assert_eq!(merge(&g, MergeRule::KeepFirst).unwrap().get("label"), Some(&Value::from("a")));
        assert_eq!(merge(&g, MergeRule::KeepLast).unwrap().get("label"), Some(&Value::from("b")));
        let avg = merge(&g, MergeRule::Average).unwrap();
        assert_eq!(avg.get("x"), Some(&Value::Double(4.0)));
        assert_eq!(avg.get("n"), Some(&Value::Long(30)));
        assert_eq!(avg.get("label"), Some(&Value::from("b")));
        let med = merge(&g, MergeRule::Median).unwrap();
        assert_eq!(med.get("x"), Some(&Value::Double(3.0)));
        assert_eq!(med.get("n"), Some(&Value::Long(20)));
        assert_eq!(
            merge(&[&a, &b], MergeRule::Median).unwrap().get("x"),
            Some(&Value::Double(2.0))
        );
        assert_eq!(merge(&[], MergeRule::Median), None);
    }

    #[test]
    fn equal_create_times_tie_break_by_add_order() {
        let a = es(5, 1, 1.0, 1, "a");
        let b = es(5, 1, 2.0, 2, "b");
        assert_eq!(
            merge(&[&a, &b], MergeRule::KeepFirst).unwrap().get("label"),
            Some(&Value::from("a"))
        );
        assert_eq!(
            merge(&[&a, &b], MergeRule::KeepLast).unwrap().get("label"),
            Some(&Value::from("b"))
        );
    }
}
