//! `esgm-ros2 msg` and `esgm-ros2 pkg` as a ROS user meets them, with no running
//! system: a library type's definition, a system file's types (`--config`), one
//! definition per ROS 2 type name (a structure `Blob` and the frame `BlobFrame` that
//! `BlobSeq` nests), and an interface package that an independent parser (rosbags,
//! `tests/python/check_interfaces.py`) reads, registers and serializes.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

/// The venv with the independent implementations (`target/py-venv`).
#[path = "../../../../esgm-core/recording/tests/common/python.rs"]
mod python;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

const ESGM_ROS2: &str = env!("CARGO_BIN_EXE_esgm-ros2");

/// Runs esgm-ros2 against a domain nobody serves.
fn esgm_ros2(args: &[&str]) -> Output {
    let domain = esgm_shm::unique_domain("no-system");
    Command::new(ESGM_ROS2).arg("--domain").arg(domain).args(args).output().unwrap()
}

fn stdout(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout.clone()).unwrap()
}

/// Each `# esgm_msgs/msg/X.msg` block of `msg`'s output, by name.
fn msg_files(text: &str) -> BTreeMap<String, String> {
    let mut files = BTreeMap::new();
    let mut current: Option<(String, String)> = None;
    for line in text.lines() {
        if let Some(name) =
            line.strip_prefix("# esgm_msgs/msg/").and_then(|l| l.strip_suffix(".msg"))
        {
            files.extend(current.take());
            current = Some((name.to_owned(), String::new()));
        } else if let Some((_, body)) = current.as_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    files.extend(current);
    files
}

const SYSTEM: &str = r#"
[[type]]
name = "Track"
attributes = ["label: String", "seen: Time", "pose: PositionAltitudeRotation",
              "velocity: Vec", "outline: Pos2Seq", "scores: DoubleSeq", "tags: SymbolSeq",
              "raw: OctetSeq", "parts: EntityFrameSeq<Blob>", "best: EntityFrame<Blob>"]
"#;

#[test]
fn library_types_need_no_system_and_each_name_has_one_definition() {
    let blob = msg_files(&stdout(&esgm_ros2(&["msg", "Blob"])));
    let seq = msg_files(&stdout(&esgm_ros2(&["msg", "BlobSeq"])));
    assert_eq!(blob.keys().collect::<Vec<_>>(), ["Blob"]);
    assert_eq!(seq.keys().collect::<Vec<_>>(), ["BlobFrame", "BlobSeq"]);
    assert!(blob["Blob"].contains("std_msgs/Header header\n"), "{}", blob["Blob"]);
    assert!(seq["BlobSeq"].contains("esgm_msgs/BlobFrame[] items\n"), "{}", seq["BlobSeq"]);
    assert!(seq["BlobFrame"].contains("string name\n") && !seq["BlobFrame"].contains("Header"));

    let image = stdout(&esgm_ros2(&["msg", "Image"]));
    assert!(image.contains("standard message sensor_msgs/msg/Image"), "{image}");

    let unknown = esgm_ros2(&["msg", "Nope"]);
    assert!(!unknown.status.success());
    let e = String::from_utf8_lossy(&unknown.stderr);
    assert!(e.contains("`Nope`") && e.contains("--config"), "{e}");
}

#[test]
fn a_system_files_types_make_a_package_an_independent_parser_reads() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("system.toml");
    std::fs::write(&config, SYSTEM).unwrap();
    let config = config.to_str().unwrap();
    let track = msg_files(&stdout(&esgm_ros2(&["msg", "Track", "--config", config])));
    assert_eq!(track.keys().collect::<Vec<_>>(), ["BlobFrame", "Track"]);

    let ws = dir.path().join("src");
    let written = stdout(&esgm_ros2(&["pkg", ws.to_str().unwrap(), "--config", config]));
    assert!(written.contains("esgm_msgs"), "{written}");
    // Library types beside the file's, named.
    let more = dir.path().join("more");
    stdout(&esgm_ros2(&[
        "pkg",
        more.to_str().unwrap(),
        "Blob",
        "BlobSeq",
        "Track",
        "--config",
        config,
    ]));
    let names = |p: &Path| {
        let mut v: Vec<String> = std::fs::read_dir(p.join("esgm_msgs/msg"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&ws), ["BlobFrame.msg", "Track.msg"]);
    assert_eq!(names(&more), ["Blob.msg", "BlobFrame.msg", "BlobSeq.msg", "Track.msg"]);

    for package in [ws.join("esgm_msgs"), more.join("esgm_msgs")] {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_interfaces.py");
        let out = Command::new(python::venv_python()).arg(script).arg(&package).output().unwrap();
        assert!(
            out.status.success(),
            "rosbags refused {}:\n{}",
            package.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let checked: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let track = &checked["messages"]["esgm_msgs/msg/Track"];
        assert_eq!(track[0], "header");
        assert_eq!(track.as_array().unwrap().len(), 11, "{track}");
        assert_eq!(checked["messages"]["esgm_msgs/msg/BlobFrame"][0], "name");
    }

    // A type without a message is refused by name when asked for.
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[[type]]\nname = \"Odd\"\nattributes = [\"Speed: Double\"]\n").unwrap();
    let refused = esgm_ros2(&[
        "pkg",
        dir.path().join("x").to_str().unwrap(),
        "Odd",
        "--config",
        bad.to_str().unwrap(),
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("Speed"));
}
