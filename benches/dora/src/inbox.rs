//! Receiving the next message from the node's one input, spinning or blocking, with a
//! deadline.

use std::time::{Duration, Instant};

use dora_node_api::{Event, EventStream, TryRecvError};

use crate::config::Wait;

/// What arrived.
pub enum Got {
    /// A message: its sequence number and length.
    Message { seq: u64, len: usize },
    /// The dataflow is stopping, or the input closed.
    Closed,
}

/// Waits for the next input, at most `timeout`; its payload is read in place and only
/// its sequence number kept.
pub fn next(events: &mut EventStream, wait: Wait, timeout: Duration) -> Result<Got, String> {
    let deadline = Instant::now() + timeout;
    loop {
        let event = match wait {
            Wait::Spin => match events.try_recv() {
                Ok(event) => event,
                Err(TryRecvError::Empty) => {
                    if Instant::now() > deadline {
                        return Err(format!("nothing received within {timeout:?}"));
                    }
                    std::hint::spin_loop();
                    continue;
                }
                Err(TryRecvError::Closed) => return Ok(Got::Closed),
            },
            Wait::Block => {
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return Err(format!("nothing received within {timeout:?}"));
                }
                match events.recv_timeout(left) {
                    Some(event) => event,
                    None => return Ok(Got::Closed),
                }
            }
        };
        match event {
            Event::Input { data, .. } => {
                let payload = <&[u8]>::try_from(&data)
                    .map_err(|e| format!("an input that is not bytes: {e}"))?;
                let seq = crate::message::read(payload)
                    .ok_or_else(|| format!("a torn message of {} bytes", payload.len()))?;
                return Ok(Got::Message { seq, len: payload.len() });
            }
            Event::Stop(_) | Event::InputClosed { .. } => return Ok(Got::Closed),
            // recv_timeout's timeout is an Error event: the loop's deadline decides.
            Event::Error(e) if wait == Wait::Block && Instant::now() > deadline => {
                return Err(format!("nothing received within {timeout:?} ({e})"));
            }
            _ => {}
        }
    }
}
