//! Writing frames as binary PPM, the simplest format an image viewer opens, so a frame
//! can be looked at without an encoder dependency.

use std::io::{self, Write};

/// Writes packed RGB8 `pixels` of a `width`×`height` frame as a binary PPM (`P6`).
///
/// Fails with [`io::ErrorKind::InvalidInput`] if `pixels` is not `width × height × 3`
/// bytes long, and otherwise only as the writer does.
pub fn write_ppm(mut out: impl Write, width: u32, height: u32, pixels: &[u8]) -> io::Result<()> {
    let expected = width as usize * height as usize * 3;
    if pixels.len() != expected {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{width}×{height} RGB8 needs {expected} bytes, got {}", pixels.len()),
        ));
    }
    write!(out, "P6\n{width} {height}\n255\n")?;
    out.write_all(pixels)?;
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_header_then_pixels() {
        let mut out = Vec::new();
        write_ppm(&mut out, 2, 1, &[1, 2, 3, 4, 5, 6]).unwrap();
        assert_eq!(out, b"P6\n2 1\n255\n\x01\x02\x03\x04\x05\x06");
    }

    #[test]
    fn rejects_a_short_buffer() {
        let err = write_ppm(Vec::new(), 2, 2, &[0; 11]).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
    }
}
