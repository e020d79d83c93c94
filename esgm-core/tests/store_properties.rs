//! Property tests of the trajectory store: random policies, random operation sequences
//! on a simulated clock, and invariants checked after every operation.
//!
//! Every offered structure carries a unique tag in its create time (no constraint
//! generated here reads create times), so the test can follow each one to exactly one
//! fate: delivered to the subscriber (added), reported to the violation subscriber or
//! refused as ill-typed (dropped), held for reordering, or dropped by a reset. The model
//! built from those observations is compared with the store's own stats, and queries are
//! compared with naive scans over `samples()`.

// Helpers outside `#[test]` functions: a panic there is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;
use std::sync::Arc;

use esgm_core::library::Blob;
use esgm_core::{
    AddError, AddOutcome, CacheConstraint, ChangeConstraint, Constraint, DelayConstraint,
    DropCause, DurationConstraint, Entity, EntityStructure, FluentStreamPolicy, OrderConstraint,
    PolicyViolation, QueryError, Sample, SimClock, SubscribeOptions, Subscription, Time,
    TrajectoryStore, TypeChecker, TypeRegistry,
};
use proptest::prelude::*;

/// Where the simulated clock starts (a positive time, so `from = 0` means "now" ≠ 0).
const START: Time = 1_000;

/// One step of a test case.
#[derive(Debug, Clone)]
enum Op {
    /// Offer a structure valid at `now + dvt` whose `x` is `x` (a small range, so that
    /// "any change" sees repeats); `ill` makes it ill-typed.
    Add { dvt: Time, x: i64, ill: Option<Ill> },
    /// Move the clock forward.
    Advance(Time),
    /// Release held samples that are due.
    Release,
    /// Empty the stream.
    Reset,
}

/// Ways to make a `Blob` ill-typed.
#[derive(Debug, Clone, Copy)]
enum Ill {
    MissingAttribute,
    WrongSort,
    UnknownAttribute,
}

fn policy() -> impl Strategy<Value = FluentStreamPolicy> {
    let cache = prop_oneof![
        Just(CacheConstraint::All),
        (1usize..20).prop_map(CacheConstraint::Elements),
        (1i64..500).prop_map(CacheConstraint::Duration),
    ];
    let order = prop_oneof![
        Just(OrderConstraint::Any),
        Just(OrderConstraint::Monotone),
        Just(OrderConstraint::StrictMonotone),
    ];
    let delay = prop_oneof![Just(DelayConstraint::Any), (1i64..300).prop_map(DelayConstraint::Max)];
    let change = prop_oneof![
        2 => Just(ChangeConstraint::Unconstrained),
        1 => Just(ChangeConstraint::AnyChange),
        1 => (1i64..50).prop_map(ChangeConstraint::SampleEvery),
    ];
    // `from = 0` is the creation time (START); `to = 0` is forever.
    let duration = prop_oneof![
        2 => Just(DurationConstraint::Unbounded),
        1 => (prop_oneof![Just(0i64), 500i64..1_500], proptest::option::of(0i64..3_000)).prop_map(
            |(from, span)| {
                let start = if from == 0 { START } else { from };
                DurationConstraint::Between { from, to: span.map_or(0, |s| start + s) }
            }
        ),
    ];
    let filter = proptest::option::weighted(0.15, Just("x > 0".to_owned()));
    (cache, order, delay, any::<bool>(), change, duration, filter).prop_map(
        |(cache, order, delay, reorder, change, duration, filter)| FluentStreamPolicy {
            change,
            cache,
            filter,
            duration,
            order,
            delay,
            reorder,
        },
    )
}

fn op() -> impl Strategy<Value = Op> {
    let ill = prop_oneof![
        30 => Just(None),
        1 => Just(Some(Ill::MissingAttribute)),
        1 => Just(Some(Ill::WrongSort)),
        1 => Just(Some(Ill::UnknownAttribute)),
    ];
    prop_oneof![
        12 => (-350i64..100, 0i64..3, ill).prop_map(|(dvt, x, ill)| Op::Add { dvt, x, ill }),
        6 => (0i64..200).prop_map(Op::Advance),
        2 => Just(Op::Release),
        1 => Just(Op::Reset),
    ]
}

/// A test case: a policy, the operations, and query points (offsets from the clock,
/// with a span for `get_between`) that are cycled through, a few per operation.
fn case() -> impl Strategy<Value = (FluentStreamPolicy, Vec<Op>, Vec<(Time, Time)>)> {
    (
        policy(),
        proptest::collection::vec(op(), 1..60),
        proptest::collection::vec((-500i64..150, -20i64..400), 4..12),
    )
}

/// The same stream with order `Any`, so that out-of-order arrivals exercise the store's
/// valid-time index.
fn unordered_case() -> impl Strategy<Value = (FluentStreamPolicy, Vec<Op>, Vec<(Time, Time)>)> {
    case().prop_map(|(p, ops, queries)| (p.order(OrderConstraint::Any), ops, queries))
}

/// What became of one offered structure, as observed from outside the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fate {
    Held,
    Added,
    Dropped(DropCause),
}

struct Harness {
    clock: Arc<SimClock>,
    store: TrajectoryStore,
    sub: Subscription<Sample>,
    violations: Subscription<PolicyViolation>,
    /// Fate of every offered structure, by tag.
    fates: BTreeMap<Time, Fate>,
    /// Tags the subscriber received since the last reset, in order.
    epoch: Vec<(Time, Time)>,
    /// Samples the store held when it was reset (they are not evicted).
    cleared: u64,
    next_tag: Time,
}

fn blob(tag: Time, vt: Time, x: i64, ill: Option<Ill>) -> EntityStructure {
    let mut es = Blob { x, y: 7, size: 3 }.to_structure("b", vt, tag);
    match ill {
        None => {}
        Some(Ill::MissingAttribute) => {
            es.attributes.pop();
        }
        Some(Ill::WrongSort) => es.set("y", 7.0),
        Some(Ill::UnknownAttribute) => es.set("colour", "red"),
    }
    es
}

impl Harness {
    fn new(policy: FluentStreamPolicy) -> Self {
        let clock = SimClock::shared(START);
        let checker = TypeChecker::new(&TypeRegistry::with_library(), "Blob").unwrap();
        let mut store = TrajectoryStore::builder("blobs", checker)
            .policy(policy)
            .clock(clock.clone())
            .create()
            .unwrap();
        let sub = store.subscribe(SubscribeOptions::default().capacity(4096));
        let violations = store.subscribe_violations(4096);
        Self {
            clock,
            store,
            sub,
            violations,
            fates: BTreeMap::new(),
            epoch: Vec::new(),
            cleared: 0,
            next_tag: 1,
        }
    }

    /// Moves a structure to its new fate; it must have been just offered or held.
    fn settle(&mut self, tag: Time, fate: Fate, fresh: Option<Time>) {
        let before = self.fates.get(&tag).copied();
        assert!(
            before == Some(Fate::Held) || (before.is_none() && fresh == Some(tag)),
            "structure {tag} became {fate:?} but was {before:?}"
        );
        self.fates.insert(tag, fate);
    }

    /// Reads what the subscribers got during one operation and records the fates;
    /// returns how many samples entered the stream.
    fn observe(&mut self, fresh: Option<Time>) -> usize {
        let received = self.sub.drain();
        for s in &received {
            self.settle(s.create_time(), Fate::Added, fresh);
            self.epoch.push((s.valid_time(), s.create_time()));
        }
        for v in self.violations.drain() {
            self.settle(v.create_time, Fate::Dropped(DropCause::Violation(v.constraint)), fresh);
        }
        received.len()
    }

    fn step(&mut self, op: &Op) {
        match *op {
            Op::Add { dvt, x, ill } => {
                let tag = self.next_tag;
                self.next_tag += 1;
                let es = blob(tag, self.clock.now() + dvt, x, ill);
                let result = self.store.add(es);
                self.observe(Some(tag));
                let seen = self.fates.get(&tag).copied();
                match result {
                    Ok(AddOutcome::Added) => assert_eq!(seen, Some(Fate::Added)),
                    Ok(AddOutcome::Dropped(v)) => {
                        assert_eq!(v.create_time, tag);
                        assert_eq!(seen, Some(Fate::Dropped(DropCause::Violation(v.constraint))));
                    }
                    Ok(AddOutcome::Held { release_at }) => {
                        assert_eq!(seen, None, "a held structure was also delivered");
                        assert!(release_at > self.clock.now());
                        let next = self.store.next_release_time();
                        assert!(next.is_some_and(|n| n <= release_at), "{next:?} > {release_at}");
                        self.fates.insert(tag, Fate::Held);
                    }
                    Err(AddError::InvalidType { .. }) => {
                        assert!(ill.is_some(), "a well-typed structure was refused");
                        assert_eq!(seen, None, "an ill-typed structure was also delivered");
                        self.fates.insert(tag, Fate::Dropped(DropCause::InvalidType));
                    }
                    Ok(AddOutcome::Forwarded) => {
                        panic!("a store without a writer elsewhere forwarded")
                    }
                    Err(e) => panic!("unexpected error {e}"),
                }
                if ill.is_some() {
                    assert_eq!(self.fates[&tag], Fate::Dropped(DropCause::InvalidType));
                }
            }
            Op::Advance(d) => {
                self.clock.advance(d);
                assert_eq!(self.observe(None), 0, "advancing the clock alone added something");
            }
            Op::Release => {
                let released = self.store.release_due();
                assert_eq!(self.observe(None), released, "release_due miscounted");
                let now = self.clock.now();
                assert!(self.store.next_release_time().is_none_or(|t| t > now));
            }
            Op::Reset => {
                self.cleared += self.store.len() as u64;
                self.store.reset();
                assert_eq!(self.observe(None), 0, "reset added something");
                for fate in self.fates.values_mut() {
                    if *fate == Fate::Held {
                        *fate = Fate::Dropped(DropCause::Reset);
                    }
                }
                self.epoch.clear();
                assert!(self.store.is_empty());
                assert_eq!(self.store.next_release_time(), None);
            }
        }
    }

    /// Invariants that hold after every operation.
    fn check_invariants(&self) {
        let store = &self.store;
        let policy = store.policy();
        let stats = store.stats();
        let samples = store.samples();
        let vts: Vec<Time> = samples.iter().map(|s| s.valid_time()).collect();

        // Accounting: every offered structure has exactly one fate, and the stats agree.
        let offered = (self.next_tag - 1) as u64;
        assert_eq!(self.fates.len() as u64, offered, "a structure has no fate");
        let count = |f: Fate| self.fates.values().filter(|x| **x == f).count() as u64;
        assert_eq!(stats.added, count(Fate::Added), "added");
        assert_eq!(stats.held as u64, count(Fate::Held), "held");
        let mut dropped: BTreeMap<DropCause, u64> = BTreeMap::new();
        for fate in self.fates.values() {
            if let Fate::Dropped(cause) = fate {
                *dropped.entry(*cause).or_default() += 1;
            }
        }
        let reported: BTreeMap<DropCause, u64> =
            stats.dropped.iter().copied().filter(|(_, n)| *n > 0).collect();
        assert_eq!(reported, dropped, "drops by cause");
        assert_eq!(stats.dropped_total, stats.dropped.iter().map(|(_, n)| n).sum::<u64>());
        assert_eq!(offered, stats.added + stats.dropped_total + stats.held as u64);
        assert_eq!(stats.evicted + stats.stored as u64, stats.added - self.cleared);
        assert_eq!(stats.stored, store.len());
        assert_eq!(samples.len(), store.len());
        assert_eq!(self.sub.overflowed(), 0);
        assert_eq!(self.violations.overflowed(), 0);

        // Every stored sample was delivered in this epoch, in the same relative order.
        let mut delivered = self.epoch.iter();
        for s in &samples {
            assert!(
                delivered.any(|(_, tag)| *tag == s.create_time()),
                "stored sample {} is not a subsequence of what was delivered",
                s.create_time()
            );
        }

        // Cache.
        match policy.cache {
            CacheConstraint::Elements(n) => assert!(store.len() <= n, "{} > {n}", store.len()),
            CacheConstraint::Duration(t) => {
                if let Some(max) = vts.iter().max() {
                    assert!(vts.iter().all(|vt| max - vt < t), "{vts:?} spans {t} or more");
                    assert_eq!(store.end_time().ok(), Some(*max));
                }
            }
            CacheConstraint::All => {}
        }
        assert_eq!(store.start_time().ok(), vts.iter().min().copied());
        assert_eq!(store.end_time().ok(), vts.iter().max().copied());

        // Order, of what is stored and of what the subscriber received.
        let epoch_vts: Vec<Time> = self.epoch.iter().map(|(vt, _)| *vt).collect();
        for (what, v) in [("stored", &vts), ("delivered", &epoch_vts)] {
            match policy.order {
                OrderConstraint::Monotone => {
                    assert!(v.windows(2).all(|w| w[0] <= w[1]), "{what} not monotone: {v:?}")
                }
                OrderConstraint::StrictMonotone => {
                    assert!(v.windows(2).all(|w| w[0] < w[1]), "{what} not strict: {v:?}")
                }
                OrderConstraint::Any => {}
            }
        }

        // Duration.
        if let DurationConstraint::Between { from, to } = policy.duration {
            let from = if from == 0 { START } else { from };
            assert!(vts.iter().all(|vt| *vt >= from && (to == 0 || *vt <= to)), "{vts:?}");
        }
    }

    /// Queries agree with naive scans over `samples()` (add order).
    fn check_queries(&self, t: Time, span: Time) {
        let store = &self.store;
        let samples = store.samples();
        let tags = |v: &[Sample]| v.iter().map(|s| (s.valid_time(), s.create_time())).collect();

        let (a, b) = (t, t + span);
        let mut expected: Vec<Sample> = samples
            .iter()
            .filter(|s| a <= s.valid_time() && s.valid_time() <= b)
            .cloned()
            .collect();
        // A stable sort keeps add order among equal valid times.
        expected.sort_by_key(|s| s.valid_time());
        let got: Vec<(Time, Time)> = tags(&store.get_between(a, b));
        assert_eq!(got, tags(&expected), "get_between({a}, {b})");

        // The largest valid time ≤ t, the latest added among equals.
        let closest =
            samples.iter().filter(|s| s.valid_time() <= t).fold(None::<&Sample>, |m, s| match m {
                Some(m) if m.valid_time() > s.valid_time() => Some(m),
                _ => Some(s),
            });
        let got = store.get_closest_at_or_before(t);
        match closest {
            Some(c) => assert_eq!(
                got.as_ref().map(|s| (s.valid_time(), s.create_time())).ok(),
                Some((c.valid_time(), c.create_time())),
                "get_closest_at_or_before({t})"
            ),
            None => assert!(
                matches!(got, Err(QueryError::ValueNotAvailable { .. })),
                "get_closest_at_or_before({t}) = {got:?}, nothing stored at or before"
            ),
        }

        let exact = samples.iter().rfind(|s| s.valid_time() == t);
        let got = store.get_at(t);
        assert_eq!(
            got.as_ref().map(|s| s.create_time()).ok(),
            exact.map(|s| s.create_time()),
            "get_at({t})"
        );
    }
}

fn run(policy: FluentStreamPolicy, ops: &[Op], queries: &[(Time, Time)]) {
    let mut h = Harness::new(policy);
    let mut q = queries.iter().cycle();
    for op in ops {
        h.step(op);
        h.check_invariants();
        for _ in 0..2 {
            if let Some((dt, span)) = q.next() {
                h.check_queries(h.clock.now() + dt, *span);
            }
        }
    }
    // At the end, at and around every stored valid time.
    for vt in h.store.samples().iter().map(|s| s.valid_time()) {
        for t in [vt - 1, vt, vt + 1] {
            h.check_queries(t, 0);
            h.check_queries(t, 15);
        }
    }
}

/// A monotone stream that holds late samples for reordering (C6), where most of the
/// held / released / reset bookkeeping happens.
fn reordering_case() -> impl Strategy<Value = (FluentStreamPolicy, Vec<Op>, Vec<(Time, Time)>)> {
    (
        case(),
        prop_oneof![Just(OrderConstraint::Monotone), Just(OrderConstraint::StrictMonotone)],
        1i64..300,
    )
        .prop_map(|((p, ops, queries), order, delay)| {
            (p.order(order).delay(DelayConstraint::Max(delay)).reorder(true), ops, queries)
        })
}

proptest! {
    #[test]
    fn store_invariants_hold_for_random_policies((policy, ops, queries) in case()) {
        run(policy, &ops, &queries);
    }

    #[test]
    fn queries_agree_with_a_scan_on_out_of_order_streams(
        (policy, ops, queries) in unordered_case()
    ) {
        run(policy, &ops, &queries);
    }

    #[test]
    fn held_samples_are_released_in_order_or_accounted(
        (policy, ops, queries) in reordering_case()
    ) {
        run(policy, &ops, &queries);
    }
}

/// The deterministic corner of the properties above: a monotone, reordering stream
/// with a held sample reset away, and an out-of-order one that builds the index.
#[test]
fn held_samples_dropped_by_reset_are_accounted() {
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .delay(DelayConstraint::Max(100));
    let ops = [
        Op::Add { dvt: -10, x: 1, ill: None },
        Op::Add { dvt: -20, x: 1, ill: None },
        Op::Advance(85),
        Op::Release,
        Op::Reset,
        Op::Add { dvt: -5, x: 2, ill: Some(Ill::WrongSort) },
        Op::Add { dvt: -500, x: 2, ill: None },
    ];
    let mut h = Harness::new(policy);
    for op in &ops {
        h.step(op);
        h.check_invariants();
    }
    let stats = h.store.stats();
    assert_eq!(stats.dropped_for(DropCause::Reset), 1);
    assert_eq!(stats.dropped_for(DropCause::InvalidType), 1);
    assert_eq!(stats.dropped_for(DropCause::Violation(Constraint::Delay)), 1);
    assert_eq!(stats.added, 1);
}
