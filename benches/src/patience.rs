//! Waiting for another process without ever hanging.
//!
//! Nothing tells a waiting reader that the process at the other end died (iceoryx2
//! does not signal it; a socket does only on close). So every cross-process wait here
//! goes through a [`Patience`]: it waits in slices of at most [`SLICE`], and between
//! slices checks that the peer process still runs and that [`PEER_TIMEOUT`] has not
//! passed. The hot path — the message is there, or comes within the first slice —
//! reads no clock and makes no system call for this.

use std::time::{Duration, Instant};

use anyhow::bail;

pub use crate::inbox::PEER_TIMEOUT;
use crate::peer_process::PeerProcess;

/// The longest a wait blocks between two checks of the peer.
pub const SLICE: Duration = Duration::from_millis(20);

/// Polls between two looks at the clock while spinning.
const POLLS_PER_CLOCK_READ: u32 = 4096;

/// How long to wait for the other process, and how to tell it is gone.
#[derive(Debug)]
pub struct Patience<'a> {
    peer: Option<&'a mut PeerProcess>,
    timeout: Duration,
}

impl<'a> Patience<'a> {
    /// For the measuring process: gives up when `peer` exits or after [`PEER_TIMEOUT`].
    pub fn for_peer(peer: &'a mut PeerProcess) -> Self {
        Self { peer: Some(peer), timeout: PEER_TIMEOUT }
    }

    /// For a peer process: gives up after [`PEER_TIMEOUT`] (its parent kills it if it
    /// is gone too long, and it ends by itself if the parent is gone).
    pub fn alone() -> Self {
        Self { peer: None, timeout: PEER_TIMEOUT }
    }

    /// Fails if the peer exited or if waiting since `since` took too long. `what`
    /// names what was awaited.
    pub fn check(&mut self, what: &str, since: Instant) -> anyhow::Result<()> {
        if let Some(peer) = self.peer.as_deref_mut() {
            peer.check_running()?;
        }
        if since.elapsed() > self.timeout {
            bail!(
                "no {what} within {} s: the other process hangs or lost the connection",
                self.timeout.as_secs()
            );
        }
        Ok(())
    }

    /// Busy-polls `poll` until it yields a value; `poll` fails or gives up the wait.
    pub fn spin<T>(
        &mut self,
        what: &str,
        mut poll: impl FnMut() -> anyhow::Result<Option<T>>,
    ) -> anyhow::Result<T> {
        let mut polls = 0u32;
        // Read lazily: a message that comes within a few thousand polls never pays for
        // a clock read.
        let mut since: Option<Instant> = None;
        let mut next_check = Duration::ZERO;
        loop {
            if let Some(v) = poll()? {
                return Ok(v);
            }
            polls = polls.wrapping_add(1);
            if polls % POLLS_PER_CLOCK_READ == 0 {
                let since = *since.get_or_insert_with(Instant::now);
                if since.elapsed() >= next_check {
                    self.check(what, since)?;
                    next_check = since.elapsed() + SLICE;
                }
            }
            std::hint::spin_loop();
        }
    }

    /// Calls `wait` — which blocks at most the slice it is given and yields a value if
    /// one came — until it yields a value; `wait` fails or gives up the wait.
    pub fn block<T>(
        &mut self,
        what: &str,
        mut wait: impl FnMut(Duration) -> anyhow::Result<Option<T>>,
    ) -> anyhow::Result<T> {
        let mut since: Option<Instant> = None;
        loop {
            if let Some(v) = wait(SLICE)? {
                return Ok(v);
            }
            // Started before this first look at the clock, by at most a slice: close
            // enough for a timeout of seconds, and free on the hot path.
            let since = *since.get_or_insert_with(Instant::now);
            self.check(what, since)?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_return_what_comes() {
        let mut p = Patience::alone();
        let mut n = 0;
        let v = p
            .spin("x", || {
                n += 1;
                Ok((n == 10_000).then_some(7))
            })
            .unwrap();
        assert_eq!(v, 7);
        let mut n = 0;
        let v = p
            .block("y", |_| {
                n += 1;
                Ok((n == 3).then_some(8))
            })
            .unwrap();
        assert_eq!(v, 8);
    }

    #[test]
    fn a_wait_gives_up_after_its_timeout() {
        let mut p = Patience { peer: None, timeout: Duration::from_millis(30) };
        let e = p.spin::<()>("pong", || Ok(None)).unwrap_err().to_string();
        assert!(e.contains("no pong"), "{e}");
        let e = p
            .block::<()>("pong", |slice| {
                std::thread::sleep(slice.min(Duration::from_millis(5)));
                Ok(None)
            })
            .unwrap_err()
            .to_string();
        assert!(e.contains("no pong"), "{e}");
    }
}
