//! CDR bytes of a message as a ROS 2 MCAP file stores them (message encoding `cdr`):
//! the 4-byte encapsulation header of little-endian plain CDR, then the message.

use cdr_encoding::CdrDeserializer;
use serde::Serialize;
use serde::de::{DeserializeOwned, DeserializeSeed};

/// The encapsulation header of little-endian plain CDR (`CDR_LE`).
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// The encapsulation header of big-endian plain CDR (`CDR_BE`).
pub const CDR_BE: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// A message could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// The bytes are not the message (too short, a wrong length, a bad string).
    #[error("CDR: {0}")]
    Encoding(#[from] cdr_encoding::Error),
    /// The encapsulation header is not plain CDR's.
    #[error("CDR: encapsulation header {0:02x?} is not plain CDR (little or big endian)")]
    Encapsulation(Vec<u8>),
}

/// The message in `bytes` (encapsulation header, then the message), little- or
/// big-endian as its header says. Bytes past the message are allowed (padding).
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    decode_seed(bytes, std::marker::PhantomData::<T>)
}

/// [`decode`] through `seed`: a message whose layout is known only at run time (a
/// generated message, [`crate::generated_in`]).
pub fn decode_seed<'de, S: DeserializeSeed<'de>>(
    bytes: &'de [u8],
    seed: S,
) -> Result<S::Value, CdrError> {
    let Some((header, body)) = bytes.split_at_checked(4) else {
        return Err(CdrError::Encapsulation(bytes.to_vec()));
    };
    // The options bytes (2..4) only say how much padding ends the message.
    Ok(match [header[0], header[1]] {
        [0x00, 0x01] => {
            seed.deserialize(&mut CdrDeserializer::<byteorder::LittleEndian>::new(body))?
        }
        [0x00, 0x00] => {
            seed.deserialize(&mut CdrDeserializer::<byteorder::BigEndian>::new(body))?
        }
        _ => return Err(CdrError::Encapsulation(header.to_vec())),
    })
}

/// Appends `message`, with the encapsulation header, to `out`.
pub fn encode_into<T: Serialize>(message: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    out.extend_from_slice(&CDR_LE);
    // Alignment is counted from the byte after the header, where CDR data starts.
    let mut body = Vec::new();
    cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut body, message)?;
    out.extend_from_slice(&body);
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::msgs;

    #[test]
    fn a_message_comes_back_as_it_was_encoded() {
        let pose = msgs::Pose2D { x: 1.5, y: -2.0, theta: 0.25 };
        let mut bytes = Vec::new();
        encode_into(&pose, &mut bytes).unwrap();
        assert_eq!(decode::<msgs::Pose2D>(&bytes).unwrap(), pose);
        assert!(matches!(decode::<msgs::Pose2D>(&bytes[..10]), Err(CdrError::Encoding(_))));
        assert!(matches!(decode::<msgs::Pose2D>(&[7, 7, 0, 0]), Err(CdrError::Encapsulation(_))));
        assert!(matches!(decode::<msgs::Pose2D>(&[0]), Err(CdrError::Encapsulation(_))));
    }
}
