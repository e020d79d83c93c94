//! CDR bytes of a message as a ROS 2 MCAP file stores them (message encoding `cdr`):
//! the 4-byte encapsulation header of little-endian plain CDR, then the message.

use serde::Serialize;

/// The encapsulation header of little-endian plain CDR (`CDR_LE`).
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A message could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode the message as CDR: {0}")]
pub struct CdrError(#[from] cdr_encoding::Error);

/// Appends `message`, with the encapsulation header, to `out`.
pub fn encode_into<T: Serialize>(message: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    out.extend_from_slice(&CDR_LE);
    // Alignment is counted from the byte after the header, where CDR data starts.
    let mut body = Vec::new();
    cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut body, message)?;
    out.extend_from_slice(&body);
    Ok(())
}
