//! What a conformance test needs from a runtime.

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::{Esgm, InProcessEsgm, SimClock, Time, secs};

/// A runtime under test plus control of its clock.
pub trait Harness {
    /// The runtime.
    type E: Esgm;
    /// The runtime under test.
    fn esgm(&self) -> &Self::E;
    /// The runtime's current time.
    fn now(&self) -> Time;
    /// Moves the runtime's time forward by `d`: a simulated clock jumps, a real one is
    /// waited for.
    fn advance(&self, d: Time);
}

/// The in-process runtime on a simulated clock starting at 1000 s.
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
    fn now(&self) -> Time {
        self.clock.now()
    }
    fn advance(&self, d: Time) {
        self.clock.advance(d);
    }
}

/// The shared-memory runtime ([`esgm_shm::connect`]) against a coordinator of its own
/// (on a thread, in a unique domain so tests run in parallel), on a simulated clock
/// starting at 1000 s.
#[derive(Debug)]
pub struct ShmHarness {
    clock: Arc<SimClock>,
    // Dropped in this order: the client leaves before its coordinator stops.
    esgm: esgm_shm::ShmEsgm,
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
        let esgm = esgm_shm::ShmEsgm::builder()
            .domain(&domain)
            .clock(clock.clone())
            .connect()
            .expect("connect to the coordinator");
        Self { clock, esgm, _coordinator: coordinator }
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
        &self.esgm
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
