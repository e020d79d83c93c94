//! Types (E1) and primitive trajectories (E2, T1–T5, C7): written through the
//! harness's writer, read through its reader.

use esgm_core::{
    AddError, AddOutcome, Constraint, DropCause, EntityStructureType, EntityTrajectoryStructure,
    Esgm, FluentStreamPolicy, OrderConstraint, QueryError, SubscribeOptions, TrajectorySpec,
    TypeRegistryError, ValueApproximation, ValueSort, millis,
};

use super::{WAIT, contents, read, reading, register_reading, wait_stored, wait_visible, x_of};
use crate::{Harness, wait_for};

/// The `x` of every stored sample, oldest first.
fn xs<T: EntityTrajectoryStructure>(t: &T) -> Vec<Option<f64>> {
    contents(t)
        .unwrap()
        .iter()
        .map(|(_, es)| es.get("x").and_then(esgm_core::Value::as_double))
        .collect()
}

/// E1 with the seed's errors; types are system-wide, so what one side registers or
/// destroys the other sees at once.
pub fn types_create_get_destroy<H: Harness>(h: &H) {
    let (e, r) = (h.esgm(), h.reader());
    let t = EntityStructureType::new("BlobType").attr("x", ValueSort::Long);
    e.create_entity_structure_type("blob", t.clone()).unwrap();
    for side in [e, r] {
        assert_eq!(side.get_entity_structure_type("blob").unwrap(), t);
        assert!(side.entity_structure_type_names().unwrap().contains(&"blob".to_owned()));
        assert!(matches!(
            side.create_entity_structure_type("blob", t.clone()),
            Err(TypeRegistryError::EntityStructureTypeAlreadyExists { .. })
        ));
    }
    e.destroy_entity_structure_type("blob").unwrap();
    for side in [e, r] {
        let err = side.get_entity_structure_type("blob").unwrap_err();
        assert!(matches!(err, TypeRegistryError::NoSuchEntityStructureType { .. }));
        assert!(
            side.entity_structure_type_names().unwrap().contains(&"Image".to_owned()),
            "library types present"
        );
    }
    // The other way round: registered and destroyed by the reader, seen by the writer.
    let u = EntityStructureType::new("Pose").attr("theta", ValueSort::Double);
    r.create_entity_structure_type("pose", u.clone()).unwrap();
    assert_eq!(e.get_entity_structure_type("pose").unwrap(), u);
    r.destroy_entity_structure_type("pose").unwrap();
    assert!(matches!(
        e.get_entity_structure_type("pose"),
        Err(TypeRegistryError::NoSuchEntityStructureType { .. })
    ));
}

/// E2 + T1/T2: what the writer adds, the reader queries; a reset empties both.
pub fn primitive_add_and_query<H: Harness>(h: &H) {
    register_reading(h);
    let w = h.esgm().create_primitive_entity_trajectory_structure("readings", "Reading").unwrap();
    let t = read(h, "readings");
    assert!(matches!(t.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    let t0 = h.now();
    for (i, dt) in [0, 100, 200].into_iter().enumerate() {
        w.add(reading(t0 + millis(dt), i as f64)).unwrap();
    }
    w.create_at("r", t0 + millis(300), reading(0, 3.0).attributes.into()).unwrap();
    wait_visible(&w, &t);
    let latest = t.get_latest().unwrap();
    assert_eq!((latest.valid_time(), x_of(&latest)), (t0 + millis(300), Some(3.0)));
    assert_eq!(latest.add_time, w.get_latest().unwrap().add_time, "the writer's add time");
    assert_eq!(x_of(&t.get_nth_latest(3).unwrap()), Some(0.0));
    assert_eq!(t.get_between(t0 + millis(50), t0 + millis(250)).unwrap().len(), 2);
    assert_eq!(x_of(&t.get_at(t0 + millis(100)).unwrap()), Some(1.0));
    assert_eq!(x_of(&t.get_closest_at_or_before(t0 + millis(150)).unwrap()), Some(1.0));
    let lin = t.get_at_approximating(t0 + millis(150), &ValueApproximation::Linear).unwrap();
    assert_eq!(x_of(&lin), Some(1.5));
    let recent = t.get_at_approximating(t0 + millis(150), &ValueApproximation::MostRecent);
    assert_eq!(x_of(&recent.unwrap()), Some(1.0));
    assert_eq!(t.start_time().unwrap(), t0);
    assert_eq!(t.end_time().unwrap(), t0 + millis(300));
    assert_eq!(t.entity_type().unwrap().name, "Reading");
    assert_eq!(t.policy().unwrap(), w.policy().unwrap());
    assert_eq!(
        h.reader().get_entity_trajectory_structure_type("readings").unwrap().name,
        "Reading"
    );
    w.reset_blocking().unwrap();
    assert!(matches!(w.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
    // The reader had all four samples; an empty replica is the reset arriving.
    wait_visible(&w, &t);
    assert!(matches!(t.get_latest(), Err(QueryError::ValueNotAvailable { .. })));
}

/// The richer constructor: a primitive trajectory with the seed's reasonable policy.
/// The blocking add's PolicyViolation and the type error are the writer's own
/// outcomes; the reader sees the stream the gate let through, and the violation.
pub fn primitive_policy_is_enforced<H: Harness>(h: &H) {
    register_reading(h);
    let policy =
        FluentStreamPolicy::reasonable(0, 2).unwrap().order(OrderConstraint::StrictMonotone);
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "r");
    let violations = r.subscribe_violations(16).unwrap();
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
    // The reader: the last two (the cache), never the refused ones.
    wait_visible(&t, &r);
    assert_eq!(xs(&r), vec![Some(2.0), Some(3.0)]);
    let v = violations.recv_timeout(WAIT).unwrap();
    assert_eq!((v.constraint, v.valid_time), (Constraint::Order, t0));
    let counted = || r.stats().map(|s| (s.added, s.evicted, s.violations));
    assert!(wait_for(WAIT, || counted() == Ok((4, 2, 1))), "reader stats {:?}", r.stats());
}

/// E7 across locations: a trajectory's statistics read through the reader's `stats()`
/// agree with the writer's — what entered, what the cache evicted, and every drop by
/// cause (policy violations, blocking or not, and structures refused for their type,
/// which never reach a replica: the system's statistics are the writer's). A replica
/// handle's own `stats()` counts what that process received.
pub fn stats_agree_across_locations<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::reasonable(0, 3).unwrap();
    let w = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "r");
    let t0 = h.now();
    for k in 0..5 {
        w.add(reading(t0 + 10 * k, k as f64)).unwrap();
    }
    assert!(matches!(w.add(reading(t0 + 5, 9.0)), Ok(AddOutcome::Dropped(_))));
    assert!(w.add_blocking(reading(t0 + 6, 9.0)).is_err());
    let bad = reading(t0 + 100, 1.0).with("x", "text");
    assert!(matches!(w.add(bad), Err(AddError::InvalidType { .. })));
    w.add(reading(t0 + 200, 5.0)).unwrap();
    let ws = w.stats().unwrap();
    assert_eq!((ws.added, ws.evicted, ws.stored, ws.violations), (6, 3, 3, 2));
    assert_eq!(ws.dropped_for(DropCause::InvalidType), 1);
    wait_visible(&w, &r);
    let summary = |s: esgm_core::TrajectoryStats| {
        let mut dropped = s.dropped.clone();
        dropped.sort_by_key(|(cause, _)| format!("{cause:?}"));
        (s.added, s.evicted, s.stored, s.violations, s.dropped_total, dropped)
    };
    let seen = || h.reader().stats().unwrap().get("r").map(|t| summary(t.stats.clone()));
    let agree = || seen() == w.stats().ok().map(summary);
    assert!(
        wait_for(WAIT, agree),
        "stats differ:\n writer {:?}\n reader {:?}",
        w.stats().map(summary),
        seen()
    );
}

/// T3: later adds in add order, a replay of the last N, unsubscribe ends it — a
/// subscriber in the reading location.
pub fn subscriptions_in_add_order_with_replay<H: Harness>(h: &H) {
    register_reading(h);
    let t = h.esgm().create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let r = read(h, "r");
    let t0 = h.now();
    for k in 0..3 {
        t.add(reading(t0 + k, k as f64)).unwrap();
    }
    // "The last N" are the last N the reader has: wait until it has the writer's.
    wait_visible(&t, &r);
    let late = r.subscribe(SubscribeOptions::default().last(1)).unwrap();
    for k in [5, 4] {
        t.add(reading(t0 + k, k as f64)).unwrap();
    }
    let got: Vec<_> = (0..3).map(|_| late.recv_timeout(WAIT).map(|s| x_of(&s))).collect();
    assert_eq!(got, vec![Ok(Some(2.0)), Ok(Some(5.0)), Ok(Some(4.0))]);
    r.unsubscribe(late.id()).unwrap();
    t.add(reading(t0 + 9, 9.0)).unwrap();
    wait_visible(&t, &r);
    assert_eq!(
        late.recv_timeout(std::time::Duration::from_millis(50)).map(|s| s.valid_time()),
        Err(esgm_core::store::RecvError::Closed)
    );
}

/// C7/T4: non-blocking adds drop, count and notify: the writer gets the outcome, the
/// reader's violation subscribers the reports, and the reader's stats count them.
pub fn violations_are_delivered_and_counted<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::default().order(OrderConstraint::Monotone).filter("x >= 0.0");
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "r");
    let v = r.subscribe_violations(16).unwrap();
    let t0 = h.now();
    t.add(reading(t0 + 10, 1.0)).unwrap();
    assert!(matches!(t.add(reading(t0 + 5, 1.0)), Ok(AddOutcome::Dropped(_))));
    assert!(matches!(t.add(reading(t0 + 20, -1.0)), Ok(AddOutcome::Dropped(_))));
    let a = v.recv_timeout(WAIT).unwrap();
    let b = v.recv_timeout(WAIT).unwrap();
    assert_eq!((a.constraint, b.constraint), (Constraint::Order, Constraint::Filter));
    assert_eq!((a.valid_time, b.valid_time), (t0 + 5, t0 + 20));
    let st = t.stats().unwrap();
    assert_eq!((st.added, st.violations), (1, 2));
    let counted = || r.stats().map(|s| (s.added, s.violations));
    assert!(wait_for(WAIT, || counted() == Ok((1, 2))), "reader stats {:?}", r.stats());
    wait_visible(&t, &r);
}

/// C6: the runtime releases held samples when their window passes, with no further
/// add, and a subscriber in the reading location gets them in valid-time order.
pub fn held_samples_are_released_on_time<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::reasonable(millis(100), 0).unwrap();
    let t = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "r");
    let sub = r.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    assert!(matches!(t.add(reading(t0, 2.0)), Ok(AddOutcome::Held { .. })));
    assert!(matches!(t.add(reading(t0 - millis(50), 1.0)), Ok(AddOutcome::Held { .. })));
    h.advance(millis(100));
    let first = sub.recv_timeout(WAIT).unwrap();
    let second = sub.recv_timeout(WAIT).unwrap();
    assert_eq!((x_of(&first), x_of(&second)), (Some(1.0), Some(2.0)), "valid-time order");
    wait_visible(&t, &r);
}

/// T4 from the reading side: adds through the reader's handle of a primitive
/// trajectory are forwarded to its writer (where the reader is another location),
/// whose gate orders, checks and counts them with the writer's own; both sides see
/// the one stream.
pub fn adds_through_the_reader_reach_the_writer<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::default().order(OrderConstraint::Monotone);
    let w = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("r", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "r");
    let at_writer = w.subscribe(SubscribeOptions::default()).unwrap();
    let at_reader = r.subscribe(SubscribeOptions::default()).unwrap();
    let violations = r.subscribe_violations(16).unwrap();
    let remote = h.reader_is_remote();
    let accepted = |out: Result<AddOutcome, AddError>| match remote {
        true => assert_eq!(out, Ok(AddOutcome::Forwarded)),
        false => assert_eq!(out, Ok(AddOutcome::Added)),
    };
    let t0 = h.now();
    accepted(r.add(reading(t0 + 10, 1.0)));
    assert!(wait_for(WAIT, || w.get_latest().map(|s| x_of(&s)) == Ok(Some(1.0))), "at the writer");
    wait_visible(&w, &r);
    // Several in a row reach the gate in add order (monotone: none is dropped).
    for k in 2..=4 {
        accepted(r.add(reading(t0 + 10 * k, k as f64)));
    }
    // Out of order: the writer's gate decides, drops and reports it.
    match (remote, r.add(reading(t0 + 5, 0.5))) {
        (true, out) => assert_eq!(out, Ok(AddOutcome::Forwarded)),
        (false, out) => assert!(matches!(out, Ok(AddOutcome::Dropped(_))), "{out:?}"),
    }
    accepted(r.add(reading(t0 + 50, 5.0)));
    let gate = || w.stats().map(|s| (s.added, s.violations));
    assert!(wait_for(WAIT, || gate() == Ok((5, 1))), "writer stats {:?}", w.stats());
    // The writer's own adds and the reader's interleave in the one stream. A reader's
    // add reaches the gate after it returns, so the writer added only once the
    // reader's had passed (order is add order per side, not across sides).
    w.add(reading(t0 + 60, 6.0)).unwrap();
    accepted(r.add(reading(t0 + 70, 7.0)));
    assert!(wait_for(WAIT, || w.stats().map(|s| s.added) == Ok(7)), "{:?}", w.stats());
    wait_visible(&w, &r);
    let seen = || r.stats().map(|s| (s.added, s.violations));
    assert!(wait_for(WAIT, || seen() == Ok((7, 1))), "reader stats {:?}", r.stats());
    let all: Vec<_> = (1..=7).map(|k| Some(k as f64)).collect();
    assert_eq!(xs(&w), all);
    let v = violations.recv_timeout(WAIT).unwrap();
    assert_eq!((v.constraint, v.valid_time), (Constraint::Order, t0 + 5));
    assert_eq!(w.stats().unwrap().violations, 1, "counted by the writer's gate");
    for sub in [&at_writer, &at_reader] {
        let got: Vec<_> = (0..7).map(|_| sub.recv_timeout(WAIT).map(|s| x_of(&s))).collect();
        assert_eq!(got, all.iter().map(|x| Ok(*x)).collect::<Vec<_>>(), "in add order");
    }
    // A structure of another type is refused where it is added, at once.
    let wrong = reading(t0 + 80, 8.0).with("x", "text");
    assert!(matches!(r.add(wrong), Err(AddError::InvalidType { .. })));
}

/// T4 across processes: a blocking add through the reader returns the writer's own
/// outcome — added, or the policy violation with its constraint — never `Forwarded`.
pub fn blocking_adds_through_the_reader_get_the_writers_outcome<H: Harness>(h: &H) {
    register_reading(h);
    let policy = FluentStreamPolicy::default().order(OrderConstraint::StrictMonotone);
    let w = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive("b", "Reading").policy(policy))
        .unwrap();
    let r = read(h, "b");
    let t0 = h.now();
    assert_eq!(r.add_blocking(reading(t0 + 10, 1.0)), Ok(AddOutcome::Added));
    assert_eq!(x_of(&w.get_latest().unwrap()), Some(1.0), "in the writer when it returns");
    match r.add_blocking(reading(t0 + 10, 2.0)) {
        Err(AddError::PolicyViolation(v)) => {
            assert_eq!((v.constraint, v.valid_time), (Constraint::Order, t0 + 10));
        }
        other => panic!("expected the writer's order violation, got {other:?}"),
    }
    let created = r.create_at_blocking("b", t0 + 20, reading(0, 3.0).attributes.into());
    assert_eq!(created, Ok(AddOutcome::Added));
    assert_eq!(w.stats().unwrap().added, 2);
    assert_eq!(w.stats().unwrap().violations, 1, "counted once, by the writer's gate");
    wait_visible(&w, &r);
    assert_eq!(xs(&r), vec![Some(1.0), Some(3.0)]);
}
