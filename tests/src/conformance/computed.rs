//! Computed trajectories (E4, E6 units): input order, ValueNotAvailable, chains,
//! isolation, type checks. Units live with the writer (so their worker statistics
//! are the writer's); their outputs are read through the reader.

use std::sync::Arc;

use esgm_core::{
    ComputeError, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InputType, OrderConstraint, Sample, SubscribeOptions, Time, TrajectorySpec,
    ValueSort,
};

use super::{WAIT, read, reading, register_reading, wait_stored, wait_visible, x_of};
use crate::{Harness, wait_for};

/// A unit that outputs a Reading whose x is the inputs' x values as decimal digits
/// (inputs 1, 2 → 12), valid at the latest input's valid time: it shows input order.
fn digits(inputs: &[Sample], _qtime: Time) -> Result<EntityStructure, ComputeError> {
    let x = inputs.iter().fold(0.0, |acc, s| acc * 10.0 + x_of(s).unwrap_or(0.0));
    let vt = inputs.iter().map(|s| s.valid_time()).max().unwrap_or(0);
    Ok(reading(vt, x))
}

fn worker_stats<H: Harness>(h: &H, name: &str) -> esgm_core::esgm::WorkerStats {
    h.esgm().stats().unwrap().get(name).map(|r| r.worker).unwrap_or_default()
}

/// E4: called on each update of any input with the latest of every input, in input
/// order, once all inputs have one.
pub fn inputs_in_order_once_all_have_one<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("digits", "Reading", vec![ValueSort::EntityFrame.into(); 2], Arc::new(digits))
        .unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let w = e.create_computed_entity_trajectory_structure("ab", "digits", &["a", "b"]).unwrap();
    let out = read(h, "ab");
    let t0 = h.now();
    b.add(reading(t0, 2.0)).unwrap();
    a.add(reading(t0 + 1, 1.0)).unwrap();
    wait_stored(&out, 1);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(12.0), "inputs in declared order");
    assert_eq!(out.get_latest().unwrap().valid_time(), t0 + 1);
    b.add(reading(t0 + 2, 3.0)).unwrap();
    wait_stored(&out, 2);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(13.0));
    wait_visible(&w, &out);
    assert_eq!(worker_stats(h, "ab").calls, 2, "no call before both inputs had a value");
}

/// E4: ValueNotAvailable from the unit means no output.
pub fn value_not_available_means_no_output<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let positive_only = |inputs: &[Sample], q: Time| -> Result<EntityStructure, ComputeError> {
        match x_of(&inputs[0]) {
            Some(x) if x > 0.0 => digits(inputs, q),
            _ => Err(ComputeError::ValueNotAvailable),
        }
    };
    e.add_comp_unit("pos", "Reading", vec!["Reading".into()], Arc::new(positive_only)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let writer = e.create_computed_entity_trajectory_structure("p", "pos", &["a"]).unwrap();
    let out = read(h, "p");
    let t0 = h.now();
    for (k, x) in [-1.0, 5.0, 0.0].into_iter().enumerate() {
        a.add(reading(t0 + k as Time, x)).unwrap();
    }
    assert!(wait_for(WAIT, || worker_stats(h, "p").calls == 3));
    let w = worker_stats(h, "p");
    assert_eq!((w.outputs, w.no_value), (1, 2));
    assert_eq!(writer.stats().unwrap().added, 1);
    wait_visible(&writer, &out);
    assert_eq!(out.stats().unwrap().added, 1);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(5.0));
}

/// The tutorial's three levels: source → detection → selection → decision.
pub fn three_level_chain<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let double = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(reading(i[0].valid_time(), x_of(&i[0]).unwrap_or(0.0) * 2.0))
    };
    e.add_comp_unit("double", "Reading", vec!["Reading".into()], Arc::new(double)).unwrap();
    e.add_comp_unit(
        "digits",
        "Reading",
        vec!["Reading".into(), "Reading".into()],
        Arc::new(digits),
    )
    .unwrap();
    let src = e.create_primitive_entity_trajectory_structure("src", "Reading").unwrap();
    let other = e.create_primitive_entity_trajectory_structure("other", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("l1", "double", &["src"]).unwrap();
    e.create_computed_entity_trajectory_structure("l2", "double", &["l1"]).unwrap();
    e.create_computed_entity_trajectory_structure("l3", "digits", &["other", "l2"]).unwrap();
    let l3 = read(h, "l3");
    let sub = l3.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    other.add(reading(t0, 1.0)).unwrap();
    src.add(reading(t0 + 5, 2.0)).unwrap();
    let s = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((x_of(&s), s.valid_time()), (Some(18.0), t0 + 5), "1 then 2·2·2 = 8");
    // Every level is readable from the reader too.
    for (name, x) in [("l1", 4.0), ("l2", 8.0)] {
        let level = read(h, name);
        let got = || level.get_latest().map(|s| x_of(&s));
        assert!(wait_for(WAIT, || got() == Ok(Some(x))), "{name}: {:?}", got());
    }
}

/// A unit that panics is isolated and counted; the trajectory keeps working.
pub fn unit_panic_is_isolated<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let fragile = |i: &[Sample], q: Time| -> Result<EntityStructure, ComputeError> {
        if x_of(&i[0]) == Some(13.0) {
            panic!("unlucky input");
        }
        digits(i, q)
    };
    e.add_comp_unit("fragile", "Reading", vec!["Reading".into()], Arc::new(fragile)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("f", "fragile", &["a"]).unwrap();
    let out = read(h, "f");
    let t0 = h.now();
    for (k, x) in [1.0, 13.0, 2.0].into_iter().enumerate() {
        a.add(reading(t0 + k as Time, x)).unwrap();
    }
    wait_stored(&out, 2);
    assert_eq!(worker_stats(h, "f").panics, 1);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(2.0));
    assert_eq!(x_of(&out.get_nth_latest(1).unwrap()), Some(1.0));
}

/// A unit's output is type-checked against its declared type.
pub fn unit_output_is_type_checked<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let wrong = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(EntityStructure::new("r", i[0].valid_time(), i[0].valid_time())
            .with("x", "not a number"))
    };
    e.add_comp_unit("wrong", "Reading", vec!["Reading".into()], Arc::new(wrong)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let out = e.create_computed_entity_trajectory_structure("w", "wrong", &["a"]).unwrap();
    let seen = read(h, "w");
    a.add(reading(h.now(), 1.0)).unwrap();
    assert!(wait_for(WAIT, || worker_stats(h, "w").invalid_outputs == 1));
    assert_eq!(out.stats().unwrap().dropped_for(esgm_core::DropCause::InvalidType), 1);
    assert!(out.get_latest().is_err());
    // Nothing of it reaches the reader (the writer refused it before publishing).
    wait_visible(&out, &seen);
    assert!(seen.get_latest().is_err());
    assert_eq!(seen.stats().unwrap().added, 0);
}

/// E6: input count and input types are checked when the trajectory is created, by
/// whichever side creates it (the unit lives with the writer).
pub fn inputs_are_checked_at_creation<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("one", "Reading", vec![InputType::Type("Reading".into())], Arc::new(digits))
        .unwrap();
    e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    e.create_primitive_entity_trajectory_structure("img", "Image").unwrap();
    for side in [e, h.reader()] {
        assert!(matches!(
            side.create_computed_entity_trajectory_structure("x", "one", &["a", "a"]),
            Err(CreateError::WrongInputCount { expected: 1, found: 2, .. })
        ));
        let err =
            side.create_computed_entity_trajectory_structure("x", "one", &["img"]).unwrap_err();
        assert!(matches!(err, CreateError::InvalidInput { position: 0, .. }), "{err}");
        assert_eq!(
            err.to_string(),
            "input 0 (`img`) of `one` has type `Image`, expected type `Reading`"
        );
        assert!(matches!(
            side.create_computed_entity_trajectory_structure("x", "onee", &["a"]),
            Err(CreateError::NoSuchCompUnit { suggestion: Some(_), .. })
        ));
        assert!(matches!(
            side.create_computed_entity_trajectory_structure("x", "one", &["b"]),
            Err(CreateError::NoSuchEntityStructure { .. })
        ));
    }
    assert!(e.get_entity_trajectory_structure("x").is_err(), "nothing was created");
}

/// The reasonable constraints on a computed trajectory: monotone order drops a unit
/// output that goes back in time.
pub fn computed_policy_applies<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("id", "Reading", vec!["Reading".into()], Arc::new(digits)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let policy = FluentStreamPolicy::default().order(OrderConstraint::Monotone);
    let out =
        e.create_trajectory(TrajectorySpec::computed("m", "id", ["a"]).policy(policy)).unwrap();
    let seen = read(h, "m");
    let violations = seen.subscribe_violations(16).unwrap();
    let t0 = h.now();
    for vt in [t0 + 10, t0 + 5, t0 + 20] {
        a.add(reading(vt, 1.0)).unwrap();
    }
    assert!(wait_for(WAIT, || out.stats().map(|s| s.added + s.dropped_total) == Ok(3)));
    assert_eq!(out.stats().unwrap().violations, 1);
    let v = violations.recv_timeout(WAIT).unwrap();
    assert_eq!((v.constraint, v.valid_time), (esgm_core::Constraint::Order, t0 + 5));
    wait_visible(&out, &seen);
    let vts: Vec<Time> =
        seen.get_between(t0, t0 + 20).unwrap().iter().map(|s| s.valid_time()).collect();
    assert_eq!(vts, vec![t0 + 10, t0 + 20]);
    let counted = || seen.stats().map(|s| (s.added, s.violations));
    assert!(wait_for(WAIT, || counted() == Ok((2, 1))), "reader stats {:?}", seen.stats());
}

/// T5/E4: after an input is reset it has no latest sample, so the unit is not called
/// again until that input gets a new one (no pre-reset values mixed in).
pub fn reset_inputs_are_forgotten<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("digits", "Reading", vec![ValueSort::EntityFrame.into(); 2], Arc::new(digits))
        .unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("ab", "digits", &["a", "b"]).unwrap();
    let out = read(h, "ab");
    let a_seen = read(h, "a");
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 1, 2.0)).unwrap();
    wait_stored(&out, 1);
    wait_visible(&a, &a_seen);
    a.reset_blocking().unwrap();
    b.add(reading(t0 + 2, 3.0)).unwrap();
    assert!(
        wait_for(WAIT, || worker_stats(h, "ab").calls == 1 && b.stats().map(|s| s.added) == Ok(2))
    );
    a.add(reading(t0 + 3, 4.0)).unwrap();
    wait_stored(&out, 2);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(43.0), "a's new sample with b's latest");
    assert_eq!(worker_stats(h, "ab").calls, 2, "no call mixed a pre-reset sample in");
    // The reader had a's first sample; after the reset it has only the new one.
    wait_visible(&a, &a_seen);
    assert_eq!(a_seen.get_between(Time::MIN, Time::MAX).unwrap().len(), 1);
}
