//! Recordings in the ROS 2 MCAP profile (`esgm record --ros2`), read by the ROS 2 MCAP
//! decoder from PyPI (`mcap-ros2-support`, as rosbag2's readers decode), which knows
//! nothing of esgm: images as `sensor_msgs/msg/Image`, robot states as
//! `geometry_msgs/msg/Pose2D`, a type without a standard message as its generated
//! `esgm_msgs/msg/BlobSeq`. The recording still reads back whole through esgm.

#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // a failure is a failed test

#[path = "common/fixtures.rs"]
mod fixtures;
#[path = "common/python.rs"]
mod python;

use fixtures::info;

use esgm_core::Entity;
use esgm_core::esgm::TrajectoryKind;
use esgm_core::library::{Blob, BlobSeq, Image, RobotState};
use esgm_core::{EntityStructureType, TypeRegistry};
use esgm_recording::{RecordOptions, Recording, RecordingWriter, TypeSchema};

fn library(name: &str) -> Option<EntityStructureType> {
    TypeRegistry::with_library().get_entity_structure_type(name).ok().map(|t| (*t).clone())
}

#[test]
fn ros2_tools_decode_images_poses_and_generated_messages() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ros2.mcap");
    let mut w = RecordingWriter::create(&path, RecordOptions::default().ros2(true)).unwrap();
    let robot = w
        .add_trajectory(
            info("robot_state", TrajectoryKind::Primitive, "RobotState"),
            TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
        )
        .unwrap();
    let images = w
        .add_trajectory(
            info("images", TrajectoryKind::Sampled, "Image"),
            TypeSchema::collect(Image::entity_structure_type(), &|_| None),
        )
        .unwrap();
    let blobs = w
        .add_trajectory(
            info("blobs", TrajectoryKind::Computed, "BlobSeq"),
            TypeSchema::collect(BlobSeq::entity_structure_type(), &library),
        )
        .unwrap();
    let base = 1_700_000_000_000_000_000;
    for i in 0..5_i64 {
        let t = base + i * 100_000_000;
        let state = RobotState { x: i as f64, y: -1.5, dir: 90.0 };
        w.write(robot, &state.to_structure("robot", t, t), t, t).unwrap();
        let mut pixels = vec![0_u8; 4 * 3 * 3];
        pixels[0] = 10 + i as u8;
        pixels[35] = 99;
        let image =
            Image { width: 4, height: 3, format: Image::FORMAT_RGB8, image_data: pixels.into() };
        w.write(images, &image.to_structure("camera", t, t), t, t).unwrap();
        let seq = BlobSeq { items: vec![Blob { x: 1, y: 2, size: 3 + i }] };
        w.write(blobs, &seq.to_structure("camera", t, t), t, t).unwrap();
    }
    w.finish().unwrap();

    let v = python::ros2_reader(&path);
    let image = &v["images"];
    assert_eq!(image["schema"], "sensor_msgs/msg/Image", "{v}");
    assert_eq!(image["count"], 5, "{v}");
    let first = &image["first"];
    assert_eq!((first["width"].as_u64(), first["height"].as_u64()), (Some(4), Some(3)), "{v}");
    assert_eq!((first["encoding"].as_str(), first["step"].as_u64()), (Some("rgb8"), Some(12)));
    assert_eq!(first["header"]["frame_id"], "camera");
    assert_eq!(first["header"]["stamp"]["sec"].as_i64(), Some(base / 1_000_000_000));
    assert_eq!(first["data"]["length"], 36);
    assert_eq!(
        (first["data"]["first"].as_u64(), first["data"]["last"].as_u64()),
        (Some(10), Some(99))
    );
    let pose = &v["robot_state"];
    assert_eq!(pose["schema"], "geometry_msgs/msg/Pose2D", "{v}");
    assert_eq!(pose["first"]["y"], -1.5);
    assert!((pose["first"]["theta"].as_f64().unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    let seq = &v["blobs"];
    assert_eq!(seq["schema"], "esgm_msgs/msg/BlobSeq", "{v}");
    assert_eq!(seq["count"], 5);
    assert_eq!(seq["first"]["items"][0]["x"], 1, "{v}");
    assert_eq!(seq["first"]["items"][0]["size"], 3, "{v}");

    // esgm reads its lossless channels back whole, pixels included.
    let rec = Recording::open(&path).unwrap();
    let samples: Vec<_> = rec.samples().unwrap().collect::<Result<_, _>>().unwrap();
    assert_eq!(samples.len(), 15);
    let first_image = samples
        .iter()
        .find(|s| s.structure.name == "camera" && s.structure.get("width").is_some())
        .unwrap();
    let image = Image::from_structure(&first_image.structure).unwrap();
    let pixels: &[u8] = image.image_data.as_ref();
    assert_eq!((pixels[0], pixels[35]), (10, 99));
    // The pixels are stored once: in the ROS 2 message, which the lossless one points to.
    let images: Vec<_> = samples.iter().filter(|s| s.structure.get("width").is_some()).collect();
    assert_eq!(images.len(), 5);
    for (i, s) in images.iter().enumerate() {
        assert!(s.header.pixels_in_view, "image {i} holds its pixels twice");
        let image = Image::from_structure(&s.structure).unwrap();
        assert_eq!(image.image_data.as_ref()[0], 10 + i as u8);
    }
}

/// A bag written by another tool in the ROS 2 MCAP profile (mcap-ros2-support's
/// writer, as rosbag2 writes them) reads as a recording: each standard message's topic
/// is a primitive trajectory named as `esgm ros2 --import` names it, images keep their
/// stamps and pixels, poses their log times; what does not map is a counted loss, and a
/// topic of another type stays foreign.
#[test]
fn a_ros2_bag_from_another_tool_reads_as_trajectories() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rosbag.mcap");
    python::ros2_bag_writer(&path);
    let rec = Recording::open(&path).unwrap();
    assert!(rec.complete && rec.damage.is_none(), "{:?}", rec.damage);
    let images = rec.trajectory("camera_image_raw").expect("the image topic's trajectory");
    assert_eq!(
        (images.info.type_name.as_str(), images.info.kind),
        ("Image", TrajectoryKind::Primitive)
    );
    assert_eq!(images.count, 3);
    assert_eq!(images.losses.get("ros2_unconvertible"), Some(&1), "{:?}", images.losses);
    let poses = rec.trajectory("odom2d").expect("the pose topic's trajectory");
    assert_eq!((poses.info.type_name.as_str(), poses.count), ("RobotState", 2));
    assert_eq!(rec.foreign_topics, vec!["/chatter".to_owned()]);

    let samples: Vec<_> = rec.samples().unwrap().map(Result::unwrap).collect();
    let of = |name: &str| {
        let index = rec.trajectories.iter().position(|t| t.info.name == name).unwrap();
        samples.iter().filter(move |s| s.trajectory == index)
    };
    for (i, s) in of("camera_image_raw").enumerate() {
        let image = Image::from_structure(&s.structure).unwrap();
        assert_eq!(s.structure.valid_time, 1_000_000_000_000 + i as i64 * 1_000_000);
        assert_eq!((image.width, image.height, image.format), (4, 3, Image::FORMAT_RGB8));
        let expected: Vec<u8> = (0..36).map(|k| ((k + 7 * i) % 251) as u8).collect();
        assert_eq!(image.image_data.as_ref(), expected.as_slice(), "image {i}");
        assert_eq!(s.header.add_time, 1_500_000_000_000 + i as i64);
    }
    for (i, s) in of("odom2d").enumerate() {
        let pose = RobotState::from_structure(&s.structure).unwrap();
        assert_eq!(s.structure.valid_time, 2_000_000_000_000 + i as i64 * 1_000_000);
        assert_eq!((pose.x, pose.y), (i as f64, -(i as f64)));
        assert!((pose.dir - 90.0).abs() < 1e-9, "{}", pose.dir);
    }
}
