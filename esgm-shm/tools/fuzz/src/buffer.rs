//! Bytes laid out as a reader gets them: in 16-byte [`Block16`]s, the payload element
//! of a trajectory sample, so on [`ARCHIVE_ALIGNMENT`] (or deliberately off it).
//!
//! [`ARCHIVE_ALIGNMENT`]: esgm_core::codec::ARCHIVE_ALIGNMENT

use esgm_shm::Block16;
use esgm_shm::unstable::{BLOCK_LEN, as_bytes, blocks_for};

/// A copy of some bytes in blocks, starting `shift` bytes into the first block.
#[derive(Debug, Clone)]
pub struct Blocks {
    blocks: Vec<Block16>,
    shift: usize,
    len: usize,
}

impl Blocks {
    /// `bytes` on the archive's alignment.
    pub fn aligned(bytes: &[u8]) -> Self {
        Self::shifted(bytes, 0)
    }

    /// `bytes` starting `shift` (below 16) bytes past the alignment.
    pub fn shifted(bytes: &[u8], shift: usize) -> Self {
        let shift = shift % BLOCK_LEN;
        let mut blocks = vec![Block16::default(); blocks_for(shift + bytes.len())];
        let all: &mut [u8] = bytemuck::cast_slice_mut(&mut blocks);
        all[shift..shift + bytes.len()].copy_from_slice(bytes);
        Self { blocks, shift, len: bytes.len() }
    }

    /// The bytes copied in.
    pub fn bytes(&self) -> &[u8] {
        &as_bytes(&self.blocks)[self.shift..self.shift + self.len]
    }

    /// Every byte of the blocks: the copied ones and the zeros after them, as a
    /// sample's loaned slice holds an archive and its slack.
    pub fn payload(&self) -> &[u8] {
        as_bytes(&self.blocks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_keep_their_bytes_and_alignment() {
        let data: Vec<u8> = (0..40).collect();
        for shift in 0..16 {
            let b = Blocks::shifted(&data, shift);
            assert_eq!(b.bytes(), &data[..]);
            assert_eq!(b.bytes().as_ptr() as usize % 16, shift);
        }
        assert_eq!(Blocks::aligned(&data).payload().len(), 48);
    }
}
