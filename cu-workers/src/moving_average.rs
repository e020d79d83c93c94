//! A generic unit: the running average of every numeric attribute of a structure over
//! its last N samples, for smoothing a noisy stream (positions, blob centroids) before
//! it is acted on.
//!
//! It works on attributes rather than on one Rust type, so a runtime can offer it as a
//! built-in unit for any trajectory; [`MovingAverage::push_entity`] is the typed form.
//!
//! What is averaged: `Long`, `Double` and `Altitude` values, the components of `Vec`,
//! `Pos2`, `Position`, `Rotation`, `PositionAltitude` and `PositionAltitudeRotation`
//! values, and, element by element, those inside sequences, tuples and nested frames.
//! Everything else (strings, symbols, booleans, times, octets, no value) is taken from
//! the newest sample, as are attribute names and the order of attributes.
//!
//! Averages are taken in `f64`: `Long`s are exact up to 2⁵³ and their average is rounded
//! to the nearest integer (halves away from zero). Angles that wrap (headings in
//! degrees) are averaged as plain numbers; unwrap them first if they cross 0°/360°.

use std::collections::VecDeque;
use std::num::NonZeroUsize;

use esgm_core::entity::{Entity, FromEntityError};
use esgm_core::value::frame::{AttributeValuePair, EntityFrame, EntityStructure};
use esgm_core::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort, Vec3,
};

/// The running average over the last `window` samples of each numeric attribute.
///
/// The window restarts whenever a sample's shape differs from the previous one (another
/// attribute name or order, another sort, a sequence of another length): averaging a
/// value with an unrelated one means nothing.
#[derive(Debug, Clone)]
pub struct MovingAverage {
    window: NonZeroUsize,
    /// The shape shared by every sample in `samples`.
    shape: Vec<ShapeToken>,
    /// The numbers of the newest samples, oldest first, at most `window` of them.
    samples: VecDeque<Vec<f64>>,
    /// Scratch for the shape of the sample being pushed.
    next_shape: Vec<ShapeToken>,
}

/// One step of a sample's shape: two samples average together only if their shapes are
/// equal.
#[derive(Debug, Clone, PartialEq)]
enum ShapeToken {
    Name(String),
    Sort(ValueSort),
    Len(usize),
}

impl MovingAverage {
    /// An average over the last `window` samples; a window of 1 passes samples through.
    pub fn new(window: NonZeroUsize) -> Self {
        Self {
            window,
            shape: Vec::new(),
            samples: VecDeque::with_capacity(window.get()),
            next_shape: Vec::new(),
        }
    }

    /// The number of samples averaged once the window is full.
    pub fn window(&self) -> usize {
        self.window.get()
    }

    /// The number of samples the last average included: at most
    /// [`window`](Self::window), fewer after a start, a reset or a change of shape.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True before the first sample and after a [`reset`](Self::reset).
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Forgets every sample, as after a gap in the stream.
    pub fn reset(&mut self) {
        self.samples.clear();
        self.shape.clear();
    }

    /// Adds a sample and returns the average: the newest sample's attributes with each
    /// numeric value replaced by its mean over the window.
    pub fn push(&mut self, attributes: &[AttributeValuePair]) -> Vec<AttributeValuePair> {
        // Reuse the evicted sample's buffer when the window is full.
        let evicted =
            if self.samples.len() >= self.window() { self.samples.pop_front() } else { None };
        let mut buf = evicted.unwrap_or_default();
        buf.clear();
        self.next_shape.clear();
        for pair in attributes {
            self.next_shape.push(ShapeToken::Name(pair.name.clone()));
            flatten(&pair.value, &mut buf, &mut self.next_shape);
        }
        if self.next_shape != self.shape {
            self.samples.clear();
            std::mem::swap(&mut self.shape, &mut self.next_shape);
        }
        self.samples.push_back(buf);

        let count = self.samples.len() as f64;
        let mut means = vec![0.0; self.samples.back().map_or(0, Vec::len)];
        for sample in &self.samples {
            for (mean, x) in means.iter_mut().zip(sample) {
                *mean += x;
            }
        }
        let mut means = means.into_iter().map(|sum| sum / count);
        attributes
            .iter()
            .map(|pair| AttributeValuePair {
                name: pair.name.clone(),
                value: rebuild(&pair.value, &mut means),
            })
            .collect()
    }

    /// [`push`](Self::push) for a structure: the average keeps the newest structure's
    /// name and times.
    pub fn push_structure(&mut self, structure: &EntityStructure) -> EntityStructure {
        EntityStructure {
            name: structure.name.clone(),
            valid_time: structure.valid_time,
            create_time: structure.create_time,
            attributes: self.push(&structure.attributes),
        }
    }

    /// [`push`](Self::push) for a typed entity. Fails only if `T`'s conversions
    /// disagree with each other, which `#[derive(Entity)]` never does.
    pub fn push_entity<T: Entity>(&mut self, value: &T) -> Result<T, FromEntityError> {
        T::from_attributes(&self.push(&value.to_attributes()))
    }
}

/// Appends `value`'s numbers to `numbers` and its shape to `shape`, depth first.
fn flatten(value: &Value, numbers: &mut Vec<f64>, shape: &mut Vec<ShapeToken>) {
    shape.push(ShapeToken::Sort(value.sort()));
    let frame = |f: &EntityFrame, numbers: &mut Vec<f64>, shape: &mut Vec<ShapeToken>| {
        shape.push(ShapeToken::Name(f.name.clone()));
        for pair in &f.attributes {
            shape.push(ShapeToken::Name(pair.name.clone()));
            flatten(&pair.value, numbers, shape);
        }
        shape.push(ShapeToken::Len(f.attributes.len()));
    };
    match value {
        Value::Long(v) => numbers.push(*v as f64),
        Value::Double(v) | Value::Altitude(v) => numbers.push(*v),
        Value::Vec(v) => numbers.extend(vec3(v)),
        Value::Pos2(p) => numbers.extend([p.x, p.y]),
        Value::Position(p) => numbers.extend(position(p)),
        Value::Rotation(r) => numbers.extend(rotation(r)),
        Value::PositionAltitude(p) => {
            numbers.extend(position(&p.position));
            numbers.push(p.altitude);
        }
        Value::PositionAltitudeRotation(p) => {
            numbers.extend(position(&p.position));
            numbers.push(p.altitude);
            numbers.extend(rotation(&p.rotation));
        }
        Value::LongSeq(v) => {
            shape.push(ShapeToken::Len(v.len()));
            numbers.extend(v.iter().map(|&x| x as f64));
        }
        Value::DoubleSeq(v) => {
            shape.push(ShapeToken::Len(v.len()));
            numbers.extend(v);
        }
        Value::VecSeq(v) => {
            shape.push(ShapeToken::Len(v.len()));
            numbers.extend(v.iter().flat_map(vec3));
        }
        Value::Pos2Seq(v) => {
            shape.push(ShapeToken::Len(v.len()));
            numbers.extend(v.iter().flat_map(|p| [p.x, p.y]));
        }
        Value::Agg(vs) | Value::Collection(vs) => {
            shape.push(ShapeToken::Len(vs.len()));
            for v in vs {
                flatten(v, numbers, shape);
            }
        }
        Value::EntityFrame(f) => frame(f, numbers, shape),
        Value::EntityFrameSeq(fs) => {
            shape.push(ShapeToken::Len(fs.len()));
            for f in fs {
                frame(f, numbers, shape);
            }
        }
        Value::NoValue
        | Value::Bool(_)
        | Value::String(_)
        | Value::Time(_)
        | Value::Symbol(_)
        | Value::OctetSeq(_)
        | Value::SymbolSeq(_) => {}
    }
}

fn vec3(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn position(p: &Position) -> [f64; 2] {
    [p.north, p.east]
}

fn rotation(r: &Rotation) -> [f64; 3] {
    [r.roll, r.pitch, r.yaw]
}

/// `value` with its numbers replaced, in [`flatten`]'s order, by the next of `means`.
fn rebuild(value: &Value, means: &mut impl Iterator<Item = f64>) -> Value {
    // `means` has exactly as many numbers as `value` (both follow one shape); were it
    // short, the missing ones would read as 0 rather than panic.
    let mut next = || means.next().unwrap_or(0.0);
    let vec3 = |next: &mut dyn FnMut() -> f64| Vec3 { x: next(), y: next(), z: next() };
    let pos2 = |next: &mut dyn FnMut() -> f64| Pos2 { x: next(), y: next() };
    let position = |next: &mut dyn FnMut() -> f64| Position { north: next(), east: next() };
    let rotation =
        |next: &mut dyn FnMut() -> f64| Rotation { roll: next(), pitch: next(), yaw: next() };
    // `as` saturates out-of-range values and maps NaN to 0: never a panic.
    let long = |x: f64| x.round() as i64;
    match value {
        Value::Long(_) => Value::Long(long(next())),
        Value::Double(_) => Value::Double(next()),
        Value::Altitude(_) => Value::Altitude(next()),
        Value::Vec(_) => Value::Vec(vec3(&mut next)),
        Value::Pos2(_) => Value::Pos2(pos2(&mut next)),
        Value::Position(_) => Value::Position(position(&mut next)),
        Value::Rotation(_) => Value::Rotation(rotation(&mut next)),
        Value::PositionAltitude(_) => Value::PositionAltitude(PositionAltitude {
            position: position(&mut next),
            altitude: next(),
        }),
        Value::PositionAltitudeRotation(_) => {
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: position(&mut next),
                altitude: next(),
                rotation: rotation(&mut next),
            })
        }
        Value::LongSeq(v) => Value::LongSeq(v.iter().map(|_| long(next())).collect()),
        Value::DoubleSeq(v) => Value::DoubleSeq(v.iter().map(|_| next()).collect()),
        Value::VecSeq(v) => Value::VecSeq(v.iter().map(|_| vec3(&mut next)).collect()),
        Value::Pos2Seq(v) => Value::Pos2Seq(v.iter().map(|_| pos2(&mut next)).collect()),
        Value::Agg(vs) => Value::Agg(vs.iter().map(|v| rebuild(v, means)).collect()),
        Value::Collection(vs) => Value::Collection(vs.iter().map(|v| rebuild(v, means)).collect()),
        Value::EntityFrame(f) => Value::EntityFrame(Box::new(rebuild_frame(f, means))),
        Value::EntityFrameSeq(fs) => {
            Value::EntityFrameSeq(fs.iter().map(|f| rebuild_frame(f, means)).collect())
        }
        other => other.clone(),
    }
}

fn rebuild_frame(frame: &EntityFrame, means: &mut impl Iterator<Item = f64>) -> EntityFrame {
    EntityFrame {
        name: frame.name.clone(),
        attributes: frame
            .attributes
            .iter()
            .map(|p| AttributeValuePair { name: p.name.clone(), value: rebuild(&p.value, means) })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::library::{Blob, BlobSeq, RobotState};

    fn avg(window: usize) -> MovingAverage {
        MovingAverage::new(NonZeroUsize::new(window).unwrap())
    }

    #[test]
    fn averages_the_last_n_samples_of_each_attribute() {
        let mut m = avg(3);
        let state = |x: f64, dir: f64| RobotState { x, y: -x, dir };
        assert_eq!(m.push_entity(&state(3.0, 10.0)).unwrap(), state(3.0, 10.0));
        assert_eq!(m.push_entity(&state(6.0, 20.0)).unwrap(), state(4.5, 15.0));
        assert_eq!(m.push_entity(&state(9.0, 30.0)).unwrap(), state(6.0, 20.0));
        assert_eq!(m.len(), 3);
        // The first sample leaves the window.
        assert_eq!(m.push_entity(&state(0.0, 40.0)).unwrap(), state(5.0, 30.0));
        assert_eq!(m.len(), 3);
        m.reset();
        assert!(m.is_empty());
        assert_eq!(m.push_entity(&state(1.0, 1.0)).unwrap(), state(1.0, 1.0));
    }

    #[test]
    fn longs_round_to_the_nearest_integer() {
        let mut m = avg(2);
        m.push_entity(&Blob { x: 1, y: -1, size: 10 }).unwrap();
        assert_eq!(
            m.push_entity(&Blob { x: 2, y: -2, size: 13 }).unwrap(),
            Blob { x: 2, y: -2, size: 12 }
        );
    }

    #[test]
    fn a_window_of_one_passes_samples_through() {
        let mut m = avg(1);
        for x in [1.0, 7.0, -3.0] {
            let s = RobotState { x, y: 2.0 * x, dir: x };
            assert_eq!(m.push_entity(&s).unwrap(), s);
        }
    }

    #[test]
    fn nested_frames_average_element_by_element_and_a_new_shape_restarts() {
        let mut m = avg(4);
        let seq = |items: &[(i64, i64, i64)]| BlobSeq {
            items: items.iter().map(|&(x, y, size)| Blob { x, y, size }).collect(),
        };
        m.push_entity(&seq(&[(10, 10, 100), (0, 0, 4)])).unwrap();
        assert_eq!(
            m.push_entity(&seq(&[(20, 30, 200), (2, 2, 6)])).unwrap(),
            seq(&[(15, 20, 150), (1, 1, 5)])
        );
        // Three blobs are not comparable with two: the window restarts.
        let three = seq(&[(1, 1, 1), (2, 2, 2), (3, 3, 3)]);
        assert_eq!(m.push_entity(&three).unwrap(), three);
        assert_eq!(m.len(), 1);
    }

    #[test]
    fn composite_values_average_and_others_come_from_the_newest_sample() {
        let mut m = avg(2);
        let sample = |k: f64, label: &str| {
            vec![
                AttributeValuePair::new("label", Value::String(label.into())),
                AttributeValuePair::new(
                    "pose",
                    Value::PositionAltitudeRotation(PositionAltitudeRotation {
                        position: Position { north: k, east: 2.0 * k },
                        altitude: 3.0 * k,
                        rotation: Rotation { roll: k, pitch: k, yaw: -k },
                    }),
                ),
                AttributeValuePair::new("v", Value::Vec(Vec3 { x: k, y: 0.0, z: 1.0 })),
                AttributeValuePair::new("path", Value::Pos2Seq(vec![Pos2 { x: k, y: k }])),
                AttributeValuePair::new("t", Value::Time(k as i64)),
                AttributeValuePair::new(
                    "agg",
                    Value::Agg(vec![Value::Double(k), Value::Bool(k > 1.0)]),
                ),
                AttributeValuePair::new("alt", Value::Altitude(k)),
            ]
        };
        m.push(&sample(1.0, "old"));
        assert_eq!(
            m.push(&sample(3.0, "new")),
            vec![
                AttributeValuePair::new("label", Value::String("new".into())),
                AttributeValuePair::new(
                    "pose",
                    Value::PositionAltitudeRotation(PositionAltitudeRotation {
                        position: Position { north: 2.0, east: 4.0 },
                        altitude: 6.0,
                        rotation: Rotation { roll: 2.0, pitch: 2.0, yaw: -2.0 },
                    },)
                ),
                AttributeValuePair::new("v", Value::Vec(Vec3 { x: 2.0, y: 0.0, z: 1.0 })),
                AttributeValuePair::new("path", Value::Pos2Seq(vec![Pos2 { x: 2.0, y: 2.0 }])),
                AttributeValuePair::new("t", Value::Time(3)),
                AttributeValuePair::new(
                    "agg",
                    Value::Agg(vec![Value::Double(2.0), Value::Bool(true)])
                ),
                AttributeValuePair::new("alt", Value::Altitude(2.0)),
            ]
        );
    }

    #[test]
    fn a_changed_sort_or_name_restarts_the_window() {
        let mut m = avg(3);
        m.push(&[AttributeValuePair::new("a", Value::Double(10.0))]);
        let as_long = m.push(&[AttributeValuePair::new("a", Value::Long(2))]);
        assert_eq!(as_long, [AttributeValuePair::new("a", Value::Long(2))]);
        let renamed = m.push(&[AttributeValuePair::new("b", Value::Long(4))]);
        assert_eq!(renamed, [AttributeValuePair::new("b", Value::Long(4))]);
        assert_eq!(m.len(), 1);
    }

    #[test]
    fn structures_keep_the_newest_name_and_times() {
        let mut m = avg(2);
        let es = |x: f64, t| RobotState { x, y: 0.0, dir: 0.0 }.to_structure("robot1", t, t + 1);
        m.push_structure(&es(2.0, 10));
        let out = m.push_structure(&es(4.0, 20));
        assert_eq!((out.name.as_str(), out.valid_time, out.create_time), ("robot1", 20, 21));
        assert_eq!(RobotState::from_structure(&out).unwrap().x, 3.0);
    }

    #[test]
    fn huge_and_nan_values_do_not_panic() {
        let mut m = avg(2);
        m.push(&[AttributeValuePair::new("a", Value::Long(i64::MAX))]);
        let out = m.push(&[AttributeValuePair::new("a", Value::Long(i64::MAX))]);
        assert_eq!(out, [AttributeValuePair::new("a", Value::Long(i64::MAX))]);
        let mut m = avg(2);
        m.push(&[AttributeValuePair::new("a", Value::Double(f64::NAN))]);
        let out = m.push(&[AttributeValuePair::new("a", Value::Double(1.0))]);
        assert!(matches!(out[0].value, Value::Double(x) if x.is_nan()));
    }
}
