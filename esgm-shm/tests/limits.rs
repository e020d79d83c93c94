//! P6: a domain's limits are settings, and reaching one is a typed error for the
//! process that would exceed it, never a lock-up: every other process, and every
//! later command, is served as before.
//!
//! Each process of a domain is a connection (`esgm_shm::connect`); these tests make
//! many connections in one test process, which is what the limits count.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{TIMEOUT, robot, wait_for};
use esgm_core::esgm::{Limit, LimitReached, LookupError, TrajectorySpec};
use esgm_core::{AddOutcome, EntityTrajectoryStructure, Esgm};
use esgm_shm::DomainLimits;
use esgm_shm::control::{Coordinator, CoordinatorThread, Registry};
use esgm_shm::{ConnectError, ShmEsgm};

fn coordinator(prefix: &str, limits: DomainLimits) -> CoordinatorThread {
    common::node(); // quiet iceoryx2's config warning
    let domain = esgm_shm::unique_domain(prefix);
    let registry = Registry::new(esgm_core::TypeRegistry::with_library()).with_limits(limits);
    Coordinator::spawn(&domain, registry).expect("start a coordinator")
}

fn join(domain: &str, host: &str) -> Result<ShmEsgm, ConnectError> {
    ShmEsgm::builder().domain(domain).host(host).timeout(TIMEOUT).connect()
}

/// A short-lived command's connection (`esgm latest`, `esgm push`).
fn tool(domain: &str) -> ShmEsgm {
    ShmEsgm::builder().domain(domain).host("esgm-cli").timeout(TIMEOUT).tool().connect().unwrap()
}

/// The message a user sees: the limit, its value and the setting, in esgm's words.
fn check_message(e: &dyn std::error::Error, value: usize, setting: &str) {
    let text = e.to_string();
    assert!(text.contains(&format!("= {value})")), "names the value: {text}");
    assert!(text.contains(setting), "names the setting: {text}");
    assert!(!text.contains("Exceeds") && !text.contains("Error::"), "no iceoryx2 words: {text}");
    assert_eq!(text.matches("unavailable").count(), 0, "not a failure to reach: {text}");
}

#[test]
fn a_reader_past_a_trajectorys_readers_is_refused_and_the_trajectory_is_served_on() {
    let c = coordinator("limit-readers", DomainLimits::default());
    let d = c.domain().to_owned();
    let writer = join(&d, "writer").unwrap();
    let tf = writer
        .create_trajectory(TrajectorySpec::primitive("tf", "RobotState").readers(64))
        .unwrap();
    tf.add(robot(1)).unwrap();
    // 64 reader processes, each with the writer's history.
    let readers: Vec<_> = (0..64)
        .map(|i| {
            let r = join(&d, &format!("reader{i}")).unwrap();
            let t = r.get_entity_trajectory_structure("tf").unwrap();
            assert!(wait_for(|| t.get_latest().is_ok()), "reader {i} has the history");
            (r, t)
        })
        .collect();
    // The 65th is refused, naming the limit.
    let extra = join(&d, "reader64").unwrap();
    match extra.get_entity_trajectory_structure("tf") {
        Err(LookupError::LimitReached(e)) => {
            assert_eq!((e.limit, e.value), (Limit::Readers, 64), "{e}");
            assert!(e.subject.contains("`tf`"), "{e}");
            check_message(&e, 64, "--readers N");
        }
        other => panic!("the 65th reader: {other:?}"),
    }
    // Every later command is served: a tool adds (through the writer's inbox) and reads,
    // and every reader receives what was added.
    let cli = tool(&d);
    let t = cli.get_entity_trajectory_structure("tf").unwrap();
    assert_eq!(t.add(robot(2)).unwrap(), AddOutcome::Forwarded);
    let added = |t: &esgm_core::InProcessTrajectory| {
        t.get_latest().is_ok_and(|s| s.structure.valid_time() == robot(2).valid_time)
    };
    assert!(wait_for(|| added(&t)), "the tool reads what it added");
    assert!(wait_for(|| added(&tf)), "the writer has it");
    for (i, (_, r)) in readers.iter().enumerate() {
        assert!(wait_for(|| added(r)), "reader {i} has it");
    }
    // A reader leaving makes room for another.
    drop(readers);
    assert!(
        wait_for(|| extra.get_entity_trajectory_structure("tf").is_ok()),
        "a reader fits once others left"
    );
}

#[test]
fn a_process_past_the_domains_limit_is_refused_and_every_other_is_served() {
    let limits = DomainLimits { max_processes: 8, readers: 4 };
    let c = coordinator("limit-procs", limits);
    let d = c.domain().to_owned();
    let mut members: Vec<_> = (0..8).map(|i| join(&d, &format!("p{i}")).unwrap()).collect();
    let refused = join(&d, "p8").map(|_| ()).unwrap_err();
    match &refused {
        ConnectError::LimitReached(LimitReached { limit: Limit::Processes, value: 8, .. }) => {
            check_message(&refused, 8, "--max-processes N");
        }
        other => panic!("the 9th process: {other}"),
    }
    // Every member is served, and so is a command: create, add, query.
    let odom =
        members[0].create_primitive_entity_trajectory_structure("odom", "RobotState").unwrap();
    odom.add(robot(1)).unwrap();
    let replica = members[7].get_entity_trajectory_structure("odom").unwrap();
    assert!(wait_for(|| replica.get_latest().is_ok()), "a member reads another's trajectory");
    let cli = tool(&d);
    let t = cli.get_entity_trajectory_structure("odom").unwrap();
    assert_eq!(t.add(robot(2)).unwrap(), AddOutcome::Forwarded);
    assert!(wait_for(|| odom
        .get_nth_latest(0)
        .is_ok_and(|s| s.structure.valid_time() == robot(2).valid_time)));
    assert!(cli.stats().unwrap().trajectories.contains_key("odom"), "the domain answers stats");
    // A member leaving makes room.
    drop(members.pop());
    assert!(wait_for(|| join(&d, "p8").is_ok()), "a process fits once another left");
}

#[test]
fn an_illegal_readers_setting_is_refused_at_creation() {
    let c = coordinator("limit-illegal", DomainLimits { max_processes: 16, readers: 4 });
    let d = c.domain().to_owned();
    let p = join(&d, "p").unwrap();
    for readers in [0, 17] {
        let e = p
            .create_trajectory(TrajectorySpec::primitive("x", "RobotState").readers(readers))
            .unwrap_err()
            .to_string();
        assert!(e.contains("readers") && e.contains("--max-processes"), "{readers}: {e}");
    }
    p.create_trajectory(TrajectorySpec::primitive("x", "RobotState").readers(16)).unwrap();
}
