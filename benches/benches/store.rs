//! Criterion micro-benchmarks of the trajectory store: add throughput, time lookups and
//! range queries, each next to a plain-collection baseline measured in the same run, so
//! that ratios stay meaningful on a noisy machine.
//!
//! Run: `cargo bench -p esgm-benches --bench store` (settings are short on purpose:
//! 1 s warm-up, 2 s measurement per benchmark). `-- --test` runs each one once.
//!
//! What is measured:
//! - `add/*`: one `add` into a store with an `Elements(1000)` cache, in steady state
//!   (every add evicts the oldest sample), unconstrained order on a simulated clock.
//!   `store_add_clone/*` includes cloning a small template structure and setting its
//!   valid time, because `add` takes an owned structure; `store_add_shared/*` hands over
//!   pre-made `Arc`s with `add_shared` (evicting one frees it, as in a runtime that
//!   passes its `Arc` on). `baseline_vecdeque/*` does the same clone into a
//!   `VecDeque<(Time, Arc<EntityStructure>)>` capped at 1000: the floor for any store.
//! - `query/<n>/*`: lookups on stores of `n` samples valid at 0, 10, 20, …, at times
//!   spread over the whole range by a precomputed pseudo-random list. Exact times hit a
//!   sample; the others fall halfway between two. The baselines answer
//!   "at or before t" from a `VecDeque` by binary search and from a `BTreeMap`;
//!   `baseline_vecdeque/*` keeps each valid time next to its `Arc`, while
//!   `baseline_vecdeque_deref/*` reads it through the `Arc` as the store's history does,
//!   which separates the cost of that layout (a cache miss per probe on a large store)
//!   from the store's own work.
// A benchmark that cannot set itself up should stop at once and say why.
#![allow(clippy::expect_used)]

use std::collections::{BTreeMap, VecDeque};
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use esgm_core::library::{Blob, RobotState};
use esgm_core::{
    CacheConstraint, Entity, EntityStructure, FluentStreamPolicy, SimClock, Time, TrajectoryStore,
    TypeChecker, TypeRegistry, ValueApproximation,
};

/// Valid times are 0, PERIOD, 2 PERIOD, …
const PERIOD: Time = 10;
/// The cache of the add benchmarks.
const CACHE: usize = 1_000;
/// Query times per list (a power of two, cycled through with a mask).
const QUERIES: usize = 4_096;
/// Pre-made `Arc`s per timed chunk of `store_add_shared`.
const SHARED_CHUNK: i64 = 512;
/// Samples `get_between` returns.
const RANGE: Time = 100;

fn store(type_name: &str, cache: CacheConstraint) -> TrajectoryStore {
    let checker = TypeChecker::new(&TypeRegistry::with_library(), type_name)
        .expect("the library defines the type");
    TrajectoryStore::builder("bench", checker)
        .policy(FluentStreamPolicy::unconstrained().cache(cache))
        .clock(SimClock::shared(0))
        .create()
        .expect("an unconstrained policy is valid")
}

fn blob(i: i64) -> EntityStructure {
    Blob { x: i, y: 2 * i, size: 3 }.to_structure("blob", i * PERIOD, i * PERIOD)
}

fn robot_state(i: i64) -> EntityStructure {
    let f = i as f64;
    RobotState { x: f, y: 2.0 * f, dir: 90.0 }.to_structure("robot", i * PERIOD, i * PERIOD)
}

/// `count` indices in `0..n`, spread over the range in a fixed pseudo-random order
/// (a linear congruential generator: no dependency, same list every run).
fn spread(n: usize, count: usize) -> Vec<i64> {
    let mut x: u64 = 0x2545_f491_4f6c_dd1d;
    (0..count)
        .map(|_| {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            ((x >> 33) % n as u64) as i64
        })
        .collect()
}

fn add(c: &mut Criterion) {
    let mut group = c.benchmark_group("add");
    group.throughput(Throughput::Elements(1));

    for (type_name, make) in
        [("Blob", blob as fn(i64) -> EntityStructure), ("RobotState", robot_state)]
    {
        group.bench_function(BenchmarkId::new("store_add_clone", type_name), |b| {
            let mut s = store(type_name, CacheConstraint::Elements(CACHE));
            for i in 0..CACHE as i64 {
                s.add(make(i)).expect("well-typed");
            }
            let template = make(0);
            let mut vt = CACHE as Time * PERIOD;
            b.iter(|| {
                let mut es = template.clone();
                es.valid_time = vt;
                vt += PERIOD;
                s.add(es)
            });
            let stats = s.stats();
            assert_eq!((stats.dropped_total, stats.stored), (0, CACHE), "{stats:?}");
        });
    }

    group.bench_function(BenchmarkId::new("store_add_shared", "Blob"), |b| {
        b.iter_custom(|iters| {
            let mut s = store("Blob", CacheConstraint::Elements(CACHE));
            for i in 0..CACHE as i64 {
                s.add(blob(i)).expect("well-typed");
            }
            // The `Arc`s are made (untimed) in chunks just before they are added, so
            // they are as warm in cache as a structure a runtime has just received.
            let mut elapsed = Duration::ZERO;
            let mut next = CACHE as i64;
            let end = next + iters as i64;
            while next < end {
                let chunk = (end - next).min(SHARED_CHUNK);
                let arcs: Vec<Arc<EntityStructure>> =
                    (next..next + chunk).map(|i| Arc::new(blob(i))).collect();
                next += chunk;
                let start = Instant::now();
                for es in arcs {
                    black_box(s.add_shared(es, false)).expect("well-typed");
                }
                elapsed += start.elapsed();
            }
            assert_eq!(s.stats().dropped_total, 0);
            elapsed
        });
    });

    group.bench_function(BenchmarkId::new("baseline_vecdeque", "Blob"), |b| {
        let mut q: VecDeque<(Time, Arc<EntityStructure>)> = VecDeque::with_capacity(CACHE + 1);
        for i in 0..CACHE as i64 {
            q.push_back((i * PERIOD, Arc::new(blob(i))));
        }
        let template = blob(0);
        let mut vt = CACHE as Time * PERIOD;
        b.iter(|| {
            let mut es = template.clone();
            es.valid_time = vt;
            vt += PERIOD;
            q.push_back((es.valid_time, Arc::new(es)));
            if q.len() > CACHE { q.pop_front() } else { None }
        });
    });

    group.finish();
}

/// A store of `n` Blob samples valid at 0, 10, 20, …, and the same `Arc`s in the two
/// baseline collections.
struct Filled {
    store: TrajectoryStore,
    deque: VecDeque<(Time, Arc<EntityStructure>)>,
    tree: BTreeMap<Time, Arc<EntityStructure>>,
}

fn filled(n: usize) -> Filled {
    let mut store = store("Blob", CacheConstraint::All);
    let mut deque = VecDeque::with_capacity(n);
    let mut tree = BTreeMap::new();
    for i in 0..n as i64 {
        let es = Arc::new(blob(i));
        store.add_shared(Arc::clone(&es), false).expect("well-typed");
        deque.push_back((es.valid_time, Arc::clone(&es)));
        tree.insert(es.valid_time, es);
    }
    Filled { store, deque, tree }
}

fn query(c: &mut Criterion) {
    for n in [1_000usize, 1_000_000] {
        let f = filled(n);
        let s = &f.store;
        // Exact sample times, and times halfway between two samples (never after the
        // last, so linear interpolation always has both sides).
        let exact: Vec<Time> = spread(n, QUERIES).into_iter().map(|i| i * PERIOD).collect();
        let between: Vec<Time> =
            spread(n - 1, QUERIES).into_iter().map(|i| i * PERIOD + PERIOD / 2).collect();
        let starts: Vec<Time> =
            spread(n - RANGE as usize, QUERIES).into_iter().map(|i| i * PERIOD).collect();

        // Every benchmark below measures a successful answer, not an error path.
        assert!(s.get_at(exact[0]).is_ok());
        assert!(s.get_at_approximating(between[0], &ValueApproximation::Linear).is_ok());
        assert_eq!(s.get_between(starts[0], starts[0] + (RANGE - 1) * PERIOD).len(), 100);

        let mut group = c.benchmark_group(format!("query/{n}"));
        let mask = QUERIES - 1;
        let mut k = 0usize;
        let mut next = move |list: &[Time]| {
            k = k.wrapping_add(1);
            list[k & mask]
        };

        group.bench_function("get_at", |b| b.iter(|| s.get_at(next(&exact))));
        group.bench_function("get_closest_at_or_before", |b| {
            b.iter(|| s.get_closest_at_or_before(next(&between)))
        });
        group.bench_function("get_at_approximating/most_recent", |b| {
            b.iter(|| s.get_at_approximating(next(&between), &ValueApproximation::MostRecent))
        });
        group.bench_function("get_at_approximating/linear", |b| {
            b.iter(|| s.get_at_approximating(next(&between), &ValueApproximation::Linear))
        });
        group.bench_function("get_between_100", |b| {
            b.iter(|| {
                let from = next(&starts);
                s.get_between(from, from + (RANGE - 1) * PERIOD)
            })
        });

        let deque = &f.deque;
        group.bench_function("baseline_vecdeque/at_or_before", |b| {
            b.iter(|| {
                let t = next(&between);
                let i = deque.partition_point(|(vt, _)| *vt <= t);
                i.checked_sub(1).map(|i| Arc::clone(&deque[i].1))
            })
        });
        group.bench_function("baseline_vecdeque/between_100", |b| {
            b.iter(|| {
                let from = next(&starts);
                let to = from + (RANGE - 1) * PERIOD;
                let lo = deque.partition_point(|(vt, _)| *vt < from);
                let hi = deque.partition_point(|(vt, _)| *vt <= to);
                deque.range(lo..hi).map(|(_, es)| Arc::clone(es)).collect::<Vec<_>>()
            })
        });
        // The store's own layout: the valid time is read through each entry's `Arc`.
        let arcs: VecDeque<Arc<EntityStructure>> =
            deque.iter().map(|(_, es)| Arc::clone(es)).collect();
        group.bench_function("baseline_vecdeque_deref/at_or_before", |b| {
            b.iter(|| {
                let t = next(&between);
                let i = arcs.partition_point(|es| es.valid_time <= t);
                i.checked_sub(1).map(|i| Arc::clone(&arcs[i]))
            })
        });
        let tree = &f.tree;
        group.bench_function("baseline_btreemap/at_or_before", |b| {
            b.iter(|| tree.range(..=next(&between)).next_back().map(|(_, es)| Arc::clone(es)))
        });
        group.finish();
    }
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .sample_size(50)
}

criterion_group! {
    name = benches;
    config = config();
    targets = add, query
}
criterion_main!(benches);
