//! What a conformance test needs from a runtime: a writing side, a reading side, and
//! control of the clock.
//!
//! A test creates trajectories and adds to them through [`Harness::esgm`], and reads
//! what a user elsewhere would read — queries, subscriptions, violations, stats —
//! through [`Harness::reader`]. On the shared-memory runtime the two are separate
//! connections (two locations in the registry, each with its own ports and local
//! runtime), so every such check crosses the process boundary; on the in-process
//! runtime they are one runtime. Replication across the boundary is asynchronous: a
//! reader-side check waits (with [`wait_for`] and a deadline) for what the writer did
//! to arrive, and never asserts how long that took.

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::{Esgm, InProcessEsgm, SimClock, Time, secs};

/// A runtime under test, seen from a writing and a reading side, plus control of its
/// clock.
pub trait Harness {
    /// The runtime.
    type E: Esgm;
    /// The writing side: it registers types, sensors and units, creates trajectories
    /// and adds to them (and, where a sensor or unit lives here, runs them).
    fn esgm(&self) -> &Self::E;
    /// The reading side, in a second location where the runtime has more than one:
    /// handles from its `get_entity_trajectory_structure` see the writer's
    /// trajectories as another process does. The same runtime as [`Harness::esgm`]
    /// where the runtime has one location.
    fn reader(&self) -> &Self::E;
    /// True if [`Harness::reader`] is another location than [`Harness::esgm`]: adds
    /// through it to a primitive trajectory are forwarded to the writer
    /// ([`esgm_core::AddOutcome::Forwarded`]) instead of being admitted on the spot.
    fn reader_is_remote(&self) -> bool;
    /// The runtime's current time.
    fn now(&self) -> Time;
    /// Moves the runtime's time forward by `d`: a simulated clock jumps, a real one is
    /// waited for.
    fn advance(&self, d: Time);
}

/// The in-process runtime on a simulated clock starting at 1000 s; writer and reader
/// are the same runtime.
#[derive(Debug)]
pub struct InProcessHarness {
    clock: Arc<SimClock>,
    esgm: InProcessEsgm,
}

impl InProcessHarness {
    /// A fresh runtime with the library types.
    pub fn new() -> Self {
        let clock = SimClock::shared(secs(1_000));
        let esgm = InProcessEsgm::builder().clock(clock.clone()).create();
        Self { clock, esgm }
    }
}

impl Default for InProcessHarness {
    fn default() -> Self {
        Self::new()
    }
}

impl Harness for InProcessHarness {
    type E = InProcessEsgm;
    fn esgm(&self) -> &InProcessEsgm {
        &self.esgm
    }
    fn reader(&self) -> &InProcessEsgm {
        &self.esgm
    }
    fn reader_is_remote(&self) -> bool {
        false
    }
    fn now(&self) -> Time {
        self.clock.now()
    }
    fn advance(&self, d: Time) {
        self.clock.advance(d);
    }
}

/// The shared-memory runtime ([`esgm_shm::connect`]) against a coordinator of its own
/// (on a thread, in a unique domain so tests run in parallel), on a simulated clock
/// starting at 1000 s, with two connections: the writer (host `writer`) and the
/// reader (host `reader`), two locations as two processes of one robot would be.
/// Both share the one simulated clock, as processes share the host's timeline (M1).
#[derive(Debug)]
pub struct ShmHarness {
    clock: Arc<SimClock>,
    // Dropped in this order: the clients leave before their coordinator stops.
    writer: esgm_shm::ShmEsgm,
    reader: esgm_shm::ShmEsgm,
    _coordinator: esgm_shm::control::CoordinatorThread,
}

impl ShmHarness {
    /// A fresh system with the library types.
    pub fn new() -> Self {
        let domain = esgm_shm::unique_domain("conformance");
        let registry = esgm_shm::control::Registry::new(esgm_core::TypeRegistry::with_library());
        let coordinator =
            esgm_shm::control::Coordinator::spawn(&domain, registry).expect("start a coordinator");
        let clock = SimClock::shared(secs(1_000));
        let connect = |host: &str| {
            esgm_shm::ShmEsgm::builder()
                .domain(&domain)
                .host(host)
                .clock(clock.clone())
                .connect()
                .unwrap_or_else(|e| panic!("connect `{host}` to the coordinator: {e}"))
        };
        let writer = connect("writer");
        let reader = connect("reader");
        Self { clock, writer, reader, _coordinator: coordinator }
    }
}

impl Default for ShmHarness {
    fn default() -> Self {
        Self::new()
    }
}

impl Harness for ShmHarness {
    type E = esgm_shm::ShmEsgm;
    fn esgm(&self) -> &esgm_shm::ShmEsgm {
        &self.writer
    }
    fn reader(&self) -> &esgm_shm::ShmEsgm {
        &self.reader
    }
    fn reader_is_remote(&self) -> bool {
        true
    }
    fn now(&self) -> Time {
        self.clock.now()
    }
    fn advance(&self, d: Time) {
        self.clock.advance(d);
    }
}

/// Polls `cond` until it holds or `timeout` passes; returns whether it held. Tests
/// assert on the result, so a runtime that never gets there fails instead of hanging.
pub fn wait_for(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    loop {
        if cond() {
            return true;
        }
        if Instant::now() > deadline {
            return false;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
}
