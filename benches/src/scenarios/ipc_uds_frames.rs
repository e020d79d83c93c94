//! Length-prefixed frames over a Unix stream socket, the way a socket-based transport
//! would carry codec bytes: a 16-byte header (the body length, little-endian, then
//! zeros) and the body.
//!
//! The reader receives into one reusable buffer of 16-byte blocks, so the body — right
//! after the 16-byte header — is aligned for [`esgm_core::codec::access`] without a
//! copy. The writer sends header and body in one vectored write, without joining them.
//!
//! Both wait as the socket is set up ([`configure`]): a non-blocking socket is
//! busy-polled (the `spin` rows), a blocking one blocks in slices of
//! [`crate::patience::SLICE`]; either way through a [`Patience`], so a dead peer ends
//! the wait.

use std::io::{self, IoSlice, Read, Write};
use std::os::unix::net::UnixStream;

use anyhow::{Context as _, bail};
use esgm_shm::Block16;
use esgm_shm::unstable::blocks_for;

use crate::patience::{Patience, SLICE};

/// Bytes before each body.
pub const HEADER_LEN: usize = 16;

/// Sets `stream` up for busy-polling (`spin`) or blocking in slices.
pub fn configure(stream: &UnixStream, spin: bool) -> io::Result<()> {
    stream.set_nonblocking(spin)?;
    if !spin {
        stream.set_read_timeout(Some(SLICE))?;
        stream.set_write_timeout(Some(SLICE))?;
    }
    Ok(())
}

/// Sends `body` as one frame.
pub fn send(
    stream: &UnixStream,
    body: &[u8],
    spin: bool,
    patience: &mut Patience<'_>,
    what: &str,
) -> anyhow::Result<()> {
    let mut header = [0u8; HEADER_LEN];
    header[..8].copy_from_slice(&(body.len() as u64).to_le_bytes());
    let mut slices = [IoSlice::new(&header), IoSlice::new(body)];
    let mut rest: &mut [IoSlice<'_>] = &mut slices;
    while !rest.is_empty() {
        let write = || -> anyhow::Result<Option<usize>> {
            match (&*stream).write_vectored(rest) {
                Ok(0) => bail!("the socket closed while sending a {what}"),
                Ok(n) => Ok(Some(n)),
                Err(e) if would_block(&e) => Ok(None),
                Err(e) => Err(e).with_context(|| format!("could not send a {what}")),
            }
        };
        let n =
            if spin { patience.spin(what, write)? } else { patience.block(what, |_| write())? };
        IoSlice::advance_slices(&mut rest, n);
    }
    Ok(())
}

/// Receives frames of bodies up to a fixed size into one aligned buffer.
#[derive(Debug)]
pub struct FrameReader {
    buf: Vec<Block16>,
    /// Bytes of `buf` holding received data.
    filled: usize,
    /// End of the frame last returned (dropped on the next receive).
    frame_end: usize,
}

impl FrameReader {
    /// A reader for bodies of at most `max_body` bytes.
    pub fn new(max_body: usize) -> Self {
        Self {
            buf: vec![Block16::default(); blocks_for(HEADER_LEN + max_body)],
            filled: 0,
            frame_end: 0,
        }
    }

    /// The next frame's body (16-byte aligned), or `None` if the socket closed between
    /// frames.
    pub fn receive(
        &mut self,
        stream: &UnixStream,
        spin: bool,
        patience: &mut Patience<'_>,
        what: &str,
    ) -> anyhow::Result<Option<&[u8]>> {
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut self.buf);
        if self.frame_end > 0 {
            // Keep what came after the last frame at the front, still aligned.
            bytes.copy_within(self.frame_end..self.filled, 0);
            self.filled -= self.frame_end;
            self.frame_end = 0;
        }
        loop {
            if let Some(end) = frame_end(&bytes[..self.filled], bytes.len())? {
                self.frame_end = end;
                return Ok(Some(&bytemuck::cast_slice(&self.buf)[HEADER_LEN..end]));
            }
            let free = &mut bytes[self.filled..];
            let mut read = || -> anyhow::Result<Option<usize>> {
                match (&*stream).read(free) {
                    Ok(n) => Ok(Some(n)),
                    Err(e) if would_block(&e) => Ok(None),
                    Err(e) => Err(e).with_context(|| format!("could not receive a {what}")),
                }
            };
            let n =
                if spin { patience.spin(what, read)? } else { patience.block(what, |_| read())? };
            if n == 0 {
                if self.filled == 0 {
                    return Ok(None);
                }
                bail!("the socket closed in the middle of a {what}");
            }
            self.filled += n;
        }
    }
}

/// Where the frame at the start of `data` ends, if it is all there. `capacity` is the
/// most a frame may take.
fn frame_end(data: &[u8], capacity: usize) -> anyhow::Result<Option<usize>> {
    let Some(header) = data.get(..8) else { return Ok(None) };
    let mut len = [0u8; 8];
    len.copy_from_slice(header);
    let len = u64::from_le_bytes(len);
    let end = usize::try_from(len).ok().and_then(|n| n.checked_add(HEADER_LEN));
    match end {
        Some(end) if end <= capacity => Ok((data.len() >= end).then_some(end)),
        _ => bail!("a frame of {len} bytes does not fit the {capacity}-byte buffer"),
    }
}

fn would_block(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_cross_a_socket_aligned_and_in_order() {
        for spin in [false, true] {
            let (a, b) = UnixStream::pair().unwrap();
            configure(&a, spin).unwrap();
            configure(&b, spin).unwrap();
            let mut p = Patience::alone();
            let big: Vec<u8> = (0..300_000u32).map(|i| i as u8).collect();
            let writer = std::thread::spawn(move || {
                let mut p = Patience::alone();
                send(&a, b"first", spin, &mut p, "frame").unwrap();
                send(&a, &big, spin, &mut p, "frame").unwrap();
                send(&a, b"", spin, &mut p, "frame").unwrap();
            });
            let mut reader = FrameReader::new(300_000);
            let first = reader.receive(&b, spin, &mut p, "frame").unwrap().unwrap();
            assert_eq!(first, b"first");
            assert_eq!(first.as_ptr() as usize % 16, 0);
            let second = reader.receive(&b, spin, &mut p, "frame").unwrap().unwrap();
            assert_eq!(second.len(), 300_000);
            assert!(second.iter().enumerate().all(|(i, &x)| x == i as u8));
            assert_eq!(reader.receive(&b, spin, &mut p, "frame").unwrap().unwrap(), b"");
            writer.join().unwrap();
            assert!(reader.receive(&b, spin, &mut p, "frame").unwrap().is_none(), "closed");
        }
    }

    #[test]
    fn an_oversized_frame_is_refused() {
        let mut header = [0u8; HEADER_LEN];
        header[..8].copy_from_slice(&1_000u64.to_le_bytes());
        assert!(frame_end(&header, 100).is_err());
        assert_eq!(frame_end(&header[..4], 100).unwrap(), None);
    }
}
