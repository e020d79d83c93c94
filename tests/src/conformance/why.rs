//! Why a trajectory did not produce (X2): each cause of silence made on purpose, and
//! named by `why` asked from the reader (on the shared-memory runtime another process
//! than the writer, which answers).

use std::sync::Arc;

use esgm_core::esgm::{CallOutcome, MissCause, Why};
use esgm_core::operators::sync::{ApproximateConfig, EpsilonConfig, SyncDropReason, SyncPolicy};
use esgm_core::{
    ComputeError, Constraint, DropCause, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, Sample, SensorError, Time, TrajectorySpec, millis,
};

use super::{WAIT, read, reading, register_reading, wait_stored, x_of};
use crate::{Harness, wait_for};

/// The reader's answer for `name` since `since`, once `done` holds (the writer's
/// worker runs asynchronously); fails the test with the last answer otherwise.
fn why_when<H: Harness>(h: &H, name: &str, since: Time, done: impl Fn(&Why) -> bool) -> Why {
    let mut last = None;
    let ok = wait_for(WAIT, || {
        let why = h.reader().why(name, since).expect("why answers");
        let ok = done(&why);
        last = Some(why);
        ok
    });
    let why = last.expect("asked at least once");
    assert!(ok, "`why {name}` never said what was expected: {why:#?}");
    why
}

fn says(why: &Why, words: &str) -> bool {
    why.reasons.iter().any(|r| r.contains(words))
}

/// A unit that answers "no value", one that fails and one that panics: each is named
/// with its last calls, and the message of the failure.
pub fn why_names_what_the_unit_returned<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let nothing = |_: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Err(ComputeError::ValueNotAvailable)
    };
    let failing = |_: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Err(ComputeError::Failed { reason: "calibration missing".into() })
    };
    let panicking = |_: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        panic!("index out of bounds in the blob finder")
    };
    let one = || vec!["Reading".into()];
    e.add_comp_unit("nothing", "Reading", one(), Arc::new(nothing)).unwrap();
    e.add_comp_unit("failing", "Reading", one(), Arc::new(failing)).unwrap();
    e.add_comp_unit("panicking", "Reading", one(), Arc::new(panicking)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    for (name, unit) in [("n", "nothing"), ("f", "failing"), ("p", "panicking")] {
        e.create_computed_entity_trajectory_structure(name, unit, &["a"]).unwrap();
    }
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    a.add(reading(t0 + 1, 2.0)).unwrap();
    let since = t0 - 1;
    let n = why_when(h, "n", since, |w| w.recent_calls.len() >= 2);
    assert!(n.recent_calls.iter().all(|c| c.outcome == CallOutcome::NoValue), "{n:#?}");
    assert!(says(&n, "its last 2 call(s) returned no value"), "{:?}", n.reasons);
    assert!(says(&n, "it has never produced"), "{:?}", n.reasons);
    assert_eq!(n.worker.map(|w| w.no_value), Some(2));
    let f = why_when(h, "f", since, |w| w.recent_calls.len() >= 2);
    assert!(says(&f, "failed: computation failed: calibration missing"), "{:?}", f.reasons);
    let p = why_when(h, "p", since, |w| w.recent_calls.len() >= 2);
    assert!(says(&p, "raised: index out of bounds in the blob finder"), "{:?}", p.reasons);
    assert_eq!(p.inputs.len(), 1);
    assert_eq!(p.inputs[0].latest_valid_time, Some(t0 + 1));
}

/// A unit over two inputs, one of which never got a structure: never called, and the
/// empty input is named; an input with nothing new since the time asked is named too.
pub fn why_names_the_input_it_waits_for<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let sum = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(reading(i[0].valid_time(), i.iter().filter_map(|s| x_of(s)).sum()))
    };
    e.add_comp_unit("sum", "Reading", vec!["Reading".into(); 2], Arc::new(sum)).unwrap();
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(sum)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    e.create_primitive_entity_trajectory_structure("silent", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("both", "sum", &["a", "silent"]).unwrap();
    e.create_computed_entity_trajectory_structure("copy_a", "copy", &["a"]).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    let both =
        why_when(h, "both", t0 - 1, |w| w.inputs.iter().any(|i| i.latest_add_time.is_some()));
    assert!(says(&both, "input `silent` holds no structure"), "{:?}", both.reasons);
    assert!(says(&both, "its producer was never called"), "{:?}", both.reasons);
    assert_eq!(both.worker.map(|w| w.calls), Some(0));
    // copy_a produced once; asked about a later time, a is what went quiet.
    wait_stored(&read(h, "copy_a"), 1);
    h.advance(millis(100));
    let later = h.now();
    let copy = why_when(h, "copy_a", later, |w| w.last_added.is_some());
    assert!(!copy.produced(), "{copy:#?}");
    assert!(
        says(&copy, "input `a` has had nothing new since the time asked"),
        "{:?}",
        copy.reasons
    );
    assert!(says(&copy, "nothing since the time asked"), "{:?}", copy.reasons);
    a.add(reading(later + 1, 2.0)).unwrap();
    let produced = why_when(h, "copy_a", later, Why::produced);
    assert!(says(&produced, "it produced: 1 structure(s)"), "{:?}", produced.reasons);
}

/// Outputs a constraint drops are named with the constraint and the last detail, and
/// a primitive trajectory's gate names what it dropped the same way.
pub fn why_names_the_constraint_that_dropped<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let copy = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(i[0].structure.to_structure())
    };
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let big_only = FluentStreamPolicy::default().filter("x > 10");
    e.create_trajectory(TrajectorySpec::computed("big", "copy", ["a"]).policy(big_only)).unwrap();
    let ordered = FluentStreamPolicy::default().order(esgm_core::OrderConstraint::Monotone);
    let o = e
        .create_trajectory(TrajectorySpec::primitive("ordered", "Reading").policy(ordered))
        .unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    a.add(reading(t0 + 1, 2.0)).unwrap();
    let big = why_when(h, "big", t0 - 1, |w| w.recent_calls.len() >= 2);
    assert!(
        matches!(&big.recent_calls[1].outcome, CallOutcome::Dropped(d) if d.contains("filter")),
        "{big:#?}"
    );
    let filter = big.drops.iter().find(|d| d.cause == DropCause::Violation(Constraint::Filter));
    let filter = filter.unwrap_or_else(|| panic!("no filter drops: {big:#?}"));
    assert_eq!((filter.since, filter.total), (2, 2));
    assert_eq!(filter.last.as_ref().map(|l| l.valid_time), Some(t0 + 1));
    assert!(says(&big, "the filter constraint dropped 2 structure(s)"), "{:?}", big.reasons);
    o.add(reading(t0 + 10, 1.0)).unwrap();
    let _dropped = o.add(reading(t0 + 5, 1.0)).unwrap();
    let ordered = why_when(h, "ordered", t0, |w| !w.drops.is_empty());
    let order = &ordered.drops[0];
    assert_eq!(order.cause, DropCause::Violation(Constraint::Order));
    assert_eq!(order.last.as_ref().map(|l| l.valid_time), Some(t0 + 5));
    assert!(says(&ordered, "the order constraint dropped 1"), "{:?}", ordered.reasons);
}

/// A sync names the input it waits for, how far behind it is against its tolerance,
/// and what it gave up on.
pub fn why_names_what_a_sync_waits_for<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let policy = SyncPolicy::Epsilon(EpsilonConfig::default().tolerance(5));
    e.create_trajectory(TrajectorySpec::sync("ab", ["a", "b"], policy)).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 4, 2.0)).unwrap();
    wait_stored(&read(h, "ab"), 1);
    a.add(reading(t0 + 100, 3.0)).unwrap();
    a.add(reading(t0 + 200, 3.0)).unwrap();
    let since = t0 + 50;
    let why = why_when(h, "ab", since, |w| {
        w.inputs.iter().any(|i| i.latest_valid_time == Some(t0 + 200))
    });
    let sync = why.sync.as_ref().expect("a sync says what it waits for");
    assert_eq!(sync.waits_for.as_deref(), Some("b"), "{why:#?}");
    assert_eq!((sync.gap, sync.tolerance), (Some(196), Some(5)));
    assert!(says(&why, "the sync waits for `b`"), "{:?}", why.reasons);
}

/// An ApproximateTime sync names, per input, what it dropped and why, with
/// message_filters' semantics: `a` runs ahead of a silent `b`, so its queue (of 2)
/// overflows twice; then `b`'s first item is too far from `a`'s (tolerance 10), and
/// each of the two is dropped in turn, with no partner.
pub fn why_names_each_inputs_sync_drops<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let policy = SyncPolicy::Approximate(ApproximateConfig::default().queue_size(2).tolerance(10));
    e.create_trajectory(TrajectorySpec::sync("ab", ["a", "b"], policy)).unwrap();
    let t0 = h.now();
    for k in 0..4 {
        a.add(reading(t0 + 100 * k, 1.0)).unwrap();
    }
    b.add(reading(t0 + 250, 2.0)).unwrap();
    let why = why_when(h, "ab", t0, |w| w.sync.as_ref().is_some_and(|s| s.discarded == 4));
    let sync = why.sync.as_ref().expect("a sync says what it dropped");
    let of = |name: &str| {
        let input = sync.dropped.iter().find(|d| d.input == name);
        input.unwrap_or_else(|| panic!("no drops of `{name}`: {why:#?}")).drops.clone()
    };
    let (from_a, from_b) = (of("a"), of("b"));
    assert_eq!((from_a.queue_full, from_a.no_partner, from_a.total()), (2, 1, 3), "{why:#?}");
    assert_eq!(from_a.last, Some((t0 + 200, SyncDropReason::NoPartner)));
    assert_eq!((from_b.no_partner, from_b.total()), (1, 1), "{why:#?}");
    assert_eq!(from_b.last, Some((t0 + 250, SyncDropReason::NoPartner)));
    let said = "the sync dropped 3 of `a`'s structure(s): 2 pushed out of its full queue, 1 with no partner within the tolerance";
    assert!(says(&why, said), "{:?}", why.reasons);
    assert!(says(&why, "the sync dropped 1 of `b`'s structure(s)"), "{:?}", why.reasons);
}

/// Skipped sample points, each cause made on purpose on the simulated clock and
/// named by `why`: a sensor call that takes 35 ms of a 10 ms period (the clock moves
/// while the sensor is held in its call), then a sampler that wakes 40 ms late with a
/// quick sensor (the clock jumps while it sleeps).
pub fn why_names_missed_sample_points<H: Harness>(h: &H) {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Mutex, mpsc};
    register_reading(h);
    let e = h.esgm();
    let hold = Arc::new(AtomicBool::new(true));
    let (called, was_called) = mpsc::channel::<()>();
    let (go, gone) = mpsc::channel::<()>();
    let (called, gone) = (Mutex::new(called), Mutex::new(gone));
    let held = Arc::clone(&hold);
    let sensor = move |t: Time| -> Result<EntityStructure, SensorError> {
        if held.swap(false, Ordering::SeqCst) {
            let _ = called.lock().map(|c| c.send(()));
            let _ = gone.lock().map(|g| g.recv_timeout(WAIT));
        }
        Ok(reading(t, 1.0))
    };
    e.add_sensor_interface("slow", "Reading", Arc::new(sensor)).unwrap();
    let since = h.now();
    e.create_trajectory(TrajectorySpec::sampled("lagging", "slow", millis(10)).unwrap()).unwrap();
    was_called.recv_timeout(WAIT).expect("the sampler calls the sensor");
    h.advance(millis(35));
    go.send(()).unwrap();
    let why = why_when(h, "lagging", since, |w| !w.missed.is_empty());
    assert_eq!(
        why.missed[0].cause,
        MissCause::SlowCall { took: millis(35), period: millis(10) },
        "{why:#?}"
    );
    assert_eq!(why.missed[0].missed, 2, "{why:#?}");
    let said = "2 sample point(s) were missed since the time asked: its producer's calls took up to 35.0 ms, longer than its 10.0 ms period";
    assert!(says(&why, said), "{:?}", why.reasons);

    // The sampler sleeps until the next sample time; the clock jumps past four.
    let before = why.missed[0].at + 1;
    assert!(wait_for(WAIT, || e
        .get_entity_trajectory_structure("lagging")
        .is_ok_and(|t| t.get_latest().is_ok_and(|s| s.valid_time() == since + millis(30)))));
    h.advance(millis(45));
    let why = why_when(h, "lagging", before, |w| w.missed.len() == 2);
    assert_eq!(
        why.missed[1].cause,
        MissCause::LateWakeUp { late: millis(40), period: millis(10) },
        "{why:#?}"
    );
    let said =
        "4 sample point(s) were missed since the time asked: its sampler woke up to 40.0 ms late";
    assert!(says(&why, said), "{:?}", why.reasons);
    assert!(why.worker.as_ref().is_some_and(|w| w.missed_periods == 6), "{why:#?}");
    // Asked from after the last skip, none are since; the total is still told.
    let quiet = h.reader().why("lagging", why.missed[1].at + 1).unwrap();
    assert!(says(&quiet, "6 sample point(s) were missed since it was made"), "{:?}", quiet.reasons);
}

/// A sampled trajectory whose sensor has no value names its sensor's answers.
pub fn why_names_what_the_sensor_returned<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let blind =
        |_: Time| -> Result<EntityStructure, SensorError> { Err(SensorError::ValueNotAvailable) };
    e.add_sensor_interface("blind", "Reading", Arc::new(blind)).unwrap();
    e.create_trajectory(TrajectorySpec::sampled("dark", "blind", millis(10)).unwrap()).unwrap();
    let since = h.now();
    let why = why_when(h, "dark", since, |w| !w.recent_calls.is_empty());
    assert_eq!(why.recent_calls[0].outcome, CallOutcome::NoValue);
    assert!(says(&why, "returned no value"), "{:?}", why.reasons);
    assert!(matches!(
        h.reader().why("drak", since),
        Err(esgm_core::LookupError::NoSuchEntityStructure { .. })
    ));
}
