//! The input loop behind computed and operator trajectories: every input feeds one
//! tagged channel ([`FanIn`]), so the worker sees the inputs' samples in the order they
//! were added across all inputs, and one blocking receive waits on all of them.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crossbeam_channel::{Receiver, select};

use crate::sample::Sample;
use crate::store::FanIn;

/// Calls `on_sample(input_index, sample)` for every sample any input adds, until
/// `stop` is set or `wake` disconnects (the worker is being stopped).
///
/// Samples the worker fell too far behind to keep are counted in `overflow`.
pub(crate) fn run(
    fan_in: FanIn<Sample>,
    wake: Receiver<()>,
    stop: &Arc<AtomicBool>,
    overflow: &AtomicU64,
    mut on_sample: impl FnMut(usize, Sample),
) {
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
                Err(_) => return,
            },
            // Only ever disconnection: the worker is being stopped.
            recv(wake) -> _ => return,
        }
    }
}
