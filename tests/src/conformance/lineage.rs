//! Lineage (X1): every structure a computed, sync, merge or generated trajectory adds
//! names the input structures it was made from, read through the reader (across the
//! process boundary on the shared-memory runtime), and a trace follows it back to the
//! pushed structures.

use std::sync::Arc;

use esgm_core::esgm::{Found, trace};
use esgm_core::operators::sync::{ExactConfig, SyncPolicy};
use esgm_core::{
    ComputeError, EntityStructure, EntityTrajectoryStructure, Esgm, GeneratorPolicy, InputRef,
    MergeRule, Sample, SubscribeOptions, Time, TrajectorySpec, ValueApproximation, millis,
};

use super::{WAIT, read, reading, register_reading, wait_stored, x_of};
use crate::{Harness, wait_for};

/// The (trajectory, valid time, add time) of each input `sample`'s lineage names.
fn named(sample: &Sample) -> Vec<(String, Time, Time)> {
    let lineage = sample.lineage.as_ref().expect("a produced structure has lineage");
    lineage.inputs.iter().map(|i| (i.trajectory.clone(), i.valid_time, i.add_time)).collect()
}

/// The writer's stored structure of `name` valid at `vt`, as (name, vt, add time).
fn stored<H: Harness>(h: &H, name: &str, vt: Time) -> (String, Time, Time) {
    let t = h.esgm().get_entity_trajectory_structure(name).unwrap();
    let s = t.get_at(vt).unwrap_or_else(|e| panic!("{name} at {vt}: {e}"));
    (name.to_owned(), s.valid_time(), s.add_time)
}

/// A three-stage pipeline: two pushed inputs, a unit over both, a unit over that. The
/// last output names the middle one, the middle one names the pushed ones, and a trace
/// from the reader finds all of them, with each hop's time.
pub fn a_three_stage_pipeline_names_its_inputs<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let sum = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        let vt = i.iter().map(|s| s.valid_time()).max().unwrap_or(0);
        Ok(reading(vt, i.iter().filter_map(|s| x_of(s)).sum()))
    };
    for (unit, inputs) in [("sum2", 2), ("sum1", 1)] {
        let types = vec!["Reading".into(); inputs];
        e.add_comp_unit(unit, "Reading", types, Arc::new(sum)).unwrap();
    }
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("mid", "sum2", &["a", "b"]).unwrap();
    e.create_computed_entity_trajectory_structure("out", "sum1", &["mid"]).unwrap();
    let out = read(h, "out");
    let sub = out.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 5, 2.0)).unwrap();
    let delivered = sub.recv_timeout(WAIT).unwrap();
    assert_eq!(x_of(&delivered), Some(3.0));
    // Delivered and queried alike.
    let latest = out.get_latest().unwrap();
    assert_eq!(named(&delivered), named(&latest));
    assert_eq!(named(&latest), vec![stored(h, "mid", t0 + 5)]);
    let lineage = latest.lineage.as_ref().unwrap();
    assert!(!lineage.complete, "a unit may read more than its inputs: it says so");
    let mid = read(h, "mid");
    wait_stored(&mid, 1);
    let mid_latest = mid.get_latest().unwrap();
    assert_eq!(named(&mid_latest), vec![stored(h, "a", t0), stored(h, "b", t0 + 5)]);
    // Pushed structures are where a trace ends.
    assert!(read(h, "a").get_latest().unwrap().lineage.is_none());

    let tree = trace(h.reader(), "out", &latest);
    let walked: Vec<_> = tree
        .walk()
        .into_iter()
        .map(|(depth, n)| (depth, n.trajectory.as_str(), n.valid_time, n.found))
        .collect();
    assert_eq!(
        walked,
        vec![
            (0, "out", t0 + 5, Found::Stored),
            (1, "mid", t0 + 5, Found::Stored),
            (2, "a", t0, Found::Stored),
            (2, "b", t0 + 5, Found::Stored),
        ]
    );
    let sources: Vec<_> = tree.sources().iter().map(|n| n.trajectory.clone()).collect();
    assert_eq!(sources, ["a", "b"]);
    // Each hop's time is its add time minus its last input's.
    let hop = tree.hop.expect("out has inputs");
    assert_eq!(hop, latest.add_time - mid_latest.add_time);
    assert!(hop >= 0);
}

/// Syncs name the members of each set, merges the one input each structure came from,
/// and generators the stored samples a value was taken or interpolated from.
pub fn operators_name_their_inputs<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    e.create_trajectory(TrajectorySpec::sync(
        "ab",
        ["a", "b"],
        SyncPolicy::Exact(ExactConfig::default()),
    ))
    .unwrap();
    e.create_trajectory(TrajectorySpec::merge("m", ["a", "b"])).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 0.0)).unwrap();
    b.add(reading(t0, 5.0)).unwrap();
    a.add(reading(t0 + millis(100), 10.0)).unwrap();
    let linear =
        GeneratorPolicy { approximation: ValueApproximation::Linear, merge: MergeRule::KeepLast };
    e.create_trajectory(
        TrajectorySpec::sampled_generators("ga", [("a", linear)], millis(50))
            .between(t0, t0 + millis(100)),
    )
    .unwrap();

    let ab = read(h, "ab");
    wait_stored(&ab, 1);
    let state = ab.get_latest().unwrap();
    assert_eq!(named(&state), vec![stored(h, "a", t0), stored(h, "b", t0)]);
    assert!(state.lineage.as_ref().unwrap().complete);

    let m = read(h, "m");
    wait_stored(&m, 3);
    let merged: Vec<_> = m.get_between(Time::MIN, Time::MAX).unwrap().iter().map(named).collect();
    assert_eq!(
        merged,
        vec![
            vec![stored(h, "a", t0)],
            vec![stored(h, "b", t0)],
            vec![stored(h, "a", t0 + millis(100))],
        ]
    );

    let ga = read(h, "ga");
    wait_stored(&ga, 1);
    h.advance(millis(50));
    assert!(
        wait_for(WAIT, || ga.stats().map(|s| s.added) == Ok(2)),
        "the generator's second value"
    );
    let mid = ga.get_at(t0 + millis(50)).unwrap();
    assert_eq!(x_of(&mid), Some(5.0));
    assert_eq!(
        named(&mid),
        vec![stored(h, "a", t0), stored(h, "a", t0 + millis(100))],
        "interpolated between the samples on both sides"
    );
    let first = ga.get_at(t0).unwrap();
    assert_eq!(named(&first), vec![stored(h, "a", t0)], "taken from the sample at t");
}

/// A trace says which inputs are gone: a structure its trajectory's cache evicted, and
/// a trajectory destroyed since.
pub fn a_trace_names_what_is_gone<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let copy = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(reading(i[0].valid_time(), x_of(&i[0]).unwrap_or(0.0)))
    };
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    let policy = esgm_core::FluentStreamPolicy {
        cache: esgm_core::CacheConstraint::Elements(1),
        ..Default::default()
    };
    let a = e.create_trajectory(TrajectorySpec::primitive("a", "Reading").policy(policy)).unwrap();
    e.create_computed_entity_trajectory_structure("c", "copy", &["a"]).unwrap();
    let c = read(h, "c");
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    a.add(reading(t0 + 1, 2.0)).unwrap();
    wait_stored(&c, 2);
    let first = c.get_at(t0).unwrap();
    let input: &InputRef = &first.lineage.as_ref().unwrap().inputs[0];
    assert_eq!((input.trajectory.as_str(), input.valid_time), ("a", t0));
    let evicted = trace(h.reader(), "c", &first);
    assert_eq!(evicted.inputs[0].found, Found::Evicted, "a keeps only its last structure");
    let latest = c.get_latest().unwrap();
    assert_eq!(trace(h.reader(), "c", &latest).inputs[0].found, Found::Stored);
    e.destroy_entity_trajectory_structure("c").unwrap();
    e.destroy_entity_trajectory_structure("a").unwrap();
    let gone = || trace(h.reader(), "c", &latest).inputs[0].found == Found::NoTrajectory;
    assert!(wait_for(WAIT, gone), "a destroyed input is named as such");
}
