//! Releases samples held for reordering (C6) when their delay window passes, so a
//! held sample enters its stream on time even if nothing else is added.
//!
//! The thread sleeps until the earliest release time it knows of; holding a sample
//! wakes it (a "kick") so a newly held sample with an earlier deadline is not late.

use std::sync::Weak;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crossbeam_channel::Receiver;

use super::Inner;
use super::periodic::STOP_POLL;

use crate::time::Time;

pub(crate) fn run(inner: Weak<Inner>, kicks: Receiver<()>) {
    loop {
        let Some(rt) = inner.upgrade() else { return };
        if rt.shutdown.load(Ordering::Relaxed) {
            return;
        }
        let now = rt.clock.now();
        let mut next: Option<Time> = None;
        for cell in rt.cells() {
            let mut store = cell.store.lock();
            if store.next_release_time().is_some_and(|t| t <= now) {
                store.release_due();
            }
            next = match (next, store.next_release_time()) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
        }
        let clock = rt.clock.clone();
        drop(rt);
        // Wait for the next deadline (on the runtime's clock), a kick, or the poll
        // interval that notices shutdown. A simulated clock only moves when a test moves
        // it; its waits are bounded by the poll interval.
        let Some(t) = next else {
            // Nothing held: asleep until a hold or a shutdown kicks, or the runtime is
            // gone (its end of the channel with it). An idle process's runtime wakes
            // for nothing; each look at every store cost it a wake-up a second.
            match kicks.recv() {
                Ok(()) => while kicks.try_recv().is_ok() {},
                // The runtime is gone: nothing is left to release.
                Err(_) => return,
            }
            continue;
        };
        let wait = Duration::from_nanos(u64::try_from(t.saturating_sub(clock.now())).unwrap_or(0))
            .min(STOP_POLL);
        if kicks.recv_timeout(wait).is_ok() {
            // Drain bursts of kicks: one re-plan covers them all.
            while kicks.try_recv().is_ok() {}
        }
    }
}
