//! Hop probes: where a structure's time goes between its writer's gate and the unit
//! that reads it, step by step, in both processes (issue 51's breakdown).
//!
//! Built only with the `hop-probe` feature, which nothing that ships enables: each
//! step reads the clock (tens of nanoseconds on a VM), which the data path must not
//! pay. Without it every function here is an empty inline function, so call sites need
//! no `cfg` of their own.
//!
//! A thread marks the steps it passes ([`mark`]); once it knows the add time of the
//! structure they were for (the writer after its gate, a reader once it received the
//! sample), it records each mark's distance from that add time ([`settle`]). Both
//! processes stamp on the host's one timeline (M1), so a reader's "woken 12 µs after
//! the add" and a writer's "sent 8 µs after the add" line up. [`report`] gives each
//! step's count, median and 99th percentile for the process to print.

/// A step of a hop, in the order a structure passes them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Step {
    /// Writer: the store's gate admitted it and the tap is told (type check, policy).
    Gate,
    /// Writer: a shared-memory slice was loaned for it.
    Loaned,
    /// Writer: it was written into the loan.
    Encoded,
    /// Writer: iceoryx2 sent it.
    Sent,
    /// Writer: the readers were rung (futex word, event).
    Rung,
    /// Writer: it is kept in the trajectory's kept history.
    Kept,
    /// Writer: the store holds it and its local subscribers have it.
    Stored,
    /// Reader: the thread that feeds the replica woke.
    Woken,
    /// Reader: the import's lock was taken.
    Locked,
    /// Reader: iceoryx2 handed the sample over (header and archive checked).
    Received,
    /// Reader: the structure is held where it arrived, ready to read.
    Held,
    /// Reader: the writer check and the type check passed.
    Checked,
    /// Reader: the replica's store holds it and its subscribers have it.
    Replicated,
    /// Reader: the unit's worker took it from its input queue.
    Taken,
    /// Reader: the unit's `compute` was called with it.
    Computed,
}

impl Step {
    /// Every step, in order.
    pub const ALL: [Step; 15] = [
        Step::Gate,
        Step::Loaned,
        Step::Encoded,
        Step::Sent,
        Step::Rung,
        Step::Kept,
        Step::Stored,
        Step::Woken,
        Step::Locked,
        Step::Received,
        Step::Held,
        Step::Checked,
        Step::Replicated,
        Step::Taken,
        Step::Computed,
    ];

    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Step::Gate => "gate",
            Step::Loaned => "loaned",
            Step::Encoded => "encoded",
            Step::Sent => "sent",
            Step::Rung => "rung",
            Step::Kept => "kept",
            Step::Stored => "stored",
            Step::Woken => "woken",
            Step::Locked => "locked",
            Step::Received => "received",
            Step::Held => "held",
            Step::Checked => "checked",
            Step::Replicated => "replicated",
            Step::Taken => "taken",
            Step::Computed => "computed",
        }
    }
}

/// One step's figures in this process: how many structures passed it, and the median
/// and 99th percentile of its distance from their add time (ns; negative: before it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepFigures {
    /// The step.
    pub step: Step,
    /// Structures that passed it.
    pub n: usize,
    /// Median distance from the add time.
    pub p50: i64,
    /// 99th percentile.
    pub p99: i64,
}

#[cfg(feature = "hop-probe")]
mod on {
    use std::cell::RefCell;
    use std::sync::Mutex;

    use super::{Step, StepFigures};
    use crate::clock::{Clock as _, SystemClock};
    use crate::time::Time;

    /// Distances kept per step at most (the oldest go first).
    const KEEP: usize = 200_000;

    static LOGS: [Mutex<Vec<i64>>; 15] = [const { Mutex::new(Vec::new()) }; 15];

    thread_local! {
        static MARKS: RefCell<[Option<Time>; 15]> = const { RefCell::new([None; 15]) };
    }

    pub fn mark(step: Step) {
        let now = SystemClock.now();
        MARKS.with(|m| m.borrow_mut()[step as usize] = Some(now));
    }

    pub fn settle(add_time: Time) {
        MARKS.with(|m| {
            for (i, at) in m.borrow_mut().iter_mut().enumerate() {
                if let Some(at) = at.take() {
                    if let Ok(mut log) = LOGS[i].lock() {
                        if log.len() >= KEEP {
                            log.remove(0);
                        }
                        log.push(at - add_time);
                    }
                }
            }
        });
    }

    pub fn forget() {
        MARKS.with(|m| *m.borrow_mut() = [None; 15]);
    }

    pub fn report() -> Vec<StepFigures> {
        Step::ALL
            .iter()
            .filter_map(|&step| {
                let mut log = LOGS[step as usize].lock().ok()?.clone();
                if log.is_empty() {
                    return None;
                }
                log.sort_unstable();
                let at = |q: f64| log[((log.len() - 1) as f64 * q).round() as usize];
                Some(StepFigures { step, n: log.len(), p50: at(0.5), p99: at(0.99) })
            })
            .collect()
    }
}

/// Notes that this thread passed `step` now (nothing without the `hop-probe` feature).
#[inline(always)]
pub fn mark(step: Step) {
    #[cfg(feature = "hop-probe")]
    on::mark(step);
    #[cfg(not(feature = "hop-probe"))]
    let _ = step;
}

/// Records the distance of every step this thread marked since it last settled from
/// `add_time`, the add time of the structure they were for.
#[inline(always)]
pub fn settle(add_time: crate::time::Time) {
    #[cfg(feature = "hop-probe")]
    on::settle(add_time);
    #[cfg(not(feature = "hop-probe"))]
    let _ = add_time;
}

/// Forgets this thread's marks (they were for nothing that entered).
#[inline(always)]
pub fn forget() {
    #[cfg(feature = "hop-probe")]
    on::forget();
}

/// Each step's figures in this process; empty without the `hop-probe` feature.
pub fn report() -> Vec<StepFigures> {
    #[cfg(feature = "hop-probe")]
    return on::report();
    #[cfg(not(feature = "hop-probe"))]
    Vec::new()
}

/// True when this build has the probes.
pub const ENABLED: bool = cfg!(feature = "hop-probe");
