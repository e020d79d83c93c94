//! Which ROS 2 message each esgm library type is, and the conversions both ways.
//!
//! | esgm type | ROS 2 message | how |
//! |---|---|---|
//! | `Image` | `sensor_msgs/msg/Image` | `rgb8` ↔ `FORMAT_RGB8`, `mono8` ↔ `FORMAT_MONO8`; `header.stamp` ↔ valid time, `header.frame_id` ↔ the structure's name; rows padded past `width × bytes per pixel` (`step`) are unpadded on import |
//! | `RobotState` | `geometry_msgs/msg/Pose2D` | `x`, `y`; `dir` (degrees) ↔ `theta` (radians) |
//! | `DrivingDirection` | `geometry_msgs/msg/Vector3` | the planar velocity: `x = speed·cos(dir)`, `y = speed·sin(dir)`, `z = 0`; back, `speed = ‖(x, y)‖`, `dir = atan2(y, x)` in degrees |
//!
//! A message without a header (`Pose2D`, `Vector3`) is valid when it is received.
//! Anything that does not map is refused with a [`MappingError`] that names the field
//! and its value (`esgm ros2` counts it).

use esgm_core::library::{DrivingDirection, Image, RobotState};
use esgm_core::pixel_buffer::PixelBuffer;
use esgm_core::{Entity, EntityStructure, InProcessTrajectory, Time};

use crate::msgs::{self, Time as RosTime};

/// A ROS 2 message type esgm maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RosType {
    /// `sensor_msgs/msg/Image` ↔ `Image`.
    Image,
    /// `geometry_msgs/msg/Pose2D` ↔ `RobotState`.
    Pose2D,
    /// `geometry_msgs/msg/Vector3` ↔ `DrivingDirection`.
    Vector3,
}

/// A message or structure that cannot be mapped; names what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MappingError {
    /// The ROS 2 type is not one esgm maps (`--import TOPIC:TYPE`).
    #[error("no esgm type for the ROS 2 message `{name}`; esgm maps {known}")]
    UnknownMessage {
        /// The type asked for.
        name: String,
        /// The types esgm maps.
        known: String,
    },
    /// The esgm type has no ROS 2 message (`--export TRAJ`).
    #[error("no ROS 2 message for the esgm type `{esgm_type}`; esgm maps {known}")]
    NoMessage {
        /// The trajectory's type.
        esgm_type: String,
        /// The types esgm maps.
        known: String,
    },
    /// A field's value has no counterpart on the other side.
    #[error("field `{field}` = {value}: {why}")]
    Unconvertible {
        /// The field (of the message on import, of the structure on export).
        field: &'static str,
        /// Its value, as shown.
        value: String,
        /// Why it does not map.
        why: &'static str,
    },
}

fn unconvertible(
    field: &'static str,
    value: impl std::fmt::Display,
    why: &'static str,
) -> MappingError {
    MappingError::Unconvertible { field, value: value.to_string(), why }
}

impl RosType {
    /// Every mapped type.
    pub const ALL: [RosType; 3] = [RosType::Image, RosType::Pose2D, RosType::Vector3];

    /// Its ROS 2 name, `package/msg/Type`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Image => "sensor_msgs/msg/Image",
            Self::Pose2D => "geometry_msgs/msg/Pose2D",
            Self::Vector3 => "geometry_msgs/msg/Vector3",
        }
    }

    /// The esgm library type it maps to.
    pub fn esgm_type(self) -> &'static str {
        match self {
            Self::Image => Image::TYPE_NAME,
            Self::Pose2D => RobotState::TYPE_NAME,
            Self::Vector3 => DrivingDirection::TYPE_NAME,
        }
    }

    /// The type named `name` (`sensor_msgs/msg/Image`; `sensor_msgs/Image` too, as ROS
    /// 1 and older tools write it).
    pub fn parse(name: &str) -> Result<Self, MappingError> {
        let full = |t: &RosType| {
            let n = t.name();
            n == name || n.replacen("/msg/", "/", 1) == name
        };
        Self::ALL.into_iter().find(full).ok_or_else(|| MappingError::UnknownMessage {
            name: name.to_owned(),
            known: Self::known(),
        })
    }

    /// The message the esgm type `esgm_type` is exported as.
    pub fn for_esgm_type(esgm_type: &str) -> Result<Self, MappingError> {
        Self::ALL.into_iter().find(|t| t.esgm_type() == esgm_type).ok_or_else(|| {
            MappingError::NoMessage { esgm_type: esgm_type.to_owned(), known: Self::known() }
        })
    }

    fn known() -> String {
        Self::ALL
            .iter()
            .map(|t| format!("{} ({})", t.name(), t.esgm_type()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Its package and message name (`("sensor_msgs", "Image")`).
    pub fn package_and_name(self) -> (&'static str, &'static str) {
        let mut parts = self.name().split('/');
        let package = parts.next().unwrap_or_default();
        let name = parts.next_back().unwrap_or_default();
        (package, name)
    }
}

/// esgm's time (nanoseconds) as a ROS 2 stamp; refused outside what a stamp holds
/// (seconds in an `i32`).
pub fn ros_time(t: Time) -> Result<RosTime, MappingError> {
    let sec = t.div_euclid(1_000_000_000);
    let nanosec = t.rem_euclid(1_000_000_000);
    let sec = i32::try_from(sec)
        .map_err(|_| unconvertible("header.stamp", t, "outside the seconds a ROS 2 stamp holds"))?;
    // rem_euclid of a positive divisor is within 0..1e9.
    Ok(RosTime { sec, nanosec: u32::try_from(nanosec).unwrap_or(0) })
}

/// A ROS 2 stamp as esgm's time.
pub fn esgm_time(t: RosTime) -> Time {
    i64::from(t.sec) * 1_000_000_000 + i64::from(t.nanosec)
}

/// An imported `sensor_msgs/msg/Image` as an `Image` structure, its pixels written once
/// into `trajectory`'s own memory (a loan of its shared memory, which local readers
/// read without a copy).
pub fn image_in(
    msg: &msgs::Image,
    trajectory: &InProcessTrajectory,
    add_time: Time,
) -> Result<EntityStructure, MappingError> {
    image_in_with(msg, add_time, |w, h, f| trajectory.image_buffer(w, h, f))
}

/// [`image_in`], the pixels written into the buffer `buffer(width, height, format)`
/// gives (a heap buffer where no trajectory is at hand, as in a recording).
pub fn image_in_with(
    msg: &msgs::Image,
    add_time: Time,
    buffer: impl FnOnce(i64, i64, i64) -> Option<PixelBuffer>,
) -> Result<EntityStructure, MappingError> {
    let format = match msg.encoding.as_str() {
        "rgb8" => Image::FORMAT_RGB8,
        "mono8" | "8UC1" => Image::FORMAT_MONO8,
        other => {
            return Err(unconvertible("encoding", other, "esgm's Image holds rgb8 and mono8"));
        }
    };
    let bytes_per_pixel = Image::bytes_per_pixel(format).unwrap_or(1);
    let row = msg.width as usize * bytes_per_pixel;
    let (width, height) = (i64::from(msg.width), i64::from(msg.height));
    if (msg.step as usize) < row {
        return Err(unconvertible("step", msg.step, "shorter than a row of pixels"));
    }
    let needed = msg.step as usize * msg.height as usize;
    if msg.data.len() < needed {
        return Err(unconvertible(
            "data",
            format!("{} bytes", msg.data.len()),
            "fewer than step × height",
        ));
    }
    let Some(mut buffer) = buffer(width, height, format) else {
        return Err(unconvertible(
            "width × height",
            format!("{width} × {height}"),
            "too large an image",
        ));
    };
    let pixels = buffer.pixels_mut();
    for (r, out) in pixels.chunks_exact_mut(row.max(1)).enumerate().take(msg.height as usize) {
        let start = r * msg.step as usize;
        out.copy_from_slice(&msg.data[start..start + row]);
    }
    let valid = esgm_time(msg.header.stamp);
    let name = if msg.header.frame_id.is_empty() { "image" } else { msg.header.frame_id.as_str() };
    let image = Image { width, height, format, image_data: buffer.into_octets() };
    Ok(image.to_structure(name, valid, add_time))
}

/// An `Image` structure as a `sensor_msgs/msg/Image` (one copy of its pixels, into the
/// message DDS sends).
pub fn image_out(es: &EntityStructure) -> Result<msgs::Image, MappingError> {
    let image =
        Image::from_structure(es).map_err(|e| unconvertible("attributes", e, "not an Image"))?;
    let encoding = match image.format {
        Image::FORMAT_RGB8 => "rgb8",
        Image::FORMAT_MONO8 => "mono8",
        other => return Err(unconvertible("format", other, "no ROS 2 encoding for it")),
    };
    let bytes_per_pixel = Image::bytes_per_pixel(image.format).unwrap_or(1);
    let width = u32::try_from(image.width)
        .map_err(|_| unconvertible("width", image.width, "negative or too large"))?;
    let height = u32::try_from(image.height)
        .map_err(|_| unconvertible("height", image.height, "negative or too large"))?;
    let step = u32::try_from(width as usize * bytes_per_pixel)
        .map_err(|_| unconvertible("width", width, "a row longer than a ROS 2 step holds"))?;
    let data: &[u8] = image.image_data.as_ref();
    if data.len() != step as usize * height as usize {
        return Err(unconvertible(
            "image_data",
            format!("{} bytes", data.len()),
            "not width × height × bytes per pixel",
        ));
    }
    Ok(msgs::Image {
        header: msgs::Header { stamp: ros_time(es.valid_time)?, frame_id: es.name.clone() },
        height,
        width,
        encoding: encoding.to_owned(),
        is_bigendian: 0,
        step,
        data: data.to_vec(),
    })
}

/// An imported `geometry_msgs/msg/Pose2D` as a `RobotState` valid at `received`.
pub fn pose_in(msg: &msgs::Pose2D, name: &str, received: Time) -> EntityStructure {
    RobotState { x: msg.x, y: msg.y, dir: msg.theta.to_degrees() }
        .to_structure(name, received, received)
}

/// A `RobotState` structure as a `geometry_msgs/msg/Pose2D`.
pub fn pose_out(es: &EntityStructure) -> Result<msgs::Pose2D, MappingError> {
    let s = RobotState::from_structure(es)
        .map_err(|e| unconvertible("attributes", e, "not a RobotState"))?;
    Ok(msgs::Pose2D { x: s.x, y: s.y, theta: s.dir.to_radians() })
}

/// An imported `geometry_msgs/msg/Vector3` (a planar velocity) as a `DrivingDirection`
/// valid at `received`.
pub fn velocity_in(msg: &msgs::Vector3, name: &str, received: Time) -> EntityStructure {
    let speed = msg.x.hypot(msg.y);
    let dir = if speed == 0.0 { 0.0 } else { msg.y.atan2(msg.x).to_degrees() };
    DrivingDirection { dir, speed }.to_structure(name, received, received)
}

/// A `DrivingDirection` structure as a `geometry_msgs/msg/Vector3`.
pub fn velocity_out(es: &EntityStructure) -> Result<msgs::Vector3, MappingError> {
    let d = DrivingDirection::from_structure(es)
        .map_err(|e| unconvertible("attributes", e, "not a DrivingDirection"))?;
    let (sin, cos) = d.dir.to_radians().sin_cos();
    Ok(msgs::Vector3 { x: d.speed * cos, y: d.speed * sin, z: 0.0 })
}

/// A ROS 2 message stored as CDR (in a ROS 2 bag: rosbag2's, or `esgm record
/// --ros2`'s) could not be read as a structure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The bytes are not a message of the type.
    #[error("{0}")]
    Cdr(#[from] crate::cdr::CdrError),
    /// The message does not map to its esgm type.
    #[error("{0}")]
    Mapping(#[from] MappingError),
}

/// A message of `t` from its CDR bytes, as the structure `esgm ros2`'s import makes of
/// it (named `name` where the message has no frame id, valid at `received` where it
/// has no header); an image's pixels go into the buffer `image_buffer` gives.
pub fn structure_from_cdr(
    t: RosType,
    cdr: &[u8],
    name: &str,
    received: Time,
    image_buffer: impl FnOnce(i64, i64, i64) -> Option<PixelBuffer>,
) -> Result<EntityStructure, DecodeError> {
    Ok(match t {
        RosType::Image => {
            image_in_with(&crate::cdr::decode::<msgs::Image>(cdr)?, received, image_buffer)?
        }
        RosType::Pose2D => pose_in(&crate::cdr::decode(cdr)?, name, received),
        RosType::Vector3 => velocity_in(&crate::cdr::decode(cdr)?, name, received),
    })
}

/// The trajectory a topic goes into by default: its name without the leading `/`,
/// with `/` as `_` (`/camera/image_raw` → `camera_image_raw`).
pub fn trajectory_for(topic: &str) -> String {
    topic.trim_start_matches('/').replace('/', "_")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]
    use super::*;

    #[test]
    fn names_parse_both_ways_and_unknown_ones_name_the_known() {
        assert_eq!(RosType::parse("sensor_msgs/msg/Image").unwrap(), RosType::Image);
        assert_eq!(RosType::parse("geometry_msgs/Pose2D").unwrap(), RosType::Pose2D);
        let e = RosType::parse("sensor_msgs/msg/PointCloud2").unwrap_err();
        assert!(e.to_string().contains("sensor_msgs/msg/Image (Image)"), "{e}");
        assert_eq!(RosType::for_esgm_type("DrivingDirection").unwrap(), RosType::Vector3);
        assert!(matches!(RosType::for_esgm_type("Blob"), Err(MappingError::NoMessage { .. })));
        assert_eq!(RosType::Image.package_and_name(), ("sensor_msgs", "Image"));
    }

    #[test]
    fn stamps_round_trip_and_refuse_what_a_stamp_cannot_hold() {
        for t in [0, 1, 999_999_999, 1_700_000_000_123_456_789, -1_500_000_000] {
            assert_eq!(esgm_time(ros_time(t).unwrap()), t);
        }
        assert!(ros_time(i64::MAX).is_err());
    }

    #[test]
    fn poses_and_velocities_round_trip() {
        let es = RobotState { x: 1.5, y: -2.0, dir: 90.0 }.to_structure("robot", 5, 5);
        let msg = pose_out(&es).unwrap();
        assert!((msg.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let back = RobotState::from_structure(&pose_in(&msg, "robot", 7)).unwrap();
        assert!((back.dir - 90.0).abs() < 1e-9 && back.x == 1.5 && back.y == -2.0);
        let es = DrivingDirection { dir: 30.0, speed: 2.0 }.to_structure("cmd", 1, 1);
        let v = velocity_out(&es).unwrap();
        let back = DrivingDirection::from_structure(&velocity_in(&v, "cmd", 2)).unwrap();
        assert!((back.dir - 30.0).abs() < 1e-9 && (back.speed - 2.0).abs() < 1e-12);
    }

    #[test]
    fn an_image_maps_with_its_padding_removed_and_bad_ones_name_the_field() {
        let esgm = esgm_core::InProcessEsgm::builder().create();
        let t =
            esgm_core::Esgm::create_primitive_entity_trajectory_structure(&esgm, "cam", "Image")
                .unwrap();
        // 2 × 2 rgb8 with 2 bytes of padding a row.
        let msg = msgs::Image {
            header: msgs::Header {
                stamp: RosTime { sec: 3, nanosec: 5 },
                frame_id: "camera".into(),
            },
            height: 2,
            width: 2,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 8,
            data: (0..16).collect(),
        };
        let es = image_in(&msg, &t, 1).unwrap();
        assert_eq!((es.name.as_str(), es.valid_time), ("camera", 3_000_000_005));
        let image = Image::from_structure(&es).unwrap();
        let pixels: &[u8] = image.image_data.as_ref();
        assert_eq!(pixels, &[0, 1, 2, 3, 4, 5, 8, 9, 10, 11, 12, 13]);
        let out = image_out(&es).unwrap();
        assert_eq!((out.step, out.encoding.as_str(), out.header), (6, "rgb8", msg.header.clone()));
        let bad = |f: &dyn Fn(&mut msgs::Image)| {
            let mut m = msg.clone();
            f(&mut m);
            match image_in(&m, &t, 1) {
                Err(MappingError::Unconvertible { field, .. }) => field,
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(bad(&|m| m.encoding = "bgr16".into()), "encoding");
        assert_eq!(bad(&|m| m.step = 5), "step");
        assert_eq!(bad(&|m| m.data.truncate(10)), "data");
    }
}
