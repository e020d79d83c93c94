//! The periodic loop behind sampled trajectories: a tick at every sample time from
//! `from` to `to`, on the runtime's clock.
//!
//! Sample times are exact multiples of the period after `from` (the query time handed
//! to the sensor is the scheduled time, not the wake-up time), so a sampled stream's
//! valid times are evenly spaced however the thread is scheduled. A worker that wakes
//! a period or more late skips the missed sample times and counts them.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::clock::SharedClock;
use crate::esgm::{MissCause, MissedPoints};
use crate::time::Time;

/// How long a sleeping worker waits before re-checking its stop flag.
pub(crate) const STOP_POLL: Duration = Duration::from_millis(20);

/// When to tick.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Schedule {
    /// First sample time (already resolved: never 0 for "now").
    pub from: Time,
    /// Last sample time, if any.
    pub to: Option<Time>,
    pub period: Time,
}

/// Asks the kernel to wake this thread at its deadlines. Linux lets a sleeping thread
/// oversleep by its timer slack (50 µs by default) to batch wake-ups; a sampler's
/// jitter is the spread of its wake-ups, so it gives the slack up (the least the
/// kernel allows, 1 ns), as `SCHED_FIFO` threads have it already. Only this thread
/// changes, and only how late its timed sleeps may end.
fn precise_wake_ups() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: PR_SET_TIMERSLACK reads its integer argument and changes the calling
        // thread's slack only; no memory is passed.
        let _refused = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
    }
}

/// Runs `tick(sample_time)` at every sample time until `stop` is set or the schedule
/// ends. `missed` is told about skipped sample times, and why they were skipped: the
/// previous call took a period or more, or the thread woke that late on its own.
///
/// A tick may set `call_ended` to when its producer's call returned, before it stores
/// the result: the call's duration is then measured to there, not to after the store
/// (which a reader may see first). Left unset, it is measured to the tick's end.
pub(crate) fn run(
    clock: &SharedClock,
    stop: &Arc<AtomicBool>,
    schedule: Schedule,
    call_ended: &std::cell::Cell<Option<Time>>,
    mut missed: impl FnMut(MissedPoints),
    mut tick: impl FnMut(Time),
) {
    precise_wake_ups();
    let mut next = schedule.from;
    // How long the last call took (the clock read after it, minus the wake-up).
    let mut last_call: Time = 0;
    while !stop.load(Ordering::Relaxed) {
        if schedule.to.is_some_and(|to| next > to) {
            break;
        }
        let now = clock.sleep_until(next, STOP_POLL);
        if now < next {
            continue;
        }
        let late = now.saturating_sub(next) / schedule.period;
        if late > 0 {
            let period = schedule.period;
            let cause = if last_call >= period {
                MissCause::SlowCall { took: last_call, period }
            } else {
                MissCause::LateWakeUp { late: now.saturating_sub(next), period }
            };
            missed(MissedPoints { at: now, missed: late as u64, cause });
            next = next.saturating_add(late.saturating_mul(schedule.period));
            if schedule.to.is_some_and(|to| next > to) {
                break;
            }
        }
        if stop.load(Ordering::Relaxed) {
            break;
        }
        call_ended.set(None);
        tick(next);
        last_call = call_ended.get().unwrap_or_else(|| clock.now()).saturating_sub(now);
        match next.checked_add(schedule.period) {
            Some(n) => next = n,
            // The end of time: nothing more to sample.
            None => break,
        }
    }
}
