//! The input loop behind computed and operator trajectories: every input feeds one
//! tagged channel ([`FanIn`]), so the worker sees the inputs' samples in the order they
//! were added across all inputs, and one blocking receive waits on all of them.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use std::time::Duration;

use crossbeam_channel::{Receiver, TryRecvError, select};

use crate::sample::Sample;
use crate::store::FanIn;

/// The longest a worker waiting on its input's writer sleeps before looking at its stop.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// The input tag of a flush marker: not a sample, but a point in the queue the
/// runtime's `flush` waits for the worker to reach (counted in `flushed`).
pub(crate) const FLUSH_MARKER: usize = usize::MAX;

/// Calls `on_sample(input_index, sample)` for every sample any input adds, until
/// `stop` is set or `wake` disconnects (the worker is being stopped).
///
/// Samples the worker fell too far behind to keep are counted in `overflow`.
pub(crate) fn run(
    mut fan_in: FanIn<Sample>,
    wake: Receiver<()>,
    stop: &Arc<AtomicBool>,
    overflow: &AtomicU64,
    flushed: &AtomicU64,
    mut on_sample: impl FnMut(usize, Sample),
) {
    let mut on_sample = move |input: usize, sample: Sample| {
        if input == FLUSH_MARKER {
            flushed.fetch_add(1, Ordering::Release);
        } else {
            on_sample(input, sample);
        }
    };
    if let Some(mut waiter) = fan_in.take_waiter() {
        // Replica inputs only: wait on their writers' wake-ups, feed, take (see
        // `ReplicaFeed`). Stop is noticed within a wait slice.
        loop {
            if stop.load(Ordering::Relaxed)
                || matches!(wake.try_recv(), Err(TryRecvError::Disconnected))
            {
                return;
            }
            match fan_in.receiver().try_recv() {
                Ok((input, sample)) => {
                    overflow.store(fan_in.overflowed(), Ordering::Relaxed);
                    on_sample(input, sample);
                    continue;
                }
                Err(TryRecvError::Disconnected) => return,
                Err(TryRecvError::Empty) => {}
            }
            waiter.feed();
            if !fan_in.receiver().is_empty() {
                continue;
            }
            if !waiter.wait_and_feed(WAIT_SLICE) {
                // It cannot wait on the writer: the runtime's feeding thread wakes it.
                break;
            }
        }
    }
    loop {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        select! {
            recv(fan_in.receiver()) -> msg => match msg {
                Ok((input, sample)) => {
                    overflow.store(fan_in.overflowed(), Ordering::Relaxed);
                    on_sample(input, sample);
                }
                // Every input's sender is gone (destroyed, or the runtime stopping).
                Err(_) => return,
            },
            // Only ever disconnection: the worker is being stopped.
            recv(wake) -> _ => return,
        }
    }
}
