//! Attribute paths: how `best.size` or `pose.position.north` reaches a value, both
//! statically (which fields a value sort has) and at run time (walking a structure's
//! attributes without allocating).

use crate::value::frame::AttributeValuePair;
use crate::value::{Position, Rotation, Value, ValueSort};

/// A checked attribute path: an attribute, then attributes of nested frames and
/// fields of structured values.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Path {
    steps: Box<[Step]>,
}

#[derive(Debug, Clone, PartialEq)]
pub(super) enum Step {
    /// An attribute of the structure or of a nested frame. `index` is its position in
    /// the declared type, tried first: structures usually list attributes in that order.
    Attr { name: Box<str>, index: usize },
    /// A field of a structured value (`Pos2`, `Vec`, `Position`, …).
    Field(Field),
}

/// A field of a structured value sort.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Field {
    X,
    Y,
    Z,
    North,
    East,
    Roll,
    Pitch,
    Yaw,
    Position,
    Altitude,
    Rotation,
}

impl Field {
    /// The fields a value sort has, with their names and sorts; empty for sorts that
    /// are not structured values.
    pub fn of(sort: ValueSort) -> &'static [(&'static str, Field, ValueSort)] {
        use ValueSort::{Altitude, Double};
        match sort {
            ValueSort::Pos2 => &[("x", Field::X, Double), ("y", Field::Y, Double)],
            ValueSort::Vec => {
                &[("x", Field::X, Double), ("y", Field::Y, Double), ("z", Field::Z, Double)]
            }
            ValueSort::Position => {
                &[("north", Field::North, Double), ("east", Field::East, Double)]
            }
            ValueSort::Rotation => &[
                ("roll", Field::Roll, Double),
                ("pitch", Field::Pitch, Double),
                ("yaw", Field::Yaw, Double),
            ],
            ValueSort::PositionAltitude => &[
                ("position", Field::Position, ValueSort::Position),
                ("altitude", Field::Altitude, Altitude),
            ],
            ValueSort::PositionAltitudeRotation => &[
                ("position", Field::Position, ValueSort::Position),
                ("altitude", Field::Altitude, Altitude),
                ("rotation", Field::Rotation, ValueSort::Rotation),
            ],
            _ => &[],
        }
    }

    fn apply(self, found: Found<'_>) -> Option<Found<'_>> {
        let value = match found {
            Found::Value(v) => v,
            Found::Position(p) => return self.of_position(&p),
            Found::Rotation(r) => return self.of_rotation(&r),
            Found::Float(_) => return None,
        };
        let f = match (self, value) {
            (Field::X, Value::Pos2(p)) => p.x,
            (Field::Y, Value::Pos2(p)) => p.y,
            (Field::X, Value::Vec(v)) => v.x,
            (Field::Y, Value::Vec(v)) => v.y,
            (Field::Z, Value::Vec(v)) => v.z,
            (_, Value::Position(p)) => return self.of_position(p),
            (_, Value::Rotation(r)) => return self.of_rotation(r),
            (Field::Position, Value::PositionAltitude(pa)) => {
                return Some(Found::Position(pa.position));
            }
            (Field::Altitude, Value::PositionAltitude(pa)) => pa.altitude,
            (Field::Position, Value::PositionAltitudeRotation(p)) => {
                return Some(Found::Position(p.position));
            }
            (Field::Altitude, Value::PositionAltitudeRotation(p)) => p.altitude,
            (Field::Rotation, Value::PositionAltitudeRotation(p)) => {
                return Some(Found::Rotation(p.rotation));
            }
            _ => return None,
        };
        Some(Found::Float(f))
    }

    fn of_position(self, p: &Position) -> Option<Found<'static>> {
        match self {
            Field::North => Some(Found::Float(p.north)),
            Field::East => Some(Found::Float(p.east)),
            _ => None,
        }
    }

    fn of_rotation(self, r: &Rotation) -> Option<Found<'static>> {
        match self {
            Field::Roll => Some(Found::Float(r.roll)),
            Field::Pitch => Some(Found::Float(r.pitch)),
            Field::Yaw => Some(Found::Float(r.yaw)),
            _ => None,
        }
    }
}

/// What a path reaches: a value in the structure, or a copy of a (small) part of one.
#[derive(Debug, Clone, Copy)]
pub(super) enum Found<'a> {
    Value(&'a Value),
    Float(f64),
    Position(Position),
    Rotation(Rotation),
}

impl<'a> Found<'a> {
    pub fn as_long(self) -> Option<i64> {
        match self {
            Found::Value(Value::Long(v) | Value::Time(v)) => Some(*v),
            _ => None,
        }
    }

    pub fn as_double(self) -> Option<f64> {
        match self {
            Found::Value(Value::Double(v) | Value::Altitude(v)) => Some(*v),
            Found::Float(v) => Some(v),
            _ => None,
        }
    }

    pub fn as_bool(self) -> Option<bool> {
        match self {
            Found::Value(Value::Bool(v)) => Some(*v),
            _ => None,
        }
    }

    pub fn as_str(self) -> Option<&'a str> {
        match self {
            Found::Value(Value::String(v) | Value::Symbol(v)) => Some(v),
            _ => None,
        }
    }

    /// The number of elements of a sequence, or of characters of a string.
    pub fn len(self) -> Option<i64> {
        let Found::Value(value) = self else { return None };
        let n = match value {
            Value::String(s) | Value::Symbol(s) => s.chars().count(),
            Value::OctetSeq(v) => v.len(),
            Value::LongSeq(v) => v.len(),
            Value::DoubleSeq(v) => v.len(),
            Value::SymbolSeq(v) => v.len(),
            Value::VecSeq(v) => v.len(),
            Value::Pos2Seq(v) => v.len(),
            Value::Agg(v) | Value::Collection(v) => v.len(),
            Value::EntityFrameSeq(v) => v.len(),
            _ => return None,
        };
        // No length in memory exceeds `i64::MAX`.
        i64::try_from(n).ok()
    }
}

/// True for the sorts `len` measures.
pub(super) fn has_len(sort: ValueSort) -> bool {
    matches!(
        sort,
        ValueSort::String
            | ValueSort::Symbol
            | ValueSort::OctetSeq
            | ValueSort::LongSeq
            | ValueSort::DoubleSeq
            | ValueSort::SymbolSeq
            | ValueSort::VecSeq
            | ValueSort::Pos2Seq
            | ValueSort::Agg
            | ValueSort::Collection
            | ValueSort::EntityFrameSeq
    )
}

impl Path {
    pub fn new(steps: Vec<Step>) -> Self {
        Path { steps: steps.into_boxed_slice() }
    }

    /// Walks the path through `attributes`; `None` if the structure does not have what
    /// the type promised (a missing attribute or a value of another sort).
    pub fn get<'a>(&self, attributes: &'a [AttributeValuePair]) -> Option<Found<'a>> {
        let mut found: Option<Found<'a>> = None;
        for step in &self.steps {
            found = Some(match (step, found) {
                (Step::Attr { name, index }, None) => {
                    Found::Value(lookup(attributes, name, *index)?)
                }
                (Step::Attr { name, index }, Some(Found::Value(Value::EntityFrame(frame)))) => {
                    Found::Value(lookup(&frame.attributes, name, *index)?)
                }
                (Step::Field(field), Some(f)) => field.apply(f)?,
                _ => return None,
            });
        }
        found
    }
}

fn lookup<'a>(attributes: &'a [AttributeValuePair], name: &str, index: usize) -> Option<&'a Value> {
    match attributes.get(index) {
        Some(pair) if pair.name == name => Some(&pair.value),
        _ => attributes.iter().find(|p| p.name == name).map(|p| &p.value),
    }
}
