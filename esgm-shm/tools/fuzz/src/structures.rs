//! Entity structures to encode: the library's types as robots send them, a compound
//! of every value sort, nesting up to the bound, and random ones.

use esgm_core::codec::MAX_NESTING;
use esgm_core::library::{Blob, BlobSeq, DrivingDirection, Image, Pose, RobotState, Twist};
use esgm_core::value::{
    Octets, Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, Vec3,
};
use esgm_core::{AttributeValuePair, Entity, EntityFrame, EntityStructure};

use crate::rng::Rng;

const POSE: PositionAltitudeRotation = PositionAltitudeRotation {
    position: Position { north: 58.4, east: 15.6 },
    altitude: 120.0,
    rotation: Rotation { roll: 0.1, pitch: -0.2, yaw: 3.1 },
};

/// Valid structures of every kind a reader meets.
pub fn valid() -> Vec<EntityStructure> {
    let blob = Blob { x: 10, y: 20, size: 30 };
    let pixels: Vec<u8> = (0..96u8).collect();
    let mut all = vec![
        Image { width: 4, height: 8, format: Image::FORMAT_RGB8, image_data: Octets::from(pixels) }
            .to_structure("camera", 1_000, 1_001),
        RobotState { x: 1.5, y: -2.5, dir: 90.0 }.to_structure("robot_state", 2_000, 2_000),
        DrivingDirection { dir: 45.0, speed: 0.5 }.to_structure("driving_direction", 3, 4),
        blob.to_structure("current_blob", i64::MIN, i64::MAX),
        BlobSeq { items: vec![blob; 3] }.to_structure("blobs", 5, 6),
        Pose { pose: POSE }.to_structure("pose", 7, 8),
        Twist { linear: Vec3 { x: 1.0, y: 0.0, z: 0.0 }, angular: Vec3 { x: 0.0, y: 0.0, z: 0.3 } }
            .to_structure("twist", 9, 10),
        EntityStructure::default(),
        every_sort(),
    ];
    all.extend([1, 8, MAX_NESTING].map(nested));
    all
}

/// One attribute of every value sort.
fn every_sort() -> EntityStructure {
    let frame = EntityFrame::new("f").with("x", 1i64).with("s", "ü");
    let p2 = Pos2 { x: 1.0, y: 2.0 };
    let v3 = Vec3 { x: f64::NAN, y: f64::INFINITY, z: -0.0 };
    EntityStructure::new("every_sort", 11, 12)
        .with("no", Value::NoValue)
        .with("long", Value::Long(-7))
        .with("double", Value::Double(f64::MIN_POSITIVE))
        .with("bool", Value::Bool(true))
        .with("string", Value::String("hello".into()))
        .with("time", Value::Time(1_700_000_000_000_000_000))
        .with("symbol", Value::Symbol("sym".into()))
        .with("octets", Value::OctetSeq(Octets::from(vec![0xAB; 33])))
        .with("longs", Value::LongSeq(vec![1, -1, i64::MAX]))
        .with("doubles", Value::DoubleSeq(vec![0.5, -0.5]))
        .with("symbols", Value::SymbolSeq(vec!["a".into(), String::new()]))
        .with("vec", Value::Vec(v3))
        .with("vecs", Value::VecSeq(vec![v3, v3]))
        .with("pos2", Value::Pos2(p2))
        .with("pos2s", Value::Pos2Seq(vec![p2]))
        .with("position", Value::Position(POSE.position))
        .with("altitude", Value::Altitude(3.0))
        .with("rotation", Value::Rotation(POSE.rotation))
        .with(
            "position_altitude",
            Value::PositionAltitude(PositionAltitude { position: POSE.position, altitude: 1.0 }),
        )
        .with("pose", Value::PositionAltitudeRotation(POSE))
        .with("agg", Value::Agg(vec![Value::Long(1), Value::String("x".into())]))
        .with("collection", Value::Collection(vec![Value::Bool(false)]))
        .with("frame", Value::from(frame.clone()))
        .with("frames", Value::from(vec![frame.clone(), frame]))
}

/// A structure whose one attribute nests `depth` levels (aggregates and frames in
/// turn), as the codec's own nesting test builds it.
pub fn nested(depth: usize) -> EntityStructure {
    let mut v = Value::Long(7);
    for level in 0..depth {
        v = if level % 2 == 0 {
            Value::Agg(vec![v])
        } else {
            Value::from(EntityFrame::new("f").with("inner", v))
        };
    }
    EntityStructure::new("deep", 1, 2).with("v", v)
}

/// A random structure: random names, times and value trees up to `depth` levels, now
/// and then just past the nesting bound.
pub fn random(rng: &mut Rng) -> EntityStructure {
    if rng.chance(1) {
        return wide(rng);
    }
    let depth = match rng.below(10) {
        0 => MAX_NESTING + 1 + rng.below(3),
        1 => MAX_NESTING - rng.below(2),
        _ => rng.below(6),
    };
    let mut es = EntityStructure::new(name(rng), rng.next_u64() as i64, rng.next_u64() as i64);
    // A bound on values in all, so deep trees stay chains rather than growing
    // exponentially (a few hundred values, at most some 100 KiB encoded).
    let mut budget = 300;
    for _ in 0..rng.below(6) {
        es = es.with(name(rng), value(rng, depth, &mut budget));
    }
    es
}

/// A structure with thousands of small attributes (a few duplicated): what costs a
/// reader per attribute, not per byte, shows here.
pub fn wide(rng: &mut Rng) -> EntityStructure {
    let n = *rng.pick(&[1_000usize, 10_000, 30_000]);
    let mut es = EntityStructure::new("wide", 1, 2);
    // Pushed, not `with`: that replaces an attribute of the same name, so it would
    // search the list each time and remove the duplicates.
    es.attributes = (0..n)
        .map(|i| {
            let name = if rng.chance(1) { "x".to_owned() } else { format!("a{i}") };
            AttributeValuePair::new(name, Value::Long(i as i64))
        })
        .collect();
    es
}

fn name(rng: &mut Rng) -> String {
    let n = rng.len(40);
    (0..n).map(|_| *rng.pick(&['a', 'z', '_', '0', 'é', '/', ' ', '\u{1F916}'])).collect()
}

fn value(rng: &mut Rng, depth: usize, budget: &mut usize) -> Value {
    *budget = budget.saturating_sub(1);
    let count = rng.len(8).min(*budget);
    // Deep trees nest at every level, so the bound is reached (and passed) for sure.
    let sorts = match (depth > 0 && *budget > 0, depth > 8) {
        (false, _) => 0..10,
        (true, false) => 0..14,
        (true, true) => 10..14,
    };
    match sorts.start + rng.below(sorts.len()) {
        0 => Value::NoValue,
        1 => Value::Long(rng.next_u64() as i64),
        2 => Value::Double(double(rng)),
        3 => Value::String(name(rng)),
        4 => Value::OctetSeq(Octets::from({
            let n = rng.len(8192);
            rng.bytes(n)
        })),
        5 => Value::LongSeq((0..count).map(|_| rng.next_u64() as i64).collect()),
        6 => Value::SymbolSeq((0..count).map(|_| name(rng)).collect()),
        7 => Value::Vec(Vec3 { x: double(rng), y: double(rng), z: double(rng) }),
        8 => Value::Pos2Seq(vec![Pos2 { x: double(rng), y: double(rng) }; count]),
        9 => Value::PositionAltitudeRotation(POSE),
        10 => Value::Agg((0..count.max(1)).map(|_| value(rng, depth - 1, budget)).collect()),
        11 => Value::Collection((0..count.max(1)).map(|_| value(rng, depth - 1, budget)).collect()),
        12 => Value::from(frame(rng, depth - 1, budget)),
        _ => Value::from(
            (0..count.max(1)).map(|_| frame(rng, depth - 1, budget)).collect::<Vec<_>>(),
        ),
    }
}

/// Any 64 bits as a float: NaNs, infinities and subnormals included.
fn double(rng: &mut Rng) -> f64 {
    f64::from_bits(rng.next_u64())
}

fn frame(rng: &mut Rng, depth: usize, budget: &mut usize) -> EntityFrame {
    let mut f = EntityFrame::new(name(rng));
    // A frame always holds a value, so the nesting goes all the way down.
    for _ in 0..1 + rng.below(3).min(*budget) {
        f = f.with(name(rng), value(rng, depth, budget));
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn depth(v: &Value) -> usize {
        match v {
            Value::Agg(vs) | Value::Collection(vs) => 1 + vs.iter().map(depth).max().unwrap_or(0),
            Value::EntityFrame(f) => {
                1 + f.attributes.iter().map(|p| depth(&p.value)).max().unwrap_or(0)
            }
            Value::EntityFrameSeq(fs) => {
                1 + fs
                    .iter()
                    .flat_map(|f| f.attributes.iter().map(|p| depth(&p.value)))
                    .max()
                    .unwrap_or(0)
            }
            _ => 0,
        }
    }

    #[test]
    fn random_structures_are_bounded_and_sometimes_too_deep() {
        let mut deepest = 0;
        for i in 0..300 {
            let es = random(&mut Rng::for_case(5, i));
            let bytes = esgm_core::codec::encode(&es).map(|b| b.len()).unwrap_or(0);
            assert!(bytes < 4 << 20, "{bytes} bytes");
            deepest = deepest.max(es.attributes.iter().map(|p| depth(&p.value)).max().unwrap_or(0));
        }
        assert!(deepest > MAX_NESTING, "deepest {deepest}");
    }
}
