//! The wake word's protocol under a model checker: shuttle schedules the atomic steps
//! of writers, sleepers and receivers (each cell access a step), kills threads at any
//! step, and maps slots anew after a death, over thousands of random and PCT
//! schedules per test (a bound that fits CI). The futex is modelled as the kernel
//! keeps it: the compare and the sleep are one step against a wake, and a wake
//! returns how many sleepers it took off the queue. A lost wake-up shows as a thread
//! blocked for ever, which shuttle reports as a deadlock.
//!
//! The claims (module docs of [`super`] and of `wake_word`):
//! - no lost wake-up;
//! - the totals are never below what the slots hold, and once every live thread is
//!   done and a look counted the dead slots out, they are zero — but for a death
//!   between a total and its slot, which leaves the total too high by one (a notify
//!   or a `FUTEX_WAKE` for nothing), never too low;
//! - a ring that lets the writer skip the event's notify leaves a live thread that
//!   feeds every receiver: each sample is fed.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failed model is a failed test

use std::cell::Cell;
use std::time::Duration;

use shuttle::sync::atomic::{AtomicU32, AtomicU64};
use shuttle::sync::{Arc, Condvar, Mutex};
use shuttle::thread;

use super::{Cell32, Cell64, Page, RECEIVER_FLAG, SLEEPER_BITS, asleep_in, count_out, covered_in};
use super::{covered_out, decode, receiver_in, ring, sleep};

/// Schedules explored per test and scenario.
const RANDOM: usize = 2_000;
const PCT: usize = 1_000;
/// How many of a thread's cell accesses a scenario may kill it before.
const MAX_STEPS: u32 = 12;
/// The sequentially consistent ordering every step uses.
const SEQ: std::sync::atomic::Ordering = std::sync::atomic::Ordering::SeqCst;

/// A model thread killed at a step: unwinds the thread, as SIGKILL stops a process.
struct Died;

/// The kernel's futex queue: who sleeps, and wakes that have happened.
#[derive(Default)]
struct Queue {
    waiting: u32,
    wakes: u64,
}

/// The word and what the model's processes share besides it.
struct Shared {
    sequence: AtomicU32,
    sleepers: AtomicU32,
    counts: AtomicU64,
    slots: [AtomicU32; 4],
    /// Slots whose mapping is gone (its process died): a look may count them out.
    dead: [AtomicU32; 4],
    futex: Mutex<Queue>,
    woken: Condvar,
    /// Samples the writer sent (the data service, as far as the protocol cares).
    sent: AtomicU32,
    /// The highest sample fed into each connection's replica, by any of its threads.
    fed: [AtomicU32; 2],
    /// The event's notifies, for the connections' receiver threads.
    notified: Mutex<u32>,
    notify: Condvar,
}

impl Shared {
    fn new() -> Arc<Self> {
        Arc::new(Self {
            sequence: AtomicU32::new(0),
            sleepers: AtomicU32::new(0),
            counts: AtomicU64::new(0),
            slots: std::array::from_fn(|_| AtomicU32::new(0)),
            dead: std::array::from_fn(|_| AtomicU32::new(0)),
            futex: Mutex::new(Queue::default()),
            woken: Condvar::new(),
            sent: AtomicU32::new(0),
            fed: std::array::from_fn(|_| AtomicU32::new(0)),
            notified: Mutex::new(0),
            notify: Condvar::new(),
        })
    }

    /// Feeds what was sent into connection `c`'s replica.
    fn feed(&self, c: usize) {
        self.fed[c].fetch_max(self.sent.load(SEQ), SEQ);
    }

    /// The event's notify: wakes the receiver thread.
    fn notify_event(&self) {
        *self.notified.lock().unwrap() += 1;
        self.notify.notify_all();
    }
}

/// One mapping of the word, used by one model thread, which dies before its
/// `budget`th step if it has one.
struct Mapping {
    shared: Arc<Shared>,
    slot: Option<usize>,
    budget: Cell<Option<u32>>,
}

impl Mapping {
    fn new(shared: &Arc<Shared>, slot: Option<usize>, budget: Option<u32>) -> Self {
        Self { shared: Arc::clone(shared), slot, budget: Cell::new(budget) }
    }

    /// One step of this thread: it dies here if its budget is spent.
    fn step(&self) {
        if let Some(left) = self.budget.get() {
            if left == 0 {
                std::panic::resume_unwind(Box::new(Died));
            }
            self.budget.set(Some(left - 1));
        }
    }
}

impl Page for Mapping {
    type C32 = AtomicU32;
    type C64 = AtomicU64;

    fn sequence(&self) -> &AtomicU32 {
        self.step();
        &self.shared.sequence
    }

    fn sleepers(&self) -> &AtomicU32 {
        self.step();
        &self.shared.sleepers
    }

    fn counts(&self) -> &AtomicU64 {
        self.step();
        &self.shared.counts
    }

    fn own_slot(&self) -> Option<&AtomicU32> {
        self.step();
        self.slot.map(|s| &self.shared.slots[s])
    }

    fn wake_all(&self) -> i64 {
        self.step();
        let mut q = self.shared.futex.lock().unwrap();
        let woken = q.waiting;
        q.waiting = 0;
        q.wakes += 1;
        self.shared.woken.notify_all();
        i64::from(woken)
    }

    fn wait(&self, seen: u32, _timeout: Duration) {
        self.step();
        let mut q = self.shared.futex.lock().unwrap();
        // The kernel's compare, under the queue's lock.
        if Cell32::load(&self.shared.sequence) != seen {
            return;
        }
        q.waiting += 1;
        let wakes = q.wakes;
        // No timeout: a sleeper nobody wakes blocks for ever (a deadlock to shuttle).
        while q.wakes == wakes {
            q = self.shared.woken.wait(q).unwrap();
        }
    }
}

/// Runs `body` as a model thread that may die: true if it died.
fn mortal(body: impl FnOnce()) -> bool {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)) {
        Ok(()) => false,
        Err(payload) if payload.is::<Died>() => true,
        Err(payload) => std::panic::resume_unwind(payload),
    }
}

/// A reader of connection 0: looks for the sample, sleeps on the word until it is
/// there, and feeds (the subscription or worker path).
fn reader(page: &Mapping) {
    loop {
        let seen = Cell32::load(page.sequence());
        if page.shared.sent.load(SEQ) > 0 {
            page.shared.feed(0);
            return;
        }
        sleep(page, seen, Duration::MAX);
    }
}

/// A covering reader of connection `c` (`coverage.rs`): counted covered before its
/// last look, out before it feeds, on every path.
fn covering_reader(page: &Mapping, c: usize) {
    covered_in(page);
    loop {
        let seen = Cell32::load(page.sequence());
        if page.shared.sent.load(SEQ) > 0 {
            covered_out(page);
            page.shared.feed(c);
            return;
        }
        sleep(page, seen, Duration::MAX);
    }
}

/// The writer: sends, rings, and notifies the event unless the ring says nobody needs
/// it (`listeners`: the event's listeners iceoryx2 would count).
fn writer(page: &Mapping, listeners: usize) -> bool {
    page.shared.sent.store(1, SEQ);
    let rang = ring(page, || listeners);
    if !rang.covered {
        page.shared.notify_event();
    }
    rang.covered
}

/// A look for the dead, once every thread is done: counts out each slot whose
/// mapping died.
fn look(shared: &Arc<Shared>) {
    let page = Mapping::new(shared, None, None);
    for s in 0..shared.slots.len() {
        if shared.dead[s].load(SEQ) != 0 {
            count_out(&page, &shared.slots[s]);
        }
    }
}

/// The totals are never below what the slots hold.
fn totals_cover_slots(shared: &Shared) {
    let slots = |mask: u32| shared.slots.iter().filter(|s| Cell32::load(*s) & mask != 0).count();
    let asleep: u32 = shared.slots.iter().map(|s| Cell32::load(s) & SLEEPER_BITS).sum();
    assert!(Cell32::load(&shared.sleepers) >= asleep, "sleepers below the slots' sum");
    let (receivers, _) = decode(Cell64::load(&shared.counts));
    assert!(receivers as usize >= slots(RECEIVER_FLAG), "receivers below the slots'");
}

/// Two readers in two processes and a writer: whatever the interleaving, both wake
/// and feed; afterwards every count is zero.
#[test]
fn no_sleeper_misses_a_ring() {
    let scenario = || {
        let shared = Shared::new();
        let readers: Vec<_> = (0..2)
            .map(|slot| {
                let shared = Arc::clone(&shared);
                thread::spawn(move || reader(&Mapping::new(&shared, Some(slot), None)))
            })
            .collect();
        let w = Arc::clone(&shared);
        let writer = thread::spawn(move || writer(&Mapping::new(&w, None, None), 0));
        for r in readers {
            r.join().unwrap();
        }
        writer.join().unwrap();
        assert_eq!(Cell32::load(&shared.sleepers), 0);
        assert!(shared.slots.iter().all(|s| Cell32::load(s) == 0));
        assert_eq!(shared.fed[0].load(SEQ), 1);
    };
    shuttle::check_random(scenario, RANDOM);
    shuttle::check_pct(scenario, PCT, 3);
}

/// Two connections, each with a receiver thread listening to the event; connection 0
/// has a reader covering it, whose process is killed at any step; connection 1 has
/// one too, or none (its receiver alone feeds it, so it needs every notify); the
/// writer decides whether to notify. Each live connection's replica is always fed (by
/// its covering reader, or by its receiver the notify wakes), and once a look counted
/// the dead out, nothing is counted too low and at most the documented one too high.
#[test]
fn a_skipped_notify_is_never_one_a_reader_needed() {
    let cases = (0..=MAX_STEPS).map(Some).chain([None]).flat_map(|d| [(d, true), (d, false)]);
    for (death, cover1) in cases {
        let scenario = move || {
            let shared = Shared::new();
            let mut receivers = Vec::new();
            for c in 0..2 {
                // Each connection's receiver listens to the event (counted in after its
                // listener exists; the slot is its connection's mapping).
                assert!(receiver_in(&Mapping::new(&shared, Some(c), None)));
                let r = Arc::clone(&shared);
                receivers.push(thread::spawn(move || {
                    let mut notified = r.notified.lock().unwrap();
                    while *notified == 0 {
                        notified = r.notify.wait(notified).unwrap();
                    }
                    drop(notified);
                    r.feed(c);
                }));
            }
            let coverers: Vec<_> = (0..if cover1 { 2 } else { 1 })
                .map(|c| {
                    let s = Arc::clone(&shared);
                    thread::spawn(move || {
                        let page = Mapping::new(&s, Some(c), if c == 0 { death } else { None });
                        let died = mortal(|| covering_reader(&page, c));
                        if died {
                            // Its process is gone, its record lock with it.
                            s.dead[c].store(1, SEQ);
                        }
                        died
                    })
                })
                .collect();
            let w = Arc::clone(&shared);
            let writer = thread::spawn(move || writer(&Mapping::new(&w, None, None), 2));
            let skipped = writer.join().unwrap();
            let mut died: Vec<bool> = coverers.into_iter().map(|t| t.join().unwrap()).collect();
            died.resize(2, false);
            if skipped {
                // Nobody notifies the receivers: every live connection's reader fed.
                for c in (0..2).filter(|c| !died[*c]) {
                    assert_eq!(
                        shared.fed[c].load(SEQ),
                        1,
                        "connection {c}: a needed notify skipped"
                    );
                }
                // Lets the receivers end (the model's, not the protocol's).
                shared.notify_event();
            }
            for r in receivers {
                r.join().unwrap();
            }
            for c in (0..2).filter(|c| !died[*c]) {
                assert_eq!(shared.fed[c].load(SEQ), 1, "connection {c} not fed");
            }
            totals_cover_slots(&shared);
            look(&shared);
            totals_cover_slots(&shared);
            let sleepers = Cell32::load(&shared.sleepers);
            let (receivers, covered) = decode(Cell64::load(&shared.counts));
            let dead = died.iter().filter(|d| **d).count() as u32;
            // The live connection is still a receiver; a death between a total and its
            // slot may leave one sleeper, one receiver or one covered too many, or one
            // covered too few: never more.
            assert!(
                (2 - dead..=2 - dead + 1).contains(&receivers),
                "receivers {receivers} with {dead} dead"
            );
            assert!(sleepers <= dead && covered <= dead, "sleepers {sleepers}, covered {covered}");
        };
        shuttle::check_random(scenario, RANDOM / 4);
    }
}

/// A reader dies asleep, its slot is taken by the next process's mapping (which
/// counts out what the dead one left, as `claim_slot` does), and that one sleeps and
/// is woken: the writer's wake reaches it, and the totals come back to zero.
#[test]
fn a_slot_mapped_anew_after_a_death_counts_the_dead_out() {
    for death in (0..=6).map(Some) {
        let scenario = move || {
            let shared = Shared::new();
            let d = Arc::clone(&shared);
            let dying = thread::spawn(move || {
                let page = Mapping::new(&d, Some(1), death);
                mortal(|| {
                    asleep_in(&page);
                    // Asleep until killed: it never counts itself out.
                    page.budget.set(Some(0));
                    page.step();
                })
            });
            assert!(dying.join().unwrap(), "the model thread dies");
            // The next process maps the word and claims the dead one's slot.
            let claimer = Mapping::new(&shared, None, None);
            count_out(&claimer, &shared.slots[1]);
            let n = Arc::clone(&shared);
            let next = thread::spawn(move || reader(&Mapping::new(&n, Some(1), None)));
            let w = Arc::clone(&shared);
            let writer = thread::spawn(move || writer(&Mapping::new(&w, None, None), 0));
            next.join().unwrap();
            writer.join().unwrap();
            totals_cover_slots(&shared);
            let sleepers = Cell32::load(&shared.sleepers);
            // Only a death between the total and the slot leaves one.
            assert!(sleepers <= 1, "{sleepers} sleepers left");
            assert_eq!(Cell32::load(&shared.slots[1]), 0);
        };
        shuttle::check_random(scenario, RANDOM / 4);
    }
}
