//! Operators (G2–G4): sync, merge, generators and states. The operators run with the
//! writer, which creates them; their streams are read through the reader.

use esgm_core::operators::sync::{
    ApproximateConfig, EpsilonConfig, ExactConfig, MEMBER_CREATE_TIMES, MEMBER_VALID_TIMES,
    SyncPolicy,
};
use esgm_core::{
    EntityTrajectoryStructure, Esgm, GeneratorPolicy, MergeRule, SubscribeOptions, TrajectorySpec,
    ValueApproximation, millis,
};

use super::{WAIT, read, reading, register_reading, wait_stored, wait_visible, x_of};
use crate::{Harness, wait_for};

fn frame_x(s: &esgm_core::Sample, input: &str) -> Option<f64> {
    s.get(input).and_then(|v| v.as_frame()).and_then(|f| f.get("x")).and_then(|v| v.as_double())
}

/// G2 exact: a state only for valid times present in every input.
pub fn sync_exact<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let w = e
        .create_trajectory(TrajectorySpec::sync(
            "ab",
            ["a", "b"],
            SyncPolicy::Exact(ExactConfig::default()),
        ))
        .unwrap();
    let s = read(h, "ab");
    let sub = s.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    a.add(reading(t0 + 10, 1.0)).unwrap();
    b.add(reading(t0 + 15, 2.0)).unwrap();
    a.add(reading(t0 + 20, 3.0)).unwrap();
    b.add(reading(t0 + 20, 4.0)).unwrap();
    let state = sub.recv_timeout(WAIT).unwrap();
    assert_eq!(state.valid_time(), t0 + 20);
    assert_eq!((frame_x(&state, "a"), frame_x(&state, "b")), (Some(3.0), Some(4.0)));
    // One frame per input, and the members' times.
    assert_eq!(s.entity_type().unwrap().attributes.len(), 4);
    assert_eq!(s.entity_type().unwrap(), w.entity_type().unwrap(), "the synthesized type");
    wait_visible(&w, &s);
    // a@10 and b@15 never found a partner: counted, not lost silently.
    let discarded = || h.esgm().stats().unwrap().get("ab").map(|r| r.worker.discarded);
    assert!(wait_for(WAIT, || discarded() == Some(2)), "discarded {:?}", discarded());
}

/// G2 approximate: sets as message_filters' ApproximateTime picks them.
pub fn sync_approximate<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let policy = SyncPolicy::Approximate(ApproximateConfig::default());
    e.create_trajectory(TrajectorySpec::sync("ab", ["a", "b"], policy)).unwrap();
    let sub = read(h, "ab").subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    // a every 10, b every 10 offset by 3: pairs (0,3), (10,13), …
    for k in 0..4 {
        a.add(reading(t0 + 10 * k, k as f64)).unwrap();
        b.add(reading(t0 + 10 * k + 3, 10.0 + k as f64)).unwrap();
    }
    let first = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((frame_x(&first, "a"), frame_x(&first, "b")), (Some(0.0), Some(10.0)));
    let second = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((frame_x(&second, "a"), frame_x(&second, "b")), (Some(1.0), Some(11.0)));
    // Which samples were matched: every member's valid and create time, by input.
    assert_eq!(member_times(&second, MEMBER_VALID_TIMES), Some(vec![t0 + 10, t0 + 13]));
    assert_eq!(member_times(&second, MEMBER_CREATE_TIMES), Some(vec![t0 + 10, t0 + 13]));
    assert_eq!(second.valid_time(), t0 + 13, "a set is valid at its latest member's time");
}

fn member_times(s: &esgm_core::Sample, attr: &str) -> Option<Vec<esgm_core::Time>> {
    s.get(attr)?.as_long_seq().map(|v| v.into_owned())
}

/// G2 epsilon (message_filters' ApproximateEpsilonTime): a set leaves as soon as every
/// input has a head within the tolerance of the oldest; an oldest head no input can
/// match goes, counted. The output keeps each member's times.
pub fn sync_epsilon<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let policy = SyncPolicy::Epsilon(EpsilonConfig::default().tolerance(5));
    e.create_trajectory(TrajectorySpec::sync("ab", ["a", "b"], policy)).unwrap();
    let s = read(h, "ab");
    let sub = s.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 4, 2.0)).unwrap(); // within 5 of a@0: out at once
    let first = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((frame_x(&first, "a"), frame_x(&first, "b")), (Some(1.0), Some(2.0)));
    assert_eq!(member_times(&first, MEMBER_VALID_TIMES), Some(vec![t0, t0 + 4]));
    a.add(reading(t0 + 10, 3.0)).unwrap();
    b.add(reading(t0 + 30, 4.0)).unwrap(); // a@10 has no partner: dropped
    a.add(reading(t0 + 27, 5.0)).unwrap(); // within 5 of b@30
    let second = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((frame_x(&second, "a"), frame_x(&second, "b")), (Some(5.0), Some(4.0)));
    assert_eq!(member_times(&second, MEMBER_VALID_TIMES), Some(vec![t0 + 27, t0 + 30]));
    let discarded = || h.esgm().stats().unwrap().get("ab").map(|r| r.worker.discarded);
    assert!(wait_for(WAIT, || discarded() == Some(1)), "discarded {:?}", discarded());
    // A negative tolerance is refused when the trajectory is created, on either side.
    for side in [e, h.reader()] {
        let bad = SyncPolicy::Epsilon(EpsilonConfig::default().tolerance(-1));
        assert!(side.create_trajectory(TrajectorySpec::sync("bad", ["a", "b"], bad)).is_err());
    }
}

/// G3: every sample of every input, in arrival order.
pub fn merge_interleaves_inputs<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    e.create_primitive_entity_trajectory_structure("img", "Image").unwrap();
    e.create_trajectory(TrajectorySpec::merge("m", ["a", "b"])).unwrap();
    let m = read(h, "m");
    let t0 = h.now();
    a.add(reading(t0, 1.0)).unwrap();
    b.add(reading(t0 + 1, 2.0)).unwrap();
    a.add(reading(t0 + 2, 3.0)).unwrap();
    wait_stored(&m, 3);
    let all: Vec<_> = m.get_between(t0, t0 + 2).unwrap().iter().map(|s| x_of(s)).collect();
    assert_eq!(all, vec![Some(1.0), Some(2.0), Some(3.0)]);
    for side in [e, h.reader()] {
        assert!(
            side.create_trajectory(TrajectorySpec::merge("bad", ["a", "img"])).is_err(),
            "types differ"
        );
    }
}

/// G3 under a burst: interleaved adds on two inputs reach a monotone merge in add
/// order, so none is an order violation.
pub fn merge_keeps_add_order_across_inputs<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let policy =
        esgm_core::FluentStreamPolicy::default().order(esgm_core::OrderConstraint::StrictMonotone);
    let w = e.create_trajectory(TrajectorySpec::merge("m", ["a", "b"]).policy(policy)).unwrap();
    let m = read(h, "m");
    let t0 = h.now();
    let n = 500; // within the input buffer (1,024): nothing may be discarded
    for k in 0..n {
        let target = if k % 2 == 0 { &a } else { &b };
        target.add(reading(t0 + k, k as f64)).unwrap();
    }
    assert!(wait_for(WAIT, || w.stats().map(|s| s.added + s.dropped_total) == Ok(n as u64)));
    assert_eq!(w.stats().unwrap().dropped_total, 0, "every sample in add order");
    let all = || m.stats().map(|s| (s.added, s.dropped_total));
    assert!(wait_for(WAIT, || all() == Ok((n as u64, 0))), "reader stats {:?}", m.stats());
    wait_visible(&w, &m);
}

/// G1/G4: a stream sampled from a generator (values at each sample time, linearly
/// interpolated), and a state of two generators.
pub fn sampled_generator_and_state<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let t0 = h.now();
    a.add(reading(t0, 0.0)).unwrap();
    a.add(reading(t0 + millis(100), 10.0)).unwrap();
    b.add(reading(t0, 5.0)).unwrap();
    let linear =
        GeneratorPolicy { approximation: ValueApproximation::Linear, merge: MergeRule::KeepLast };
    let recent = GeneratorPolicy {
        approximation: ValueApproximation::MostRecent,
        merge: MergeRule::KeepLast,
    };
    e.create_trajectory(
        TrajectorySpec::sampled_generators("ga", [("a", linear.clone())], millis(25))
            .between(t0, t0 + millis(100)),
    )
    .unwrap();
    e.create_trajectory(
        TrajectorySpec::sampled_generators("state", [("a", linear), ("b", recent)], millis(50))
            .between(t0, t0 + millis(100)),
    )
    .unwrap();
    let (g, st) = (read(h, "ga"), read(h, "state"));
    // Both samplers tick at t0 first; advancing before they have would make them skip a
    // period (as a real late worker does).
    wait_stored(&g, 1);
    wait_stored(&st, 1);
    for k in 1..=4 {
        h.advance(millis(25));
        assert!(wait_for(WAIT, || g.stats().map(|s| s.added) == Ok(k + 1)), "generator sample {k}");
    }
    let xs: Vec<_> = g.get_between(t0, t0 + millis(100)).unwrap().iter().map(|s| x_of(s)).collect();
    assert_eq!(xs, vec![Some(0.0), Some(2.5), Some(5.0), Some(7.5), Some(10.0)]);
    wait_stored(&st, 3);
    let mid = st.get_at(t0 + millis(50)).unwrap();
    assert_eq!((frame_x(&mid, "a"), frame_x(&mid, "b")), (Some(5.0), Some(5.0)));
}

/// A unit's temporal function (`compute_at`) sampled over generators: the seed's
/// `feature(l, f(s1..sn))` as a stream, with E6's optional `compute_at`.
pub fn sampled_temporal_function<H: Harness>(h: &H) {
    use std::sync::Arc;

    use esgm_core::{CompUnit, ComputeError, EntityStructure, Sample, Time};

    /// Sums the inputs' x at exactly `t`.
    struct Sum;
    impl CompUnit for Sum {
        fn compute(&self, _: &[Sample], _: Time) -> Result<EntityStructure, ComputeError> {
            Err(ComputeError::OperationNotSupported)
        }
        fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
            Ok(reading(t, inputs.iter().filter_map(|s| x_of(s)).sum()))
        }
    }
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("sum", "Reading", vec!["Reading".into(), "Reading".into()], Arc::new(Sum))
        .unwrap();
    let only_compute = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok(i[0].structure.to_structure())
    };
    e.add_comp_unit(
        "plain",
        "Reading",
        vec!["Reading".into(), "Reading".into()],
        Arc::new(only_compute),
    )
    .unwrap();
    let a = e.create_primitive_entity_trajectory_structure("a", "Reading").unwrap();
    let b = e.create_primitive_entity_trajectory_structure("b", "Reading").unwrap();
    let t0 = h.now();
    a.add(reading(t0, 0.0)).unwrap();
    a.add(reading(t0 + millis(100), 10.0)).unwrap();
    b.add(reading(t0, 5.0)).unwrap();
    let linear =
        GeneratorPolicy { approximation: ValueApproximation::Linear, merge: MergeRule::KeepLast };
    let recent = GeneratorPolicy {
        approximation: ValueApproximation::MostRecent,
        merge: MergeRule::KeepLast,
    };
    e.create_trajectory(
        TrajectorySpec::sampled_function(
            "f",
            "sum",
            [("a", linear.clone()), ("b", recent.clone())],
            millis(50),
        )
        .between(t0, t0 + millis(100)),
    )
    .unwrap();
    let f = read(h, "f");
    let g = e
        .create_trajectory(
            TrajectorySpec::sampled_function(
                "g",
                "plain",
                [("a", linear), ("b", recent)],
                millis(50),
            )
            .between(t0, t0 + millis(100)),
        )
        .unwrap();
    // A unit without compute_at: every tick is a counted failure, nothing is stored.
    let failures = || e.stats().unwrap().get("g").map(|r| r.worker.failures);
    // Both samplers must take each tick before the clock moves on (a late sampler
    // skips a period, as it should).
    wait_stored(&f, 1);
    assert!(wait_for(WAIT, || failures() == Some(1)), "{:?}", failures());
    for k in 1..=2 {
        h.advance(millis(50));
        wait_stored(&f, k + 1);
        assert!(wait_for(WAIT, || failures() == Some(k as u64 + 1)), "{:?}", failures());
    }
    let xs: Vec<_> = f.get_between(t0, t0 + millis(100)).unwrap().iter().map(|s| x_of(s)).collect();
    assert_eq!(xs, vec![Some(5.0), Some(10.0), Some(15.0)]);
    assert!(g.get_latest().is_err());
    let g_seen = read(h, "g");
    wait_visible(&g, &g_seen);
    assert!(g_seen.get_latest().is_err());
    assert!(matches!(e.remove_comp_unit("sum"), Err(esgm_core::RegistrationError::InUse { .. })));
}

/// G1: an average or median merge over a type with an attribute that has no mean or
/// median (a string) is refused when the generator is created, on either side, with
/// an error naming the attribute; keep-last takes it, and numbers and geometric
/// values take an average.
pub fn merge_rules_are_checked_against_the_type<H: Harness>(h: &H) {
    let e = h.esgm();
    e.create_type(
        esgm_core::EntityStructureType::new("Tagged")
            .attr("x", esgm_core::ValueSort::Double)
            .attr("label", esgm_core::ValueSort::String),
    )
    .unwrap();
    e.create_primitive_entity_trajectory_structure("t", "Tagged").unwrap();
    e.create_primitive_entity_trajectory_structure("pose", "RobotState").unwrap();
    let policy = |merge| GeneratorPolicy { approximation: ValueApproximation::MostRecent, merge };
    for side in [e, h.reader()] {
        for rule in [MergeRule::Average, MergeRule::Median] {
            let spec = TrajectorySpec::sampled_generators("g", [("t", policy(rule))], millis(10));
            let err = side.create_trajectory(spec).unwrap_err().to_string();
            assert!(err.contains("`label`") && err.contains("String"), "{err}");
        }
    }
    let spec =
        TrajectorySpec::sampled_generators("g", [("t", policy(MergeRule::KeepLast))], millis(10));
    e.create_trajectory(spec).unwrap();
    let spec =
        TrajectorySpec::sampled_generators("p", [("pose", policy(MergeRule::Median))], millis(10));
    e.create_trajectory(spec).unwrap();
}
