//! What a message carries: its sequence number in its first 8 bytes and the number's
//! low byte as its last byte, so the reader checks both ends of the payload.

/// The smallest payload that holds a sequence number.
pub const MIN_BYTES: usize = 8;
/// The handshake's sequence number: answered, never measured.
pub const HELLO: u64 = 0;
/// Tells pong to exit.
pub const STOP: u64 = u64::MAX;

/// Stamps `seq` into a payload (at least [`MIN_BYTES`] long).
pub fn stamp(payload: &mut [u8], seq: u64) {
    if let Some(head) = payload.get_mut(..MIN_BYTES) {
        head.copy_from_slice(&seq.to_le_bytes());
    }
    if let Some(last) = payload.last_mut() {
        *last = seq as u8;
    }
}

/// The sequence number of a payload, if its last byte agrees with it.
pub fn read(payload: &[u8]) -> Option<u64> {
    let head: [u8; MIN_BYTES] = payload.get(..MIN_BYTES)?.try_into().ok()?;
    let seq = u64::from_le_bytes(head);
    (payload.last() == Some(&(seq as u8))).then_some(seq)
}

/// Fills a whole payload as a camera writes a frame (each byte depends on its place
/// and the frame), then stamps it.
pub fn fill(payload: &mut [u8], seq: u64) {
    let seed = seq as u8;
    for (i, b) in payload.iter_mut().enumerate() {
        *b = (i as u8).wrapping_mul(31).wrapping_add(seed);
    }
    stamp(payload, seq);
}
