//! Trajectories with policy and history over shared memory: the writer gates on one
//! thread with its own node, readers keep the history on others (as separate processes
//! would), and every outcome, stream and query answer is compared with an in-process
//! `TrajectoryStore` fed the same structures at the same (simulated) times.
//!
//! Every test has its own domain and every wait a timeout, so the tests run in
//! parallel.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
mod history_support;

use std::sync::Arc;
use std::sync::mpsc;
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use common::{TIMEOUT, node};
use esgm_core::codec;
use esgm_core::{
    CacheConstraint, ChangeConstraint, Constraint, DelayConstraint, DurationConstraint,
    FluentStreamPolicy, OrderConstraint, PolicyViolation, QueryError, SimClock, Time,
    ValueApproximation,
};
use esgm_shm::payload::{Block16, blocks_for};
use esgm_shm::service_name::data_service_name;
use esgm_shm::{
    HistoryError, HostedTrajectoryReader, SampleHeader, ShmTrajectoryReader, ShmTrajectoryWriter,
    TrajectoryQos, ViolationSubscriber, WriterCreateError, WriterStats, type_id, unique_domain,
};
use history_support::*;
use iceoryx2::prelude::ServiceName;

/// How both ends of a trajectory are configured.
#[derive(Debug, Clone)]
struct Setup {
    domain: String,
    policy: FluentStreamPolicy,
    qos: TrajectoryQos,
    max_history: usize,
    start: Time,
}

impl Setup {
    fn new(test: &str, policy: FluentStreamPolicy, start: Time) -> Self {
        Self {
            domain: unique_domain(test),
            policy,
            // Room for every sample a script publishes, so a reader that is not
            // reading yet loses none.
            qos: TrajectoryQos { subscriber_buffer_size: 64, ..TrajectoryQos::default() },
            max_history: 64,
            start,
        }
    }

    fn reader(&self, clock: Arc<SimClock>) -> esgm_shm::reader::ShmTrajectoryReaderBuilder {
        ShmTrajectoryReader::builder(TRAJECTORY, checker())
            .domain(&self.domain)
            .policy(self.policy.clone())
            .qos(self.qos)
            .max_history(self.max_history)
            .clock(clock)
    }
}

enum Ctl {
    UpdateConnections,
    Finish,
}

/// The writer on a thread of its own (with its own node), running a script.
struct WriterThread {
    ctl: mpsc::Sender<Ctl>,
    acks: mpsc::Receiver<()>,
    did: mpsc::Receiver<Vec<Did>>,
    handle: Option<JoinHandle<WriterStats>>,
}

impl WriterThread {
    fn spawn(setup: &Setup, script: Vec<Step>) -> Self {
        let setup = setup.clone();
        let (ctl, ctl_rx) = mpsc::channel();
        let (ack_tx, acks) = mpsc::channel();
        let (did_tx, did) = mpsc::channel();
        let handle = thread::spawn(move || {
            let n = node();
            let clock = SimClock::shared(setup.start);
            let mut w = ShmTrajectoryWriter::builder(TRAJECTORY, checker())
                .domain(&setup.domain)
                .policy(setup.policy.clone())
                .qos(setup.qos)
                .max_history(setup.max_history)
                .clock(clock.clone())
                .create(&n)
                .unwrap();
            let results = run_script(&mut w, &clock, script);
            did_tx.send(results).unwrap();
            // Stay alive (the publisher with its history) until the test is done.
            // A timeout or `Finish` ends it.
            while let Ok(Ctl::UpdateConnections) = ctl_rx.recv_timeout(TIMEOUT) {
                w.update_connections().unwrap();
                let _ = ack_tx.send(());
            }
            w.stats()
        });
        Self { ctl, acks, did, handle: Some(handle) }
    }

    fn outcomes(&self) -> Vec<Did> {
        self.did.recv_timeout(TIMEOUT).expect("the writer ran its script")
    }

    fn update_connections(&self) {
        self.ctl.send(Ctl::UpdateConnections).unwrap();
        self.acks.recv_timeout(TIMEOUT).expect("the writer updated its connections");
    }

    fn finish(mut self) -> WriterStats {
        let _ = self.ctl.send(Ctl::Finish);
        self.handle.take().unwrap().join().expect("writer thread")
    }
}

/// Runs `script` through a writer thread and a reader (created first, so it sees the
/// whole stream) and through an in-process store, and compares everything.
fn run_and_compare(test: &str, policy: FluentStreamPolicy, start: Time, script: Vec<Step>) {
    let setup = Setup::new(test, policy.clone(), start);
    let expected = in_process(&policy, start, &script);

    let reader_node = node();
    let reader_clock = SimClock::shared(start);
    let mut reader = setup.reader(reader_clock.clone()).create(&reader_node).unwrap();
    let violations = ViolationSubscriber::builder(TRAJECTORY)
        .domain(&setup.domain)
        .create(&reader_node)
        .unwrap();
    let writer = WriterThread::spawn(&setup, script);

    assert_eq!(writer.outcomes(), expected.did, "add outcomes");
    // The reader receives exactly the stream that passed the gate, in stream order,
    // with the gate's add times.
    let stream = take(&mut reader, expected.stream.len());
    assert_eq!(entered(&stream), entered(&expected.stream), "the stream readers receive");
    assert!(reader.next_sample(Duration::from_millis(20)).unwrap().is_none(), "nothing else");

    // Every violation reaches another node, in order.
    let mut seen = Vec::new();
    while seen.len() < expected.violations.len() {
        match violations.wait(TIMEOUT).unwrap() {
            Some(v) => seen.push(v),
            None => panic!("{} of {} violations arrived", seen.len(), expected.violations.len()),
        }
    }
    let key = |v: &PolicyViolation| (v.constraint, v.valid_time, v.create_time, v.add_time);
    assert_eq!(
        seen.iter().map(key).collect::<Vec<_>>(),
        expected.violations.iter().map(key).collect::<Vec<_>>(),
        "violations"
    );
    assert_eq!(violations.stats().lost, 0);

    // The history and every query answer as in process, at the same query time.
    let query_time = expected.clock.now() + 1_000;
    expected.clock.set(query_time);
    reader_clock.set(query_time);
    assert_same_answers(&expected.store, &reader);

    let stats = reader.stats();
    assert_eq!(stats.added as usize, expected.stream.len());
    assert_eq!(stats.stored, expected.store.len());
    assert_eq!(stats.evicted, expected.store.stats().evicted);
    assert_eq!((stats.lost, stats.evicted_over_bound), (0, 0));
    assert_eq!((stats.subscriber.malformed, stats.subscriber.type_mismatch), (0, 0));

    let w = writer.finish();
    let s = expected.store.stats();
    assert_eq!(
        (w.stream.added, &w.stream.dropped, w.stream.violations, w.stream.held),
        (s.added, &s.dropped, s.violations, s.held),
        "writer stats"
    );
    assert_eq!(w.stream.missed_sample_points, s.missed_sample_points);
    assert_eq!((w.published, w.publish_failures), (s.added, 0));
    assert_eq!((w.violations_published, w.violation_publish_failures), (s.violations, 0));
}

#[test]
fn delay_with_hold_and_reorder_is_gated_before_publication() {
    let (policy, start, script) = hold_and_reorder();
    run_and_compare("hold_and_reorder", policy, start, script);
}

#[test]
fn filter_duration_change_and_time_cache_are_gated_before_publication() {
    let policy = FluentStreamPolicy::default()
        .filter("x > 2.0")
        .duration(DurationConstraint::Between { from: 100, to: 2_000 })
        .change(ChangeConstraint::AnyChange)
        .cache(CacheConstraint::Duration(100));
    let script = vec![
        (100, Op::Add(reading(150, 3.0))),
        (110, Op::Add(reading(160, 1.0))), // filter
        (120, Op::Add(reading(50, 5.0))),  // before the duration
        (130, Op::Add(reading(170, 3.0))), // same value as the previous: change
        (140, Op::Add(reading(200, 4.0))),
        (150, Op::Add(reading(120, 5.0))), // out of valid-time order, inside the window
        (160, Op::Add(reading(100, 6.0))), // 100 before the newest (200): time cache
        (170, Op::Add(reading(2_500, 7.0))), // after the duration
        (180, Op::Add(reading(260, 8.0))), // evicts 150 and 120 from the cache
        (190, Op::AddBlocking(reading(255, 8.0))), // change, returned
        (200, Op::Add(reading(230, 9.0))),
        (300, Op::CreateAtNowBlocking(10.0)), // valid at 300: evicts 200
    ];
    run_and_compare("filter_duration_change_cache", policy, 100, script);
}

#[test]
fn strict_order_and_sample_period_are_gated_before_publication() {
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::StrictMonotone)
        .change(ChangeConstraint::SampleEvery(10));
    let mut script = vec![
        (100, Op::Add(reading(100, 1.0))),
        (101, Op::Add(reading(105, 2.0))), // too soon: change
        (102, Op::AddBlocking(reading(100, 3.0))), // not after 100: order
        (103, Op::Add(reading(110, 4.0))),
        (104, Op::Add(reading(140, 5.0))), // two sample points missed
    ];
    script.extend((0..5).map(|i| (105 + i, Op::Add(reading(150 + 10 * i, i as f64)))));
    run_and_compare("strict_order_sample_period", policy, 100, script);
}

#[test]
fn unconstrained_out_of_order_streams_index_by_valid_time() {
    let vts = [30, 10, 20, 20, 50, 40, 10, 60];
    let script = vts
        .iter()
        .enumerate()
        .map(|(i, vt)| (i as Time, Op::Add(reading(*vt, i as f64))))
        .collect();
    run_and_compare("out_of_order", FluentStreamPolicy::default(), 0, script);
}

#[test]
fn a_late_reader_gets_the_last_n_through_history() {
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(4));
    let script: Vec<Step> = (0..10).map(|i| (i, Op::Add(reading(100 + i, i as f64)))).collect();
    let setup = Setup::new("late_reader", policy.clone(), 0);
    let expected = in_process(&policy, 0, &script);
    // No reader yet: the writer publishes into its history only.
    let writer = WriterThread::spawn(&setup, script);
    assert_eq!(writer.outcomes(), expected.did);

    let reader_node = node();
    let clock = SimClock::shared(0);
    let mut reader = setup.reader(clock.clone()).create(&reader_node).unwrap();
    writer.update_connections();
    let got = take(&mut reader, 4);
    assert_eq!(entered(&got), entered(&expected.stream[6..]), "the last 4");
    assert!(reader.next_sample(Duration::from_millis(20)).unwrap().is_none());
    clock.set(expected.clock.now());
    assert_same_answers(&expected.store, &reader);
    assert_eq!(reader.stats().lost, 0, "history is not a loss");
    let w = writer.finish();
    assert_eq!((w.stream.stored, w.stream.evicted), (4, 6), "iceoryx2 keeps the last 4");
}

#[test]
fn an_all_cache_is_bounded_by_the_configured_maximum() {
    let policy = FluentStreamPolicy::default();
    let mut setup = Setup::new("bounded_all", policy.clone(), 0);
    setup.max_history = 3;
    let script: Vec<Step> = (0..5).map(|i| (i, Op::Add(reading(i, i as f64)))).collect();
    let expected = in_process(&policy, 0, &script);

    let reader_node = node();
    let clock = SimClock::shared(10);
    let mut reader = setup.reader(clock).create(&reader_node).unwrap();
    let writer = WriterThread::spawn(&setup, script);
    writer.outcomes();
    take(&mut reader, 5);
    // The in-process store keeps all five; shared memory needs a number.
    assert_eq!(expected.store.len(), 5);
    let kept: Vec<Time> = reader.iter().map(|s| s.valid_time()).collect();
    assert_eq!(kept, vec![2, 3, 4]);
    let stats = reader.stats();
    assert_eq!((stats.evicted, stats.evicted_over_bound, stats.stored), (0, 2, 3));
    assert_eq!(reader.start_time(), Ok(2));

    // A late reader gets the same three from the writer's history.
    let late_node = node();
    let mut late = setup.reader(SimClock::shared(10)).create(&late_node).unwrap();
    writer.update_connections();
    let got = take(&mut late, 3);
    assert_eq!(got.iter().map(|s| s.valid_time).collect::<Vec<_>>(), vec![2, 3, 4]);
    writer.finish();
}

/// Raw iceoryx2 access to a trajectory's data service, to write what esgm never would.
struct RawPublisher {
    port: iceoryx2::port::publisher::Publisher<esgm_shm::ShmService, [Block16], SampleHeader>,
}

impl RawPublisher {
    fn new(node: &esgm_shm::ShmNode, domain: &str) -> Self {
        let name = ServiceName::new(&data_service_name(domain, TRAJECTORY)).unwrap();
        let service = node
            .service_builder(&name)
            .publish_subscribe::<[Block16]>()
            .user_header::<SampleHeader>()
            .open()
            .unwrap();
        let port = service.publisher_builder().initial_max_slice_len(4096).create().unwrap();
        Self { port }
    }

    /// Sends a valid `Reading` at `vt` under sequence number `sequence`.
    fn send_reading(&self, vt: Time, sequence: u64) {
        let bytes = codec::encode(&reading(vt, 1.0)).unwrap();
        self.send(
            &bytes,
            SampleHeader {
                valid_time: vt,
                create_time: vt,
                archive_len: bytes.len() as u64,
                type_id: type_id("Reading"),
                sequence,
                kind: SampleHeader::KIND_STRUCTURE,
                ..SampleHeader::default()
            },
        );
    }

    fn send(&self, payload: &[u8], header: SampleHeader) {
        let mut blocks = vec![Block16::default(); blocks_for(payload.len()).max(1)];
        bytemuck::cast_slice_mut::<Block16, u8>(&mut blocks)[..payload.len()]
            .copy_from_slice(payload);
        let mut sample =
            self.port.loan_slice_uninit(blocks.len()).unwrap().write_from_slice(&blocks);
        *sample.user_header_mut() = header;
        sample.send().unwrap();
    }
}

/// Updates `reader` until it stores `n` samples (or the timeout), then checks it does.
fn update_until_stored(reader: &mut ShmTrajectoryReader, n: usize) {
    let deadline = Instant::now() + TIMEOUT;
    while reader.len() < n && Instant::now() < deadline {
        reader.update().unwrap();
        thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(reader.len(), n);
}

#[test]
fn malformed_injected_payloads_are_counted_not_stored() {
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(8));
    let setup = Setup::new("malformed_history", policy, 0);
    let reader_node = node();
    let mut reader = setup.reader(SimClock::shared(0)).create(&reader_node).unwrap();
    // The writer first (it refuses a trajectory that already has a publisher), then an
    // intruder writing bytes no esgm writer would.
    let writer = WriterThread::spawn(&setup, vec![(0, Op::Add(reading(1, 1.0)))]);
    writer.outcomes();
    let raw_node = node();
    let raw = RawPublisher::new(&raw_node, &setup.domain);
    let good = codec::encode(&reading(5, 5.0)).unwrap();
    let header = |len: usize, vt: Time| SampleHeader {
        valid_time: vt,
        create_time: vt,
        archive_len: len as u64,
        type_id: type_id("Reading"),
        kind: SampleHeader::KIND_STRUCTURE,
        ..SampleHeader::default()
    };
    raw.send(&[0xAB; 96], header(96, 5)); // garbage
    raw.send(&good, header(good.len() + 4096, 5)); // longer than delivered
    raw.send(&good, header(good.len() - 16, 5)); // truncated archive
    raw.send(&good, header(good.len(), 6)); // header lies about the valid time
    raw.send(&good, SampleHeader { kind: 0, ..header(good.len(), 5) }); // never filled in
    raw.send(&good, SampleHeader { type_id: 7, ..header(good.len(), 5) }); // another type

    // Wait until all seven (one good, six bad) were taken.
    let deadline = Instant::now() + TIMEOUT;
    while reader.stats().subscriber.received < 7 && Instant::now() < deadline {
        reader.update().unwrap();
        thread::sleep(Duration::from_millis(1));
    }
    let stats = reader.stats();
    assert_eq!(stats.subscriber.received, 7);
    assert_eq!((stats.subscriber.malformed, stats.subscriber.type_mismatch), (5, 1));
    assert_eq!((stats.added, stats.stored), (1, 1), "only the writer's sample is stored");
    assert_eq!(reader.get_latest().unwrap().valid_time(), 1);
    assert_eq!(reader.get_latest().unwrap().structure().unwrap().name.as_str(), "r");
    writer.finish();
}

#[test]
fn extreme_times_from_a_foreign_publisher_do_not_break_queries() {
    let setup = Setup::new("extreme_times", FluentStreamPolicy::default(), 0);
    let reader_node = node();
    let mut reader = setup.reader(SimClock::shared(0)).create(&reader_node).unwrap();
    let raw_node = node();
    let raw = RawPublisher::new(&raw_node, &setup.domain);
    // Valid archives at the ends of the timeline, with sequence numbers that jump.
    for (vt, sequence) in [(Time::MIN, u64::MAX - 1), (Time::MAX, 3), (Time::MIN, u64::MAX)] {
        raw.send_reading(vt, sequence);
    }
    update_until_stored(&mut reader, 3);
    let closest = reader.get_at_approximating(0, &ValueApproximation::Closest).unwrap();
    assert_eq!(closest.valid_time(), Time::MAX, "0 is one closer to the end than to the start");
    let linear = reader.get_at_approximating(0, &ValueApproximation::Linear).unwrap();
    assert_eq!(linear.valid_time(), 0);
    assert_eq!(reader.get_between(Time::MIN, Time::MAX).len(), 3);
    assert_eq!((reader.start_time(), reader.end_time()), (Ok(Time::MIN), Ok(Time::MAX)));
    assert_eq!(reader.stats().lost, u64::MAX - 4, "counted, saturating, never a panic");
}

#[test]
fn losses_are_counted_per_publisher_when_two_publishers_interleave() {
    let setup = Setup::new("two_publishers", FluentStreamPolicy::default(), 0);
    let reader_node = node();
    let mut reader = setup.reader(SimClock::shared(0)).create(&reader_node).unwrap();
    let (node_a, node_b) = (node(), node());
    let (a, b) =
        (RawPublisher::new(&node_a, &setup.domain), RawPublisher::new(&node_b, &setup.domain));
    let send = |p: &RawPublisher, vt: Time, sequence: u64| p.send_reading(vt, sequence);
    // Each numbers its own samples from 0: interleaved, nothing is missing.
    send(&a, 1, 0);
    send(&b, 2, 0);
    send(&a, 3, 1);
    send(&b, 4, 1);
    send(&a, 5, 2);
    // Then b skips two of its numbers: two lost, whatever a did meanwhile.
    send(&b, 6, 4);
    send(&a, 7, 3);
    update_until_stored(&mut reader, 7);
    assert_eq!(reader.stats().lost, 2, "b's gap only; interleaving is not a loss");
}

#[test]
fn a_second_writer_is_refused() {
    let setup = Setup::new("second_writer", FluentStreamPolicy::default(), 0);
    let n = node();
    let first = ShmTrajectoryWriter::builder(TRAJECTORY, checker())
        .domain(&setup.domain)
        .create(&n)
        .unwrap();
    let second =
        ShmTrajectoryWriter::builder(TRAJECTORY, checker()).domain(&setup.domain).create(&n);
    assert!(matches!(second, Err(WriterCreateError::AlreadyWritten { publishers: 2, .. })));
    drop(first);
    // Once the first is gone the trajectory can be written again.
    ShmTrajectoryWriter::builder(TRAJECTORY, checker()).domain(&setup.domain).create(&n).unwrap();
}

#[test]
fn a_hosted_reader_answers_from_any_thread() {
    let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(5));
    let setup = Setup::new("hosted", policy.clone(), 0);
    let script: Vec<Step> = (0..8).map(|i| (i, Op::Add(reading(10 * i, i as f64)))).collect();
    let expected = in_process(&policy, 0, &script);
    let reader_clock = SimClock::shared(0);
    let hosted = HostedTrajectoryReader::spawn(setup.reader(reader_clock.clone())).unwrap();
    let writer = WriterThread::spawn(&setup, script);
    writer.outcomes();

    let deadline = Instant::now() + TIMEOUT;
    while hosted.stats().unwrap().added < 8 && Instant::now() < deadline {
        thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(hosted.len().unwrap(), 5);
    reader_clock.set(expected.clock.now());
    let askers: Vec<_> = (0..2)
        .map(|_| {
            let h = hosted.clone();
            thread::spawn(move || {
                (
                    h.get_latest().unwrap(),
                    h.get_between(0, 1_000).unwrap(),
                    h.get_at_approximating(35, &ValueApproximation::Linear).unwrap(),
                    h.get_nth_latest(9).unwrap_err().to_string(),
                )
            })
        })
        .collect();
    let store = &expected.store;
    for a in askers {
        let (latest, between, linear, missing) = a.join().unwrap();
        assert_eq!(latest, store.get_latest().unwrap());
        assert_eq!(between, store.get_between(0, 1_000));
        assert_eq!(linear, store.get_at_approximating(35, &ValueApproximation::Linear).unwrap());
        assert_eq!(missing, store.get_nth_latest(9).unwrap_err().to_string());
    }
    assert_eq!(hosted.start_time().unwrap(), 30);
    assert!(matches!(
        hosted.get_at(31),
        Err(HistoryError::Query(QueryError::ValueNotAvailable { .. }))
    ));
    // A job calling back into its own reader gets an error, not a wait for itself.
    let inner = hosted.clone();
    let reentrant = hosted.with(move |_| inner.len()).unwrap();
    assert!(matches!(reentrant, Err(HistoryError::Reentrant { .. })), "{reentrant:?}");
    drop(hosted);
    writer.finish();
}

#[test]
fn violations_reach_subscribers_on_other_nodes() {
    // One subscriber per node; both see the same drops.
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .delay(DelayConstraint::Max(10))
        .reorder(false);
    let setup = Setup::new("violations", policy.clone(), 100);
    let nodes = [node(), node()];
    let subs: Vec<_> = nodes
        .iter()
        .map(|n| ViolationSubscriber::builder(TRAJECTORY).domain(&setup.domain).create(n).unwrap())
        .collect();
    let script = vec![
        (100, Op::Add(reading(95, 1.0))),
        (101, Op::Add(reading(93, 2.0))),  // order
        (120, Op::Add(reading(100, 3.0))), // delay 20
    ];
    let expected = in_process(&policy, 100, &script);
    let writer = WriterThread::spawn(&setup, script);
    writer.outcomes();
    for s in &subs {
        let a = s.wait(TIMEOUT).unwrap().expect("first violation");
        let b = s.wait(TIMEOUT).unwrap().expect("second violation");
        assert_eq!((a.constraint, a.valid_time, a.add_time), (Constraint::Order, 93, 101));
        assert_eq!((b.constraint, b.valid_time, b.add_time), (Constraint::Delay, 100, 120));
        assert_eq!(a.trajectory, TRAJECTORY);
        assert!(s.wait(Duration::from_millis(20)).unwrap().is_none());
        assert_eq!(s.stats().received, 2);
    }
    assert_eq!(expected.violations.len(), 2);
    writer.finish();
}
