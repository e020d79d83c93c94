//! E7 and T5 act on the whole system, whichever side asks, and `flush` waits for it:
//! on shared memory the reader is another process, so each check here crosses the
//! boundary; in process both sides are one runtime and the same rules hold.

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::esgm::LogLevel;
use esgm_core::prelude::*;
use esgm_core::{FluentStreamPolicy, QueryError};

use super::{WAIT, contents, read, reading, register_reading, wait_visible, x_of};
use crate::{Harness, wait_for};

/// A unit that adds 1 to its one input's x.
fn plus_one(i: &[Sample], _: Time) -> Result<EntityStructure, ComputeError> {
    Ok(reading(i[0].valid_time(), x_of(&i[0]).unwrap_or(0.0) + 1.0))
}

/// T5: a reset through any handle — the reader's replica or the writer's own — empties
/// the writer's stream, and `reset_blocking` returns once every reader has forgotten:
/// both sides are empty on return, with no wait.
pub fn reset_from_any_side_reaches_writer_and_readers<H: Harness>(h: &H) {
    register_reading(h);
    let w = h.esgm().create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let r = read(h, "r");
    let t0 = h.now();
    for k in 0..5 {
        w.add(reading(t0 + k, k as f64)).unwrap();
    }
    wait_visible(&w, &r);
    r.reset_blocking().unwrap();
    assert_eq!(contents(&w).unwrap(), vec![], "the writer forgot (reset through the reader)");
    assert_eq!(contents(&r).unwrap(), vec![], "the reader forgot");
    for k in 5..8 {
        w.add(reading(t0 + k, k as f64)).unwrap();
    }
    wait_visible(&w, &r);
    w.reset_blocking().unwrap();
    assert_eq!(contents(&r).unwrap(), vec![], "the reader forgot on return");
    // The non-blocking form reaches the writer on return, and the readers soon.
    w.add(reading(t0 + 9, 9.0)).unwrap();
    wait_visible(&w, &r);
    r.reset().unwrap();
    assert_eq!(contents(&w).unwrap(), vec![], "the writer forgot on return");
    wait_visible(&w, &r);
    // The stream goes on after a reset.
    w.add(reading(t0 + 10, 10.0)).unwrap();
    wait_visible(&w, &r);
    assert_eq!(x_of(&r.get_latest().unwrap()), Some(10.0));
}

/// E7 on the system from either side: `stats` has every trajectory with its writer's
/// counts (violations included), `memory_stats` counts what is stored, `reset` empties
/// every trajectory in every process, `set_log_level` reaches every process.
pub fn e7_acts_on_the_system_from_either_side<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::reasonable(0, 10).unwrap();
    let spec = TrajectorySpec::primitive("r", "Reading").policy(policy);
    let w = h.esgm().create_trajectory(spec).unwrap();
    let r = read(h, "r");
    let t0 = h.now();
    for k in 0..4 {
        w.add(reading(t0 + 10 * k, k as f64)).unwrap();
    }
    // Out of order: a violation, counted by the writer.
    assert!(matches!(w.add(reading(t0 + 5, 9.0)), Ok(AddOutcome::Dropped(_))));
    wait_visible(&w, &r);
    let writer = w.stats().unwrap();
    for side in [h.esgm(), h.reader()] {
        let s = side.stats().unwrap();
        let seen = &s.trajectories["r"].stats;
        assert_eq!((seen.added, seen.violations), (writer.added, writer.violations));
        assert_eq!((seen.added, seen.violations), (4, 1));
        assert!(side.memory_stats().unwrap().stored_samples >= 4);
    }
    h.reader().set_log_level(LogLevel::Debug).unwrap();
    assert_eq!(h.esgm().log_level(), LogLevel::Debug, "the writer's level, set by the reader");
    assert_eq!(h.reader().log_level(), LogLevel::Debug);
    h.esgm().set_log_level(LogLevel::Info).unwrap();
    assert_eq!(h.reader().log_level(), LogLevel::Info, "the reader's level, set by the writer");
    // A whole-system reset from the reader empties the writer and every replica.
    h.reader().reset().unwrap();
    assert_eq!(contents(&w).unwrap(), vec![]);
    assert_eq!(contents(&r).unwrap(), vec![]);
    for side in [h.esgm(), h.reader()] {
        assert_eq!(side.memory_stats().unwrap().stored_samples, 0);
    }
}

/// `flush`: once it returns, everything added before it has gone through a chain of
/// two units and reached the reader's replicas — read at once, with no wait.
pub fn flush_waits_for_units_and_replicas<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("plus_one", "Reading", vec!["Reading".into()], Arc::new(plus_one)).unwrap();
    let src = e.create_primitive_entity_trajectory_structure("src", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("one", "plus_one", &["src"]).unwrap();
    e.create_computed_entity_trajectory_structure("two", "plus_one", &["one"]).unwrap();
    // The reader reads the end of the chain (a replica, on shared memory).
    let two = read(h, "two");
    let t0 = h.now();
    const N: i64 = 200;
    for k in 0..N {
        src.add(reading(t0 + k, k as f64)).unwrap();
    }
    for side in [e, h.reader()] {
        side.flush(Instant::now() + WAIT).unwrap();
        let got = two.get_between(Time::MIN, Time::MAX).unwrap();
        assert_eq!(got.len(), N as usize, "every output of the chain is there on return");
        assert_eq!(x_of(&two.get_latest().unwrap()), Some((N - 1) as f64 + 2.0));
    }
    // Nothing added: returns at once, and again.
    e.flush(Instant::now() + WAIT).unwrap();
}

/// `flush` fails with the deadline rather than waiting past it for a unit that takes
/// longer.
pub fn flush_gives_up_at_its_deadline<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let released = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let gate = Arc::clone(&released);
    let slow = move |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        // Waits for the test to let it go (bounded, so a failing test ends).
        wait_for(WAIT, || gate.load(std::sync::atomic::Ordering::Acquire));
        Ok(i[0].structure.to_structure())
    };
    e.add_comp_unit("slow", "Reading", vec!["Reading".into()], Arc::new(slow)).unwrap();
    let src = e.create_primitive_entity_trajectory_structure("src", "Reading").unwrap();
    let out = e.create_computed_entity_trajectory_structure("out", "slow", &["src"]).unwrap();
    src.add(reading(h.now(), 1.0)).unwrap();
    let err = e.flush(Instant::now() + Duration::from_millis(200)).unwrap_err();
    assert!(matches!(err, esgm_core::FlushError::DeadlinePassed { .. }), "{err}");
    released.store(true, std::sync::atomic::Ordering::Release);
    assert!(wait_for(WAIT, || out.get_latest().is_ok()), "the unit finished after all");
    e.flush(Instant::now() + WAIT).unwrap();
    assert!(matches!(out.get_nth_latest(1), Err(QueryError::ValueNotAvailable { .. })));
}
