//! Types (E1) and primitive trajectories (E2, T1–T5, C7).

use esgm_core::{
    AddError, AddOutcome, Constraint, EntityStructureType, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, OrderConstraint, QueryError, SubscribeOptions, TrajectorySpec,
    TypeRegistryError, ValueApproximation, ValueSort, millis,
};

use super::{WAIT, reading, register_reading, wait_stored, x_of};
use crate::Harness;

/// E1 with the seed's errors.
pub fn types_create_get_destroy<H: Harness>(h: &H) {
    let e = h.esgm();
    let t = EntityStructureType::new("BlobType").attr("x", ValueSort::Long);
    e.create_entity_structure_type("blob", t.clone()).unwrap();
    assert_eq!(e.get_entity_structure_type("blob").unwrap(), t);
    assert!(matches!(
        e.create_entity_structure_type("blob", t.clone()),
        Err(TypeRegistryError::EntityStructureTypeAlreadyExists { .. })
    ));
    e.destroy_entity_structure_type("blob").unwrap();
    let err = e.get_entity_structure_type("blob").unwrap_err();
    assert!(matches!(err, TypeRegistryError::NoSuchEntityStructureType { .. }));
    assert!(e.entity_structure_type_names().contains(&"Image".to_owned()), "library types present");
}

/// E2 + T1/T2 through a handle.
pub fn primitive_add_and_query<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let t = e.create_primitive_entity_trajectory_structure("readings", "Reading").unwrap();
    assert!(matches!(t.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    let t0 = h.now();
    for (i, dt) in [0, 100, 200].into_iter().enumerate() {
        t.add(reading(t0 + millis(dt), i as f64)).unwrap();
    }
    t.create_at("r", t0 + millis(300), reading(0, 3.0).attributes.into()).unwrap();
    let latest = t.get_latest().unwrap();
    assert_eq!((latest.valid_time, x_of(&latest)), (t0 + millis(300), Some(3.0)));
    assert_eq!(x_of(&t.get_nth_latest(3).unwrap()), Some(0.0));
    assert_eq!(t.get_between(t0 + millis(50), t0 + millis(250)).unwrap().len(), 2);
    assert_eq!(x_of(&t.get_at(t0 + millis(100)).unwrap()), Some(1.0));
    assert_eq!(x_of(&t.get_closest_at_or_before(t0 + millis(150)).unwrap()), Some(1.0));
    let lin = t.get_at_approximating(t0 + millis(150), &ValueApproximation::Linear).unwrap();
    assert_eq!(x_of(&lin), Some(1.5));
    assert_eq!(t.start_time().unwrap(), t0);
    assert_eq!(t.end_time().unwrap(), t0 + millis(300));
    assert_eq!(t.entity_type().unwrap().name, "Reading");
    assert_eq!(e.get_entity_trajectory_structure_type("readings").unwrap().name, "Reading");
    t.reset_blocking().unwrap();
    assert!(matches!(t.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
}

/// The richer constructor: a primitive trajectory with the seed's reasonable policy.
pub fn primitive_policy_is_enforced<H: Harness>(h: &H) {
    register_reading(h);
    let policy =
        FluentStreamPolicy::reasonable(0, 2).unwrap().order(OrderConstraint::StrictMonotone);
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let t0 = h.now();
    for k in 0..4 {
        t.add(reading(t0 + k, k as f64)).unwrap();
    }
    wait_stored(&t, 2);
    let err = t.add_blocking(reading(t0, 9.0)).unwrap_err();
    assert!(matches!(err, AddError::PolicyViolation(v) if v.constraint == Constraint::Order));
    let bad = reading(t0 + 10, 1.0).with("n", "text");
    assert!(matches!(t.add(bad), Err(AddError::InvalidType { .. })));
    let st = t.stats().unwrap();
    assert_eq!((st.added, st.evicted, st.dropped_total), (4, 2, 2));
}

/// T3: later adds in add order, a replay of the last N, unsubscribe ends it.
pub fn subscriptions_in_add_order_with_replay<H: Harness>(h: &H) {
    register_reading(h);
    let t = h.esgm().create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let t0 = h.now();
    for k in 0..3 {
        t.add(reading(t0 + k, k as f64)).unwrap();
    }
    let late = t.subscribe(SubscribeOptions::default().last(1)).unwrap();
    for k in [5, 4] {
        t.add(reading(t0 + k, k as f64)).unwrap();
    }
    let got: Vec<_> = (0..3).map(|_| late.recv_timeout(WAIT).map(|s| x_of(&s))).collect();
    assert_eq!(got, vec![Ok(Some(2.0)), Ok(Some(5.0)), Ok(Some(4.0))]);
    t.unsubscribe(late.id()).unwrap();
    t.add(reading(t0 + 9, 9.0)).unwrap();
    assert_eq!(
        late.recv_timeout(std::time::Duration::from_millis(50)).map(|s| s.valid_time),
        Err(esgm_core::store::RecvError::Closed)
    );
}

/// C7/T4: non-blocking adds drop, count and notify.
pub fn violations_are_delivered_and_counted<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::default().order(OrderConstraint::Monotone).filter("x >= 0.0");
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let v = t.subscribe_violations(16).unwrap();
    let t0 = h.now();
    t.add(reading(t0 + 10, 1.0)).unwrap();
    assert!(matches!(t.add(reading(t0 + 5, 1.0)), Ok(AddOutcome::Dropped(_))));
    assert!(matches!(t.add(reading(t0 + 20, -1.0)), Ok(AddOutcome::Dropped(_))));
    let a = v.recv_timeout(WAIT).unwrap();
    let b = v.recv_timeout(WAIT).unwrap();
    assert_eq!((a.constraint, b.constraint), (Constraint::Order, Constraint::Filter));
    let st = t.stats().unwrap();
    assert_eq!((st.added, st.violations), (1, 2));
}

/// C6: the runtime releases held samples when their window passes, with no further add.
pub fn held_samples_are_released_on_time<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::reasonable(millis(100), 0).unwrap();
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let sub = t.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    assert!(matches!(t.add(reading(t0, 2.0)), Ok(AddOutcome::Held { .. })));
    assert!(matches!(t.add(reading(t0 - millis(50), 1.0)), Ok(AddOutcome::Held { .. })));
    h.advance(millis(100));
    let first = sub.recv_timeout(WAIT).unwrap();
    let second = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((x_of(&first), x_of(&second)), (Some(1.0), Some(2.0)), "valid-time order");
}
