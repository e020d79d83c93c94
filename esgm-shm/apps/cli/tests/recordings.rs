//! Recording a running system end to end, as a new user would: record the tutorial,
//! `esgm info` it, kill a recorder with -9 and read what it left, rerun the units
//! deterministically, replay into a fresh domain while recording that, and compare.
//! Real processes, unique domains, a watchdog on every command.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

/// The independent reader (PyPI's `mcap`), shared with the recording crate's tests.
#[path = "../../../../esgm-core/recording/tests/common/python.rs"]
mod python;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{ESGM, StopOnDrop as Down, esgm, finish};

const TUTORIAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tutorial.toml");

/// Runs `esgm args…` under a watchdog: exit code, stdout, stderr.
fn run(args: &[&str], limit: Duration) -> (Option<i32>, String, String) {
    let o = esgm(args, limit);
    (o.code, o.stdout, o.stderr)
}

fn ok(args: &[&str], limit: Duration) -> String {
    let (code, out, err) = run(args, limit);
    assert_eq!(code, Some(0), "`esgm {}` failed:\n{out}\n{err}", args.join(" "));
    out
}

fn info(path: &Path) -> serde_json::Value {
    let out = ok(&["--json", "info", path.to_str().unwrap()], Duration::from_secs(60));
    serde_json::from_str(&out).expect("info --json is JSON")
}

fn count(info: &serde_json::Value, trajectory: &str) -> u64 {
    info["trajectories"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"] == trajectory)
        .unwrap_or_else(|| panic!("no `{trajectory}` in {info:#}"))["count"]
        .as_u64()
        .unwrap()
}

#[test]
fn record_info_kill_rerun_replay_and_compare_the_tutorial() {
    let dir = tempfile::tempdir().unwrap();
    let file = |name: &str| dir.path().join(name);
    let path = |name: &str| file(name).display().to_string();
    let long = Duration::from_secs(120);

    // The tutorial, running.
    let a = esgm_shm::unique_domain("rec-a");
    ok(&["--domain", &a, "up", "--detach"], long);
    let _down_a = Down(a.clone());
    ok(&["--domain", &a, "apply", TUTORIAL], long);
    ok(&["--domain", &a, "echo", "driving_direction", "--count", "3", "--seconds", "60"], long);

    // Record it: nothing missed, everything in the file.
    let out = ok(
        &["--domain", &a, "record", "--all", "-o", &path("live.mcap"), "--duration", "4s"],
        long,
    );
    assert!(out.contains("nothing missed"), "{out}");
    let live = info(&file("live.mcap"));
    assert_eq!(live["complete"], true, "{live:#}");
    assert!(count(&live, "images") >= 8, "{live:#}");
    assert!(count(&live, "robot_state") >= 20, "{live:#}");
    assert!(count(&live, "driving_direction") >= 10, "{live:#}");
    for t in live["trajectories"].as_array().unwrap() {
        assert_eq!(t["losses"], serde_json::json!({}), "{t:#}");
    }
    // Foxglove's reader reads all of it: every message, an image, a structure.
    let foxglove = python::independent_reader(&file("live.mcap"));
    for name in ["images", "robot_state", "blobs", "current_blob", "driving_direction"] {
        assert_eq!(
            foxglove["messages_per_topic"][name].as_u64(),
            Some(count(&live, name)),
            "{name}: {foxglove:#}"
        );
        assert_eq!(
            foxglove["messages_per_topic"][format!("esgm/{name}")].as_u64(),
            Some(count(&live, name))
        );
    }
    assert_eq!(foxglove["first_image"]["width"], 640, "{foxglove:#}");
    assert_eq!(foxglove["first_image"]["encoding"], "rgb8", "{foxglove:#}");
    assert!(foxglove["first_json"]["robot_state"]["x"].is_number(), "{foxglove:#}");

    // A recorder killed with -9 loses at most its flush interval.
    let mut killed = Command::new(ESGM)
        .args(["--domain", &a, "record", "--all", "-o", &path("killed.mcap"), "--flush", "500ms"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until it has flushed a few seconds' worth, then kill it mid-stream.
    let deadline = Instant::now() + long;
    let flushed = loop {
        assert!(Instant::now() < deadline, "the recorder flushed nothing within {long:?}");
        std::thread::sleep(Duration::from_millis(500));
        if file("killed.mcap").exists() {
            let (code, out, _) = run(&["--json", "info", &path("killed.mcap")], long);
            if code == Some(0) {
                let partial: serde_json::Value = serde_json::from_str(&out).unwrap();
                if partial["trajectories"].as_array().is_some_and(|t| t.len() == 5)
                    && count(&partial, "images") >= 6
                {
                    break count(&partial, "robot_state");
                }
            }
        }
    };
    std::thread::sleep(Duration::from_secs(1));
    let killed_at =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos()
            as i64;
    killed.kill().unwrap(); // SIGKILL
    killed.wait().unwrap();
    let cut = info(&file("killed.mcap"));
    assert_eq!(cut["complete"], false, "{cut:#}");
    assert!(cut["damage"]["reason"].as_str().unwrap().contains("summary"), "{cut:#}");
    assert!(count(&cut, "robot_state") >= flushed, "what was flushed stays readable: {cut:#}");
    // At most the flush interval (500 ms) is lost, plus a robot period and the
    // scheduling slack of a loaded 2-core machine.
    let last = cut["end_valid_time"].as_i64().unwrap();
    assert!(
        killed_at - last < 2_000_000_000,
        "{} ms lost: {cut:#}",
        (killed_at - last) / 1_000_000
    );

    // The units rerun on the recorded inputs, deterministically.
    for out in ["rerun1.mcap", "rerun2.mcap"] {
        ok(
            &[
                "replay",
                &path("live.mcap"),
                "--in-process",
                "--config",
                TUTORIAL,
                "--record",
                &path(out),
            ],
            long,
        );
    }
    let (one, two) =
        (std::fs::read(file("rerun1.mcap")).unwrap(), std::fs::read(file("rerun2.mcap")).unwrap());
    assert!(one == two, "two reruns of one recording wrote different files");
    let rerun = info(&file("rerun1.mcap"));
    python::independent_reader(&file("rerun1.mcap"));
    assert_eq!(
        count(&rerun, "blobs"),
        count(&live, "images"),
        "one BlobSeq per recorded image: {rerun:#}"
    );
    // The single-input stages computed again equal what the live system computed
    // (over the valid times both cover; create times are when each ran).
    let (code, out, err) = run(
        &[
            "compare",
            &path("live.mcap"),
            &path("rerun1.mcap"),
            "--only",
            "blobs",
            "current_blob",
            "--ignore-create-time",
            "--overlap",
        ],
        long,
    );
    assert_eq!(code, Some(0), "the rerun's blobs differ from the live ones:\n{out}\n{err}");
    // Every trajectory: where a live structure differs from the rerun's, its lineage
    // says why, and never a recorded input (both ran on the same ones): the live
    // multi-input unit paired other structures than the rerun, or computed otherwise.
    let (_, out, err) = run(
        &[
            "--json",
            "compare",
            &path("live.mcap"),
            &path("rerun1.mcap"),
            "--ignore-create-time",
            "--overlap",
        ],
        long,
    );
    let report: serde_json::Value =
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
    for t in report["trajectories"].as_array().unwrap() {
        let Some(first) = t.get("first_difference").filter(|f| !f.is_null()) else { continue };
        let origins = first["origins"].as_array().unwrap_or_else(|| panic!("no origins: {t:#}"));
        assert!(!origins.is_empty(), "{t:#}");
        for o in origins {
            assert_ne!(o["origin"], "source", "the same inputs cannot differ: {t:#}");
        }
    }

    // Replay into a fresh domain while recording it there; the two recordings match.
    let b = esgm_shm::unique_domain("rec-b");
    ok(&["--domain", &b, "up", "--detach"], long);
    let _down_b = Down(b.clone());
    let recorder = Command::new(ESGM)
        .args([
            "--domain",
            &b,
            "record",
            "robot_state",
            "images",
            "--wait",
            "--flush",
            "200ms",
            "-o",
            &path("replayed.mcap"),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let replay = ok(
        &[
            "--domain",
            &b,
            "replay",
            &path("live.mcap"),
            "--keep-times",
            // Real time: the recorder (`--wait`) subscribes once `images` exists, and a
            // late joiner gets the last 16 images of its history; at 4x a loaded CI
            // machine once let the replay run two images past that before it joined.
            "--rate",
            "1",
            "--only",
            "robot_state",
            "images",
        ],
        long,
    );
    assert!(replay.contains("created `images`"), "{replay}");
    // Interrupted once its flushed file holds every replayed structure, not after a
    // guess at how long that takes.
    let wanted = [("images", count(&live, "images")), ("robot_state", count(&live, "robot_state"))];
    let deadline = Instant::now() + long;
    loop {
        let (code, out, err) = run(&["--json", "info", &path("replayed.mcap")], long);
        let counts: Vec<(&str, u64)> = match (code, serde_json::from_str::<serde_json::Value>(&out))
        {
            (Some(0), Ok(partial)) => wanted
                .iter()
                .map(|(name, _)| {
                    let found = partial["trajectories"].as_array().and_then(|all| {
                        all.iter().find(|t| t["name"] == *name).and_then(|t| t["count"].as_u64())
                    });
                    (*name, found.unwrap_or(0))
                })
                .collect(),
            _ => Vec::new(),
        };
        if counts == wanted {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the recorder did not record the replay within {long:?}: {counts:?} of {wanted:?}\n{err}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let stop = Command::new("kill").args(["-INT", &recorder.id().to_string()]).status().unwrap();
    assert!(stop.success());
    let recorded = finish(recorder, long, "record");
    let said = &recorded.stdout;
    assert_eq!(recorded.code, Some(0), "{said}\n{}", recorded.stderr);
    assert!(said.contains("nothing missed"), "{said}");
    let (code, out, err) = run(
        &["compare", &path("live.mcap"), &path("replayed.mcap"), "--only", "robot_state", "images"],
        long,
    );
    assert_eq!(code, Some(0), "the replayed recording differs:\n{out}\n{err}");
    let replayed = info(&file("replayed.mcap"));
    python::independent_reader(&file("replayed.mcap"));
    assert_eq!(count(&replayed, "images"), count(&live, "images"));
    assert_eq!(count(&replayed, "robot_state"), count(&live, "robot_state"));

    // A damaged file is named with its position.
    let mut bytes = std::fs::read(file("live.mcap")).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(file("half.mcap"), bytes).unwrap();
    let half = info(&file("half.mcap"));
    assert!(half["damage"]["position"].as_u64().unwrap() > 0, "{half:#}");
    let (code, _, err) = run(&["info", "/nonexistent/recording.mcap"], long);
    assert_eq!(code, Some(1));
    assert!(err.contains("/nonexistent/recording.mcap"), "{err}");
}

/// `esgm record --ros2` writes a rosbag2 directory that ROS 2's own libraries read as
/// theirs (rosbags' rosbag2 reader and deserializer, the ROS 2 MCAP decoder with no
/// topic filtered out), with only ROS 2 channels; `--lossless` keeps esgm's recording
/// beside it, which `esgm info` prefers; without it, `esgm info` reads the bag itself.
#[test]
fn a_ros2_recording_is_a_rosbag2_directory_ros2_libraries_read() {
    let dir = tempfile::tempdir().unwrap();
    let long = Duration::from_secs(120);
    let d = esgm_shm::unique_domain("rec-bag");
    ok(&["--domain", &d, "up", "--detach"], long);
    let _down = Down(d.clone());
    ok(&["--domain", &d, "apply", TUTORIAL], long);
    ok(&["--domain", &d, "echo", "driving_direction", "--count", "3", "--seconds", "60"], long);

    let bag = dir.path().join("run");
    let bag_s = bag.to_str().unwrap();
    let out = ok(
        &[
            "--domain",
            &d,
            "record",
            "--all",
            "--ros2",
            "--lossless",
            "-o",
            bag_s,
            "--duration",
            "3s",
        ],
        long,
    );
    assert!(out.contains("nothing missed"), "{out}");
    assert!(bag.join("metadata.yaml").is_file() && bag.join("run_0.mcap").is_file());
    assert!(bag.join("lossless/run.mcap").is_file());

    let checked = Command::new(python::venv_python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_bag.py"))
        .arg(&bag)
        .output()
        .unwrap();
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    let c: serde_json::Value = serde_json::from_slice(&checked.stdout).unwrap();
    let topics = c["topics"].as_object().unwrap();
    let types: Vec<(&str, &str)> =
        topics.iter().map(|(t, v)| (t.as_str(), v["type"].as_str().unwrap())).collect();
    assert_eq!(
        types,
        [
            ("/blobs", "esgm_msgs/msg/BlobSeq"),
            ("/current_blob", "esgm_msgs/msg/Blob"),
            ("/driving_direction", "geometry_msgs/msg/Vector3"),
            ("/images", "sensor_msgs/msg/Image"),
            ("/robot_state", "geometry_msgs/msg/Pose2D"),
        ]
    );
    let total: u64 = topics.values().map(|v| v["count"].as_u64().unwrap()).sum();
    assert_eq!(c["message_count"], total, "metadata.yaml counts every message");
    for (topic, v) in topics {
        assert_eq!(c["decoded"][topic], v["count"], "{topic}: every message deserializes");
    }
    assert_eq!(c["mcap_ros2"], total, "the ROS 2 MCAP decoder reads every channel");
    assert!(c["decoded"]["/images"].as_u64().unwrap() >= 6, "{c}");
    let image = &c["first"]["/images"];
    assert_eq!((image["width"].as_u64(), image["encoding"].as_str()), (Some(640), Some("rgb8")));
    assert!(c["first"]["/blobs"]["items_len"].as_u64().is_some(), "{c}");

    // esgm's readers take the directory: its lossless recording, every trajectory.
    let lossless = info(&bag);
    assert_eq!(lossless["complete"], true, "{lossless:#}");
    assert!(count(&lossless, "blobs") >= 6, "{lossless:#}");
    // Without --lossless, the bag alone: its standard messages read as trajectories,
    // the generated ones named as other topics.
    let plain = dir.path().join("plain");
    ok(
        &[
            "--domain",
            &d,
            "record",
            "--all",
            "--ros2",
            "-o",
            plain.to_str().unwrap(),
            "--duration",
            "2s",
        ],
        long,
    );
    assert!(!plain.join("lossless").exists());
    let bag_only = info(&plain);
    assert!(count(&bag_only, "images") >= 4, "{bag_only:#}");
    assert!(count(&bag_only, "robot_state") >= 10, "{bag_only:#}");
    let foreign = bag_only["foreign_topics"].as_array().unwrap();
    assert!(foreign.iter().any(|t| t == "/blobs"), "{bag_only:#}");

    // A bag is a new directory: one that holds something is refused, naming why.
    let (code, _, err) =
        run(&["--domain", &d, "record", "--all", "--ros2", "-o", bag_s, "--duration", "1s"], long);
    assert_eq!(code, Some(1));
    assert!(err.contains("not empty"), "{err}");
}

/// The other way: a bag that rosbags (an independent ROS 2 library) writes, as a
/// robot's `ros2 bag record -s mcap` would, is a recording to esgm: `info` reads the
/// directory, `load` makes its standard topics queryable trajectories (named as
/// `esgm ros2 --import` names them), and a topic esgm does not map is named, not read.
#[test]
fn a_bag_rosbags_writes_loads_into_esgm() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("robot_bag");
    let written = Command::new(python::venv_python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/write_bag.py"))
        .arg(&bag)
        .arg("10")
        .output()
        .unwrap();
    assert!(written.status.success(), "{}", String::from_utf8_lossy(&written.stderr));
    assert!(bag.join("metadata.yaml").is_file());

    let read = info(&bag);
    assert_eq!(count(&read, "camera_image_raw"), 10, "{read:#}");
    assert_eq!(count(&read, "odom_pose"), 10, "{read:#}");
    assert_eq!(read["foreign_topics"], serde_json::json!(["/chatter"]), "{read:#}");

    let long = Duration::from_secs(120);
    let d = esgm_shm::unique_domain("rec-rosbags");
    ok(&["--domain", &d, "up", "--detach"], long);
    let _down = Down(d.clone());
    ok(&["--domain", &d, "load", bag.to_str().unwrap()], long);
    let pose = ok(&["--domain", &d, "--json", "latest", "odom_pose"], long);
    let pose: serde_json::Value = serde_json::from_str(pose.trim()).unwrap();
    assert_eq!(pose["valid_time"], 1_700_000_000_900_000_000_i64, "{pose}");
    assert_eq!(pose["attributes"]["x"], 9.0, "{pose}");
    let image = ok(&["--domain", &d, "--json", "latest", "camera_image_raw"], long);
    assert!(image.contains("\"width\":4") && image.contains("\"height\":2"), "{image}");
}
