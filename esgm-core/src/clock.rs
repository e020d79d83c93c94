//! The clock every timing rule reads (M1).
//!
//! Nothing in esgm-core reads the operating system's time directly: stores, schedulers
//! and constraints are handed a [`Clock`]. Production code uses [`SystemClock`] (the
//! host's wall clock, so that separate processes share one timeline); tests and replays
//! use [`SimClock`], which only moves when told to, so every delay, period and cache rule
//! can be tested without sleeping.

use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use parking_lot::{Condvar, Mutex};

use crate::time::{Time, to_std_duration};

/// A source of the current time, shared by everything that applies timing rules.
///
/// Implementations must be monotone enough for the rules that read them: a clock that
/// jumps backwards makes a delay constraint reject samples it should accept.
pub trait Clock: Send + Sync + std::fmt::Debug {
    /// The current time on the shared timeline.
    fn now(&self) -> Time;

    /// Blocks the calling thread until [`Clock::now`] is at least `deadline`, or until
    /// `max_wait` of real time has passed, whichever comes first. Returns the time read
    /// on waking.
    ///
    /// The real-time bound exists so that threads waiting on a simulated clock still
    /// notice shutdown requests and never hang a test.
    fn sleep_until(&self, deadline: Time, max_wait: std::time::Duration) -> Time;
}

/// A shared handle on a clock, the form stores and runtimes keep.
pub type SharedClock = Arc<dyn Clock>;

/// The host's wall clock (`CLOCK_REALTIME`, nanoseconds since the Unix epoch).
///
/// A wall clock rather than a monotonic one because valid times cross process
/// boundaries (and, over a bridge, hosts): every process must agree on what a number
/// means, and the seed's timeline is calendar time.
#[derive(Debug, Default, Clone, Copy)]
pub struct SystemClock;

impl SystemClock {
    /// A shared handle on the system clock.
    pub fn shared() -> SharedClock {
        Arc::new(SystemClock)
    }
}

impl Clock for SystemClock {
    fn now(&self) -> Time {
        match SystemTime::now().duration_since(UNIX_EPOCH) {
            Ok(d) => i64::try_from(d.as_nanos()).unwrap_or(i64::MAX),
            // A wall clock set before 1970: report negative time rather than panic.
            Err(e) => -i64::try_from(e.duration().as_nanos()).unwrap_or(i64::MAX),
        }
    }

    fn sleep_until(&self, deadline: Time, max_wait: std::time::Duration) -> Time {
        let now = self.now();
        if deadline > now {
            std::thread::sleep(to_std_duration(deadline - now).min(max_wait));
        }
        self.now()
    }
}

/// A clock that only moves when a test (or a replay) moves it.
///
/// Threads blocked in [`Clock::sleep_until`] wake as soon as the clock is advanced past
/// their deadline, so a runtime driven by a `SimClock` runs deterministically.
#[derive(Debug, Default)]
pub struct SimClock {
    now: Mutex<Time>,
    moved: Condvar,
}

impl SimClock {
    /// A simulated clock starting at `start`.
    pub fn new(start: Time) -> Self {
        Self { now: Mutex::new(start), moved: Condvar::new() }
    }

    /// A shared simulated clock starting at `start`; keep the `Arc<SimClock>` to move
    /// it and hand clones to whatever needs a [`SharedClock`].
    pub fn shared(start: Time) -> Arc<SimClock> {
        Arc::new(Self::new(start))
    }

    /// The current simulated time (also available through [`Clock::now`]).
    pub fn now(&self) -> Time {
        *self.now.lock()
    }

    /// Moves the clock forward by `d` (negative values are ignored: time never runs
    /// backwards) and returns the new time.
    pub fn advance(&self, d: Time) -> Time {
        let mut now = self.now.lock();
        *now = now.saturating_add(d.max(0));
        self.moved.notify_all();
        *now
    }

    /// Sets the clock to `t` if that is not in its past, and returns the current time.
    pub fn set(&self, t: Time) -> Time {
        let mut now = self.now.lock();
        if t > *now {
            *now = t;
            self.moved.notify_all();
        }
        *now
    }
}

impl Clock for SimClock {
    fn now(&self) -> Time {
        SimClock::now(self)
    }

    fn sleep_until(&self, deadline: Time, max_wait: std::time::Duration) -> Time {
        let give_up = std::time::Instant::now() + max_wait;
        let mut now = self.now.lock();
        while *now < deadline {
            if self.moved.wait_until(&mut now, give_up).timed_out() {
                break;
            }
        }
        *now
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn sim_clock_moves_only_forward() {
        let c = SimClock::new(100);
        assert_eq!(c.advance(50), 150);
        assert_eq!(c.advance(-10), 150);
        assert_eq!(c.set(120), 150);
        assert_eq!(c.set(200), 200);
        assert_eq!(c.now(), 200);
    }

    #[test]
    fn sim_clock_wakes_sleepers_when_advanced() {
        let c = SimClock::shared(0);
        let c2 = Arc::clone(&c);
        let t = std::thread::spawn(move || c2.sleep_until(1_000, Duration::from_secs(10)));
        // Advance in steps; the sleeper must wake exactly when the deadline is reached.
        c.advance(500);
        c.advance(500);
        let woke_at = t.join().map_err(|_| "sleeper panicked").unwrap_or(-1);
        assert_eq!(woke_at, 1_000);
    }

    #[test]
    fn sim_clock_sleep_gives_up_after_max_wait() {
        let c = SimClock::new(0);
        assert_eq!(c.sleep_until(10, Duration::from_millis(5)), 0);
    }

    #[test]
    fn system_clock_is_after_2020() {
        assert!(SystemClock.now() > 1_577_836_800 * crate::time::TIMEUNITS_PER_SECOND);
    }
}
