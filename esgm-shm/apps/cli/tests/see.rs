//! Seeing a running system: `esgm top --once` and `esgm plot`, end to end with the real
//! binary. Unique domains, a watchdog on every command (one that overstays is killed
//! and fails the test).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::time::Duration;

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Esgm};

mod common;

use common::{StopOnDrop as Down, esgm};

fn ok(args: &[&str]) -> String {
    common::ok_within(args, Duration::from_secs(60))
}

#[test]
fn top_once_prints_every_trajectory_and_the_coordinator() {
    let d = esgm_shm::unique_domain("cli-top");
    ok(&["--domain", &d, "up", "--detach"]);
    let _down = Down(d.clone());

    let system = esgm_shm::ShmEsgm::builder().domain(&d).connect().unwrap();
    let robot = system.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    let t0 = 1_700_000_000_000_000_000_i64;
    for i in 0..20 {
        let t = t0 + i * 50_000_000;
        let es =
            EntityStructure::new("r1", t, t).with("x", i as f64).with("y", 0.0).with("dir", 0.0);
        robot.add(es).unwrap();
    }

    let out = ok(&["--domain", &d, "top", "--once"]);
    let mut lines = out.lines();
    let header = lines.next().unwrap_or_default();
    for column in ["trajectory", "kind", "type", "rate Hz", "p99 ms", "violations", "bytes"] {
        assert!(header.contains(column), "no `{column}` column:\n{out}");
    }
    let row = out.lines().find(|l| l.starts_with("robot ")).unwrap_or_else(|| panic!("{out}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(&cells[..3], ["robot", "primitive", "RobotState"], "{row}");
    // The replica this command opened received the 20 adds, 50 ms of valid time apart.
    assert_eq!(cells[4], "20", "added: {row}");
    assert!(cells[3].parse::<f64>().is_ok(), "rate: {row}");
    let coordinator =
        out.lines().find(|l| l.starts_with("coordinator")).unwrap_or_else(|| panic!("{out}"));
    let pid: u32 = coordinator.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(pid > 0, "{coordinator}");
    assert!(coordinator.contains("MiB") || coordinator.contains("KiB"), "rss: {coordinator}");
    // The statistics are the writer's (this test process), across processes.
    assert!(out.contains("memory: "), "the system's memory: {out}");
    assert!(!out.contains("unavailable"), "{out}");

    // The filter and JSON.
    let filtered = ok(&["--domain", &d, "top", "--once", "--filter", "nothing-like-it"]);
    assert!(!filtered.contains("robot"), "{filtered}");
    let json = ok(&["--domain", &d, "--json", "top", "--once"]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["trajectories"][0]["name"], "robot");
    assert_eq!(v["trajectories"][0]["added"], 20);
    drop(robot);
    drop(system);
}

/// A recording of robot states (x = i / 2, y = -i, 100 ms apart) and a few images.
fn recording(path: &std::path::Path) {
    use esgm_core::Entity;
    use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
    use esgm_core::library::{Image, RobotState};
    use esgm_recording::{RecordOptions, RecordingWriter, TypeSchema};

    let info = |name: &str, type_name: &str| {
        TrajectoryInfo::new(name, TrajectoryKind::Primitive, type_name)
    };
    let mut w = RecordingWriter::create(path, RecordOptions::default()).unwrap();
    let robot = w
        .add_trajectory(
            info("robot_state", "RobotState"),
            TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
        )
        .unwrap();
    let camera = w
        .add_trajectory(
            info("camera", "Image"),
            TypeSchema::collect(Image::entity_structure_type(), &|_| None),
        )
        .unwrap();
    let t0 = 1_700_000_000_000_000_000_i64;
    for i in 0..50 {
        let t = t0 + i * 100_000_000;
        let rs = RobotState { x: i as f64 * 0.5, y: -(i as f64), dir: 90.0 };
        w.write(robot, &rs.to_structure("r1", t, t), t + 1_000, t + 2_000).unwrap();
        if i % 10 == 0 {
            let im = Image {
                width: 2,
                height: 1,
                format: Image::FORMAT_MONO8,
                image_data: vec![1, 2].into(),
            };
            w.write(camera, &im.to_structure("cam", t, t), t + 1_000, t + 2_000).unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn plot_from_a_recording_writes_a_png_and_names_bad_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.mcap");
    recording(&rec);
    let (rec, png) = (rec.to_str().unwrap(), dir.path().join("xy.png"));
    let png_arg = png.to_str().unwrap();

    let out = ok(&["plot", "robot_state", "x", "y", "--file", rec, "-o", png_arg]);
    assert!(out.contains("over 50 structures (100 points)"), "{out}");
    let bytes = std::fs::read(&png).unwrap();
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    assert!(bytes.len() > 1000, "{} bytes", bytes.len());

    // A window of valid time, relative to the latest sample: 1 s back holds 11 samples.
    let window = dir.path().join("window.png");
    let out = ok(&[
        "--json",
        "plot",
        "robot_state",
        "x",
        "--from",
        "-1s",
        "--file",
        rec,
        "-o",
        window.to_str().unwrap(),
    ]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["structures"], 11, "{out}");

    let unknown = dir.path().join("never.png");
    for (args, expected) in [
        (
            ["robot_state", "z"],
            "`robot_state` (RobotState) has no attribute `z`; plottable: x, y, dir",
        ),
        (["camera", "image_data"], "attribute `image_data` of `camera` (Image) is"),
        (["nobody", "x"], "has no trajectory `nobody`; it has robot_state, camera"),
    ] {
        let mut all = vec!["plot"];
        all.extend(args);
        all.extend(["--file", rec, "-o", unknown.to_str().unwrap()]);
        let o = esgm(&all, Duration::from_secs(60));
        assert_eq!(o.code, Some(1), "{}", o.stderr);
        assert_eq!(o.stderr.trim().lines().count(), 1, "one line: {}", o.stderr);
        assert!(o.stderr.contains(expected), "expected `{expected}` in: {}", o.stderr);
        assert!(!unknown.exists(), "no file is written for a refused plot");
    }
}

/// Waits until process `pid` has a node in `domain`.
fn attached(domain: &str, pid: u32) {
    let deadline = std::time::Instant::now() + common::PATIENCE;
    while !esgm_shm::processes_of(domain).unwrap().contains_key(&pid) {
        assert!(std::time::Instant::now() < deadline, "process {pid} never joined `{domain}`");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits for `child` to exit; fails the test if it outlives `limit`.
fn exits(child: &mut std::process::Child, limit: Duration, what: &str) {
    let deadline = std::time::Instant::now() + limit;
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            panic!("{what} still runs after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The pids whose parent is `pid`.
fn children_of(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(child) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        // `pid (comm) state ppid …`
        let ppid = stat.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().nth(1));
        if ppid == Some(pid.to_string().as_str()) {
            out.push(child);
        }
    }
    out
}

/// `esgm view` stopped with SIGTERM leaves nothing running: the external subcommand is
/// the process that got the signal, not a child that outlives it (issue 24: esgm-view
/// kept running, mapping the domain).
#[test]
fn a_stopped_esgm_view_leaves_no_process_behind() {
    let view = std::path::Path::new(common::ESGM).with_file_name("esgm-view");
    let built = common::capability::built(&view);
    if common::capability::needs("esgm-view (cargo build -p esgm-view)", built).is_none() {
        return;
    }
    let d = esgm_shm::unique_domain("cli-view-stop");
    ok(&["--domain", &d, "up", "--detach"]);
    let _down = Down(d.clone());
    let mut run = std::process::Command::new(common::ESGM)
        .args(["--domain", &d, "view", "--port", "0"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    attached(&d, run.id());
    assert_eq!(children_of(run.id()), Vec::<u32>::new(), "esgm view runs esgm-view as a child");
    // SAFETY: a signal to the child this test spawned.
    assert_eq!(unsafe { libc::kill(run.id() as libc::pid_t, libc::SIGTERM) }, 0);
    exits(&mut run, common::PATIENCE, "esgm view after SIGTERM");
    assert!(!esgm_shm::processes_of(&d).unwrap().contains_key(&run.id()));
}

/// `esgm down` stops every process still attached to the domain, tools esgm did not
/// start included (issue 24: they kept mapping the domain's shared memory).
#[test]
fn down_stops_the_processes_still_attached() {
    let d = esgm_shm::unique_domain("cli-down-attached");
    ok(&["--domain", &d, "up", "--detach"]);
    let _down = Down(d.clone());
    ok(&["--domain", &d, "traj", "create", "robot", "--primitive", "RobotState"]);
    let mut echo = std::process::Command::new(common::ESGM)
        .args(["--domain", &d, "echo", "robot"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    attached(&d, echo.id());
    let out = ok(&["--domain", &d, "down"]);
    assert!(out.contains("stopped"), "{out}");
    exits(&mut echo, Duration::from_secs(10), "esgm echo after esgm down");
    assert!(esgm_shm::processes_of(&d).unwrap().is_empty());
}
