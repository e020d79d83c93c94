//! A trajectory's history outlives its writer (SPEC D1, issue 39): what `add`
//! acknowledged stays queryable from every process, whichever process exits or is
//! killed, until the policy evicts it or the trajectory is reset or destroyed.
//!
//! The writers here are child processes (this test binary run in a role), killed with
//! SIGKILL or left to exit; each test has its own coordinator in a unique domain, and
//! every wait has a deadline.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::{Duration, Instant};

use common::{TIMEOUT, coordinator, location, reap, spawn_child, state, wait_for, x};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    AddError, AddOutcome, CacheConstraint, EntityTrajectoryStructure, Esgm, FluentStreamPolicy,
    InProcessTrajectory, SubscribeOptions,
};
use esgm_shm::ShmEsgm;

const ROLE: &str = "ESGM_KEPT_ROLE";
const DOMAIN: &str = "ESGM_KEPT_DOMAIN";
/// How many structures the killed writer adds, and how many its policy keeps.
const ADDED: i64 = 100;
const CACHE: usize = 20;

/// Every `x` the trajectory holds, oldest first.
fn all(t: &InProcessTrajectory) -> Vec<f64> {
    t.get_between(i64::MIN, i64::MAX).map(|s| s.iter().map(x).collect()).unwrap_or_default()
}

fn range(from: i64, to: i64) -> Vec<f64> {
    (from..to).map(|i| i as f64).collect()
}

/// A connection as a short-lived command makes it (`esgm latest`).
fn tool(domain: &str) -> ShmEsgm {
    ShmEsgm::builder().domain(domain).tool().connect().unwrap()
}

/// Adds to `t` until its writer is taken over here (`WriterGone` meanwhile).
fn add_taking_over(t: &InProcessTrajectory, vt: i64) -> AddOutcome {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        match t.add(state(vt, vt as f64)) {
            Ok(outcome) => return outcome,
            Err(AddError::WriterGone { .. }) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => panic!("an add after the writer died: {e:?}"),
        }
    }
}

/// The case, as a new user met it: a setup program creates `odo` and exits; a
/// second program adds to it (acknowledged) and exits; a command then reads it.
#[test]
fn a_structure_acknowledged_by_a_program_that_exited_is_read_by_the_next() {
    let c = coordinator("kept-two");
    for role in ["create", "add"] {
        let child = spawn_child("child_program", (ROLE, role), (DOMAIN, c.domain()));
        let (status, output) = reap(child, TIMEOUT * 3);
        assert!(status.success(), "the {role} program failed:\n{output}");
    }
    let esgm = tool(c.domain());
    let odo = esgm.get_entity_trajectory_structure("odo").unwrap();
    assert_eq!(x(&odo.get_latest().unwrap()), 2.0, "the latest acknowledged structure");
    assert_eq!(all(&odo), [1.0, 2.0], "add's and add_blocking's");
}

/// A writer killed with SIGKILL after acknowledging its adds: a command started later
/// reads what its policy keeps; a reader that was there sees no reset and no
/// duplicate; the next adder takes the trajectory over and continues the same
/// history, with no gap.
#[test]
fn a_killed_writer_keeps_what_it_acknowledged_and_the_next_writer_continues_it() {
    let c = coordinator("kept-kill");
    let mut child = spawn_child("child_program", (ROLE, "writer"), (DOMAIN, c.domain()));
    let early = location(&c, "early");
    let found = said_done(&early);
    if !found {
        let _ = child.kill();
        let (_, output) = reap(child, TIMEOUT);
        panic!("the writer never said done:\n{output}");
    }
    let kept = early.get_entity_trajectory_structure("kept").unwrap();
    assert!(wait_for(|| all(&kept) == range(ADDED - CACHE as i64, ADDED)), "{:?}", all(&kept));
    let subscription = kept.subscribe(SubscribeOptions::default()).unwrap();
    child.kill().unwrap();
    let _ = child.wait();

    // A command started after the writer died reads what it acknowledged.
    let later = tool(c.domain());
    let there = later.get_entity_trajectory_structure("kept").unwrap();
    assert_eq!(all(&there), range(ADDED - CACHE as i64, ADDED));
    drop(there);
    drop(later);

    // The next adder continues the history.
    let taker = location(&c, "taker");
    let taken = taker.get_entity_trajectory_structure("kept").unwrap();
    assert_eq!(all(&taken), range(ADDED - CACHE as i64, ADDED), "read from the kept history");
    assert_eq!(add_taking_over(&taken, ADDED), AddOutcome::Added);
    assert_eq!(all(&taken), range(ADDED - CACHE as i64 + 1, ADDED + 1));
    assert!(
        wait_for(|| all(&kept) == range(ADDED - CACHE as i64 + 1, ADDED + 1)),
        "the reader that was there holds {:?}",
        all(&kept)
    );
    // It was handed the history again and skipped it: its subscriber got the new
    // structure only (no reset, no duplicate).
    assert_eq!(x(&subscription.recv_timeout(TIMEOUT).unwrap()), ADDED as f64);
    assert!(subscription.try_recv().is_none(), "delivered once, and nothing else");

    // And a command reads the continued history, from the new writer.
    let last = tool(c.domain());
    let there = last.get_entity_trajectory_structure("kept").unwrap();
    assert!(
        wait_for(|| all(&there) == range(ADDED - CACHE as i64 + 1, ADDED + 1)),
        "{:?}",
        all(&there)
    );
}

/// A writer that comes back under its stable name (as a supervisor restarts it) takes
/// its trajectory back with the history it kept, and goes on numbering it: readers
/// hold each structure once.
#[test]
fn a_restarted_writer_continues_its_history() {
    let c = coordinator("kept-restart");
    let mut first = spawn_child("child_program", (ROLE, "writer"), (DOMAIN, c.domain()));
    let reader = location(&c, "reader");
    assert!(said_done(&reader), "the writer never said done");
    let kept = reader.get_entity_trajectory_structure("kept").unwrap();
    first.kill().unwrap();
    let _ = first.wait();
    let again = spawn_child("child_program", (ROLE, "restarted"), (DOMAIN, c.domain()));
    let expected = range(ADDED - CACHE as i64 + 5, ADDED + 5);
    let held = wait_for(|| all(&kept) == expected);
    reader.create_primitive_entity_trajectory_structure("seen", "RobotState").unwrap();
    let (status, output) = reap(again, TIMEOUT * 3);
    assert!(status.success(), "the restarted writer failed:\n{output}");
    assert!(held, "the reader holds {:?}", all(&kept));
    let later = tool(c.domain());
    assert_eq!(all(&later.get_entity_trajectory_structure("kept").unwrap()), expected);
}

/// Images written into loans (never copied on their way to readers) are kept too: a
/// command started after their writer was killed reads their pixels.
#[test]
fn images_outlive_their_killed_writer() {
    let c = coordinator("kept-images");
    let mut child = spawn_child("child_program", (ROLE, "camera"), (DOMAIN, c.domain()));
    let early = location(&c, "early");
    let found = said_done(&early);
    child.kill().unwrap();
    let (_, output) = reap(child, TIMEOUT);
    assert!(found, "the camera never said done:\n{output}");
    let later = tool(c.domain());
    let frames = later.get_entity_trajectory_structure("frames").unwrap();
    let kept = frames.get_between(i64::MIN, i64::MAX).unwrap();
    assert_eq!(kept.iter().map(|s| s.structure.valid_time()).collect::<Vec<_>>(), [7, 8, 9]);
    for s in &kept {
        let Some(esgm_core::value::Value::OctetSeq(pixels)) = s.structure.value("image_data")
        else {
            panic!("no pixels in {s:?}")
        };
        assert_eq!(pixels.len(), 64 * 48 * 3);
        common::check_pattern(&pixels, s.structure.valid_time() as u64);
    }
}

/// An image whose structure does not match the loan its pixels were written into
/// (another shape of the same size) is written the ordinary way, and the pixels its
/// producer and its writer's store hold stay its own while later images are loaned
/// where that loan was; a reader in another process reads them too.
#[test]
fn an_image_that_does_not_match_its_loan_keeps_its_pixels() {
    let c = coordinator("kept-mismatch");
    let camera = location(&c, "camera");
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(3));
    let spec = TrajectorySpec::primitive("frames", "Image").policy(policy);
    let frames = camera.create_trajectory(spec).unwrap();
    let image = |vt: i64, (width, height): (i64, i64), pixels: esgm_core::Octets| {
        esgm_core::EntityStructure::new("cam", vt, vt)
            .with("width", width)
            .with("height", height)
            .with("format", 0i64)
            .with("image_data", pixels)
    };
    let mut buffer = frames.image_buffer(64, 48, 0).expect("a loan");
    common::fill(buffer.pixels_mut(), 1);
    let odd = buffer.into_octets();
    assert_eq!(frames.add(image(1, (48, 64), odd.clone())).unwrap(), AddOutcome::Added);
    let stored = frames.get_latest().unwrap();
    // Enough frames for the kept history's ring to come round many times.
    for vt in 2..200 {
        let mut buffer = frames.image_buffer(64, 48, 0).expect("a loan");
        common::fill(buffer.pixels_mut(), vt as u64);
        assert_eq!(
            frames.add(image(vt, (64, 48), buffer.into_octets())).unwrap(),
            AddOutcome::Added
        );
    }
    common::check_pattern(&odd, 1);
    let Some(esgm_core::value::Value::OctetSeq(pixels)) = stored.structure.value("image_data")
    else {
        panic!("no pixels in {stored:?}")
    };
    common::check_pattern(&pixels, 1);
    let reader = location(&c, "reader");
    for (who, esgm) in [("the writer's store", &camera), ("a reader", &reader)] {
        let t = esgm.get_entity_trajectory_structure("frames").unwrap();
        let kept = t.get_between(i64::MIN, i64::MAX).unwrap();
        assert_eq!(
            kept.iter().map(|s| s.valid_time()).collect::<Vec<_>>(),
            [197, 198, 199],
            "{who}"
        );
        for s in &kept {
            let Some(esgm_core::value::Value::OctetSeq(pixels)) = s.structure.value("image_data")
            else {
                panic!("no pixels in {s:?}")
            };
            common::check_pattern(&pixels, s.valid_time() as u64);
        }
    }
}

/// Destroying a trajectory removes its kept history: a name created again starts
/// empty, in every process.
#[test]
fn a_destroyed_trajectory_takes_its_kept_history_with_it() {
    let c = coordinator("kept-destroy");
    let writer = location(&c, "writer");
    let t = writer.create_primitive_entity_trajectory_structure("gone", "RobotState").unwrap();
    t.add(state(1, 1.0)).unwrap();
    let files = || {
        std::fs::read_dir("/dev/shm")
            .unwrap()
            .flatten()
            .filter(|e| {
                e.file_name().to_string_lossy().starts_with(&format!("esgm_keep@{}.", c.domain()))
            })
            .count()
    };
    assert_eq!(files(), 1, "one kept history");
    drop(t);
    writer.destroy_entity_trajectory_structure("gone").unwrap();
    assert!(wait_for(|| files() == 0), "removed with the trajectory");
    let t = writer.create_primitive_entity_trajectory_structure("gone", "RobotState").unwrap();
    assert!(all(&t).is_empty());
    drop(t);
    drop(writer);
    let domain = c.domain().to_owned();
    drop(c);
    assert_eq!(
        std::fs::read_dir("/dev/shm")
            .unwrap()
            .flatten()
            .filter(|e| e
                .file_name()
                .to_string_lossy()
                .starts_with(&format!("esgm_keep@{domain}.")))
            .count(),
        0,
        "nothing kept after the domain's end"
    );
}

/// Waits until a child said `done` ([`done_then_wait_to_be_killed`]), at most
/// [`TIMEOUT`]; whether it did.
fn said_done(esgm: &ShmEsgm) -> bool {
    wait_for(|| esgm.get_entity_trajectory_structure("done").is_ok_and(|d| d.get_latest().is_ok()))
}

/// Says `done` (a trajectory the parent waits for), then waits to be killed by it.
fn done_then_wait_to_be_killed(esgm: &ShmEsgm) {
    esgm.create_primitive_entity_trajectory_structure("done", "RobotState")
        .unwrap()
        .add(state(1, 1.0))
        .unwrap();
    std::thread::sleep(TIMEOUT * 6);
    panic!("not killed");
}

#[test]
fn child_program() {
    let Ok(role) = std::env::var(ROLE) else { return };
    let domain = std::env::var(DOMAIN).unwrap();
    match role.as_str() {
        "create" => {
            let esgm = ShmEsgm::builder().domain(&domain).host("setup").connect().unwrap();
            esgm.create_primitive_entity_trajectory_structure("odo", "RobotState").unwrap();
        }
        "add" => {
            let esgm = ShmEsgm::builder().domain(&domain).host("adder").connect().unwrap();
            let odo = esgm.get_entity_trajectory_structure("odo").unwrap();
            assert_eq!(add_taking_over(&odo, 1), AddOutcome::Added);
            odo.add_blocking(state(2, 2.0)).unwrap();
        }
        "writer" => {
            let esgm = ShmEsgm::builder().domain(&domain).host("robot").connect().unwrap();
            let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(CACHE));
            let spec = TrajectorySpec::primitive("kept", "RobotState").policy(policy);
            let kept = esgm.create_trajectory(spec).unwrap();
            for i in 0..ADDED {
                assert_eq!(kept.add(state(i, i as f64)).unwrap(), AddOutcome::Added);
            }
            done_then_wait_to_be_killed(&esgm);
        }
        "camera" => {
            let esgm = ShmEsgm::builder().domain(&domain).host("camera").connect().unwrap();
            let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(3));
            let spec = TrajectorySpec::primitive("frames", "Image").policy(policy);
            let frames = esgm.create_trajectory(spec).unwrap();
            for vt in 0..10 {
                let mut buffer = frames.image_buffer(64, 48, 0).expect("a loan");
                common::fill(buffer.pixels_mut(), vt as u64);
                let image = esgm_core::EntityStructure::new("cam", vt, vt)
                    .with("width", 64i64)
                    .with("height", 48i64)
                    .with("format", 0i64)
                    .with("image_data", buffer.into_octets());
                assert_eq!(frames.add(image).unwrap(), AddOutcome::Added);
            }
            done_then_wait_to_be_killed(&esgm);
        }
        "restarted" => {
            let esgm = ShmEsgm::builder().domain(&domain).host("robot").connect().unwrap();
            let kept = esgm.get_entity_trajectory_structure("kept").unwrap();
            assert_eq!(all(&kept), range(ADDED - CACHE as i64, ADDED), "its history, back");
            for i in ADDED..ADDED + 5 {
                assert_eq!(kept.add(state(i, i as f64)).unwrap(), AddOutcome::Added);
            }
            // Serving until the parent has read them.
            let deadline = Instant::now() + TIMEOUT * 2;
            while esgm.get_entity_trajectory_structure("seen").is_err() {
                assert!(Instant::now() < deadline, "the parent never said seen");
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        other => panic!("unknown role {other}"),
    }
}
