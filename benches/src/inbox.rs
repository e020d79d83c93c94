//! Receiving with either wait strategy, without ever hanging.
//!
//! A benchmark thread waits for its peer in one of two ways ([`Wait`]): busy-polling
//! or blocking. Both give up after [`PEER_TIMEOUT`], so a peer that died turns into an
//! error naming what was awaited instead of a run that never ends.

use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, TryRecvError};
use esgm_core::Subscription;

use crate::report::Wait;

/// How long a receiver waits for its peer before declaring it gone.
pub const PEER_TIMEOUT: Duration = Duration::from_secs(10);

/// Polls between two looks at the clock while spinning: reading the clock on every
/// poll would add its cost to the hop being measured.
const POLLS_PER_CLOCK_READ: u32 = 4096;

/// Something a benchmark thread receives from.
pub trait Inbox {
    /// What arrives.
    type Item;
    /// The next item if one is waiting; `Err(())` once nothing more can arrive.
    #[allow(clippy::result_unit_err)] // "closed" is all there is to say
    fn poll(&self) -> Result<Option<Self::Item>, ()>;
    /// The next item, blocking up to `timeout`; `None` on timeout or when closed.
    fn wait(&self, timeout: Duration) -> Option<Self::Item>;
}

impl<T> Inbox for Receiver<T> {
    type Item = T;
    fn poll(&self) -> Result<Option<T>, ()> {
        match self.try_recv() {
            Ok(item) => Ok(Some(item)),
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(()),
        }
    }
    fn wait(&self, timeout: Duration) -> Option<T> {
        self.recv_timeout(timeout).ok()
    }
}

impl<T> Inbox for Subscription<T> {
    type Item = T;
    fn poll(&self) -> Result<Option<T>, ()> {
        // A subscription does not tell "empty" from "ended" without blocking; an
        // ended one is caught by the timeout.
        Ok(self.try_recv())
    }
    fn wait(&self, timeout: Duration) -> Option<T> {
        self.recv_timeout(timeout).ok()
    }
}

/// Receives the next item from `inbox`, spinning or blocking as `wait` says. `what`
/// names the awaited item in the error.
pub fn receive<I: Inbox>(inbox: &I, wait: Wait, what: &str) -> anyhow::Result<I::Item> {
    match wait {
        Wait::Event => inbox.wait(PEER_TIMEOUT).ok_or_else(|| gone(what)),
        Wait::Spin => {
            let mut polls = 0u32;
            // Read lazily: a reply that comes within a few thousand polls never pays
            // for a clock read.
            let mut started: Option<Instant> = None;
            loop {
                match inbox.poll() {
                    Ok(Some(item)) => return Ok(item),
                    Ok(None) => {}
                    Err(()) => return Err(gone(what)),
                }
                polls = polls.wrapping_add(1);
                if polls % POLLS_PER_CLOCK_READ == 0
                    && started.get_or_insert_with(Instant::now).elapsed() > PEER_TIMEOUT
                {
                    return Err(gone(what));
                }
                std::hint::spin_loop();
            }
        }
    }
}

fn gone(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "no {what} within {} s: the peer thread stopped or its channel closed",
        PEER_TIMEOUT.as_secs()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_waits_receive_and_a_closed_channel_is_an_error() {
        for wait in Wait::BOTH {
            let (tx, rx) = crossbeam_channel::bounded(1);
            tx.send(7).unwrap();
            assert_eq!(receive(&rx, wait, "seven").unwrap(), 7);
            drop(tx);
            let e = receive(&rx, wait, "eight").unwrap_err().to_string();
            assert!(e.contains("no eight"), "{e}");
        }
    }
}
