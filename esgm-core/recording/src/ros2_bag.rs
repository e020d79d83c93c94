//! ROS 2 bags read as recordings: a channel of the ROS 2 MCAP profile (`ros2msg`
//! schema, `cdr` messages), as rosbag2 writes them, whose message is a standard type
//! esgm maps (`sensor_msgs/msg/Image`, `geometry_msgs/msg/Pose2D`, `Vector3`) reads
//! as a primitive trajectory of its esgm type, named as `esgm ros2 --import` names
//! it (`/camera/image_raw` → `camera_image_raw`), so `esgm replay`, `load`, `info` and
//! `compare` take a robot's bag as they take esgm's own recordings.
//!
//! A message's valid time is its header's stamp, or its log time (when the bag
//! received it) for a type without a header, as the live import does; its add time is
//! its log time. A message that does not decode or map is counted as a loss of its
//! trajectory with the cause (`ros2_undecodable`, `ros2_unconvertible`); other
//! topics stay foreign topics (`esgm info` lists them).

use std::collections::BTreeMap;

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::pixel_buffer::PixelBuffer;
use esgm_core::{EntityStructure, Time, TypeRegistry};
use esgm_ros2msg::mapping::{self, DecodeError, RosType};

use crate::layout::TypeSchema;

/// The ROS 2 profile's schema encoding.
pub const ROS2MSG: &str = "ros2msg";
/// The ROS 2 profile's message encoding.
pub const CDR: &str = "cdr";

/// A bag channel esgm reads as a trajectory.
#[derive(Debug, Clone)]
pub struct BagChannel {
    /// Its message type.
    pub ros_type: RosType,
    /// The trajectory's declaration (primitive, of the message's esgm type).
    pub info: TrajectoryInfo,
    /// Its types.
    pub types: TypeSchema,
}

/// The trajectory a channel of `topic` holds, if it is a ROS 2 profile channel
/// (`message_encoding`, a schema named `schema_name` in `schema_encoding`) of a
/// standard type esgm maps.
pub fn bag_channel(
    topic: &str,
    message_encoding: &str,
    schema_name: &str,
    schema_encoding: &str,
) -> Option<BagChannel> {
    if message_encoding != CDR || schema_encoding != ROS2MSG {
        return None;
    }
    let ros_type = RosType::parse(schema_name).ok()?;
    let library = TypeRegistry::with_library();
    let lookup = |name: &str| library.get_entity_structure_type(name).ok().map(|t| (*t).clone());
    let types = TypeSchema::collect(lookup(ros_type.esgm_type())?, &lookup);
    let info = TrajectoryInfo::new(
        mapping::trajectory_for(topic),
        TrajectoryKind::Primitive,
        ros_type.esgm_type(),
    );
    Some(BagChannel { ros_type, info, types })
}

/// The structure a bag message of `channel` holds, logged (received) at `log_time`.
pub fn bag_structure(
    channel: &BagChannel,
    cdr: &[u8],
    log_time: Time,
) -> Result<EntityStructure, DecodeError> {
    mapping::structure_from_cdr(
        channel.ros_type,
        cdr,
        &channel.info.name,
        log_time,
        PixelBuffer::heap_image,
    )
}

/// The loss cause a message that could not be read counts under.
pub fn loss_cause(e: &DecodeError) -> &'static str {
    match e {
        DecodeError::Cdr(_) => "ros2_undecodable",
        _ => "ros2_unconvertible",
    }
}

/// Counts one loss of `cause` in `losses`.
pub fn count_loss(losses: &mut BTreeMap<String, u64>, cause: &str) {
    let n = losses.entry(cause.to_owned()).or_default();
    *n = n.saturating_add(1);
}

/// The pixels of an `esgm record --ros2` image view (a `sensor_msgs/msg/Image` in
/// CDR, rows unpadded as esgm writes them), which the lossless message leaves out.
pub fn image_pixels(cdr: &[u8]) -> Result<Vec<u8>, String> {
    let msg: esgm_ros2msg::msgs::Image =
        esgm_ros2msg::cdr::decode(cdr).map_err(|e| e.to_string())?;
    let rows = msg.step as usize * msg.height as usize;
    if msg.data.len() != rows {
        return Err(format!(
            "{} bytes of data for {} rows of {} bytes",
            msg.data.len(),
            msg.height,
            msg.step
        ));
    }
    Ok(msg.data)
}
