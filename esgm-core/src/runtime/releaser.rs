//! Releases samples held for reordering (C6) when their delay window passes, so a
//! held sample enters its stream on time even if nothing else is added.

use std::sync::Weak;
use std::sync::atomic::Ordering;

use super::Inner;
use super::periodic::STOP_POLL;
use crate::time::{Time, secs};

pub(crate) fn run(inner: Weak<Inner>) {
    loop {
        let Some(rt) = inner.upgrade() else { return };
        if rt.shutdown.load(Ordering::Relaxed) {
            return;
        }
        let cells = rt.cells();
        let now = rt.clock.now();
        let mut next: Option<Time> = None;
        for cell in &cells {
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
        drop(cells);
        drop(rt);
        clock.sleep_until(next.unwrap_or(now + secs(1)), STOP_POLL);
    }
}
