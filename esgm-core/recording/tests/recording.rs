//! Recordings written and read back: exact structures and times, every compression,
//! damaged files, foreign files, and a live recorder with violations.

#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)] // a failure is a failed test

use std::path::Path;

#[path = "common/fixtures.rs"]
mod fixtures;
use fixtures::{info, robot, schema_of};
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectoryKind;
use esgm_core::library::{Image, RobotState};
use esgm_core::{
    Entity, EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, InProcessEsgm,
    OrderConstraint, TrajectorySpec, codec,
};
use esgm_recording::{Compression, ReadError, RecordOptions, Recorder, Recording, RecordingWriter};

/// Writes `n` robot states and `n` images; returns what was written, in order.
fn write(path: &Path, options: RecordOptions, n: i64) -> Vec<(String, EntityStructure, i64, i64)> {
    let mut w = RecordingWriter::create(path, options).expect("create");
    let r = w
        .add_trajectory(
            info("robot_state", TrajectoryKind::Primitive, "RobotState"),
            schema_of::<RobotState>(),
        )
        .expect("add");
    let c = w
        .add_trajectory(info("images", TrajectoryKind::Sampled, "Image"), schema_of::<Image>())
        .expect("add");
    let mut written = Vec::new();
    for i in 0..n {
        let (rs, im) = (robot(i), fixtures::image(i, 8, 4));
        w.write(r, &rs, 5_000 + i, 6_000 + i).expect("write");
        w.write(c, &im, 7_000 + i, 8_000 + i).expect("write");
        written.push(("robot_state".to_owned(), rs, 5_000 + i, 6_000 + i));
        written.push(("images".to_owned(), im, 7_000 + i, 8_000 + i));
    }
    w.finish().expect("finish");
    written
}

fn read_all(rec: &Recording) -> Vec<(String, EntityStructure, i64, i64)> {
    rec.samples()
        .expect("samples")
        .map(|s| {
            let s = s.expect("sample");
            (
                rec.trajectories[s.trajectory].info.name.clone(),
                s.structure,
                s.header.add_time,
                s.header.recorded_time,
            )
        })
        .collect()
}

#[test]
fn structures_and_times_read_back_bit_identical_with_every_compression() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("run.mcap");
        let written = write(&path, RecordOptions::default().compression(compression), 20);
        let rec = Recording::open(&path).expect("open");
        assert!(rec.complete, "{compression:?}: a finished file is complete");
        assert_eq!(rec.damage, None);
        let read = read_all(&rec);
        assert_eq!(read.len(), written.len(), "{compression:?}");
        for (a, b) in read.iter().zip(&written) {
            assert_eq!(a.0, b.0);
            assert_eq!(a.1, b.1, "{compression:?}: the structure reads back equal");
            assert_eq!(
                codec::encode(&a.1).expect("encode").as_slice(),
                codec::encode(&b.1).expect("encode").as_slice(),
                "{compression:?}: and its archive is byte for byte the same"
            );
            assert_eq!((a.2, a.3), (b.2, b.3), "add and recorded times kept");
        }
        let robot = rec.trajectory("robot_state").expect("recorded");
        assert_eq!(robot.count, 20);
        assert_eq!(robot.info.kind, TrajectoryKind::Primitive);
        assert_eq!(
            robot.types.root,
            RobotState::entity_structure_type(),
            "the type is in the file"
        );
        assert_eq!(robot.valid_range, Some((1_000, 1_000 + 19 * 100)));
        assert_eq!(rec.trajectory("images").expect("recorded").info.kind, TrajectoryKind::Sampled);
        let info = rec.info();
        assert_eq!(info.structures, 40);
        assert_eq!(info.start_valid_time, Some(1_000));
        assert!(info.trajectories.iter().all(|t| t.losses.is_empty()));
    }
}

#[test]
fn images_are_stored_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let big = |i: i64| {
        let pixels = vec![(i % 251) as u8; 64 * 64 * 3];
        Image { width: 64, height: 64, format: Image::FORMAT_RGB8, image_data: pixels.into() }
            .to_structure("camera", i, i)
    };
    let path = dir.path().join("images.mcap");
    let mut w =
        RecordingWriter::create(&path, RecordOptions::default().compression(Compression::None))
            .expect("create");
    let c = w
        .add_trajectory(info("images", TrajectoryKind::Sampled, "Image"), schema_of::<Image>())
        .expect("add");
    for i in 0..10 {
        w.write(c, &big(i), i, i).expect("write");
    }
    let summary = w.finish().expect("finish");
    let pixels = 10 * 64 * 64 * 3;
    let file = std::fs::metadata(&path).expect("file").len();
    assert!(file < pixels + pixels / 10, "{file} bytes for {pixels} bytes of pixels: stored once");
    assert!(
        summary.lossless_bytes["images"] < 10 * 1024,
        "the lossless channel leaves the pixels to the view"
    );
    let rec = Recording::open(&path).expect("open");
    let read = read_all(&rec);
    for (i, s) in read.iter().enumerate() {
        assert_eq!(s.1, big(i as i64));
    }
}

#[test]
fn a_cut_off_file_reads_up_to_its_last_complete_chunk() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    // Small chunks: many of them.
    let written = write(&path, RecordOptions::default().chunk_size(2048), 200);
    let bytes = std::fs::read(&path).expect("read");
    for cut in [bytes.len() / 3, bytes.len() / 2] {
        let cut_path = dir.path().join(format!("cut{cut}.mcap"));
        std::fs::write(&cut_path, &bytes[..cut]).expect("write");
        let rec = Recording::open(&cut_path).expect("a cut file still opens");
        assert!(!rec.complete);
        let damage = rec.damage.clone().expect("the cut is reported");
        assert!(damage.position <= cut as u64, "{damage:?}");
        assert!(
            damage.reason.contains("truncated") || damage.reason.contains("ends"),
            "{damage:?}"
        );
        let read = read_all(&rec);
        assert!(!read.is_empty(), "chunks before the cut are readable");
        assert!(read.len() < written.len());
        for (a, b) in read.iter().zip(&written) {
            assert_eq!(a.1, b.1, "what is recovered is exact");
        }
        assert_eq!(rec.info().structures as usize, read.len());
    }
    // A file that ends at a chunk boundary without its summary (a killed recorder).
    let boundary = dir.path().join("killed.mcap");
    let mut w = RecordingWriter::create(&boundary, RecordOptions::default()).expect("create");
    let r = w
        .add_trajectory(
            info("robot_state", TrajectoryKind::Primitive, "RobotState"),
            schema_of::<RobotState>(),
        )
        .expect("add");
    for i in 0..5 {
        w.write(r, &robot(i), i, i).expect("write");
    }
    w.flush().expect("flush");
    let flushed = std::fs::read(&boundary).expect("read");
    drop(w);
    std::fs::write(&boundary, &flushed).expect("write");
    let rec = Recording::open(&boundary).expect("opens");
    assert_eq!(
        rec.trajectory("robot_state").expect("declared").count,
        5,
        "everything flushed reads"
    );
    assert!(rec.damage.expect("incomplete").reason.contains("summary"));
}

#[test]
fn a_corrupt_chunk_is_named_and_what_precedes_it_reads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let written =
        write(&path, RecordOptions::default().chunk_size(2048).compression(Compression::None), 200);
    let mut bytes = std::fs::read(&path).expect("read");
    // The middle chunk, damaged near its end (in its records).
    let chunks = top_level(&bytes).into_iter().filter(|(op, _, _)| *op == 0x06).collect::<Vec<_>>();
    assert!(chunks.len() > 4, "{} chunks", chunks.len());
    let (_, start, len) = chunks[chunks.len() / 2];
    let middle = start + 9 + len - 100;
    bytes[middle] ^= 0xFF;
    bytes[middle + 1] ^= 0xFF;
    let bad = dir.path().join("bad.mcap");
    std::fs::write(&bad, &bytes).expect("write");
    let rec = Recording::open(&bad).expect("opens");
    let damage = rec.damage.clone().expect("damage found");
    assert_eq!(damage.position as usize, start, "the damaged chunk's position: {damage:?}");
    assert!(damage.reason.contains("corrupt chunk"), "{damage:?}");
    let read = read_all(&rec);
    assert!(!read.is_empty() && read.len() < written.len(), "{} of {}", read.len(), written.len());
    for (a, b) in read.iter().zip(&written) {
        assert_eq!(a.1, b.1);
    }
    let shown = format!("{damage:?}");
    assert!(
        shown.contains("corrupt") || shown.contains("malformed") || shown.contains("truncated"),
        "{shown}"
    );
}

#[test]
fn foreign_and_unknown_files_are_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = dir.path().join("notes.mcap");
    std::fs::write(&text, b"hello, not a recording").expect("write");
    let e = Recording::open(&text).expect_err("not MCAP");
    assert!(matches!(e, ReadError::NotMcap { .. }));
    assert!(e.to_string().contains("notes.mcap"), "{e}");

    let missing = dir.path().join("missing.mcap");
    assert!(matches!(Recording::open(&missing), Err(ReadError::Io { .. })));

    // An esgm channel whose schema is not esgm's types.
    let odd = dir.path().join("odd.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&odd).expect("create"),
        ))
        .expect("writer");
        let s = w.add_schema("RobotState", "protobuf", b"").expect("schema");
        w.add_channel(
            s,
            "esgm/robot_state",
            esgm_recording::layout::ARCHIVE_ENCODING,
            &Default::default(),
        )
        .expect("channel");
        w.finish().expect("finish");
    }
    let e = Recording::open(&odd).expect_err("unknown schema");
    assert!(matches!(e, ReadError::UnknownSchema { .. }), "{e}");
    assert!(
        e.to_string().contains("esgm/robot_state") && e.to_string().contains("protobuf"),
        "{e}"
    );
}

#[test]
fn split_files_each_open_alone() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("split.mcap");
    let mut w = RecordingWriter::create(&path, RecordOptions::default().split_bytes(Some(4096)))
        .expect("create");
    let r = w
        .add_trajectory(
            info("robot_state", TrajectoryKind::Primitive, "RobotState"),
            schema_of::<RobotState>(),
        )
        .expect("add");
    for i in 0..300 {
        w.write(r, &robot(i), i, i).expect("write");
    }
    let summary = w.finish().expect("finish");
    assert!(summary.files.len() > 1, "{:?}", summary.files);
    let mut total = 0;
    let mut next = 0;
    for f in &summary.files {
        let rec = Recording::open(f).expect("each file opens alone");
        assert!(rec.complete);
        for s in read_all(&rec) {
            assert_eq!(s.1, robot(next));
            next += 1;
            total += 1;
        }
    }
    assert_eq!(total, 300);
}

#[test]
fn a_live_recorder_keeps_violations_and_counts_what_it_misses() {
    let esgm = InProcessEsgm::default();
    esgm.create_trajectory(
        TrajectorySpec::primitive("robot_state", "RobotState")
            .policy(FluentStreamPolicy::default().order(OrderConstraint::Monotone)),
    )
    .expect("create");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("live.mcap");
    let writer = RecordingWriter::create(&path, RecordOptions::default()).expect("create");
    let recorder =
        Recorder::start(&esgm, &["robot_state".to_owned()], writer, 1024).expect("start");
    let t = esgm.get_entity_trajectory_structure("robot_state").expect("get");
    for i in 0..50 {
        t.add(robot(i)).expect("add");
    }
    t.add(robot(3)).expect("an out-of-order structure is dropped, not an error");
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder.stats().recorded() < 50
        || recorder.stats().trajectories["robot_state"].violations < 1
    {
        assert!(
            Instant::now() < deadline,
            "the recorder did not see everything: {:?}",
            recorder.stats()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let (summary, stats) = recorder.stop().expect("stop");
    assert_eq!(stats.missed(), 0);
    assert_eq!(summary.structures["robot_state"], 50);
    let rec = Recording::open(&path).expect("open");
    let traj = rec.trajectory("robot_state").expect("recorded");
    assert_eq!(traj.count, 50);
    assert_eq!(traj.violations, 1, "the violation is in the file");
    assert_eq!(traj.info.policy.order, OrderConstraint::Monotone, "with the recorded policy");
    let read = read_all(&rec);
    for (i, s) in read.iter().enumerate() {
        assert_eq!(s.1, robot(i as i64));
        assert!(s.3 >= s.2, "recorded after it was added");
    }
}

#[test]
fn a_recorder_that_waited_records_what_the_trajectory_held_and_one_that_did_not_starts_now() {
    let esgm = InProcessEsgm::default();
    esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState").expect("create");
    let t = esgm.get_entity_trajectory_structure("robot_state").expect("get");
    // Written between the trajectory's creation and the recorders' subscriptions.
    for i in 0..3 {
        t.add(robot(i)).expect("add");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let names = ["robot_state".to_owned()];
    let open = |name: &str| {
        RecordingWriter::create(dir.path().join(name), RecordOptions::default()).expect("create")
    };
    let held = Recorder::start_with_held(&esgm, &names, open("held.mcap"), 1024).expect("start");
    let now = Recorder::start(&esgm, &names, open("now.mcap"), 1024).expect("start");
    for i in 3..5 {
        t.add(robot(i)).expect("add");
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while held.stats().recorded() < 5 || now.stats().recorded() < 2 {
        assert!(Instant::now() < deadline, "{:?} {:?}", held.stats(), now.stats());
        std::thread::sleep(Duration::from_millis(10));
    }
    let (held, now) = (held.stop().expect("stop").0, now.stop().expect("stop").0);
    assert_eq!(held.structures["robot_state"], 5, "what it held, then the rest, once each");
    assert_eq!(now.structures["robot_state"], 2, "from its start on");
    let read = read_all(&Recording::open(dir.path().join("held.mcap")).expect("open"));
    let read: Vec<_> = read.into_iter().map(|s| s.1).collect();
    assert_eq!(read, (0..5).map(robot).collect::<Vec<_>>(), "in order");
}

/// A recorded pipeline keeps each produced structure's lineage: read back, it names
/// the recorded input structures (X1), and a pushed one has none.
#[test]
fn lineage_is_recorded_and_read_back() {
    let esgm = InProcessEsgm::default();
    let t = esgm
        .create_primitive_entity_trajectory_structure("robot_state", "RobotState")
        .expect("create");
    let copy = |i: &[esgm_core::Sample], _: i64| Ok(i[0].structure.to_structure());
    esgm.add_comp_unit("copy", "RobotState", vec!["RobotState".into()], std::sync::Arc::new(copy))
        .expect("unit");
    esgm.create_computed_entity_trajectory_structure("copied", "copy", &["robot_state"])
        .expect("computed");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lineage.mcap");
    let writer = RecordingWriter::create(&path, RecordOptions::default()).expect("create");
    let names = ["robot_state".to_owned(), "copied".to_owned()];
    let recorder = Recorder::start(&esgm, &names, writer, 1024).expect("start");
    for i in 0..3 {
        t.add(robot(i)).expect("add");
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder.stats().recorded() < 6 {
        assert!(Instant::now() < deadline, "not recorded: {:?}", recorder.stats());
        std::thread::sleep(Duration::from_millis(10));
    }
    recorder.stop().expect("stop");
    let recording = Recording::open(&path).expect("open");
    let mut added = std::collections::HashMap::new();
    let mut lineages = Vec::new();
    for s in recording.samples().expect("samples") {
        let s = s.expect("readable");
        let name = recording.trajectories[s.trajectory].info.name.clone();
        if name == "robot_state" {
            assert!(s.lineage.is_none(), "a pushed structure has no lineage");
            added.insert(s.structure.valid_time, s.header.add_time);
        } else {
            lineages
                .push((s.structure.valid_time, s.lineage.expect("a computed structure's lineage")));
        }
    }
    assert_eq!(lineages.len(), 3);
    for (vt, lineage) in lineages {
        assert_eq!(lineage.inputs.len(), 1);
        let input = &lineage.inputs[0];
        assert_eq!((input.trajectory.as_str(), input.valid_time), ("robot_state", vt));
        assert_eq!(Some(&input.add_time), added.get(&vt), "the recorded input, by its add time");
        assert!(!lineage.complete);
    }
}

#[test]
fn a_trajectory_destroyed_while_recorded_ends_its_recording_and_keeps_what_it_held() {
    let esgm = InProcessEsgm::default();
    esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState").expect("create");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("destroyed.mcap");
    let writer = RecordingWriter::create(&path, RecordOptions::default()).expect("create");
    let recorder =
        Recorder::start(&esgm, &["robot_state".to_owned()], writer, 1024).expect("start");
    let t = esgm.get_entity_trajectory_structure("robot_state").expect("get");
    for i in 0..5 {
        t.add(robot(i)).expect("add");
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder.stats().recorded() < 5 {
        assert!(Instant::now() < deadline, "not recorded: {:?}", recorder.stats());
        std::thread::sleep(Duration::from_millis(10));
    }
    drop(t);
    esgm.destroy_entity_trajectory_structure("robot_state").expect("destroy");
    while !recorder.stats().trajectories["robot_state"].ended {
        assert!(
            Instant::now() < deadline,
            "the recording of a destroyed trajectory did not end: {:?}",
            recorder.stats()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let (summary, stats) = recorder.stop().expect("stop");
    assert_eq!(stats.missed(), 0);
    assert_eq!(summary.structures["robot_state"], 5);
    assert_eq!(
        Recording::open(&path).expect("open").trajectory("robot_state").expect("in it").count,
        5
    );
}

#[test]
fn a_recorder_that_falls_behind_counts_each_miss() {
    let esgm = InProcessEsgm::default();
    esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState").expect("create");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("slow.mcap");
    let writer = RecordingWriter::create(&path, RecordOptions::default()).expect("create");
    // A buffer of 4 against a burst of 20 000: the recorder cannot keep up.
    let recorder = Recorder::start(&esgm, &["robot_state".to_owned()], writer, 4).expect("start");
    let t = esgm.get_entity_trajectory_structure("robot_state").expect("get");
    let n = 20_000;
    for i in 0..n {
        t.add(robot(i)).expect("add never waits for the recorder");
    }
    std::thread::sleep(Duration::from_millis(400));
    let (_, stats) = recorder.stop().expect("stop");
    let c = stats.trajectories["robot_state"];
    assert_eq!(
        c.recorded + c.recorder_overflow,
        n as u64,
        "every structure recorded or counted: {c:?}"
    );
    let rec = Recording::open(&path).expect("open");
    let traj = rec.trajectory("robot_state").expect("recorded");
    assert_eq!(traj.count, c.recorded);
    assert_eq!(
        traj.losses.get("recorder_overflow").copied().unwrap_or(0),
        c.recorder_overflow,
        "{:?}",
        traj.losses
    );
}

/// The file's top-level records: (opcode, position, body length).
fn top_level(bytes: &[u8]) -> Vec<(u8, usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let op = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes")) as usize;
        out.push((op, at, len));
        at += 9 + len;
    }
    out
}

#[test]
fn a_file_damaged_after_it_was_opened_is_reported_not_taken_for_a_short_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let written = write(&path, RecordOptions::default().chunk_size(2048), 200);
    let rec = Recording::open(&path).expect("opens");
    assert!(rec.complete && rec.damage.is_none());
    // Another program cuts the file while it is replayed.
    let bytes = std::fs::read(&path).expect("read");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("cut");
    let mut read = 0;
    let mut damaged = None;
    for s in rec.samples().expect("samples") {
        match s {
            Ok(_) => read += 1,
            Err(e) => {
                damaged = Some(e);
                break;
            }
        }
    }
    assert!(read > 0 && read < written.len(), "read {read} of {}", written.len());
    match damaged {
        Some(ReadError::Damaged { position, reason, .. }) => {
            assert!(position > 0 && position < bytes.len() as u64, "at {position}: {reason}");
        }
        other => panic!("the damage was not reported: {other:?}"),
    }
}
