//! How a subscriber waits for the next sample.
//!
//! # The trade-off measured on this kind of machine
//! A sample reaches a *spinning* reader about 1.3 µs after it is sent. A reader that
//! *blocks* must be woken by the kernel: through iceoryx2's event (a Unix datagram)
//! that wake-up alone costs 10–14 µs, more than a blocking Unix-socket read (5–9 µs);
//! through a futex word in shared memory, which esgm's readers sleep on (see below),
//! about 6 µs. Spinning
//! forever wins latency but burns a core while nothing arrives, which a robot program
//! with a dozen subscribers cannot afford.
//!
//! # The default: spin briefly, then block
//! [`WaitStrategy::SpinThenBlock`] polls for [`DEFAULT_SPIN`] (25 µs) and only then
//! sleeps on the trajectory's wake-up word. Anything that arrives within the spin
//! window — the reply in a request/reply exchange, the next stage of a pipeline that is
//! already running, any sample a blocking socket would have delivered in its 5–9 µs —
//! is seen at spinning latency, so the default beats a blocking socket on small
//! structures. Anything later costs the event wake-up, as blocking would anyway.
//!
//! After [`PURE_SPIN`] (2 µs) the spin yields the CPU between polls. Without that, on a
//! busy machine the peer we are waiting for — woken by our own send, and placed by
//! Linux on *our* core — could not run until our spin ended: measured, every
//! exchange then took the whole spin window plus a wake-up (33 µs with a 25 µs spin,
//! 210 µs with 200 µs). A yield with nothing else runnable costs well under a
//! microsecond, so it keeps the latency of a pure spin when cores are free.
//!
//! Measured with `examples/wait_strategies.rs`, before readers slept on the futex word
//! (release, 2 cores shared with other
//! work, unpinned; one-way = round trip / 2, small structure, p50 / p99):
//!
//! | wait                            | p50          | p99        |
//! |---------------------------------|--------------|------------|
//! | busy spin                       | 1.5–2.5 µs   | 1.9–3.6 µs |
//! | spin-then-block 25 µs (default) | 1.6–2.6 µs   | 1.9–4.3 µs |
//! | block on the iceoryx2 event     | 11.6–17.5 µs | 17–28 µs   |
//! | blocking Unix socket (baseline) | 4.7–6.1 µs   | 8.7–12 µs  |
//!
//! Idle cost: a default-strategy reader with nothing to read used 0.08 % of a core
//! (one 25 µs spin per 100 ms timeout); reading a 1 kHz stream 4.1 % of a core, against
//! 1.9 % for pure blocking — the spin adds at most 25 µs per sample, so a 30 Hz camera
//! costs under 0.1 % more.
//!
//! # Sleeping on a futex word
//! A blocking reader sleeps on its trajectory's futex word ([`crate::data_plane::wake_word`]): the
//! writer adds one to it after every send and calls `FUTEX_WAKE` only when somebody
//! sleeps, so while readers spin, or nobody reads, a publish costs one atomic add and
//! no system call. A reader about to sleep loads the word, polls once more, and sleeps
//! only if the word still holds what it loaded: a sample sent after that poll changed
//! it, and the kernel refuses the sleep. A futex wake-up between two processes costs
//! about half of iceoryx2's event here (6 µs against 13 µs, `floor-futex`).
//!
//! Where the word cannot be mapped, and for services that have none (a trajectory's
//! violations), the reader sleeps on iceoryx2's event instead. iceoryx2 only sends a
//! datagram when the listener has consumed the previous one (its notification state
//! goes idle → notified once, and later notifies see "already notified" and stop at an
//! atomic). A reader about to sleep on it first drains stale wake-ups, then polls once
//! more, then sleeps: a sample sent after that poll finds the state idle and sends a
//! datagram, so no sample is missed between the last poll and the sleep.
//!
//! # Never forever
//! Every wait takes a timeout: a publisher that dies is not signalled to a waiting
//! reader, so without a deadline a reader could wait forever.

use crate::data_plane::service::ShmService;
use crate::data_plane::wake_word::WakeWord;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};

/// How long [`WaitStrategy::default`] spins before blocking (see the module docs).
pub const DEFAULT_SPIN: Duration = Duration::from_micros(25);

/// How long [`WaitStrategy::SpinThenBlock`] spins without yielding the CPU.
pub const PURE_SPIN: Duration = Duration::from_micros(2);

/// How a subscriber waits for a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum WaitStrategy {
    /// Poll until a sample arrives or the timeout passes: the lowest latency, one core
    /// busy for the whole wait. For a dedicated, pinned reader.
    BusySpin,
    /// Poll for `spin` (bounded by the timeout, yielding the CPU between polls after
    /// `PURE_SPIN`), then sleep on the trajectory's wake-up word.
    SpinThenBlock {
        /// How long to poll before sleeping.
        spin: Duration,
    },
    /// Sleep on the trajectory's wake-up word at once: no CPU while waiting, about
    /// 6–8 µs per wake-up (`esgm-small` event in BENCHMARKS.md).
    Block,
}

impl Default for WaitStrategy {
    /// [`WaitStrategy::SpinThenBlock`] for [`DEFAULT_SPIN`].
    fn default() -> Self {
        WaitStrategy::SpinThenBlock { spin: DEFAULT_SPIN }
    }
}

impl WaitStrategy {
    /// True if the strategy sleeps, and so needs the wake-up word (or a listener).
    pub fn blocks(&self) -> bool {
        !matches!(self, WaitStrategy::BusySpin)
    }
}

/// What a blocking reader sleeps on: the trajectory's futex word, or (where the word
/// cannot be mapped, or for a service that has none) an iceoryx2 listener.
#[derive(Debug)]
pub(crate) enum Sleeper {
    Word(WakeWord),
    Listener(Box<Listener<ShmService>>),
}

impl Sleeper {
    /// The word of the wake-up service `service` (unless [`crate::data_plane::wake_word::WAKE_ENV`]
    /// says `event`), else the listener `listener` makes.
    pub(crate) fn open<E>(
        service: &str,
        listener: impl FnOnce() -> Result<Listener<ShmService>, E>,
    ) -> Result<Sleeper, E> {
        if crate::data_plane::wake_word::futex_enabled() {
            match WakeWord::open(service) {
                Ok(word) => return Ok(Sleeper::Word(word)),
                Err(e) => tracing::debug!(service, error = %e,
                    "cannot map the wake-up word; sleeping on the iceoryx2 event"),
            }
        }
        listener().map(|l| Sleeper::Listener(Box::new(l)))
    }
}

/// A wait strategy with what it needs to block.
#[derive(Debug)]
pub(crate) enum Waiter {
    Spin,
    SpinThenBlock { spin: Duration, sleeper: Sleeper },
    Block { sleeper: Sleeper },
}

impl Waiter {
    /// The waiter for `strategy`; `sleeper` is used only if the strategy blocks.
    pub(crate) fn new(strategy: WaitStrategy, sleeper: Option<Sleeper>) -> Self {
        match (strategy, sleeper) {
            (WaitStrategy::SpinThenBlock { spin }, Some(sleeper)) => {
                Waiter::SpinThenBlock { spin, sleeper }
            }
            (WaitStrategy::Block, Some(sleeper)) => Waiter::Block { sleeper },
            // Without a sleeper nothing can wake a reader: polling is the only option.
            _ => Waiter::Spin,
        }
    }

    /// Calls `poll` until it yields a value, fails, or `deadline` passes (then
    /// `Ok(None)`). `poll` is always called at least once.
    pub(crate) fn wait<T, E: From<ListenerWaitError>>(
        &self,
        deadline: Instant,
        mut poll: impl FnMut() -> Result<Option<T>, E>,
    ) -> Result<Option<T>, E> {
        if let Some(v) = poll()? {
            return Ok(Some(v));
        }
        let (spin_until, sleeper) = match self {
            Waiter::Spin => (deadline, None),
            Waiter::SpinThenBlock { spin, sleeper } => {
                let until = Instant::now().checked_add(*spin).unwrap_or(deadline);
                (until.min(deadline), Some(sleeper))
            }
            Waiter::Block { sleeper } => (Instant::now(), Some(sleeper)),
        };

        // A blocking strategy's spin yields after a short pure spin (see the module docs).
        let yield_from = match self {
            Waiter::Spin => spin_until,
            _ => Instant::now() + PURE_SPIN,
        };
        loop {
            let now = Instant::now();
            if now >= spin_until {
                break;
            }
            if now >= yield_from {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
            if let Some(v) = poll()? {
                return Ok(Some(v));
            }
        }
        match sleeper {
            None => Ok(None),
            Some(Sleeper::Word(word)) => loop {
                // Loaded before the look: a sample sent after it changes the word, and
                // the sleep is refused (see `wake_word`).
                let seen = word.sequence();
                if let Some(v) = poll()? {
                    return Ok(Some(v));
                }
                let now = Instant::now();
                if now >= deadline {
                    return Ok(None);
                }
                word.sleep(seen, deadline - now);
            },
            Some(Sleeper::Listener(listener)) => {
                // Consume wake-ups for samples already taken, so that the next notify
                // sends a datagram instead of seeing "already notified" (see the
                // module docs).
                listener.try_wait(|_| {})?;
                loop {
                    if let Some(v) = poll()? {
                        return Ok(Some(v));
                    }
                    let now = Instant::now();
                    if now >= deadline {
                        return Ok(None);
                    }
                    timed_wait(listener, deadline - now)?;
                }
            }
        }
    }
}

/// Waits up to `timeout` on `listener`, consuming its notifications.
///
/// Every esgm wait on an iceoryx2 listener goes through here: iceoryx2 0.10 times a
/// wait with the socket's receive timeout, where a timeout that rounds down to zero
/// microseconds means *forever* — a wait that should end at once would never end.
pub(crate) fn timed_wait(
    listener: &Listener<ShmService>,
    timeout: Duration,
) -> Result<u64, ListenerWaitError> {
    if timeout < Duration::from_micros(1) {
        listener.try_wait(|_| {})
    } else {
        listener.timed_wait(|_| {}, timeout)
    }
}

/// A wait on several listeners failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WaitAnyError {
    /// `poll(2)` failed.
    #[error("cannot wait on the listeners: {0}")]
    Poll(std::io::Error),
    /// A listener's notifications could not be taken.
    #[error("cannot take a listener's notifications: {0:?}")]
    Take(ListenerWaitError),
}

/// Waits up to `timeout` until any of `listeners` is notified (one `poll(2)` on their
/// descriptors), then consumes the notifications of those that were, so that each
/// next notify wakes again. An interrupted wait returns as a wake-up: the caller looks
/// at what arrived either way.
pub(crate) fn wait_any(
    listeners: &[&Listener<ShmService>],
    timeout: Duration,
) -> Result<(), WaitAnyError> {
    use iceoryx2::prelude::FileDescriptorBased as _;
    let mut fds: Vec<libc::pollfd> = listeners
        .iter()
        .map(|l| libc::pollfd {
            // SAFETY: the descriptor belongs to the listener, which outlives this call.
            fd: unsafe { l.file_descriptor().native_handle() },
            events: libc::POLLIN,
            revents: 0,
        })
        .collect();
    // Rounded up: a timeout below a millisecond still sleeps rather than spins.
    let ms = i32::try_from(timeout.as_micros().div_ceil(1000)).unwrap_or(i32::MAX);
    let nfds = libc::nfds_t::try_from(fds.len()).unwrap_or(libc::nfds_t::MAX);
    // SAFETY: `fds` is a valid array of `nfds` pollfd entries for the whole call.
    let ready = unsafe { libc::poll(fds.as_mut_ptr(), nfds, ms) };
    if ready < 0 {
        let e = std::io::Error::last_os_error();
        return if e.kind() == std::io::ErrorKind::Interrupted {
            Ok(())
        } else {
            Err(WaitAnyError::Poll(e))
        };
    }
    for (listener, fd) in listeners.iter().zip(&fds) {
        if fd.revents != 0 {
            listener.try_wait(|_| {}).map_err(WaitAnyError::Take)?;
        }
    }
    Ok(())
}

/// `now + timeout`, saturating at a far but finite deadline.
pub(crate) fn deadline_after(timeout: Duration) -> Instant {
    let now = Instant::now();
    // A timeout too large for `Instant` still ends: a year is "forever" for a wait.
    now.checked_add(timeout)
        .or_else(|| now.checked_add(Duration::from_secs(365 * 24 * 3600)))
        .unwrap_or(now)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spinning_returns_what_poll_finds_and_times_out() {
        let w = Waiter::new(WaitStrategy::BusySpin, None);
        let mut n = 0;
        let got: Result<Option<i32>, ListenerWaitError> =
            w.wait(deadline_after(Duration::from_secs(5)), || {
                n += 1;
                Ok((n == 3).then_some(7))
            });
        assert_eq!(got.unwrap(), Some(7));

        let start = Instant::now();
        let got: Result<Option<i32>, ListenerWaitError> =
            w.wait(deadline_after(Duration::from_millis(5)), || Ok(None));
        assert_eq!(got.unwrap(), None);
        assert!(start.elapsed() >= Duration::from_millis(5));
    }

    #[test]
    fn a_blocking_strategy_without_listener_degrades_to_polling() {
        let w = Waiter::new(WaitStrategy::Block, None);
        assert!(matches!(w, Waiter::Spin));
        assert!(WaitStrategy::default().blocks());
        assert!(!WaitStrategy::BusySpin.blocks());
    }

    #[test]
    #[allow(clippy::unwrap_used, reason = "a failure is a failed test")]
    fn wait_any_wakes_on_whichever_listener_is_notified_and_consumes_it() {
        use iceoryx2::prelude::{NodeBuilder, ServiceName};
        let node = NodeBuilder::new()
            .config(crate::data_plane::service::iceoryx2_config())
            .create::<ShmService>()
            .unwrap();
        let domain = crate::data_plane::service_name::unique_domain("wait-any");
        let events: Vec<_> = ["a", "b"]
            .iter()
            .map(|n| {
                let name = ServiceName::new(&format!("{domain}/{n}")).unwrap();
                node.service_builder(&name).event().open_or_create().unwrap()
            })
            .collect();
        let listeners: Vec<_> =
            events.iter().map(|e| e.listener_builder().create().unwrap()).collect();
        let second = events[1].notifier_builder().create().unwrap();
        let all: Vec<&Listener<ShmService>> = listeners.iter().collect();

        // Nothing notified: the wait lasts its timeout.
        let start = Instant::now();
        wait_any(&all, Duration::from_millis(30)).unwrap();
        assert!(start.elapsed() >= Duration::from_millis(30));

        // The second listener notified: the wait returns long before its timeout, and
        // the notification is consumed (the next wait sleeps again).
        second.notify().unwrap();
        let start = Instant::now();
        wait_any(&all, Duration::from_secs(20)).unwrap();
        assert!(start.elapsed() < Duration::from_secs(20));
        assert_eq!(listeners[1].try_wait(|_| {}).unwrap(), 0, "consumed");
        let start = Instant::now();
        wait_any(&all, Duration::from_millis(30)).unwrap();
        assert!(start.elapsed() >= Duration::from_millis(30));
    }

    #[test]
    fn huge_timeouts_still_end() {
        let d = deadline_after(Duration::MAX);
        assert!(d > Instant::now());
    }
}
