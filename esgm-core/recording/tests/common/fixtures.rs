//! What the recording tests write: trajectory declarations and structures.

#![allow(dead_code)] // each test binary uses what it needs

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::{Image, RobotState};
use esgm_core::{Entity, EntityStructure};
use esgm_recording::TypeSchema;

/// A trajectory declaration with no policy, no source and no inputs.
pub fn info(name: &str, kind: TrajectoryKind, type_name: &str) -> TrajectoryInfo {
    TrajectoryInfo::new(name, kind, type_name)
}

/// A primitive trajectory's declaration.
pub fn primitive(name: &str, type_name: &str) -> TrajectoryInfo {
    info(name, TrajectoryKind::Primitive, type_name)
}

/// The schema of a library type (no nested types).
pub fn schema_of<E: Entity>() -> TypeSchema {
    TypeSchema::collect(E::entity_structure_type(), &|_| None)
}

/// The `i`-th robot state: valid at 1 000 + 100 i.
pub fn robot(i: i64) -> EntityStructure {
    RobotState { x: i as f64 * 0.5, y: -(i as f64), dir: 90.0 }.to_structure(
        "robot",
        1_000 + i * 100,
        2_000 + i,
    )
}

/// The `i`-th small image (`w`×`h` RGB): valid at 1 000 + 250 i.
pub fn image(i: i64, w: i64, h: i64) -> EntityStructure {
    let pixels: Vec<u8> = (0..w * h * 3).map(|p| (p * 7 + i) as u8).collect();
    Image { width: w, height: h, format: Image::FORMAT_RGB8, image_data: pixels.into() }
        .to_structure("camera", 1_000 + i * 250, 1_001 + i * 250)
}
