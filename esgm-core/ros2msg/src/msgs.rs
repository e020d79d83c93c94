//! The ROS 2 messages esgm maps its library types to, as plain serde structs whose
//! field order is the message definition's: `ros2-client` encodes them as ROS 2's CDR,
//! so their bytes are those of `rclcpp`'s messages of the same names.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds past `sec`, below 1e9.
    pub nanosec: u32,
}

/// `std_msgs/msg/Header`: when and in which frame the data was taken.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The time the data was taken (esgm's valid time).
    pub stamp: Time,
    /// The coordinate frame (esgm: the structure's name).
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`: an uncompressed image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Acquisition time and camera frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`rgb8`, `mono8`, … as `sensor_msgs/image_encodings.hpp` names
    /// them).
    pub encoding: String,
    /// Byte order of multi-byte pixels (irrelevant for 8-bit encodings).
    pub is_bigendian: u8,
    /// Bytes of one row, padding included.
    pub step: u32,
    /// `step * height` bytes.
    pub data: Vec<u8>,
}

/// `geometry_msgs/msg/Pose2D`: a pose in the plane (`theta` in radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose2D {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// Heading, radians, counter-clockwise from x.
    pub theta: f64,
}

/// `geometry_msgs/msg/Vector3`: a vector in free space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}
