//! Edge tests of every constraint and query, on a simulated clock.

use std::sync::Arc;
use std::time::Duration;

use super::*;
use crate::approximation::{MergeRule, ValueApproximation};
use crate::clock::SimClock;
use crate::generator::GeneratorPolicy;
use crate::policy::*;
use crate::type_registry::TypeRegistry;
use crate::types::EntityStructureType;
use crate::value::{Value, ValueSort};

fn registry() -> TypeRegistry {
    let mut r = TypeRegistry::with_library();
    r.create_entity_structure_type(
        "Reading",
        EntityStructureType::new("Reading")
            .attr("x", ValueSort::Double)
            .attr("n", ValueSort::Long)
            .attr("label", ValueSort::String),
    )
    .unwrap();
    r
}

struct Fixture {
    clock: Arc<SimClock>,
    store: TrajectoryStore,
}

fn store(policy: FluentStreamPolicy) -> Fixture {
    let clock = SimClock::shared(1_000);
    let checker = TypeChecker::new(&registry(), "Reading").unwrap();
    let store = TrajectoryStore::builder("readings", checker)
        .policy(policy)
        .clock(clock.clone())
        .create()
        .unwrap();
    Fixture { clock, store }
}

fn reading(vt: Time, x: f64) -> EntityStructure {
    EntityStructure::new("r", vt, vt).with("x", x).with("n", x as i64).with("label", "l")
}

fn vts(samples: &[Sample]) -> Vec<Time> {
    samples.iter().map(|s| s.valid_time()).collect()
}

fn stored_vts(s: &TrajectoryStore) -> Vec<Time> {
    vts(&s.samples())
}

fn not_available<T: std::fmt::Debug>(r: Result<T, QueryError>) -> bool {
    matches!(r, Err(QueryError::ValueNotAvailable { .. }))
}

// ---- queries -------------------------------------------------------------------

#[test]
fn empty_trajectory_answers_value_not_available() {
    let f = store(FluentStreamPolicy::default());
    let s = &f.store;
    assert!(not_available(s.get_latest()));
    assert!(not_available(s.get_nth_latest(0)));
    assert!(not_available(s.get_at(5)));
    assert!(not_available(s.get_closest_at_or_before(5)));
    for a in [
        ValueApproximation::None,
        ValueApproximation::Closest,
        ValueApproximation::MostRecent,
        ValueApproximation::Linear,
    ] {
        assert!(not_available(s.get_at_approximating(5, &a)), "{a:?}");
    }
    assert!(s.get_between(i64::MIN, i64::MAX).is_empty());
    assert!(not_available(s.start_time()));
    assert!(not_available(s.end_time()));
    let err = s.get_latest().unwrap_err().to_string();
    assert_eq!(err, "value not available in `readings`: get_latest: the trajectory is empty");
}

#[test]
fn one_sample() {
    let mut f = store(FluentStreamPolicy::default());
    assert_eq!(f.store.add(reading(100, 1.0)), Ok(AddOutcome::Added));
    f.clock.set(1_500);
    let s = &f.store;
    let latest = s.get_latest().unwrap();
    assert_eq!((latest.valid_time(), latest.add_time, latest.query_time), (100, 1_000, 1_500));
    assert_eq!(s.get_nth_latest(0).unwrap().valid_time(), 100);
    assert!(not_available(s.get_nth_latest(1)));
    assert_eq!(s.get_at(100).unwrap().valid_time(), 100);
    assert!(not_available(s.get_at(101)));
    assert!(not_available(s.get_closest_at_or_before(99)));
    assert_eq!(s.get_closest_at_or_before(100).unwrap().valid_time(), 100);
    assert_eq!(s.get_closest_at_or_before(i64::MAX).unwrap().valid_time(), 100);
    assert_eq!(vts(&s.get_between(100, 100)), vec![100]);
    assert_eq!((s.start_time().unwrap(), s.end_time().unwrap()), (100, 100));
    assert_eq!(
        s.get_at_approximating(500, &ValueApproximation::Closest).unwrap().valid_time(),
        100
    );
    assert!(not_available(s.get_at_approximating(500, &ValueApproximation::Linear)));
}

#[test]
fn query_time_is_the_clock_at_the_query() {
    let mut f = store(FluentStreamPolicy::default());
    f.store.add(reading(10, 1.0)).unwrap();
    f.clock.advance(500);
    let s = f.store.get_latest().unwrap();
    assert_eq!((s.add_time, s.query_time), (1_000, 1_500));
}

#[test]
fn equal_valid_times() {
    let mut f = store(FluentStreamPolicy::default());
    f.store.add(reading(10, 1.0)).unwrap();
    f.store.add(reading(20, 2.0)).unwrap();
    f.store.add(reading(20, 3.0)).unwrap();
    f.store.add(reading(30, 4.0)).unwrap();
    let s = &f.store;
    assert_eq!(s.get_at(20).unwrap().value("x"), Some(Value::Double(3.0)), "latest added wins");
    assert_eq!(s.get_closest_at_or_before(25).unwrap().value("x"), Some(Value::Double(3.0)));
    let between: Vec<_> = s.get_between(20, 20).iter().map(|s| s.value("x")).collect();
    assert_eq!(between, vec![Some(Value::Double(2.0)), Some(Value::Double(3.0))]);
    assert_eq!(vts(&s.get_between(0, 100)), vec![10, 20, 20, 30]);
    assert_eq!(s.get_nth_latest(1).unwrap().value("x"), Some(Value::Double(3.0)));
}

#[test]
fn between_is_inclusive_and_empty_when_reversed() {
    let mut f = store(FluentStreamPolicy::default());
    for vt in [10, 20, 30, 40] {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    assert_eq!(vts(&f.store.get_between(20, 30)), vec![20, 30]);
    assert_eq!(vts(&f.store.get_between(11, 19)), Vec::<Time>::new());
    assert_eq!(vts(&f.store.get_between(30, 20)), Vec::<Time>::new());
}

#[test]
fn out_of_order_storage_is_queried_by_valid_time() {
    let mut f = store(FluentStreamPolicy::default()); // order: any
    for vt in [30, 10, 40, 20] {
        f.store.add(reading(vt, vt as f64)).unwrap();
    }
    assert_eq!(f.store.get_latest().unwrap().valid_time(), 20, "latest is by add order");
    assert_eq!(vts(&f.store.get_between(0, 100)), vec![10, 20, 30, 40]);
    assert_eq!(f.store.get_closest_at_or_before(35).unwrap().valid_time(), 30);
    assert_eq!((f.store.start_time().unwrap(), f.store.end_time().unwrap()), (10, 40));
}

#[test]
fn approximations_at_before_and_after_the_ends() {
    let mut f = store(FluentStreamPolicy::default());
    f.store.add(reading(100, 10.0)).unwrap();
    f.store.add(reading(200, 20.0).with("label", "second")).unwrap();
    let s = &f.store;
    let lin = |t| s.get_at_approximating(t, &ValueApproximation::Linear);
    // At an end: the sample itself.
    assert_eq!(lin(100).unwrap().value("x"), Some(Value::Double(10.0)));
    assert_eq!(lin(200).unwrap().value("x"), Some(Value::Double(20.0)));
    // Inside: numeric interpolated, others most recent, valid at t, created at query time.
    let mid = lin(125).unwrap();
    assert_eq!(mid.value("x"), Some(Value::Double(12.5)));
    assert_eq!(mid.value("n"), Some(Value::Long(13)));
    assert_eq!(mid.value("label"), Some(Value::from("l")));
    assert_eq!((mid.valid_time(), mid.create_time()), (125, 1_000));
    // Outside: nothing on one side.
    assert!(not_available(lin(99)));
    assert!(not_available(lin(201)));

    let mr = |t| s.get_at_approximating(t, &ValueApproximation::MostRecent);
    assert!(not_available(mr(99)));
    assert_eq!(mr(199).unwrap().valid_time(), 100, "the stored structure, not re-stamped");
    assert_eq!(mr(5_000).unwrap().valid_time(), 200);

    let cl = |t| s.get_at_approximating(t, &ValueApproximation::Closest);
    assert_eq!(cl(149).unwrap().valid_time(), 100);
    assert_eq!(cl(150).unwrap().valid_time(), 100, "a tie goes to the earlier sample");
    assert_eq!(cl(151).unwrap().valid_time(), 200);
    assert_eq!(cl(0).unwrap().valid_time(), 100);

    let none = s.get_at_approximating(150, &ValueApproximation::None);
    assert!(not_available(none));

    let d = ValueApproximation::Default(reading(0, 7.0).attributes);
    let dv = s.get_at_approximating(150, &d).unwrap();
    assert_eq!((dv.valid_time(), dv.value("x")), (150, Some(Value::Double(7.0))));
    assert_eq!(s.get_at_approximating(100, &d).unwrap().value("x"), Some(Value::Double(10.0)));
    let bad = ValueApproximation::Default(vec![crate::AttributeValuePair::new("x", 1i64)]);
    assert!(matches!(s.get_at_approximating(150, &bad), Err(QueryError::InvalidDefault { .. })));
}

#[test]
fn generator_merges_samples_sharing_a_valid_time() {
    let mut f = store(FluentStreamPolicy::default());
    let mk = |ct: Time, x: f64| {
        let mut r = reading(100, x);
        r.create_time = ct;
        r
    };
    f.store.add(mk(3, 30.0)).unwrap();
    f.store.add(mk(1, 10.0)).unwrap();
    f.store.add(mk(2, 50.0)).unwrap();
    f.store.add(reading(200, 100.0)).unwrap();
    let x_at = |merge, approximation, t| {
        let p = GeneratorPolicy { approximation, merge };
        f.store.generator(&p).value_at(t).unwrap().value("x")
    };
    use ValueApproximation::{Linear, MostRecent};
    assert_eq!(x_at(MergeRule::KeepFirst, MostRecent, 100), Some(Value::Double(10.0)));
    assert_eq!(x_at(MergeRule::KeepLast, MostRecent, 100), Some(Value::Double(30.0)));
    assert_eq!(x_at(MergeRule::Average, MostRecent, 100), Some(Value::Double(30.0)));
    assert_eq!(x_at(MergeRule::Median, MostRecent, 100), Some(Value::Double(30.0)));
    assert_eq!(x_at(MergeRule::KeepFirst, MostRecent, 150), Some(Value::Double(10.0)));
    // Linear between the merged group (average 30) and 100.
    assert_eq!(x_at(MergeRule::Average, Linear, 150), Some(Value::Double(65.0)));
    let p = GeneratorPolicy::default();
    assert!(not_available(f.store.generator(&p).value_at(150)));
}

// ---- constraints -----------------------------------------------------------------

#[test]
fn cache_of_n_elements_evicts_oldest_first() {
    let mut f = store(FluentStreamPolicy::default().cache(CacheConstraint::Elements(3)));
    for vt in 1..=5 {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    assert_eq!(stored_vts(&f.store), vec![3, 4, 5]);
    let st = f.store.stats();
    assert_eq!((st.added, st.evicted, st.stored, st.dropped_total), (5, 2, 3, 0));
}

#[test]
fn cache_of_n_evicts_by_add_order_even_out_of_valid_order() {
    let mut f = store(FluentStreamPolicy::default().cache(CacheConstraint::Elements(2)));
    for vt in [30, 10, 20] {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    assert_eq!(stored_vts(&f.store), vec![10, 20]);
    assert_eq!(vts(&f.store.get_between(0, 100)), vec![10, 20]);
}

#[test]
fn time_cache_keeps_a_window_of_valid_time() {
    let mut f = store(FluentStreamPolicy::default().cache(CacheConstraint::Duration(100)));
    for vt in [0, 50, 100, 150] {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    // newest 150: keep valid times with 150 − vt < 100.
    assert_eq!(stored_vts(&f.store), vec![100, 150]);
    // A sample already outside the window is a cache violation, not stored.
    let out = f.store.add(reading(40, 0.0)).unwrap();
    assert!(matches!(
        out,
        AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Cache, .. })
    ));
    // Inside the window but out of order is fine under order: any.
    assert_eq!(f.store.add(reading(120, 0.0)), Ok(AddOutcome::Added));
    assert_eq!(vts(&f.store.get_between(0, 1_000)), vec![100, 120, 150]);
    assert_eq!(f.store.stats().evicted, 2);
}

#[test]
fn order_constraints() {
    let mut m = store(FluentStreamPolicy::default().order(OrderConstraint::Monotone));
    assert_eq!(m.store.add(reading(10, 0.0)), Ok(AddOutcome::Added));
    assert_eq!(m.store.add(reading(10, 1.0)), Ok(AddOutcome::Added), "equal is monotone");
    let v = m.store.add_blocking(reading(9, 0.0)).unwrap_err();
    match v {
        AddError::PolicyViolation(v) => {
            assert_eq!(v.constraint, Constraint::Order);
            assert_eq!(v.detail, "valid time 9 is before the previous 10");
        }
        other => panic!("{other:?}"),
    }
    let mut s = store(FluentStreamPolicy::default().order(OrderConstraint::StrictMonotone));
    s.store.add(reading(10, 0.0)).unwrap();
    assert!(matches!(s.store.add(reading(10, 1.0)), Ok(AddOutcome::Dropped(_))));
    assert_eq!(s.store.add(reading(11, 1.0)), Ok(AddOutcome::Added));
    assert_eq!(s.store.stats().dropped_for(DropCause::Violation(Constraint::Order)), 1);
}

#[test]
fn order_survives_eviction_and_reset_forgets_it() {
    let mut f = store(
        FluentStreamPolicy::default()
            .order(OrderConstraint::Monotone)
            .cache(CacheConstraint::Elements(1)),
    );
    f.store.add(reading(10, 0.0)).unwrap();
    f.store.add(reading(20, 0.0)).unwrap();
    assert!(matches!(f.store.add(reading(15, 0.0)), Ok(AddOutcome::Dropped(_))));
    f.store.reset();
    assert!(f.store.is_empty());
    assert_eq!(f.store.add(reading(15, 0.0)), Ok(AddOutcome::Added));
}

#[test]
fn delay_holds_and_reorders_within_the_window() {
    let mut f = store(FluentStreamPolicy::reasonable(100, 0).unwrap());
    f.clock.set(1_060);
    assert_eq!(f.store.add(reading(1_050, 0.0)), Ok(AddOutcome::Held { release_at: 1_150 }));
    f.clock.set(1_070);
    assert_eq!(f.store.add(reading(1_020, 0.0)), Ok(AddOutcome::Held { release_at: 1_120 }));
    let sub = f.store.subscribe(SubscribeOptions::default());
    assert!(f.store.is_empty());
    assert_eq!(f.store.next_release_time(), Some(1_120));
    f.clock.set(1_130);
    assert_eq!(f.store.release_due(), 1);
    f.clock.set(1_150);
    assert_eq!(f.store.release_due(), 1);
    assert_eq!(stored_vts(&f.store), vec![1_020, 1_050]);
    assert_eq!(vts(&sub.drain()), vec![1_020, 1_050], "subscribers see valid-time order");
    assert_eq!(f.store.get_latest().unwrap().add_time, 1_150);
    // Outside the delay: a delay violation at arrival.
    f.clock.set(1_300);
    let out = f.store.add(reading(1_150, 0.0)).unwrap();
    assert!(matches!(
        out,
        AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Delay, .. })
    ));
    let st = f.store.stats();
    assert_eq!((st.added, st.held, st.dropped_total), (2, 0, 1));
}

#[test]
fn adds_release_due_samples_first() {
    let mut f = store(FluentStreamPolicy::reasonable(100, 0).unwrap());
    f.clock.set(1_000);
    f.store.add(reading(1_000, 0.0)).unwrap();
    f.clock.set(1_200);
    // The held sample (due 1_100) enters before this one is considered.
    f.store.add(reading(1_150, 0.0)).unwrap();
    assert_eq!(stored_vts(&f.store), vec![1_000]);
    assert_eq!(f.store.stats().held, 1);
}

#[test]
fn without_reorder_late_samples_are_order_violations() {
    let mut f = store(FluentStreamPolicy::reasonable(100, 0).unwrap().reorder(false));
    assert_eq!(f.store.add(reading(990, 0.0)), Ok(AddOutcome::Added));
    assert!(matches!(
        f.store.add(reading(980, 0.0)),
        Ok(AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Order, .. }))
    ));
}

#[test]
fn strict_order_with_reordering_drops_equal_valid_times_at_release() {
    let mut f = store(
        FluentStreamPolicy::default()
            .order(OrderConstraint::StrictMonotone)
            .delay(DelayConstraint::Max(50)),
    );
    let violations = f.store.subscribe_violations(8);
    f.store.add(reading(1_000, 1.0)).unwrap();
    f.store.add(reading(1_000, 2.0)).unwrap();
    f.clock.advance(50);
    assert_eq!(f.store.release_due(), 1);
    let v = violations.drain();
    assert_eq!(v.len(), 1);
    assert_eq!(v[0].constraint, Constraint::Order);
    assert_eq!(f.store.get_latest().unwrap().value("x"), Some(Value::Double(1.0)));
}

#[test]
fn duration_zero_rules() {
    // from = 0: the creation time (clock at 1_000); to = 0: forever.
    let mut f = store(
        FluentStreamPolicy::default().duration(DurationConstraint::Between { from: 0, to: 0 }),
    );
    assert!(matches!(
        f.store.add(reading(999, 0.0)),
        Ok(AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Duration, .. }))
    ));
    assert_eq!(f.store.add(reading(1_000, 0.0)), Ok(AddOutcome::Added));
    assert_eq!(f.store.add(reading(i64::MAX / 2, 0.0)), Ok(AddOutcome::Added));
    let mut g = store(
        FluentStreamPolicy::default().duration(DurationConstraint::Between { from: 10, to: 20 }),
    );
    assert_eq!(g.store.add(reading(10, 0.0)), Ok(AddOutcome::Added));
    assert_eq!(g.store.add(reading(20, 0.0)), Ok(AddOutcome::Added));
    assert!(matches!(g.store.add(reading(21, 0.0)), Ok(AddOutcome::Dropped(_))));
}

#[test]
fn duration_ending_before_now_is_illegal() {
    let clock = SimClock::shared(1_000);
    let checker = TypeChecker::new(&registry(), "Reading").unwrap();
    let r = TrajectoryStore::builder("t", checker)
        .policy(
            FluentStreamPolicy::default()
                .duration(DurationConstraint::Between { from: 0, to: 500 }),
        )
        .clock(clock)
        .create();
    assert!(
        matches!(r, Err(PolicyError::IllegalPolicy { ref field, .. }) if field == "duration.to")
    );
}

#[test]
fn change_constraints() {
    let mut f = store(FluentStreamPolicy::default().change(ChangeConstraint::AnyChange));
    f.store.add(reading(1, 1.0)).unwrap();
    assert!(matches!(f.store.add(reading(2, 1.0)), Ok(AddOutcome::Dropped(_))), "same value");
    assert_eq!(f.store.add(reading(3, 2.0)), Ok(AddOutcome::Added));

    let mut u = store(FluentStreamPolicy::default().change(ChangeConstraint::AnyUpdate));
    u.store.add(reading(1, 1.0)).unwrap();
    assert_eq!(u.store.add(reading(2, 1.0)), Ok(AddOutcome::Added), "new valid time");
    assert!(matches!(u.store.add(reading(2, 1.0)), Ok(AddOutcome::Dropped(_))), "identical");

    let mut p = store(FluentStreamPolicy::default().change(ChangeConstraint::SampleEvery(10)));
    p.store.add(reading(0, 0.0)).unwrap();
    assert!(matches!(p.store.add(reading(9, 0.0)), Ok(AddOutcome::Dropped(_))), "too soon");
    assert_eq!(p.store.add(reading(10, 0.0)), Ok(AddOutcome::Added));
    assert_eq!(p.store.add(reading(40, 0.0)), Ok(AddOutcome::Added));
    let st = p.store.stats();
    assert_eq!(st.missed_sample_points, 2, "20 and 30 were skipped");
    assert_eq!(st.dropped_for(DropCause::Violation(Constraint::Change)), 1);
}

#[test]
fn invalid_type_is_an_error_in_both_forms_and_counted() {
    let mut f = store(FluentStreamPolicy::default());
    let bad = reading(1, 1.0).with("n", 2.5);
    for blocking in [false, true] {
        let r = if blocking { f.store.add_blocking(bad.clone()) } else { f.store.add(bad.clone()) };
        let err = r.unwrap_err();
        assert_eq!(
            err.to_string(),
            "trajectory `readings`: attribute `n` of type `Reading` is Double, expected Long"
        );
    }
    assert_eq!(f.store.stats().dropped_for(DropCause::InvalidType), 2);
    assert!(f.store.is_empty());
}

#[test]
fn create_at_forms_stamp_times_from_the_clock() {
    let mut f = store(FluentStreamPolicy::default());
    f.clock.set(5_000);
    let attrs = reading(0, 1.0).attributes;
    f.store.create_at("a", 4_000, attrs.clone()).unwrap();
    let s = f.store.get_latest().unwrap();
    assert_eq!((s.name(), s.valid_time(), s.create_time()), ("a", 4_000, 5_000));
    f.store.create_at_now("b", attrs.clone()).unwrap();
    let s = f.store.get_latest().unwrap();
    assert_eq!((s.valid_time(), s.create_time()), (5_000, 5_000));
    let mut m = store(FluentStreamPolicy::default().order(OrderConstraint::StrictMonotone));
    m.store.create_at_blocking("a", 10, attrs.clone()).unwrap();
    assert!(m.store.create_at_blocking("a", 10, attrs.clone()).is_err());
    m.clock.set(1_000);
    m.store.create_at_now_blocking("a", attrs.clone()).unwrap();
    assert!(m.store.create_at_now_blocking("a", attrs).is_err(), "same time: not strictly after");
}

#[test]
fn illegal_policies() {
    let checker = || TypeChecker::new(&registry(), "Reading").unwrap();
    let make = |p: FluentStreamPolicy| TrajectoryStore::builder("t", checker()).policy(p).create();
    assert!(matches!(
        make(FluentStreamPolicy::default().change(ChangeConstraint::SampleEvery(-1))),
        Err(PolicyError::IllegalPolicy { ref field, .. }) if field == "change.sample_every"
    ));
    assert!(FluentStreamPolicy::sampled(0, 0, 10, 0, -1).is_err(), "cache of -1");
    assert!(matches!(
        make(FluentStreamPolicy::default().filter("szie > 3")),
        Err(PolicyError::IllegalFilter(_))
    ));
}

#[test]
fn filter_rejects_and_counts() {
    let mut f = store(FluentStreamPolicy::default().filter("x > 2.5 && label == \"l\""));
    assert!(matches!(
        f.store.add(reading(1, 1.0)),
        Ok(AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Filter, .. }))
    ));
    assert_eq!(f.store.add(reading(2, 3.0)), Ok(AddOutcome::Added));
    assert_eq!(f.store.stats().dropped_for(DropCause::Violation(Constraint::Filter)), 1);
}

// ---- subscriptions and stats -----------------------------------------------------

#[test]
fn subscribers_get_later_adds_in_add_order_after_a_replay() {
    let mut f = store(FluentStreamPolicy::default());
    for vt in [1, 2, 3] {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    let late = f.store.subscribe(SubscribeOptions::default().last(2));
    let fresh = f.store.subscribe(SubscribeOptions::default());
    for vt in [5, 4] {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    assert_eq!(vts(&late.drain()), vec![2, 3, 5, 4]);
    assert_eq!(vts(&fresh.drain()), vec![5, 4]);
    assert_eq!(f.store.stats().subscribers, 2);
    assert!(f.store.unsubscribe(fresh.id()));
    f.store.add(reading(6, 0.0)).unwrap();
    assert_eq!(fresh.recv_timeout(Duration::from_millis(10)), Err(RecvError::Closed));
}

#[test]
fn slow_subscriber_never_blocks_the_writer_and_overflow_is_counted() {
    let mut f = store(FluentStreamPolicy::default());
    let slow = f.store.subscribe(SubscribeOptions::default().capacity(4));
    for vt in 0..100 {
        f.store.add(reading(vt, 0.0)).unwrap();
    }
    assert_eq!(vts(&slow.drain()), vec![96, 97, 98, 99], "the freshest are kept");
    assert_eq!(slow.overflowed(), 96);
    assert_eq!(f.store.stats().subscriber_overflow, 96);
    // A replay longer than the buffer keeps the newest and counts the rest.
    let late = f.store.subscribe(SubscribeOptions::default().last(10).capacity(4));
    assert_eq!(vts(&late.drain()), vec![96, 97, 98, 99]);
    assert_eq!(f.store.stats().subscriber_overflow, 96 + 6);
    assert_eq!(f.store.stats().added, 100);
}

#[test]
fn violations_are_delivered_with_their_cause() {
    let mut f = store(FluentStreamPolicy::default().order(OrderConstraint::Monotone));
    let v = f.store.subscribe_violations(16);
    f.store.add(reading(10, 0.0)).unwrap();
    f.store.add(reading(5, 0.0)).unwrap();
    let got = v.drain();
    assert_eq!(got.len(), 1);
    assert_eq!(
        (got[0].constraint, got[0].valid_time, got[0].trajectory.as_str()),
        (Constraint::Order, 5, "readings")
    );
    assert!(got[0].to_string().contains("order constraint"));
}

#[test]
fn re_pointing_keeps_subscribers() {
    let mut old = store(FluentStreamPolicy::default());
    let sub = old.store.subscribe(SubscribeOptions::default());
    let mut new = store(FluentStreamPolicy::default());
    new.store.adopt(&mut old.store);
    new.store.add(reading(1, 0.0)).unwrap();
    old.store.add(reading(2, 0.0)).unwrap();
    assert_eq!(vts(&sub.drain()), vec![1]);
}

#[test]
fn reset_counts_held_samples_and_keeps_subscribers() {
    let mut f = store(FluentStreamPolicy::reasonable(100, 0).unwrap());
    let sub = f.store.subscribe(SubscribeOptions::default());
    f.store.add(reading(1_000, 0.0)).unwrap();
    f.store.reset_blocking();
    let st = f.store.stats();
    assert_eq!((st.held, st.dropped_for(DropCause::Reset)), (0, 1));
    f.clock.advance(1);
    f.store.add(reading(1_001, 0.0)).unwrap();
    f.clock.advance(200);
    f.store.release_due();
    assert_eq!(vts(&sub.drain()), vec![1_001]);
}

#[test]
fn stats_rate_and_delay_percentiles() {
    let mut f = store(FluentStreamPolicy::default());
    for i in 0..11 {
        f.clock.set(1_000_000_000 + i * 100_000_000); // 10 Hz
        let now = f.clock.now();
        f.store.add(reading(now - 5_000_000, 0.0)).unwrap(); // 5 ms late
    }
    let st = f.store.stats();
    assert!((st.rate_hz - 10.0).abs() < 1e-6, "{}", st.rate_hz);
    // Within 1 %: the delay histogram keeps two significant digits.
    let p50 = st.add_delay_p50.unwrap();
    assert!((4_950_000..=5_050_000).contains(&p50), "{p50}");
}

#[test]
fn extreme_times_and_values_never_overflow() {
    // Delay: a valid time of i64::MIN is infinitely late, not wrapped into "on time".
    let mut d = store(FluentStreamPolicy::default().delay(DelayConstraint::Max(10)));
    assert!(matches!(
        d.store.add(reading(i64::MIN, 0.0)),
        Ok(AddOutcome::Dropped(PolicyViolation { constraint: Constraint::Delay, .. }))
    ));
    // Unconstrained: stats, queries and approximations at the ends of time.
    let mut f = store(FluentStreamPolicy::default());
    f.store.add(reading(i64::MIN + 1, 0.0).with("n", i64::MIN)).unwrap();
    f.store.add(reading(i64::MAX, 0.0).with("n", i64::MAX)).unwrap();
    let st = f.store.stats();
    assert_eq!(st.added, 2);
    assert_eq!(
        f.store.get_at_approximating(5, &ValueApproximation::Closest).unwrap().valid_time(),
        i64::MAX
    );
    let lin = f.store.get_at_approximating(0, &ValueApproximation::Linear).unwrap();
    assert!(matches!(lin.value("n"), Some(Value::Long(_))));
    // Time caches and sample periods at the extremes.
    let mut c = store(
        FluentStreamPolicy::default()
            .cache(CacheConstraint::Duration(100))
            .change(ChangeConstraint::SampleEvery(10)),
    );
    c.store.add(reading(i64::MAX, 0.0)).unwrap();
    assert!(matches!(c.store.add(reading(i64::MIN, 0.0)), Ok(AddOutcome::Dropped(_))));
}

#[test]
fn adopting_moves_held_samples_under_the_new_policy() {
    let mut old = store(FluentStreamPolicy::reasonable(100, 0).unwrap());
    let sub = old.store.subscribe(SubscribeOptions::default());
    assert!(matches!(old.store.add(reading(1_000, 1.0)), Ok(AddOutcome::Held { .. })));
    let mut new = store(FluentStreamPolicy::default());
    new.store.adopt(&mut old.store);
    // Unconstrained: the held sample enters at once, and the adopted subscriber sees it.
    assert_eq!(new.store.stats().added, 1);
    assert_eq!(vts(&sub.drain()), vec![1_000]);
    assert_eq!(old.store.stats().held, 0);
}

/// A tap that cannot pass an entry on (a mirror whose publish failed) makes the store
/// count it, so the failure shows in the trajectory's stats; the entry is still stored
/// here.
#[test]
fn entries_a_tap_could_not_pass_on_are_counted_unpublished() {
    struct FailingTap(u64);
    impl StoreTap for FailingTap {
        fn observe(&mut self, _: &StoreEvent) {}
        fn entering(&mut self, _: &Sample) -> Option<crate::SharedStructure> {
            self.0 += 1;
            None
        }
        fn take_unpublished(&mut self) -> u64 {
            std::mem::take(&mut self.0)
        }
    }
    let mut f = store(FluentStreamPolicy::default());
    let _ = f.store.set_tap(Box::new(FailingTap(0)));
    for vt in 1..=3 {
        f.store.add(reading(vt, 1.0)).unwrap();
    }
    let stats = f.store.stats();
    assert_eq!((stats.added, stats.dropped_for(DropCause::Unpublished)), (3, 3));
    assert_eq!(stored_vts(&f.store), [1, 2, 3]);
}

/// Loss counts come from another process's sequence numbers: a hostile gap saturates
/// the count, at once, instead of overflowing it or counting one by one.
#[test]
fn hostile_loss_counts_saturate_at_once() {
    let mut f = store(FluentStreamPolicy::default());
    f.store.replicate_loss(u64::MAX);
    f.store.replicate_loss(u64::MAX);
    let stats = f.store.stats();
    assert_eq!(stats.dropped_for(DropCause::Lost), u64::MAX);
    assert_eq!(stats.dropped_total, u64::MAX);
}
