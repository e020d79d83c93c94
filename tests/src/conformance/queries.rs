//! Queries (T1, T2) where the history is read: every query of the reader's handle
//! answers what the writer's answers, for streams that exercise the valid-time index
//! (out of valid-time order, equal valid times, the ends of the timeline), the cache
//! constraints (elements, a time window over an out-of-order stream) and the gate
//! (filter, duration, change, strict order, a sample period, hold-and-reorder).
//!
//! On the shared-memory runtime the reader's handle is a replica in another location,
//! an esgm-core store fed across the boundary; on the in-process runtime it is the
//! writer's own store. Both sides share one clock, so answers carry the same query
//! time.

use esgm_core::{
    AddError, ChangeConstraint, DurationConstraint, EntityStructure, EntityTrajectoryStructure,
    Esgm, FluentStreamPolicy, OrderConstraint, Time, TrajectorySpec, ValueApproximation,
};

use super::{contents, read, reading, register_reading, wait_visible};
use crate::Harness;

/// What one step of a script does through the writer's handle.
#[derive(Debug, Clone)]
enum Op {
    Add(EntityStructure),
    AddBlocking(EntityStructure),
    /// `create_at(vt, x)`.
    CreateAt(Time, f64),
    /// `create_at_now_blocking(x)`.
    CreateAtNowBlocking(f64),
    /// Nothing: the clock moves on, and the runtime releases what is due.
    Wait,
}

/// At `.0` after the script's start, do `.1`.
type Step = (Time, Op);

/// A `Reading` the type refuses (`n` is not a Long).
fn misfit(vt: Time) -> EntityStructure {
    reading(vt, 1.0).with("n", "text")
}

/// Every query of `r` answers what the same query of `w` answers, at the same time.
fn assert_same_answers<T: EntityTrajectoryStructure>(w: &T, r: &T) {
    let name = w.name();
    assert_eq!(contents(r), contents(w), "{name}: stored samples in add order");
    assert_eq!(r.get_latest(), w.get_latest(), "{name}: get_latest");
    let stored = w.stats().unwrap().stored;
    for n in 0..=stored + 1 {
        assert_eq!(r.get_nth_latest(n), w.get_nth_latest(n), "{name}: get_nth_latest({n})");
    }
    assert_eq!(r.start_time(), w.start_time(), "{name}: start_time");
    assert_eq!(r.end_time(), w.end_time(), "{name}: end_time");

    // Every stored valid time, its neighbours, the midpoints (where `Closest` breaks a
    // tie), and beyond both ends.
    let mut sorted: Vec<Time> = contents(w).unwrap().iter().map(|(_, es)| es.valid_time).collect();
    sorted.sort_unstable();
    let mut times = sorted.clone();
    times.extend(sorted.iter().flat_map(|t| [t.saturating_sub(1), t.saturating_add(1)]));
    times.extend(sorted.windows(2).map(|p| {
        let mid = (i128::from(p[0]) + i128::from(p[1])) / 2;
        Time::try_from(mid).unwrap_or(p[0])
    }));
    times.extend([Time::MIN, -1, 0, Time::MAX]);
    times.sort_unstable();
    times.dedup();
    let approximations = [
        ValueApproximation::None,
        ValueApproximation::Closest,
        ValueApproximation::MostRecent,
        ValueApproximation::Linear,
        ValueApproximation::Default(reading(0, 42.0).attributes),
        // Does not fit the type: InvalidDefault on both sides.
        ValueApproximation::Default(misfit(0).attributes),
    ];
    for &t in &times {
        assert_eq!(r.get_at(t), w.get_at(t), "{name}: get_at({t})");
        assert_eq!(
            r.get_closest_at_or_before(t),
            w.get_closest_at_or_before(t),
            "{name}: get_closest_at_or_before({t})"
        );
        for a in &approximations {
            assert_eq!(
                r.get_at_approximating(t, a),
                w.get_at_approximating(t, a),
                "{name}: get_at_approximating({t}, {a:?})"
            );
        }
    }
    for (i, &from) in times.iter().enumerate() {
        for &to in times.iter().skip(i.saturating_sub(1)).step_by(2) {
            assert_eq!(r.get_between(from, to), w.get_between(from, to), "{name}: between");
        }
    }
}

/// Creates `name` with `policy`, runs `script` through the writer (moving the shared
/// clock to `t0` + each step's time), waits until the reader has what the writer
/// stored, and compares every query.
fn run_and_compare<H: Harness>(
    h: &H,
    name: &str,
    policy: FluentStreamPolicy,
    t0: Time,
    script: &[Step],
) {
    let w = h
        .esgm()
        .create_trajectory(TrajectorySpec::primitive(name, "Reading").policy(policy))
        .unwrap_or_else(|e| panic!("create {name}: {e}"));
    let r = read(h, name);
    for (at, op) in script {
        let due = t0 + at;
        if due > h.now() {
            h.advance(due - h.now());
        }
        let outcome = match op.clone() {
            Op::Add(es) => w.add(es),
            Op::AddBlocking(es) => w.add_blocking(es),
            Op::CreateAt(vt, x) => w.create_at("r", t0 + vt, reading(0, x).attributes.into()),
            Op::CreateAtNowBlocking(x) => {
                w.create_at_now_blocking("r", reading(0, x).attributes.into())
            }
            Op::Wait => continue,
        };
        // The outcomes are the writer's store's own; what matters here is what the
        // reader holds and answers afterwards. Only a failure of the runtime is news.
        match outcome {
            Ok(_) | Err(AddError::PolicyViolation(_) | AddError::InvalidType { .. }) => {}
            Err(e) => panic!("{name}: step at {at} failed: {e}"),
        }
    }
    wait_visible(&w, &r);
    assert!(w.stats().is_ok_and(|s| s.stored > 0), "{name}: the script stored nothing");
    assert_same_answers(&w, &r);
}

/// T1/T2 on the reading side: the reader's answers are the writer's, for every query,
/// whatever the policy did to the stream.
pub fn the_reader_answers_every_query_as_the_writer<H: Harness>(h: &H) {
    register_reading(h);
    let t0 = h.now();
    let at = |dt: Time, x: f64| reading(t0 + dt, x);

    // Monotone order, delay 100 with reordering, a cache of 4: structures held,
    // released in valid-time order by later adds and as the clock passes, late ones
    // and a misfit dropped, the last one still held at the end.
    let hold = FluentStreamPolicy::reasonable(100, 4).unwrap();
    let script = [
        (1_000, Op::Add(at(950, 1.0))),
        (1_010, Op::Add(at(940, 2.0))),
        (1_020, Op::AddBlocking(at(900, 3.0))), // delay 120: violation
        (1_045, Op::Add(at(1_000, 4.0))),
        (1_055, Op::Add(at(960, 5.0))),
        (1_070, Op::Add(at(1_000, 6.0))), // an equal valid time
        (1_080, Op::CreateAt(990, 7.0)),
        (1_120, Op::Wait),
        (1_130, Op::Add(at(1_125, 8.0))),
        (1_300, Op::Wait),
        (1_300, Op::Add(at(1_000, 9.0))), // delay 300: dropped
        (1_301, Op::Add(misfit(t0 + 1_300))),
        (1_302, Op::Add(at(1_301, 10.0))), // held, never released
    ];
    run_and_compare(h, "hold_and_reorder", hold, t0, &script);

    // A filter, a duration, a change constraint and a time window over a stream that
    // arrives out of valid-time order.
    let t0 = h.now();
    let at = |dt: Time, x: f64| reading(t0 + dt, x);
    let gated = FluentStreamPolicy::default()
        .filter("x > 2.0")
        .duration(DurationConstraint::Between { from: t0 + 100, to: t0 + 2_000 })
        .change(ChangeConstraint::AnyChange)
        .cache(esgm_core::CacheConstraint::Duration(100));
    let script = [
        (100, Op::Add(at(150, 3.0))),
        (110, Op::Add(at(160, 1.0))), // filter
        (120, Op::Add(at(50, 5.0))),  // before the duration
        (130, Op::Add(at(170, 3.0))), // same value as the previous: change
        (140, Op::Add(at(200, 4.0))),
        (150, Op::Add(at(120, 5.0))), // out of valid-time order, inside the window
        (160, Op::Add(at(100, 6.0))), // 100 before the newest (200): time cache
        (170, Op::Add(at(2_500, 7.0))), // after the duration
        (180, Op::Add(at(260, 8.0))), // evicts 150 and 120 from the cache
        (190, Op::AddBlocking(at(255, 8.0))), // change, returned
        (200, Op::Add(at(230, 9.0))),
        (300, Op::CreateAtNowBlocking(10.0)), // valid at 300: evicts 200
    ];
    run_and_compare(h, "filter_duration_change_cache", gated, t0, &script);

    // Strict order and a sample period (missed sample points).
    let t0 = h.now();
    let at = |dt: Time, x: f64| reading(t0 + dt, x);
    let strict = FluentStreamPolicy::default()
        .order(OrderConstraint::StrictMonotone)
        .change(ChangeConstraint::SampleEvery(10));
    let mut script = vec![
        (100, Op::Add(at(100, 1.0))),
        (101, Op::Add(at(105, 2.0))),         // too soon: change
        (102, Op::AddBlocking(at(100, 3.0))), // not after 100: order
        (103, Op::Add(at(110, 4.0))),
        (104, Op::Add(at(140, 5.0))), // two sample points missed
    ];
    script.extend((0..5).map(|i| (105 + i, Op::Add(at(150 + 10 * i, i as f64)))));
    run_and_compare(h, "strict_order_sample_period", strict, t0, &script);

    // Unconstrained, out of valid-time order with repeated valid times: the index.
    let t0 = h.now();
    let script: Vec<Step> = [30, 10, 20, 20, 50, 40, 10, 60]
        .into_iter()
        .enumerate()
        .map(|(i, vt)| (i as Time, Op::Add(reading(t0 + vt, i as f64))))
        .collect();
    run_and_compare(h, "out_of_order", FluentStreamPolicy::default(), t0, &script);
}

/// Valid times at both ends of the timeline cross to the reader and are queried
/// without overflow: the closest sample to 0 is the one at the end (one nearer), a
/// linear approximation at 0 lies between the ends.
pub fn extreme_valid_times_are_queried<H: Harness>(h: &H) {
    register_reading(h);
    let w = h.esgm().create_primitive_entity_trajectory_structure("extremes", "Reading").unwrap();
    let r = read(h, "extremes");
    for (vt, x) in [(Time::MIN, 1.0), (Time::MAX, 2.0), (Time::MIN, 3.0)] {
        w.add(reading(vt, x)).unwrap();
    }
    wait_visible(&w, &r);
    let closest = r.get_at_approximating(0, &ValueApproximation::Closest).unwrap();
    assert_eq!(closest.structure.valid_time(), Time::MAX);
    let linear = r.get_at_approximating(0, &ValueApproximation::Linear).unwrap();
    assert_eq!(linear.structure.valid_time(), 0);
    assert_eq!(r.get_between(Time::MIN, Time::MAX).unwrap().len(), 3);
    assert_eq!((r.start_time(), r.end_time()), (Ok(Time::MIN), Ok(Time::MAX)));
    assert_same_answers(&w, &r);
}

/// Linear interpolation covers sequences of points, vectors and frames element-wise
/// when both sides have the same length. Where they differ, the answer holds the most
/// recent value and says so (`not_interpolated`), or the strict rule refuses it naming
/// the attribute; a string holds the earlier value by its nature, unmarked.
pub fn linear_interpolates_sequences_element_wise_or_says_it_did_not<H: Harness>(h: &H) {
    use esgm_core::{EntityFrame, Pos2, Value, ValueSort, Vec3};
    let e = h.esgm();
    let path = esgm_core::EntityStructureType::new("Path")
        .attr("points", ValueSort::Pos2Seq)
        .attr("normals", ValueSort::VecSeq)
        .attr("stops", ValueSort::EntityFrameSeq)
        .attr("label", ValueSort::String);
    e.create_entity_structure_type("Path", path).unwrap();
    let frame = |x: f64| EntityFrame::new("stop").with("x", x);
    let at = |vt: Time, k: f64, n: usize| {
        EntityStructure::new("p", vt, vt)
            .with("points", Value::Pos2Seq(vec![Pos2 { x: k, y: -k }; n]))
            .with("normals", Value::VecSeq(vec![Vec3 { x: 0.0, y: k, z: 1.0 }; n]))
            .with("stops", Value::EntityFrameSeq(vec![frame(k); 2]))
            .with("label", if k == 0.0 { "start" } else { "end" })
    };
    let w = e.create_primitive_entity_trajectory_structure("path", "Path").unwrap();
    let r = read(h, "path");
    w.add(at(0, 0.0, 2)).unwrap();
    w.add(at(100, 10.0, 2)).unwrap();
    w.add(at(200, 20.0, 3)).unwrap();
    wait_visible(&w, &r);

    let mid = r.get_at_approximating(25, &ValueApproximation::Linear).unwrap();
    assert_eq!(mid.not_interpolated, None, "same lengths: interpolated throughout");
    assert_eq!(mid.value("points"), Some(Value::Pos2Seq(vec![Pos2 { x: 2.5, y: -2.5 }; 2])));
    assert_eq!(mid.value("normals"), Some(Value::VecSeq(vec![Vec3 { x: 0.0, y: 2.5, z: 1.0 }; 2])));
    assert_eq!(mid.value("stops"), Some(Value::EntityFrameSeq(vec![frame(2.5); 2])));
    assert_eq!(mid.get("label").and_then(|v| v.as_str()), Some("start"));
    let strict = r.get_at_approximating(25, &ValueApproximation::LinearStrict).unwrap();
    assert_eq!(strict.structure, mid.structure);

    // 2 points before, 3 after: the points and normals hold the value at 100, marked;
    // the frames (2 on both sides) are interpolated.
    let held = r.get_at_approximating(150, &ValueApproximation::Linear).unwrap();
    let marked: Vec<&str> =
        held.not_interpolated.as_deref().unwrap_or_default().iter().map(String::as_str).collect();
    assert_eq!(marked, ["points", "normals"]);
    assert_eq!(held.value("points"), Some(Value::Pos2Seq(vec![Pos2 { x: 10.0, y: -10.0 }; 2])));
    assert_eq!(held.value("stops"), Some(Value::EntityFrameSeq(vec![frame(15.0); 2])));
    let refused = r.get_at_approximating(150, &ValueApproximation::LinearStrict).unwrap_err();
    assert!(refused.to_string().contains("`points`"), "{refused}");
    assert_eq!(
        w.get_at_approximating(150, &ValueApproximation::Linear).unwrap().not_interpolated,
        held.not_interpolated,
        "the writer answers the same"
    );
}
