//! Every file the writer makes, read by an independent reader: the `mcap` package from
//! PyPI (with `mcap-protobuf-support` decoding RawImage from the file's own schema),
//! as Foxglove would read it.

#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // a failure is a failed test

#[path = "common/fixtures.rs"]
mod fixtures;
#[path = "common/python.rs"]
mod python;

use fixtures::info;

use esgm_core::Entity;
use esgm_core::esgm::TrajectoryKind;
use esgm_core::library::{Image, RobotState};
use esgm_recording::{
    Compression, EventKind, RecordOptions, RecordedEvent, RecordingWriter, TypeSchema,
};

#[test]
fn foxglove_reads_images_structures_schemas_and_summary() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("demo.mcap");
        let mut w =
            RecordingWriter::create(&path, RecordOptions::default().compression(compression))
                .expect("create");
        let robot = w
            .add_trajectory(
                info("robot_state", TrajectoryKind::Primitive, "RobotState"),
                TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
            )
            .expect("add");
        let images = w
            .add_trajectory(
                info("images", TrajectoryKind::Sampled, "Image"),
                TypeSchema::collect(Image::entity_structure_type(), &|_| None),
            )
            .expect("add");
        let (width, height) = (32_i64, 24_i64);
        for i in 0..10_i64 {
            let t = 1_700_000_000_000_000_000 + i * 100_000_000;
            let state = RobotState { x: i as f64, y: 2.0 * i as f64, dir: 45.0 };
            w.write(robot, &state.to_structure("robot", t, t), t + 1_000, t + 2_000)
                .expect("write");
            let mut pixels = vec![0_u8; (width * height * 3) as usize];
            pixels[..3].copy_from_slice(&[10 + i as u8, 20, 30]);
            let n = pixels.len();
            pixels[n - 3..].copy_from_slice(&[7, 8, 9]);
            let image =
                Image { width, height, format: Image::FORMAT_RGB8, image_data: pixels.into() };
            w.write(images, &image.to_structure("camera", t, t), t + 3_000, t + 4_000)
                .expect("write");
        }
        w.write_event(&RecordedEvent {
            trajectory: "robot_state".into(),
            kind: EventKind::Violation,
            cause: "order".into(),
            count: 1,
            valid_time: Some(5),
            time: 6,
            detail: "valid time 5 is before 7".into(),
        })
        .expect("event");
        w.finish().expect("finish");

        let read = python::independent_reader(&path);
        let per_topic = &read["messages_per_topic"];
        assert_eq!(per_topic["images"], 10, "{read:#}");
        assert_eq!(per_topic["robot_state"], 10, "{read:#}");
        assert_eq!(per_topic["esgm/images"], 10, "{read:#}");
        assert_eq!(per_topic["esgm/robot_state"], 10, "{read:#}");
        assert_eq!(per_topic["esgm-events"], 1, "{read:#}");
        assert_eq!(read["summary"]["message_count"], 41, "{read:#}");
        let schemas: Vec<&str> = read["schemas"]
            .as_array()
            .expect("schemas")
            .iter()
            .filter_map(|s| s["name"].as_str())
            .collect();
        assert!(schemas.contains(&"foxglove.RawImage"), "{schemas:?}");
        assert!(schemas.contains(&"RobotState"), "{schemas:?}");
        let image = &read["first_image"];
        assert_eq!(image["topic"], "images");
        assert_eq!(image["width"], 32);
        assert_eq!(image["height"], 24);
        assert_eq!(image["encoding"], "rgb8");
        assert_eq!(image["first_pixel"], serde_json::json!([10, 20, 30]));
        assert_eq!(image["last_pixel"], serde_json::json!([7, 8, 9]));
        assert_eq!(image["timestamp_ns"], 1_700_000_000_000_000_000_i64);
        let state = &read["first_json"]["robot_state"];
        assert_eq!(state["x"], 0.0, "{state:#}");
        assert_eq!(state["dir"], 45.0, "{state:#}");
        assert_eq!(state["valid_time"]["sec"], 1_700_000_000_i64, "{state:#}");
    }
}
