//! The input loop behind computed and operator trajectories: wait on the
//! subscriptions of every input at once and hand each new sample on, in the order
//! each input added them.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crossbeam_channel::{Receiver, Select};

use crate::sample::Sample;
use crate::store::Subscription;

/// Calls `on_sample(input_index, sample)` for every sample any input adds, until
/// `stop` is set, `wake` disconnects, or every input has ended.
pub(crate) fn run(
    inputs: Vec<Subscription<Sample>>,
    wake: Receiver<()>,
    stop: &Arc<AtomicBool>,
    mut on_sample: impl FnMut(usize, Sample),
) {
    let mut live: Vec<Option<Subscription<Sample>>> = inputs.into_iter().map(Some).collect();
    loop {
        if stop.load(Ordering::Relaxed) || live.iter().all(Option::is_none) {
            return;
        }
        let mut sel = Select::new();
        let mut slots = Vec::new();
        for (i, s) in live.iter().enumerate() {
            if let Some(s) = s {
                sel.recv(s.receiver());
                slots.push(i);
            }
        }
        let wake_op = sel.recv(&wake);
        let op = sel.select();
        let index = op.index();
        if index == wake_op {
            // Only ever disconnection: the worker is being stopped.
            let _ = op.recv(&wake);
            return;
        }
        let input = slots[index];
        let Some(sub) = &live[input] else { continue };
        match op.recv(sub.receiver()) {
            Ok(sample) => on_sample(input, sample),
            // The input trajectory was destroyed: keep going on the others.
            Err(_) => live[input] = None,
        }
    }
}
