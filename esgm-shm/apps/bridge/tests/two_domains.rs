//! Two domains on one machine, each with its own coordinator and bridge, joined over
//! loopback TCP: what crosses, what is refused, and what a killed bridge loses.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::{BRIDGE, Bridge, Domain, eventually, free_port, one_at_a_time, run};
use esgm_core::esgm::{InputType, TrajectorySpec};
use esgm_core::value::ValueSort;
use esgm_core::{
    CacheConstraint, EntityStructure, EntityStructureType, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, Octets, Sample, Value,
};
use esgm_shm::ShmEsgm;
use zenoh::Wait as _;

const WAIT: Duration = Duration::from_secs(20);

fn robot(i: i64, base: i64) -> EntityStructure {
    EntityStructure::new("robot1", base + i * 1_000_000, base + i * 1_000_000 + 7)
        .with("x", i as f64 * 0.5)
        .with("y", -(i as f64))
        .with("dir", 90.0)
}

fn image(i: i64, base: i64) -> EntityStructure {
    let pixels: Vec<u8> = (0..64 * 48 * 3).map(|p| ((p as i64 + i) % 251) as u8).collect();
    EntityStructure::new("camera", base + i * 1_000_000, base + i * 1_000_000)
        .with("width", 64i64)
        .with("height", 48i64)
        .with("format", 0i64)
        .with("image_data", Value::OctetSeq(Octets::from(pixels)))
}

fn primitive(esgm: &ShmEsgm, name: &str, type_name: &str, cache: usize) {
    esgm.create_trajectory(
        TrajectorySpec::primitive(name, type_name)
            .policy(FluentStreamPolicy::default().cache(CacheConstraint::Elements(cache))),
    )
    .unwrap();
}

fn now() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64
}

/// Waits for `name` to exist in `esgm` and hold `n` samples; returns them.
fn samples(esgm: &ShmEsgm, name: &str, n: usize) -> Vec<Sample> {
    eventually(WAIT, &format!("{n} samples in `{name}`"), || {
        let t = esgm.get_entity_trajectory_structure(name).ok()?;
        let all = t.get_between(i64::MIN / 2, i64::MAX / 2).ok()?;
        (all.len() >= n).then_some(all)
    })
}

#[test]
fn robot_state_and_images_cross_with_their_times_and_are_computed_on() {
    let _one = one_at_a_time();
    let a = Domain::start("bridge-a");
    let b = Domain::start("bridge-b");
    primitive(a.esgm(), "robot_state", "RobotState", 100);
    primitive(a.esgm(), "images", "Image", 4);
    let base = now();
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let images = a.esgm().get_entity_trajectory_structure("images").unwrap();
    for i in 0..10 {
        states.add_blocking(robot(i, base)).unwrap();
    }
    for i in 0..3 {
        images.add_blocking(image(i, base)).unwrap();
    }

    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let import_states = format!("{}/robot_state", a.name);
    let import_images = format!("{}/images", a.name);
    let mut bridge_b = Bridge::start(
        &b.name,
        &["--listen", &listen, "--import", &import_states, "--import", &import_images],
    );
    let _bridge_a = Bridge::start(
        &a.name,
        &["--connect", &listen, "--export", "robot_state", "--export", "images"],
    );

    // History: what was written before either bridge ran.
    let got = samples(b.esgm(), "robot_state", 10);
    for (i, s) in got.iter().enumerate() {
        let want = robot(i as i64, base);
        assert_eq!(s.structure, want, "sample {i}: values and times intact");
        assert!(s.add_time >= want.valid_time, "the add time is the importer's");
    }
    // Live: written while the bridges run.
    for i in 10..20 {
        states.add_blocking(robot(i, base)).unwrap();
    }
    let got = samples(b.esgm(), "robot_state", 20);
    assert_eq!(got.len(), 20);
    assert_eq!(got[19].structure, robot(19, base));

    // Images: the cache bound (4) of the three written, then one live.
    images.add_blocking(image(3, base)).unwrap();
    let got = samples(b.esgm(), "images", 4);
    for s in &got {
        let i = (s.valid_time() - base) / 1_000_000;
        assert_eq!(s.structure, image(i, base), "image {i} intact");
    }

    // Domain B computes on the imported trajectory like on any of its own.
    let b_esgm = b.esgm();
    b_esgm
        .add_comp_unit(
            "Ahead",
            "RobotState",
            vec![InputType::Type("RobotState".into())],
            Arc::new(|inputs: &[Sample], _t: i64| {
                let s = &inputs[0];
                let x = match s.value("x") {
                    Some(Value::Double(x)) => x,
                    _ => 0.0,
                };
                Ok(EntityStructure::new("robot1", s.valid_time(), s.create_time())
                    .with("x", x + 1.0)
                    .with("y", 0.0)
                    .with("dir", 0.0))
            }),
        )
        .unwrap();
    let ahead = b_esgm
        .create_computed_entity_trajectory_structure("ahead", "Ahead", &["robot_state"])
        .unwrap();
    states.add_blocking(robot(20, base)).unwrap();
    let computed = eventually(WAIT, "a computed sample in B", || {
        ahead.get_latest().ok().filter(|s| s.valid_time() == robot(20, base).valid_time)
    });
    assert_eq!(computed.value("x"), Some(Value::Double(20.0 * 0.5 + 1.0)));

    let c = bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 21);
    assert_eq!(c["malformed"], 0);
    assert_eq!(c["lost"], serde_json::json!({}));
}

#[test]
fn malformed_payloads_are_counted_and_a_type_conflict_names_the_attribute() {
    let _one = one_at_a_time();
    let a = Domain::start("bridge-bad-a");
    let b = Domain::start("bridge-bad-b");
    primitive(a.esgm(), "robot_state", "RobotState", 100);
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let base = now();
    states.add_blocking(robot(0, base)).unwrap();
    // The same type name, another definition, on each side.
    a.esgm()
        .create_entity_structure_type(
            "Gauge",
            EntityStructureType::new("Gauge")
                .attr("level", ValueSort::Double)
                .attr("unit", ValueSort::String),
        )
        .unwrap();
    b.esgm()
        .create_entity_structure_type(
            "Gauge",
            EntityStructureType::new("Gauge")
                .attr("level", ValueSort::Long)
                .attr("unit", ValueSort::String),
        )
        .unwrap();
    primitive(a.esgm(), "gauge", "Gauge", 10);

    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let import_states = format!("{}/robot_state", a.name);
    let import_gauge = format!("{}/gauge", a.name);
    let mut bridge_b = Bridge::start(
        &b.name,
        &["--listen", &listen, "--import", &import_states, "--import", &import_gauge],
    );
    let _bridge_a = Bridge::start(
        &a.name,
        &["--connect", &listen, "--export", "robot_state", "--export", "gauge"],
    );
    samples(b.esgm(), "robot_state", 1);

    // The conflict is refused, naming the attribute, and nothing is created.
    eventually(WAIT, "the refusal on stderr", || {
        let e = bridge_b.stderr();
        e.contains("refused").then_some(e)
    });
    let stderr = bridge_b.stderr();
    assert!(
        stderr.contains(&format!("import of `{}/gauge` refused", a.name))
            && stderr.contains("type `Gauge`")
            && stderr.contains("attribute `level`"),
        "stderr:\n{stderr}"
    );
    assert!(b.esgm().get_entity_trajectory_structure("gauge").is_err());

    // A plain Zenoh publisher on the key: garbage, a header with no archive, a valid
    // header with a damaged archive.
    let mut config = zenoh::Config::default();
    config.insert_json5("connect/endpoints", &format!(r#"["{listen}"]"#)).unwrap();
    config.insert_json5("scouting/multicast/enabled", "false").unwrap();
    config.insert_json5("listen/endpoints", "[]").unwrap();
    let session = zenoh::open(config).wait().unwrap();
    let key = format!("esgm/{}/robot_state", a.name);
    let publisher = session.declare_publisher(key).wait().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let header = esgm_bridge::wire::Header {
        session: 1,
        writer: 1,
        sequence: 1,
        add_time: 0,
        skipped: 0,
        type_hash: 0,
        type_name: "RobotState".into(),
        lineage: None,
        kind: esgm_bridge::wire::Kind::Structure,
    };
    let good = esgm_core::codec::encode(&robot(1, base)).unwrap();
    let mut damaged = esgm_bridge::wire::encode(&header, &good);
    let n = damaged.len();
    damaged.truncate(n - 5);
    for payload in
        [b"not an esgm message".to_vec(), esgm_bridge::wire::encode(&header, &[]), damaged]
    {
        publisher.put(payload).wait().unwrap();
    }
    let c = bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["malformed"] == 3);
    assert_eq!(c["added"], 1);

    // The importer keeps serving.
    states.add_blocking(robot(2, base)).unwrap();
    let got = samples(b.esgm(), "robot_state", 2);
    assert_eq!(got[1].structure, robot(2, base));
}

#[test]
fn a_killed_exporter_resumes_and_its_gap_is_counted_as_lost() {
    let _one = one_at_a_time();
    let a = Domain::start("bridge-kill-a");
    let b = Domain::start("bridge-kill-b");
    primitive(a.esgm(), "robot_state", "RobotState", 5);
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let base = now();

    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let import_states = format!("{}/robot_state", a.name);
    let mut bridge_b = Bridge::start(&b.name, &["--listen", &listen, "--import", &import_states]);
    let export = ["--connect", listen.as_str(), "--export", "robot_state"];
    let mut bridge_a = Bridge::start(&a.name, &export);
    // Both bridges are through with their start once the first sample crossed.
    states.add_blocking(robot(0, base)).unwrap();
    bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 1);
    // One at a time: a burst could overflow the exporter's queue of 5 on a loaded
    // machine, a loss counted as `sequence_gap`, and this test is about the restart's.
    for i in 1..10 {
        states.add_blocking(robot(i, base)).unwrap();
        bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == i + 1);
    }

    bridge_a.kill9();
    // 30 while the exporter is gone; its successor finds the last 5 (the cache).
    for i in 10..40 {
        states.add_blocking(robot(i, base)).unwrap();
    }
    let _bridge_a = Bridge::start(&a.name, &export);
    let c = bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 15);
    assert_eq!(c["lost"]["exporter_restarted"], 25, "{c}");
    for i in 40..45 {
        states.add_blocking(robot(i, base)).unwrap();
        bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == i - 24);
    }
    let c = bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 20);
    assert_eq!(c["lost"]["exporter_restarted"], 25, "{c}");
    assert!(c["lost"].get("sequence_gap").is_none(), "{c}");

    let t = b.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let latest = eventually(WAIT, "the last sample in B", || {
        t.get_latest().ok().filter(|s| s.valid_time() == robot(44, base).valid_time)
    });
    assert_eq!(latest.structure, robot(44, base));
}

#[test]
fn another_host_queries_a_domain_through_its_bridge() {
    let _one = one_at_a_time();
    let a = Domain::start("bridge-query-a");
    primitive(a.esgm(), "robot_state", "RobotState", 100);
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let base = now();
    for i in 0..10 {
        states.add_blocking(robot(i, base)).unwrap();
    }
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    // Nothing exported: queries read the domain directly.
    let _bridge_a = Bridge::start(&a.name, &["--listen", &listen]);
    let query = |args: &[&str]| {
        let mut c = std::process::Command::new(BRIDGE);
        c.args(["--domain", &a.name, "--json", "query", "--connect", &listen]).args(args);
        run(c, WAIT)
    };
    let json = |line: &str| serde_json::from_str::<serde_json::Value>(line).unwrap();

    let o = query(&["latest", "robot_state"]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let latest = json(o.stdout.trim());
    assert_eq!(latest["valid_time"], robot(9, base).valid_time);
    assert_eq!(latest["create_time"], robot(9, base).create_time);
    assert_eq!(latest["attributes"]["x"], 4.5);

    let o = query(&["between", "robot_state", "-3ms", "+0ns"]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let valid: Vec<i64> =
        o.stdout.lines().map(|l| json(l)["valid_time"].as_i64().unwrap()).collect();
    assert_eq!(valid, (6..10).map(|i| robot(i, base).valid_time).collect::<Vec<_>>());

    let t = robot(5, base).valid_time.to_string();
    let o = query(&["at", "robot_state", &t]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    assert_eq!(json(o.stdout.trim())["valid_time"], robot(5, base).valid_time);

    let o = query(&["latest", "robt"]);
    assert_eq!(o.code, Some(1));
    assert!(o.stderr.contains("robt"), "the error names the trajectory: {}", o.stderr);

    // Through the esgm command, where cargo put it next to the bridge.
    let esgm = std::path::Path::new(BRIDGE)
        .with_file_name(format!("esgm{}", std::env::consts::EXE_SUFFIX));
    if esgm.is_file() {
        let mut c = std::process::Command::new(&esgm);
        c.args(["--domain", &a.name, "--remote", &listen, "--json", "latest", "robot_state"]);
        let o = run(c, WAIT);
        assert_eq!(o.code, Some(0), "{}", o.stderr);
        assert_eq!(json(o.stdout.trim())["valid_time"], robot(9, base).valid_time);
    } else {
        println!("esgm --remote not checked: no esgm executable next to {BRIDGE}");
    }
}

/// A process that created `robot_state`'s service in A before its writer did (with
/// room for more publishers) publishes a state one hour ahead. The exporting bridge
/// sends the writer's samples alone: the forged one is counted as `not_writer`, and B
/// never holds it.
#[test]
fn the_exporter_sends_the_writers_samples_alone() {
    use esgm_shm::control::{Request, Response};
    let _one = one_at_a_time();
    let a = Domain::start("bridge-forge-a");
    let b = Domain::start("bridge-forge-b");
    // Generations count up across the registry: the next trajectory gets the probe's + 1.
    primitive(a.esgm(), "probe", "RobotState", 1);
    let generation =
        match a.esgm().control(Request::GetEntityTrajectoryStructure { name: "probe".into() }) {
            Ok(Response::Trajectory(r)) => r.generation + 1,
            other => panic!("no record of the probe: {other:?}"),
        };
    let node = iceoryx2::prelude::NodeBuilder::new()
        .config(esgm_shm::iceoryx2_config())
        .create::<esgm_shm::ShmService>()
        .unwrap();
    let roomy = esgm_shm::TrajectoryQos {
        history_size: 128,
        subscriber_buffer_size: 128,
        max_borrowed_samples: 128,
        max_publishers: 4,
        max_subscribers: 8,
        max_nodes: 32,
        ..esgm_shm::TrajectoryQos::default()
    };
    let forger = esgm_shm::TrajectoryPublisher::builder("robot_state", "RobotState")
        .domain(format!("{}.g{generation}", a.name))
        .qos(roomy)
        .create(&node)
        .unwrap();
    primitive(a.esgm(), "robot_state", "RobotState", 100);
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let base = now();
    let hour = 3_600_000_000_000;

    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let import_states = format!("{}/robot_state", a.name);
    let mut bridge_b = Bridge::start(&b.name, &["--listen", &listen, "--import", &import_states]);
    let mut bridge_a = Bridge::start(&a.name, &["--connect", &listen, "--export", "robot_state"]);
    // While both bridges run: the writer's, the forger's, the writer's.
    states.add_blocking(robot(0, base)).unwrap();
    bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 1);
    forger.publish(&robot(99, base + hour)).unwrap();
    states.add_blocking(robot(1, base)).unwrap();
    states.add_blocking(robot(2, base)).unwrap();
    bridge_a.wait_counters("export", "robot_state", WAIT, |v| v["not_writer"] == 1);
    bridge_b.wait_counters("import", "robot_state", WAIT, |v| v["added"] == 3);
    let got = samples(b.esgm(), "robot_state", 3);
    let times: Vec<i64> = got.iter().map(|s| s.valid_time()).collect();
    let want: Vec<i64> = (0..3).map(|i| robot(i, base).valid_time).collect();
    assert_eq!(times, want, "the writer's three, not the forged one an hour ahead");
}

/// A structure computed in one domain crosses to another with its lineage: the input
/// it names is the exporting domain's, exactly as stored there (X1 across hosts).
#[test]
fn lineage_crosses_the_bridge() {
    let _one = one_at_a_time();
    let a = Domain::start("bridge-lin-a");
    let b = Domain::start("bridge-lin-b");
    primitive(a.esgm(), "robot_state", "RobotState", 100);
    let copy = |inputs: &[Sample], _t: i64| Ok(inputs[0].structure.to_structure());
    let types = vec![InputType::Type("RobotState".into())];
    a.esgm().add_comp_unit("Copy", "RobotState", types, Arc::new(copy)).unwrap();
    a.esgm()
        .create_computed_entity_trajectory_structure("copied", "Copy", &["robot_state"])
        .unwrap();
    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let import = format!("{}/copied", a.name);
    let _bridge_b = Bridge::start(&b.name, &["--listen", &listen, "--import", &import]);
    let _bridge_a = Bridge::start(&a.name, &["--connect", &listen, "--export", "copied"]);
    let states = a.esgm().get_entity_trajectory_structure("robot_state").unwrap();
    let base = now();
    for i in 0..3 {
        states.add_blocking(robot(i, base)).unwrap();
    }
    let got = samples(b.esgm(), "copied", 3);
    for s in &got {
        let lineage = s.lineage.as_ref().unwrap_or_else(|| panic!("no lineage crossed: {s:?}"));
        let input = &lineage.inputs[0];
        let there = states.get_at(s.valid_time()).unwrap();
        assert_eq!(
            (input.trajectory.as_str(), input.valid_time, input.add_time),
            ("robot_state", there.valid_time(), there.add_time),
            "named as the exporting domain stores it"
        );
        assert!(!lineage.complete);
    }
}
