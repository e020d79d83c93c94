//! Value approximation and merge rules (T2, G1, seed 3.3.4.1): how a value is estimated
//! at a time-point with no sample, and how several samples at one time-point become one.
//!
//! Numeric attributes (integers, floats, times, and the geometric tuples) are
//! interpolated, averaged and given a median component-wise; nested frames attribute
//! by attribute; every other attribute takes the most recent value (and a generator
//! refuses an average or median merge over a type with such an attribute, naming it).
//! Rotations merge as rotations: the average is the normalised mean of their
//! quaternions, the median the member with the least summed angular distance to the
//! others. Interpolation of angles is still linear without wrap-around (a heading of
//! 350° to 10° passes through 180°); interpolate a unit vector instead where that
//! matters.

use std::sync::Arc;

use crate::sample::Sample;
use crate::structure::SharedStructure;
use crate::structure::ValueRef;
use crate::time::Time;
use crate::value::frame::{AttributeValuePair, EntityFrame, EntityStructure};
use crate::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort, Vec3,
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
    /// Linear interpolation between the closest samples before and after `t`:
    /// numbers, times, geometric values, number sequences, and sequences of points,
    /// vectors and frames element-wise when both have the same length. An attribute
    /// that cannot be interpolated holds the value before `t`: strings, images and
    /// other values without a linear mean by their nature, unmarked; sequences whose
    /// lengths differ and values of different sorts marked in the answer
    /// ([`Sample::not_interpolated`]).
    Linear,
    /// [`Self::Linear`], but an answer with an attribute that could not be interpolated
    /// (a marked one) is refused with `ValueNotAvailable`, naming the attribute.
    LinearStrict,
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
    /// The average of numeric attributes, component-wise; rotations by quaternion
    /// (others from the last created).
    Average,
    /// The median of numeric attributes, component-wise; of rotations, the member
    /// nearest all others (others from the last created).
    Median,
}

/// Interpolates between structures `a` (valid before `t`) and `b` (valid after `t`),
/// producing a structure valid at `t` created at `query_time` (see
/// [`ValueApproximation::Linear`] for what is interpolated).
pub fn interpolate(
    a: &EntityStructure,
    b: &EntityStructure,
    t: Time,
    query_time: Time,
) -> EntityStructure {
    interpolate_marked(a, b, t, query_time).0
}

/// [`interpolate`], and the paths of the attributes that could not be interpolated and
/// hold `a`'s value (sequences of different lengths, values of different sorts).
pub fn interpolate_marked(
    a: &EntityStructure,
    b: &EntityStructure,
    t: Time,
    query_time: Time,
) -> (EntityStructure, Vec<String>) {
    // Differences in i128 (extreme i64 times overflow i64), then f64: converting the
    // absolute times first would lose the nanoseconds of wall-clock times (~1.7e18).
    let span = (i128::from(b.valid_time) - i128::from(a.valid_time)) as f64;
    let offset = (i128::from(t) - i128::from(a.valid_time)) as f64;
    let f = if span > 0.0 { offset / span } else { 0.0 };
    let mut held = Vec::new();
    let es = EntityStructure {
        name: a.name.clone(),
        valid_time: t,
        create_time: query_time,
        attributes: lerp_attributes(&a.attributes, &b.attributes, f, "", &mut held),
    };
    (es, held)
}

/// The answer of a linear query between `a` and `b` at `t` under `rule` (`Linear` or
/// `LinearStrict`), or why it is refused.
pub fn interpolated(
    a: &SharedStructure,
    b: &SharedStructure,
    t: Time,
    query_time: Time,
    rule: &ValueApproximation,
) -> Result<Sample, String> {
    // Interpolation makes a new structure of both sides' values, read where they are
    // (an archived side is not decoded: only the answer is built).
    let (es, held) = interpolate_shared(a, b, t, query_time);
    let mut sample = Sample::new(Arc::new(es), query_time, query_time);
    if !held.is_empty() {
        if *rule == ValueApproximation::LinearStrict {
            return Err(format!(
                "linear: {} cannot be interpolated (sequences of different lengths or \
                 values of different sorts on either side)",
                held.iter().map(|p| format!("`{p}`")).collect::<Vec<_>>().join(", ")
            ));
        }
        sample.not_interpolated = Some(held.into());
    }
    Ok(sample)
}

/// [`interpolate_marked`] of two structures read in place (owned or archived): the
/// same rules, through [`lerp_ref`], so an archived side is never decoded whole.
fn interpolate_shared(
    a: &SharedStructure,
    b: &SharedStructure,
    t: Time,
    query_time: Time,
) -> (EntityStructure, Vec<String>) {
    if let (Some(a), Some(b)) = (a.as_owned(), b.as_owned()) {
        return interpolate_marked(a, b, t, query_time);
    }
    let span = (i128::from(b.valid_time()) - i128::from(a.valid_time())) as f64;
    let offset = (i128::from(t) - i128::from(a.valid_time())) as f64;
    let f = if span > 0.0 { offset / span } else { 0.0 };
    let mut held = Vec::new();
    let attributes = a
        .attributes()
        .map(|(name, va)| {
            let value = match b.get(name) {
                Some(vb) => lerp_ref(va, vb, f, name, &mut held),
                None => va.to_value(),
            };
            AttributeValuePair { name: name.to_owned(), value }
        })
        .collect();
    let es = EntityStructure {
        name: a.name().to_owned(),
        valid_time: t,
        create_time: query_time,
        attributes,
    };
    (es, held)
}

/// [`lerp`] of two values read in place: the numbers a robot's state is made of are
/// read where they are; any other pair is converted and given to [`lerp`], the one
/// place the rules are written.
fn lerp_ref(a: ValueRef<'_>, b: ValueRef<'_>, f: f64, path: &str, held: &mut Vec<String>) -> Value {
    let scalar = match (a.sort(), b.sort()) {
        (ValueSort::Long, ValueSort::Long) => {
            a.as_long().zip(b.as_long()).map(|(x, y)| Value::Long(li(x, y, f)))
        }
        (ValueSort::Time, ValueSort::Time) => {
            a.as_long().zip(b.as_long()).map(|(x, y)| Value::Time(li(x, y, f)))
        }
        (ValueSort::Double, ValueSort::Double) => {
            a.as_double().zip(b.as_double()).map(|(x, y)| Value::Double(l(x, y, f)))
        }
        (ValueSort::Altitude, ValueSort::Altitude) => {
            a.as_double().zip(b.as_double()).map(|(x, y)| Value::Altitude(l(x, y, f)))
        }
        (ValueSort::Pos2, ValueSort::Pos2) => a
            .as_pos2()
            .zip(b.as_pos2())
            .map(|(x, y)| Value::Pos2(Pos2 { x: l(x.x, y.x, f), y: l(x.y, y.y, f) })),
        (ValueSort::Position, ValueSort::Position) => {
            a.as_position().zip(b.as_position()).map(|(x, y)| Value::Position(lpos(&x, &y, f)))
        }
        (ValueSort::Rotation, ValueSort::Rotation) => {
            a.as_rotation().zip(b.as_rotation()).map(|(x, y)| Value::Rotation(lrot(&x, &y, f)))
        }
        (ValueSort::Vec, ValueSort::Vec) => {
            a.as_vec3().zip(b.as_vec3()).map(|(x, y)| Value::Vec(lvec(&x, &y, f)))
        }
        _ => None,
    };
    scalar.unwrap_or_else(|| lerp(&a.to_value(), &b.to_value(), f, path, held))
}

fn lerp_attributes(
    a: &[AttributeValuePair],
    b: &[AttributeValuePair],
    f: f64,
    prefix: &str,
    held: &mut Vec<String>,
) -> Vec<AttributeValuePair> {
    a.iter()
        .map(|pa| {
            let path =
                if prefix.is_empty() { pa.name.clone() } else { format!("{prefix}.{}", pa.name) };
            let value = match b.iter().find(|pb| pb.name == pa.name) {
                Some(pb) => lerp(&pa.value, &pb.value, f, &path, held),
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
    lerp(a, b, f, "", &mut Vec::new())
}

/// True for sorts with no linear mean: they hold the earlier value by their nature.
fn steps(v: &Value) -> bool {
    matches!(
        v,
        Value::NoValue
            | Value::Bool(_)
            | Value::String(_)
            | Value::Symbol(_)
            | Value::OctetSeq(_)
            | Value::SymbolSeq(_)
    )
}

/// [`lerp_value`], recording in `held` the path of a value that should have been
/// interpolated but could not (it holds `a`).
fn lerp(a: &Value, b: &Value, f: f64, path: &str, held: &mut Vec<String>) -> Value {
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
            Value::EntityFrame(Box::new(lerp_frame(x, y, f, path, held)))
        }
        (Value::Pos2Seq(x), Value::Pos2Seq(y)) if x.len() == y.len() => Value::Pos2Seq(
            x.iter().zip(y).map(|(p, q)| Pos2 { x: l(p.x, q.x, f), y: l(p.y, q.y, f) }).collect(),
        ),
        (Value::VecSeq(x), Value::VecSeq(y)) if x.len() == y.len() => {
            Value::VecSeq(x.iter().zip(y).map(|(p, q)| lvec(p, q, f)).collect())
        }
        (Value::EntityFrameSeq(x), Value::EntityFrameSeq(y)) if x.len() == y.len() => {
            Value::EntityFrameSeq(
                x.iter()
                    .zip(y)
                    .enumerate()
                    .map(|(i, (p, q))| lerp_frame(p, q, f, &format!("{path}[{i}]"), held))
                    .collect(),
            )
        }
        _ => {
            if !(steps(a) && a.sort() == b.sort()) {
                held.push(path.to_owned());
            }
            a.clone()
        }
    }
}

fn lerp_frame(
    x: &EntityFrame,
    y: &EntityFrame,
    f: f64,
    path: &str,
    held: &mut Vec<String>,
) -> EntityFrame {
    EntityFrame {
        name: x.name.clone(),
        attributes: lerp_attributes(&x.attributes, &y.attributes, f, path, held),
    }
}

/// Merges structures that share a valid time (non-empty, in add order) by `rule`.
/// The result keeps the valid time; its create time is that of the sample it was
/// chosen from or, for average and median, the latest create time.
pub fn merge(group: &[&EntityStructure], rule: MergeRule) -> Option<EntityStructure> {
    let (first, last) = first_and_last(group.iter().map(|e| e.create_time))?;
    let (first, last) = (group[first], group[last]);
    match rule {
        MergeRule::KeepFirst => Some(first.clone()),
        MergeRule::KeepLast => Some(last.clone()),
        MergeRule::Average => {
            // A running mean in floating point (integers are rounded once, at the end):
            // after k samples, mean_k = lerp(mean_{k-1}, x_k, 1/k).
            let mut acc = lift(&group[0].attributes);
            for (k, e) in group.iter().enumerate().skip(1) {
                acc = lerp_attributes(
                    &acc,
                    &lift(&e.attributes),
                    1.0 / (k as f64 + 1.0),
                    "",
                    &mut Vec::new(),
                );
            }
            let mut mean = fill_non_numeric(lower(acc, &last.attributes), &last.attributes);
            mean_rotations(&mut mean, group);
            Some(with_attributes(last, mean))
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

/// The positions of the first and the last structure of a group by create time, given
/// their create times in add order: ties go to the later-added sample for the last,
/// the earlier for the first. `None` for an empty group.
fn first_and_last(create_times: impl Iterator<Item = Time> + Clone) -> Option<(usize, usize)> {
    let first = create_times.clone().enumerate().min_by_key(|&(i, t)| (t, i))?.0;
    let last = create_times.enumerate().max_by_key(|&(i, t)| (t, i))?.0;
    Some((first, last))
}

/// [`merge`] of structures as trajectories hold them: keep-first and keep-last answer
/// the chosen structure itself (an archived one stays read in place); average and
/// median compute a new one from converted values.
pub fn merge_shared(group: &[&SharedStructure], rule: MergeRule) -> Option<SharedStructure> {
    let (first, last) = first_and_last(group.iter().map(|e| e.create_time()))?;
    match rule {
        MergeRule::KeepFirst => Some(group[first].clone()),
        MergeRule::KeepLast => Some(group[last].clone()),
        MergeRule::Average | MergeRule::Median => {
            let owned: Vec<Arc<EntityStructure>> = group.iter().map(|e| e.to_arc()).collect();
            let refs: Vec<&EntityStructure> = owned.iter().map(Arc::as_ref).collect();
            merge(&refs, rule).map(SharedStructure::from)
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

/// Median of one attribute over a group: scalars as numbers; positions, 2-D points
/// and vectors component-wise; a rotation is the member with the least summed angular
/// distance to the others (a median of angles component-wise would not be a rotation
/// of the group); nested frames attribute by attribute. Values of another sort than
/// `last`'s are left out; any other sort takes the last created value, `last`.
fn median_value(last: &Value, values: &[&Value]) -> Value {
    let same: Vec<&Value> = values.iter().copied().filter(|v| v.sort() == last.sort()).collect();
    let med =
        |f: &dyn Fn(&Value) -> Option<f64>| median_f(same.iter().filter_map(|v| f(v)).collect());
    match last {
        Value::Long(_) => Value::Long(med(&|v| v.as_double()).round() as i64),
        Value::Time(_) => Value::Time(med(&|v| v.as_double()).round() as i64),
        Value::Double(_) => Value::Double(med(&|v| v.as_double())),
        Value::Altitude(_) => Value::Altitude(med(&|v| v.as_double())),
        Value::Pos2(_) => Value::Pos2(Pos2 {
            x: med(&|v| match v {
                Value::Pos2(p) => Some(p.x),
                _ => None,
            }),
            y: med(&|v| match v {
                Value::Pos2(p) => Some(p.y),
                _ => None,
            }),
        }),
        Value::Vec(_) => Value::Vec(Vec3 {
            x: med(&|v| if let Value::Vec(p) = v { Some(p.x) } else { None }),
            y: med(&|v| if let Value::Vec(p) = v { Some(p.y) } else { None }),
            z: med(&|v| if let Value::Vec(p) = v { Some(p.z) } else { None }),
        }),
        Value::Position(_) => Value::Position(median_position(&same, |v| match v {
            Value::Position(p) => Some(*p),
            _ => None,
        })),
        Value::Rotation(r) => Value::Rotation(
            rotation_medoid(&same.iter().filter_map(|v| rotation_in(v)).collect::<Vec<_>>())
                .unwrap_or(*r),
        ),
        Value::PositionAltitude(_) => Value::PositionAltitude(PositionAltitude {
            position: median_position(&same, |v| match v {
                Value::PositionAltitude(p) => Some(p.position),
                _ => None,
            }),
            altitude: med(&|v| match v {
                Value::PositionAltitude(p) => Some(p.altitude),
                _ => None,
            }),
        }),
        Value::PositionAltitudeRotation(par) => {
            let rotations: Vec<Rotation> = same
                .iter()
                .filter_map(|v| match v {
                    Value::PositionAltitudeRotation(p) => Some(p.rotation),
                    _ => None,
                })
                .collect();
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: median_position(&same, |v| match v {
                    Value::PositionAltitudeRotation(p) => Some(p.position),
                    _ => None,
                }),
                altitude: med(&|v| match v {
                    Value::PositionAltitudeRotation(p) => Some(p.altitude),
                    _ => None,
                }),
                rotation: rotation_medoid(&rotations).unwrap_or(par.rotation),
            })
        }
        Value::EntityFrame(f) => {
            let frames: Vec<&EntityFrame> = same.iter().filter_map(|v| v.as_frame()).collect();
            Value::EntityFrame(Box::new(EntityFrame {
                name: f.name.clone(),
                attributes: f
                    .attributes
                    .iter()
                    .map(|p| {
                        let values: Vec<&Value> =
                            frames.iter().filter_map(|fr| fr.get(&p.name)).collect();
                        AttributeValuePair {
                            name: p.name.clone(),
                            value: median_value(&p.value, &values),
                        }
                    })
                    .collect(),
            }))
        }
        _ => last.clone(),
    }
}

fn median_position(values: &[&Value], get: impl Fn(&Value) -> Option<Position>) -> Position {
    let ps: Vec<Position> = values.iter().filter_map(|v| get(v)).collect();
    Position {
        north: median_f(ps.iter().map(|p| p.north).collect()),
        east: median_f(ps.iter().map(|p| p.east).collect()),
    }
}

/// A rotation as a unit quaternion `[w, x, y, z]` (roll about x, pitch about y, yaw
/// about z, applied yaw first: the aerospace ZYX convention).
fn quaternion(r: &Rotation) -> [f64; 4] {
    let (sr, cr) = (r.roll / 2.0).sin_cos();
    let (sp, cp) = (r.pitch / 2.0).sin_cos();
    let (sy, cy) = (r.yaw / 2.0).sin_cos();
    [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
}

fn rotation_of(q: [f64; 4]) -> Rotation {
    let [w, x, y, z] = q;
    let sin_pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0);
    Rotation {
        roll: (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y)),
        pitch: sin_pitch.asin(),
        yaw: (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z)),
    }
}

fn dot(a: [f64; 4], b: [f64; 4]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The angle between two rotations (radians, 0..=π).
fn angular_distance(a: &Rotation, b: &Rotation) -> f64 {
    2.0 * dot(quaternion(a), quaternion(b)).abs().min(1.0).acos()
}

/// The mean of rotations: their quaternions on one hemisphere (q and −q are one
/// rotation), averaged and normalised. `None` for none, or ones that cancel out.
pub fn rotation_mean(rotations: &[Rotation]) -> Option<Rotation> {
    let first = quaternion(rotations.first()?);
    let mut sum = [0.0; 4];
    for r in rotations {
        let q = quaternion(r);
        let sign = if dot(q, first) < 0.0 { -1.0 } else { 1.0 };
        for (s, c) in sum.iter_mut().zip(q) {
            *s += sign * c;
        }
    }
    let norm = dot(sum, sum).sqrt();
    (norm > 1e-12).then(|| rotation_of(sum.map(|c| c / norm)))
}

/// The median of rotations: the member with the least summed angular distance to the
/// others (of equal ones, the first).
pub fn rotation_medoid(rotations: &[Rotation]) -> Option<Rotation> {
    let cost = |r: &Rotation| rotations.iter().map(|o| angular_distance(r, o)).sum::<f64>();
    rotations.iter().map(|r| (cost(r), *r)).min_by(|a, b| a.0.total_cmp(&b.0)).map(|(_, r)| r)
}

/// Replaces the component-wise mean of every rotation among `attributes` (top level,
/// and inside a position-altitude-rotation) by the quaternion mean of the group's.
fn mean_rotations(attributes: &mut [AttributeValuePair], group: &[&EntityStructure]) {
    for p in attributes.iter_mut() {
        let of = |f: &dyn Fn(&Value) -> Option<Rotation>| -> Vec<Rotation> {
            group.iter().filter_map(|e| e.get(&p.name)).filter_map(f).collect()
        };
        match &mut p.value {
            Value::Rotation(r) => {
                if let Some(m) = rotation_mean(&of(&rotation_in)) {
                    *r = m;
                }
            }
            Value::PositionAltitudeRotation(par) => {
                let rotations = of(&|v| match v {
                    Value::PositionAltitudeRotation(x) => Some(x.rotation),
                    _ => None,
                });
                if let Some(m) = rotation_mean(&rotations) {
                    par.rotation = m;
                }
            }
            _ => {}
        }
    }
}

fn rotation_in(v: &Value) -> Option<Rotation> {
    match v {
        Value::Rotation(r) => Some(*r),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn es(vt: Time, ct: Time, x: f64, n: i64, label: &str) -> EntityStructure {
        EntityStructure::new("r", vt, ct).with("x", x).with("n", n).with("label", label)
    }

    fn at(vt: Time, ct: Time) -> EntityStructure {
        EntityStructure::new("r", vt, ct)
    }

    fn yaw(y: f64) -> Rotation {
        Rotation { roll: 0.0, pitch: 0.0, yaw: y }
    }

    #[test]
    fn positions_and_points_merge_component_wise() {
        let g = [
            at(5, 1)
                .with("p", Value::Pos2(Pos2 { x: 0.0, y: 10.0 }))
                .with("q", Value::Position(Position { north: 1.0, east: 9.0 })),
            at(5, 2)
                .with("p", Value::Pos2(Pos2 { x: 2.0, y: 0.0 }))
                .with("q", Value::Position(Position { north: 3.0, east: 0.0 })),
            at(5, 3)
                .with("p", Value::Pos2(Pos2 { x: 9.0, y: 5.0 }))
                .with("q", Value::Position(Position { north: 2.0, east: 1.0 })),
        ];
        let g: Vec<&EntityStructure> = g.iter().collect();
        let med = merge(&g, MergeRule::Median).unwrap();
        assert_eq!(med.get("p"), Some(&Value::Pos2(Pos2 { x: 2.0, y: 5.0 })));
        assert_eq!(med.get("q"), Some(&Value::Position(Position { north: 2.0, east: 1.0 })));
        let avg = merge(&g, MergeRule::Average).unwrap();
        let Some(Value::Pos2(p)) = avg.get("p") else { panic!("{avg:?}") };
        assert!((p.x - 11.0 / 3.0).abs() < 1e-9 && (p.y - 5.0).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn rotations_average_as_quaternions_and_the_median_is_a_member() {
        let deg = std::f64::consts::PI / 180.0;
        // 350° and 10°: the mean heading is 0°, not the 180° of averaging angles.
        let g = [
            at(5, 1).with("r", Value::Rotation(yaw(350.0 * deg))),
            at(5, 2).with("r", Value::Rotation(yaw(10.0 * deg))),
        ];
        let g: Vec<&EntityStructure> = g.iter().collect();
        let Some(Value::Rotation(r)) = merge(&g, MergeRule::Average).unwrap().get("r").cloned()
        else {
            panic!("not a rotation")
        };
        assert!(r.yaw.abs() < 1e-9 && r.roll.abs() < 1e-9 && r.pitch.abs() < 1e-9, "{r:?}");
        let m = rotation_mean(&[yaw(0.3), yaw(0.5)]).unwrap();
        assert!((m.yaw - 0.4).abs() < 1e-9, "{m:?}");
        // The member closest to all others: 0.1 rad, not the outlier.
        let g = [
            at(5, 1).with("r", Value::Rotation(yaw(0.0))),
            at(5, 2).with("r", Value::Rotation(yaw(0.1))),
            at(5, 3).with("r", Value::Rotation(yaw(3.0))),
        ];
        let g: Vec<&EntityStructure> = g.iter().collect();
        assert_eq!(
            merge(&g, MergeRule::Median).unwrap().get("r"),
            Some(&Value::Rotation(yaw(0.1)))
        );
        // Euler angles come back as they went in.
        let r = Rotation { roll: 0.2, pitch: -0.3, yaw: 1.1 };
        let back = rotation_of(quaternion(&r));
        assert!((back.roll - 0.2).abs() < 1e-9 && (back.pitch + 0.3).abs() < 1e-9);
        assert!((back.yaw - 1.1).abs() < 1e-9);
    }

    #[test]
    fn nested_frames_take_the_median_attribute_by_attribute() {
        let frame = |x: f64, label: &str| EntityFrame::new("f").with("x", x).with("label", label);
        let g = [
            at(5, 1).with("f", frame(1.0, "a")),
            at(5, 2).with("f", frame(7.0, "b")),
            at(5, 3).with("f", frame(3.0, "c")),
        ];
        let g: Vec<&EntityStructure> = g.iter().collect();
        let med = merge(&g, MergeRule::Median).unwrap();
        let f = med.get("f").and_then(|v| v.as_frame()).unwrap();
        assert_eq!(f.get("x"), Some(&Value::Double(3.0)));
        assert_eq!(f.get("label"), Some(&Value::from("c")), "the last created");
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

    /// Interpolating two archived structures (read in place, as a replica of another
    /// process holds them) answers what interpolating them owned answers, attribute
    /// for attribute and with the same attributes held, for every sort.
    #[test]
    fn archived_sides_interpolate_as_owned_ones() {
        let side = |vt: Time, k: f64| {
            at(vt, vt)
                .with("n", Value::Long(k as i64 * 10))
                .with("t", Value::Time(vt * 3))
                .with("x", Value::Double(k))
                .with("alt", Value::Altitude(k * 2.0))
                .with("p", Value::Pos2(Pos2 { x: k, y: -k }))
                .with("q", Value::Position(Position { north: k, east: 2.0 * k }))
                .with("r", Value::Rotation(yaw(k)))
                .with("v", Value::Vec(Vec3 { x: k, y: k, z: -k }))
                .with("seq", Value::DoubleSeq(vec![k; (k as usize % 2) + 1]))
                .with("frame", Value::from(EntityFrame::new("f").with("y", k)))
                .with("label", Value::from(if k > 1.0 { "b" } else { "a" }))
                .with("mixed", if k > 1.0 { Value::Double(k) } else { Value::Long(1) })
        };
        let (a, b) = (side(0, 1.0), side(10, 2.0).with("only_b", 1.0));
        let archived = |es: &EntityStructure| {
            SharedStructure::archived_copy(&crate::codec::encode(es).unwrap()).unwrap()
        };
        let (sa, sb) = (SharedStructure::from(a.clone()), SharedStructure::from(b.clone()));
        for rule in [ValueApproximation::Linear, ValueApproximation::LinearStrict] {
            let owned = interpolated(&sa, &sb, 4, 99, &rule);
            let in_place = interpolated(&archived(&a), &archived(&b), 4, 99, &rule);
            match (owned, in_place) {
                (Ok(o), Ok(i)) => {
                    assert_eq!(o.structure.to_structure(), i.structure.to_structure());
                    assert_eq!(o.not_interpolated, i.not_interpolated);
                    assert!(o.not_interpolated.is_some(), "the sequence and the mixed pair");
                }
                (Err(o), Err(i)) => assert_eq!(o, i),
                (o, i) => panic!("{rule:?}: owned {o:?}, in place {i:?}"),
            }
        }
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
