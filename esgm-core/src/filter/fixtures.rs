//! Test support: a type with an attribute of every sort the language treats
//! differently, and a structure of that type.

use super::{Filter, FilterError};
use crate::type_check::TypeChecker;
use crate::type_registry::TypeRegistry;
use crate::types::{Attr, EntityStructureType};
use crate::value::frame::EntityFrame;
use crate::value::{
    Octets, Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort,
    Vec3,
};

pub fn checker() -> TypeChecker {
    use ValueSort::*;
    let mut r = TypeRegistry::new();
    let blob = EntityStructureType::new("Blob").attr("x", Long).attr("y", Long).attr("size", Long);
    r.create_entity_structure_type("Blob", blob).unwrap();
    let mut all = EntityStructureType::new("All");
    for (name, sort) in [
        ("size", Long),
        ("x", Long),
        ("t", Time),
        ("speed", Double),
        ("alt", Altitude),
        ("flag", Bool),
        ("name", String),
        ("sym", Symbol),
        ("image_data", OctetSeq),
        ("longs", LongSeq),
        ("doubles", DoubleSeq),
        ("syms", SymbolSeq),
        ("vecs", VecSeq),
        ("pts", Pos2Seq),
        ("coll", Collection),
        ("pos", Pos2),
        ("vel", Vec),
        ("at", Position),
        ("rot", Rotation),
        ("pa", PositionAltitude),
        ("pose", PositionAltitudeRotation),
        ("any", AnyValue),
        ("raw", EntityFrame),
    ] {
        all = all.attr(name, sort);
    }
    let mut all = all.frame("best", "Blob").frame_seq("items", "Blob");
    all.attributes.push(Attr::new("empty_name", ValueSort::String));
    r.create_entity_structure_type("All", all).unwrap();
    TypeChecker::new(&r, "All").unwrap()
}

pub fn blob(x: i64, size: i64) -> EntityFrame {
    EntityFrame::new("b").with("x", x).with("y", 0i64).with("size", size)
}

/// A structure of type `All` that the checker accepts.
pub fn sample() -> EntityFrame {
    let frame = EntityFrame::new("s")
        .with("size", 12i64)
        .with("x", -3i64)
        .with("t", Value::Time(1_000))
        .with("speed", 2.5)
        .with("alt", Value::Altitude(120.0))
        .with("flag", true)
        .with("name", "blob \"one\"")
        .with("sym", Value::Symbol("robot1".into()))
        .with("image_data", Octets::from(vec![0u8; 6]))
        .with("longs", Value::LongSeq(vec![1, 2, 3]))
        .with("doubles", Value::DoubleSeq(vec![0.5]))
        .with("syms", Value::SymbolSeq(vec!["a".into(), "b".into()]))
        .with("vecs", Value::VecSeq(vec![]))
        .with("pts", Value::Pos2Seq(vec![Pos2 { x: 1.0, y: 2.0 }; 4]))
        .with("coll", Value::Collection(vec![Value::Long(1), Value::Bool(true)]))
        .with("pos", Value::Pos2(Pos2 { x: 320.0, y: 240.0 }))
        .with("vel", Value::Vec(Vec3 { x: 1.0, y: -2.0, z: 0.5 }))
        .with("at", Value::Position(Position { north: 10.0, east: -5.0 }))
        .with("rot", Value::Rotation(Rotation { roll: 0.1, pitch: 0.2, yaw: 3.0 }))
        .with(
            "pa",
            Value::PositionAltitude(PositionAltitude {
                position: Position { north: 1.0, east: 2.0 },
                altitude: 30.0,
            }),
        )
        .with(
            "pose",
            Value::PositionAltitudeRotation(PositionAltitudeRotation {
                position: Position { north: 7.0, east: 8.0 },
                altitude: 9.0,
                rotation: Rotation { roll: 0.0, pitch: 0.0, yaw: -1.5 },
            }),
        )
        .with("any", 1i64)
        .with("raw", EntityFrame::new("r"))
        .with("best", blob(5, 40))
        .with("items", vec![blob(1, 2), blob(3, 4)])
        .with("empty_name", "");
    assert_eq!(checker().check(&frame.attributes), Ok(()));
    frame
}

pub fn compile(source: &str) -> Result<Filter, FilterError> {
    Filter::compile(source, &checker())
}

/// Compiles `source` against `All` and evaluates it on [`sample`].
pub fn eval(source: &str) -> bool {
    match compile(source) {
        Ok(f) => f.matches(&sample().attributes),
        Err(e) => panic!("`{source}` does not compile: {e}"),
    }
}
