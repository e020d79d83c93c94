//! Computed trajectories (E4, E6 units): input order, ValueNotAvailable, chains,
//! isolation, type checks.

use std::sync::Arc;

use esgm_core::{
    ComputeError, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InputType, OrderConstraint, Sample, SubscribeOptions, Time, TrajectorySpec,
    ValueSort,
};

use super::{WAIT, reading, register_reading, wait_stored, x_of};
use crate::{Harness, wait_for};

/// A unit that outputs a Reading whose x is the inputs' x values as decimal digits
/// (inputs 1, 2 → 12), valid at the latest input's valid time: it shows input order.
fn digits(inputs: &[Sample], _qtime: Time) -> Result<EntityStructure, ComputeError> {
    let x = inputs.iter().fold(0.0, |acc, s| acc * 10.0 + x_of(s).unwrap_or(0.0));
    let vt = inputs.iter().map(|s| s.valid_time).max().unwrap_or(0);
    Ok(reading(vt, x))
}

fn worker_stats<H: Harness>(h: &H, name: &str) -> esgm_core::esgm::WorkerStats {
    h.esgm()
        .stats()
        .trajectories
        .into_iter()
        .find(|(i, _, _)| i.name == name)
        .map(|(_, _, w)| w)
        .unwrap_or_default()
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
    let out = e.create_computed_entity_trajectory_structure("ab", "digits", &["a", "b"]).unwrap();
    let t0 = h.now();
    b.add(reading(t0, 2.0)).unwrap();
    a.add(reading(t0 + 1, 1.0)).unwrap();
    wait_stored(&out, 1);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(12.0), "inputs in declared order");
    b.add(reading(t0 + 2, 3.0)).unwrap();
    wait_stored(&out, 2);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(13.0));
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
    let out = e.create_computed_entity_trajectory_structure("p", "pos", &["a"]).unwrap();
    let t0 = h.now();
    for (k, x) in [-1.0, 5.0, 0.0].into_iter().enumerate() {
        a.add(reading(t0 + k as Time, x)).unwrap();
    }
    assert!(wait_for(WAIT, || worker_stats(h, "p").calls == 3));
    let w = worker_stats(h, "p");
    assert_eq!((w.outputs, w.no_value), (1, 2));
    assert_eq!(out.stats().unwrap().added, 1);
}

/// The tutorial's three levels: source → detection → selection → decision.
pub fn three_level_chain<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let double = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(reading(i[0].valid_time, x_of(&i[0]).unwrap_or(0.0) * 2.0))
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
    let l3 =
        e.create_computed_entity_trajectory_structure("l3", "digits", &["other", "l2"]).unwrap();
    let sub = l3.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    other.add(reading(t0, 1.0)).unwrap();
    src.add(reading(t0 + 5, 2.0)).unwrap();
    let s = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((x_of(&s), s.valid_time), (Some(18.0), t0 + 5), "1 then 2·2·2 = 8");
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
    let out = e.create_computed_entity_trajectory_structure("f", "fragile", &["a"]).unwrap();
    let t0 = h.now();
    for (k, x) in [1.0, 13.0, 2.0].into_iter().enumerate() {
        a.add(reading(t0 + k as Time, x)).unwrap();
    }
    wait_stored(&out, 2);
    assert_eq!(worker_stats(h, "f").panics, 1);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(2.0));
}

/// A unit's output is type-checked against its declared type.
pub fn unit_output_is_type_checked<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let wrong = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(EntityStructure::new("r", i[0].valid_time, i[0].valid_time).with("x", "not a number"))
    };
    e.add_comp_unit("wrong", "Reading", vec!["Reading".into()], Arc::new(wrong)).unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let out = e.create_computed_entity_trajectory_structure("w", "wrong", &["a"]).unwrap();
    a.add(reading(h.now(), 1.0)).unwrap();
    assert!(wait_for(WAIT, || worker_stats(h, "w").invalid_outputs == 1));
    assert_eq!(out.stats().unwrap().dropped_for(esgm_core::DropCause::InvalidType), 1);
    assert!(out.get_latest().is_err());
}

/// E6: input count and input types are checked when the trajectory is created.
pub fn inputs_are_checked_at_creation<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("one", "Reading", vec![InputType::Type("Reading".into())], Arc::new(digits))
        .unwrap();
    e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    e.create_primitive_entity_trajectory_structure("img", "Image").unwrap();
    assert!(matches!(
        e.create_computed_entity_trajectory_structure("x", "one", &["a", "a"]),
        Err(CreateError::WrongInputCount { expected: 1, found: 2, .. })
    ));
    let err = e.create_computed_entity_trajectory_structure("x", "one", &["img"]).unwrap_err();
    assert!(matches!(err, CreateError::InvalidInput { position: 0, .. }), "{err}");
    assert_eq!(
        err.to_string(),
        "input 0 (`img`) of `one` has type `Image`, expected type `Reading`"
    );
    assert!(matches!(
        e.create_computed_entity_trajectory_structure("x", "onee", &["a"]),
        Err(CreateError::NoSuchCompUnit { suggestion: Some(_), .. })
    ));
    assert!(matches!(
        e.create_computed_entity_trajectory_structure("x", "one", &["b"]),
        Err(CreateError::NoSuchEntityStructure { .. })
    ));
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
    let t0 = h.now();
    for vt in [t0 + 10, t0 + 5, t0 + 20] {
        a.add(reading(vt, 1.0)).unwrap();
    }
    assert!(wait_for(WAIT, || out.stats().map(|s| s.added + s.dropped_total) == Ok(3)));
    assert_eq!(out.stats().unwrap().violations, 1);
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
    let out = e.create_computed_entity_trajectory_structure("ab", "digits", &["a", "b"]).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 1, 2.0)).unwrap();
    wait_stored(&out, 1);
    a.reset_blocking().unwrap();
    b.add(reading(t0 + 2, 3.0)).unwrap();
    assert!(
        wait_for(WAIT, || worker_stats(h, "ab").calls == 1 && b.stats().map(|s| s.added) == Ok(2))
    );
    a.add(reading(t0 + 3, 4.0)).unwrap();
    wait_stored(&out, 2);
    assert_eq!(x_of(&out.get_latest().unwrap()), Some(43.0), "a's new sample with b's latest");
    assert_eq!(worker_stats(h, "ab").calls, 2, "no call mixed a pre-reset sample in");
}
