//! The predefined entity structure types (M6): the tutorial's types exactly as chapter 7
//! of the seed lists their attributes, and common robot types.
//!
//! Each is a plain struct deriving [`Entity`], so applications use fields instead of
//! the seed's `…Wrapper` classes.

use crate::entity::Entity;
use crate::types::EntityStructureType;
use crate::value::{Octets, PositionAltitudeRotation, Vec3};

/// `Image` (7.1.0.1): a single camera image.
#[derive(Debug, Clone, PartialEq, Entity)]
pub struct Image {
    /// Width in pixels.
    pub width: i64,
    /// Height in pixels.
    pub height: i64,
    /// Pixel format, see [`Image::FORMAT_RGB8`] and [`Image::FORMAT_MONO8`].
    pub format: i64,
    /// The pixels, laid out as `format` says.
    pub image_data: Octets,
}

impl Image {
    /// Packed 8-bit RGB, row-major (3 bytes a pixel): the seed's camera format 0.
    pub const FORMAT_RGB8: i64 = 0;
    /// 8-bit grey, row-major (1 byte a pixel).
    pub const FORMAT_MONO8: i64 = 1;

    /// Bytes per pixel of `format`, if known.
    pub fn bytes_per_pixel(format: i64) -> Option<usize> {
        match format {
            Self::FORMAT_RGB8 => Some(3),
            Self::FORMAT_MONO8 => Some(1),
            _ => None,
        }
    }
}

/// `Blob` (7.1.0.2): a blob found in an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Entity)]
pub struct Blob {
    /// x position within the image (pixels).
    pub x: i64,
    /// y position within the image (pixels).
    pub y: i64,
    /// Size in pixels.
    pub size: i64,
}

/// `BlobSeq` (7.1.0.3): the blobs found in one image.
#[derive(Debug, Clone, PartialEq, Eq, Entity)]
pub struct BlobSeq {
    /// The blobs (an entity frame sequence of `Blob` frames).
    pub items: Vec<Blob>,
}

/// `RobotState` (7.1.0.4): the robot's planar pose.
#[derive(Debug, Clone, Copy, PartialEq, Entity)]
pub struct RobotState {
    /// x coordinate of the robot's position.
    pub x: f64,
    /// y coordinate of the robot's position.
    pub y: f64,
    /// Heading in degrees.
    pub dir: f64,
}

/// `DrivingDirection` (7.1.0.5): the desired direction and speed.
#[derive(Debug, Clone, Copy, PartialEq, Entity)]
pub struct DrivingDirection {
    /// Desired heading in degrees.
    pub dir: f64,
    /// Desired speed.
    pub speed: f64,
}

/// A 6-DoF pose, a common robot type beyond the tutorial.
#[derive(Debug, Clone, Copy, PartialEq, Entity)]
pub struct Pose {
    /// Position, altitude and orientation.
    pub pose: PositionAltitudeRotation,
}

/// A linear and angular velocity, a common robot type beyond the tutorial.
#[derive(Debug, Clone, Copy, PartialEq, Entity)]
pub struct Twist {
    /// Linear velocity (m/s).
    pub linear: Vec3,
    /// Angular velocity (rad/s).
    pub angular: Vec3,
}

/// Every predefined type, for [`crate::TypeRegistry::with_library`].
pub fn predefined_types() -> Vec<EntityStructureType> {
    vec![
        Image::entity_structure_type(),
        Blob::entity_structure_type(),
        BlobSeq::entity_structure_type(),
        RobotState::entity_structure_type(),
        DrivingDirection::entity_structure_type(),
        Pose::entity_structure_type(),
        Twist::entity_structure_type(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::type_check::TypeChecker;
    use crate::type_registry::TypeRegistry;
    use crate::value::ValueSort;

    #[test]
    fn tutorial_types_match_chapter_7() {
        let sorts = |t: EntityStructureType| {
            t.attributes.into_iter().map(|a| (a.name, a.sort)).collect::<Vec<_>>()
        };
        use ValueSort::{Double, EntityFrameSeq, Long, OctetSeq};
        let s = |v: &[(&str, ValueSort)]| {
            v.iter().map(|(n, s)| (n.to_string(), *s)).collect::<Vec<_>>()
        };
        assert_eq!(
            sorts(Image::entity_structure_type()),
            s(&[("width", Long), ("height", Long), ("format", Long), ("image_data", OctetSeq)])
        );
        assert_eq!(
            sorts(Blob::entity_structure_type()),
            s(&[("x", Long), ("y", Long), ("size", Long)])
        );
        assert_eq!(sorts(BlobSeq::entity_structure_type()), s(&[("items", EntityFrameSeq)]));
        assert_eq!(
            BlobSeq::entity_structure_type().attributes[0].element_type.as_deref(),
            Some("Blob")
        );
        assert_eq!(
            sorts(RobotState::entity_structure_type()),
            s(&[("x", Double), ("y", Double), ("dir", Double)])
        );
        assert_eq!(
            sorts(DrivingDirection::entity_structure_type()),
            s(&[("dir", Double), ("speed", Double)])
        );
    }

    #[test]
    fn library_registers_and_checks_nested_blobs() {
        let r = TypeRegistry::with_library();
        assert_eq!(r.len(), predefined_types().len());
        let c = TypeChecker::new(&r, "BlobSeq").unwrap();
        let seq = BlobSeq { items: vec![Blob { x: 1, y: 2, size: 3 }] };
        let es = seq.to_structure("blobs", 5, 6);
        assert_eq!(c.check(&es.attributes), Ok(()));
        assert_eq!(BlobSeq::from_structure(&es).unwrap(), seq);
    }
}
