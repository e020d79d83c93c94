//! Message definitions as text: what `esgm ros2 msg` prints and what an MCAP schema
//! record of encoding `ros2msg` holds (the ROS 2 MCAP profile, as rosbag2 writes it):
//! the message's own definition, then each message it uses, after a line of 80 `=`
//! and `MSG: package/Type`.

use crate::generated::{PACKAGE, Schema};
use crate::mapping::RosType;

/// The standard messages esgm's messages use, with their definitions.
const STANDARD: [(&str, &str); 9] = [
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
    ),
    ("geometry_msgs/Pose2D", "float64 x\nfloat64 y\nfloat64 theta\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"),
    ("geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"),
    // Not used by a field; listed so every standard name resolves.
    ("std_msgs/Empty", ""),
];

const SEPARATOR: &str =
    "================================================================================";

/// The message types a definition's fields name (`package/Type`, without `[]`).
fn used(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(|t| t.trim_end_matches("[]").to_owned())
        .filter(|t| t.contains('/'))
        .collect()
}

/// `root`'s text followed by every message it uses, transitively: nested definitions
/// from `own` (generated ones), the rest from the standard ones.
fn with_dependencies(root: &str, own: &[(String, String)]) -> String {
    let mut out = root.to_owned();
    let mut seen: Vec<String> = Vec::new();
    let mut todo = used(root);
    while let Some(name) = todo.first().cloned() {
        todo.remove(0);
        if seen.contains(&name) {
            continue;
        }
        seen.push(name.clone());
        let text = own
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, t)| t.as_str())
            .or_else(|| STANDARD.iter().find(|(n, _)| *n == name).map(|(_, t)| *t));
        if let Some(text) = text {
            out.push_str(&format!("{SEPARATOR}\nMSG: {name}\n{text}"));
            todo.extend(used(text));
        }
    }
    out
}

/// The MCAP `ros2msg` schema of a standard message.
pub fn standard_schema(t: RosType) -> String {
    let (package, name) = t.package_and_name();
    let full = format!("{package}/{name}");
    let root = STANDARD.iter().find(|(n, _)| *n == full).map_or("", |(_, t)| t);
    with_dependencies(root, &[])
}

/// The MCAP `ros2msg` schema of a generated message.
pub fn generated_schema(schema: &Schema) -> String {
    let files = schema.msg_files();
    let own: Vec<(String, String)> =
        files.iter().map(|(n, t)| (format!("{PACKAGE}/{n}"), t.clone())).collect();
    let root = files.first().map_or("", |(_, t)| t.as_str());
    with_dependencies(root, &own)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn an_image_schema_carries_the_header_and_time_after_it() {
        let s = standard_schema(RosType::Image);
        assert!(s.starts_with("std_msgs/Header header\n"), "{s}");
        assert!(s.contains(&format!(
            "{SEPARATOR}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\n"
        )));
        assert!(s.contains("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"), "{s}");
        assert_eq!(s.matches("MSG: ").count(), 2, "{s}");
    }

    #[test]
    fn a_generated_schema_carries_its_nested_types_once() {
        let lookup = |n: &str| {
            esgm_core::TypeRegistry::with_library()
                .get_entity_structure_type(n)
                .ok()
                .map(|t| (*t).clone())
        };
        let s = generated_schema(&Schema::new("BlobSeq", lookup).unwrap());
        assert!(s.starts_with("# esgm entity structure"), "{s}");
        assert_eq!(s.matches("MSG: esgm_msgs/BlobFrame\n").count(), 1, "{s}");
        assert_eq!(s.matches("MSG: esgm_msgs/Blob\n").count(), 0, "{s}");
        assert!(
            s.contains("MSG: std_msgs/Header\n") && s.contains("MSG: builtin_interfaces/Time\n")
        );
    }
}
