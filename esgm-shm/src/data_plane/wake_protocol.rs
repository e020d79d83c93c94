//! The wake word's cross-process protocol as its atomic steps, apart from the page
//! they run on ([`super::wake_word`] has the page and why each step is where it is).
//!
//! Every step of the protocol — the writer's ring, a sleeper counting itself in and
//! out around its `FUTEX_WAIT`, a connection counted as a receiver and as covered, a
//! look counting a dead mapping's slot out — is written once here, over a [`Page`]: in
//! production the mapped page of `/dev/shm` and the kernel's futex; in the tests a
//! model whose atomics and futex a model checker (shuttle) schedules, so that the
//! claims the module docs make are explored over interleavings, deaths at any step
//! and mappings that come and go:
//! - no lost wake-up: a sleeper that looked before a sample was rung for wakes;
//! - no count that never returns to zero: once every thread is done and a look
//!   counted the dead out, the totals are zero;
//! - no skipped notify a reader needed: a ring that says the event's notify may be
//!   skipped leaves a live thread that will feed every receiver.

use std::time::Duration;

/// A thread asleep through a mapping, counted in its slot's low bits.
pub(crate) const SLEEPER_BITS: u32 = COVERED_FLAG - 1;
/// A slot's connection is counted among the receivers.
pub(crate) const RECEIVER_FLAG: u32 = 1 << 31;
/// A slot's connection is counted among the covered.
pub(crate) const COVERED_FLAG: u32 = 1 << 30;
/// In the counts word: the receivers (low 16 bits), the covered (the next 16), and a
/// count of changes (the high 32).
const FIELD: u64 = 0xFFFF;
const COVERED_SHIFT: u32 = 16;
const CHANGE: u64 = 1 << 32;

/// A 32-bit cell of the page, used only atomically and sequentially consistently.
pub(crate) trait Cell32 {
    fn load(&self) -> u32;
    fn fetch_add(&self, v: u32) -> u32;
    fn fetch_sub(&self, v: u32) -> u32;
    fn fetch_or(&self, v: u32) -> u32;
    fn fetch_and(&self, v: u32) -> u32;
}

/// The 64-bit counts cell of the page.
pub(crate) trait Cell64 {
    fn load(&self) -> u64;
    /// Applies `f` atomically (a compare-and-swap loop).
    fn update(&self, f: &mut dyn FnMut(u64) -> u64);
}

macro_rules! std_cells {
    ($a32:ty, $a64:ty) => {
        impl Cell32 for $a32 {
            fn load(&self) -> u32 {
                <$a32>::load(self, std::sync::atomic::Ordering::SeqCst)
            }
            fn fetch_add(&self, v: u32) -> u32 {
                <$a32>::fetch_add(self, v, std::sync::atomic::Ordering::SeqCst)
            }
            fn fetch_sub(&self, v: u32) -> u32 {
                <$a32>::fetch_sub(self, v, std::sync::atomic::Ordering::SeqCst)
            }
            fn fetch_or(&self, v: u32) -> u32 {
                <$a32>::fetch_or(self, v, std::sync::atomic::Ordering::SeqCst)
            }
            fn fetch_and(&self, v: u32) -> u32 {
                <$a32>::fetch_and(self, v, std::sync::atomic::Ordering::SeqCst)
            }
        }

        impl Cell64 for $a64 {
            fn load(&self) -> u64 {
                <$a64>::load(self, std::sync::atomic::Ordering::SeqCst)
            }
            fn update(&self, f: &mut dyn FnMut(u64) -> u64) {
                use std::sync::atomic::Ordering::SeqCst;
                let mut current = <$a64>::load(self, SeqCst);
                loop {
                    match <$a64>::compare_exchange_weak(self, current, f(current), SeqCst, SeqCst) {
                        Ok(_) => return,
                        Err(now) => current = now,
                    }
                }
            }
        }
    };
}

std_cells!(std::sync::atomic::AtomicU32, std::sync::atomic::AtomicU64);
#[cfg(test)]
std_cells!(shuttle::sync::atomic::AtomicU32, shuttle::sync::atomic::AtomicU64);

/// One mapping's view of a word: the page's cells, this mapping's slot, the futex.
pub(crate) trait Page {
    type C32: Cell32;
    type C64: Cell64;
    /// The futex word, one more per sample sent.
    fn sequence(&self) -> &Self::C32;
    /// Threads counted asleep, in every process.
    fn sleepers(&self) -> &Self::C32;
    /// Receivers, covered and changes.
    fn counts(&self) -> &Self::C64;
    /// This mapping's slot (`None`: it has none, and counts only in the totals).
    fn own_slot(&self) -> Option<&Self::C32>;
    /// Wakes every thread asleep on the sequence; how many woke.
    fn wake_all(&self) -> i64;
    /// Sleeps while the sequence is `seen`, at most `timeout` (returns at once if it
    /// is not).
    fn wait(&self, seen: u32, timeout: Duration);
}

/// Adds `receivers` and `covered` (each -1, 0 or 1) to the counts, and one to their
/// changes. A field already at 0 stays there (a count a death left too low is not
/// made to wrap, which would read as too high).
pub(crate) fn adjust(counts: &impl Cell64, receivers: i64, covered: i64) {
    let step = |field: u64, by: i64| field.saturating_add_signed(by).min(FIELD);
    counts.update(&mut |c| {
        let r = step(c & FIELD, receivers);
        let v = step((c >> COVERED_SHIFT) & FIELD, covered);
        ((c & !(CHANGE - 1)).wrapping_add(CHANGE)) | (v << COVERED_SHIFT) | r
    });
}

/// The receivers and the covered of a counts word.
pub(crate) fn decode(counts: u64) -> (u32, u32) {
    ((counts & FIELD) as u32, ((counts >> COVERED_SHIFT) & FIELD) as u32)
}

/// What a ring found (see [`super::wake_word::Ring`]), and whether it woke fewer
/// threads than sleepers were counted (one reason to look for the dead).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Rang {
    pub receivers: u32,
    pub listeners: usize,
    pub covered: bool,
    pub fruitless: bool,
}

/// The writer's ring after a send: the add, then everything the notify's decision
/// needs read before the wake-up (a thread woken counts itself out at once).
pub(crate) fn ring<P: Page>(page: &P, listeners: impl FnOnce() -> usize) -> Rang {
    page.sequence().fetch_add(1);
    let sleepers = page.sleepers().load();
    // Receivers and covered at once, after the add: a connection covered after this
    // load looks at the word after the add, and feeds.
    let snapshot = page.counts().load();
    let (receivers, covered) = decode(snapshot);
    let mut listening = 0;
    let mut steady = false;
    if receivers > 0 {
        listening = listeners();
        // Unchanged meanwhile: the listeners counted are those receivers'.
        steady = page.counts().load() == snapshot;
    }
    let mut woken = 0;
    let mut fruitless = false;
    if sleepers != 0 {
        woken = page.wake_all();
        // A sleeper between its count and its sleep, woken by an earlier ring, or
        // dead: after enough of these, look for the dead.
        fruitless = woken < i64::from(sleepers);
    }
    // A sleeper counted but not woken, or a covered connection whose thread this ring
    // did not wake (before its sleep, or dead): notify, to be sure.
    let woke_all = woken >= i64::from(sleepers.max(covered));
    let covered = steady && covered == receivers && listening == receivers as usize && woke_all;
    Rang { receivers, listeners: listening, covered, fruitless }
}

/// Sleeps through `page` while the sequence is `seen`, counted asleep meanwhile.
pub(crate) fn sleep<P: Page>(page: &P, seen: u32, timeout: Duration) {
    asleep_in(page);
    page.wait(seen, timeout);
    asleep_out(page);
}

/// Counts the calling thread asleep: in the total first and the slot second, so that a
/// death at any point leaves the total at least the sum of the slots.
pub(crate) fn asleep_in<P: Page>(page: &P) {
    page.sleepers().fetch_add(1);
    if let Some(slot) = page.own_slot() {
        slot.fetch_add(1);
    }
}

/// Counts the calling thread out of the asleep: the slot first, the total second.
pub(crate) fn asleep_out<P: Page>(page: &P) {
    if let Some(slot) = page.own_slot() {
        slot.fetch_sub(1);
    }
    page.sleepers().fetch_sub(1);
}

/// Counts the mapping's connection among the receivers: the total first, then the
/// slot (a death between leaves the total too high: a notify for nothing). False, and
/// nothing counted, without a slot: nothing could count it out.
pub(crate) fn receiver_in<P: Page>(page: &P) -> bool {
    let Some(slot) = page.own_slot() else { return false };
    adjust(page.counts(), 1, 0);
    slot.fetch_or(RECEIVER_FLAG);
    true
}

/// Counts the mapping's connection out of the receivers: the slot first, then the
/// total.
pub(crate) fn receiver_out<P: Page>(page: &P) {
    let Some(slot) = page.own_slot() else { return };
    slot.fetch_and(!RECEIVER_FLAG);
    adjust(page.counts(), -1, 0);
}

/// Counts the mapping's connection as covered: the slot first, then the total (a
/// death between leaves the total too low: a notify for nothing).
pub(crate) fn covered_in<P: Page>(page: &P) {
    let Some(slot) = page.own_slot() else { return };
    slot.fetch_or(COVERED_FLAG);
    adjust(page.counts(), 0, 1);
}

/// Counts the mapping's connection out of the covered: the total first, then the slot.
pub(crate) fn covered_out<P: Page>(page: &P) {
    let Some(slot) = page.own_slot() else { return };
    adjust(page.counts(), 0, -1);
    slot.fetch_and(!COVERED_FLAG);
}

/// Empties `slot`, whose mapping is gone (the caller holds its record lock, so nobody
/// else changes it), and counts what it held out of the totals, each step in its
/// owner's order (a look that dies midway leaves the totals erring the same way);
/// returns how many sleepers and receivers it held.
pub(crate) fn count_out<P: Page>(page: &P, slot: &P::C32) -> u32 {
    let held = slot.load();
    if held & COVERED_FLAG != 0 {
        adjust(page.counts(), 0, -1);
        slot.fetch_and(!COVERED_FLAG);
    }
    let receiver = held & RECEIVER_FLAG != 0;
    if receiver {
        slot.fetch_and(!RECEIVER_FLAG);
        adjust(page.counts(), -1, 0);
    }
    let sleepers = held & SLEEPER_BITS;
    if sleepers != 0 {
        slot.fetch_sub(sleepers);
        // The total is at least every slot's count (counted in first, out last), so
        // this does not wrap.
        page.sleepers().fetch_sub(sleepers);
    }
    sleepers + u32::from(receiver)
}

#[cfg(test)]
mod model;
