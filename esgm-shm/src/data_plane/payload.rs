//! What travels in a trajectory's shared-memory sample: the payload element
//! ([`Block16`]) and the iceoryx2 user header ([`SampleHeader`]).
//!
//! # Payload
//! A sample's payload is a slice of [`Block16`]: 16-byte, 16-aligned blocks holding the
//! codec's bytes (envelope + rkyv archive, see [`esgm_core::codec`]). Why not `[u8]`:
//! - a plain `[u8]` payload was found only 8-byte aligned, and the archived form needs
//!   [`ARCHIVE_ALIGNMENT`] (16);
//! - asking iceoryx2 for `payload_alignment(16)` on `[u8]` pads *every element* to 16
//!   bytes, which made one image publisher's segment 385 MB instead of 24 MB.
//!
//! A 16-byte element is aligned by its type, costs nothing per byte, and at most 15
//! bytes of slack per sample (zeroed by the publisher, see `publisher.rs`).
//!
//! # User header
//! [`SampleHeader`] is 64 bytes, `#[repr(C)]`, eight plain integer fields and no padding:
//!
//! | offset | field         | type | meaning                                              |
//! |-------:|---------------|------|------------------------------------------------------|
//! |      0 | `valid_time`  | i64  | the structure's valid time (ns, shared timeline)     |
//! |      8 | `create_time` | i64  | the structure's create time (ns)                     |
//! |     16 | `add_time`    | i64  | when the publisher sent it (ns, publisher's clock)   |
//! |     24 | `archive_len` | u64  | payload bytes in use, codec envelope included        |
//! |     32 | `type_id`     | u64  | [`crate::data_plane::type_id::type_id()`] of the trajectory's type name   |
//! |     40 | `sequence`    | u64  | per-publisher counter, +1 per sent sample            |
//! |     48 | `kind`        | u32  | what the payload is ([`SampleHeader::KIND_STRUCTURE`]) |
//! |     52 | `flags`       | u32  | properties of the payload ([`SampleHeader::FLAG_IMAGE_IN_PLACE`]) |
//! |     56 | `kept`        | u64  | the structure's index in its kept history + 1; 0: not kept |
//!
//! Times and the type id sit in the header so that filters, time lookups and type
//! checks never touch the payload. The archive length is there because a loaned slice
//! cannot shrink and rkyv puts the archive's root at the *end* of what was written: a
//! reader must know where the archive ends, not where the slice ends.
//!
//! Every field is a plain integer on purpose (no `bool`, no enum): the header is
//! written by another process, and any bit pattern must be a valid value, so a corrupt
//! or hostile header can be rejected by comparing numbers, never be undefined
//! behaviour. `bytemuck::Pod` on both types checks that at compile time.
//!
//! The iceoryx2 type names carry a version (`esgm.SampleHeader.v1`): iceoryx2 refuses
//! to connect ports whose payload or header type names, sizes or alignments differ, so
//! a layout change must bump it.
//!
//! [`ARCHIVE_ALIGNMENT`]: esgm_core::codec::ARCHIVE_ALIGNMENT

use std::mem::MaybeUninit;

use bytemuck::{Pod, Zeroable};
use esgm_core::Time;
use esgm_core::codec::ARCHIVE_ALIGNMENT;
use iceoryx2::prelude::ZeroCopySend;

/// One 16-byte, 16-aligned block of a sample's payload.
///
/// Two `repr` attributes because `#[derive(ZeroCopySend)]` only recognises a bare
/// `#[repr(C)]` and rejects `#[repr(C, align(16))]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[repr(C)]
#[repr(align(16))]
#[type_name("esgm.Block16.v1")]
pub struct Block16(pub [u8; 16]);

/// Bytes in one [`Block16`].
pub const BLOCK_LEN: usize = std::mem::size_of::<Block16>();

const _: () = assert!(BLOCK_LEN == 16 && std::mem::align_of::<Block16>() == ARCHIVE_ALIGNMENT);

/// The number of blocks that hold `bytes` bytes.
pub const fn blocks_for(bytes: usize) -> usize {
    bytes.div_ceil(BLOCK_LEN)
}

/// The payload read as bytes (a reader's view).
pub fn as_bytes(blocks: &[Block16]) -> &[u8] {
    bytemuck::cast_slice(blocks)
}

/// A loaned, not yet written payload viewed as bytes.
pub(crate) fn as_uninit_bytes(blocks: &mut [MaybeUninit<Block16>]) -> &mut [MaybeUninit<u8>] {
    let len = blocks.len() * BLOCK_LEN;
    // SAFETY: a `MaybeUninit<Block16>` is 16 bytes with no invariant, so the same memory
    // read as 16 `MaybeUninit<u8>` each has none either; the length covers exactly the
    // borrowed slice, and the returned borrow keeps `blocks` borrowed mutably.
    unsafe { std::slice::from_raw_parts_mut(blocks.as_mut_ptr().cast::<MaybeUninit<u8>>(), len) }
}

/// Writes zeros over `bytes` and returns them as initialised bytes.
pub(crate) fn zero_fill(bytes: &mut [MaybeUninit<u8>]) -> &mut [u8] {
    // SAFETY: the pointer and length come from a valid mutable slice; after `write_bytes`
    // every byte is initialised, so viewing them as `u8` is sound.
    unsafe {
        std::ptr::write_bytes(bytes.as_mut_ptr(), 0, bytes.len());
        &mut *(bytes as *mut [MaybeUninit<u8>] as *mut [u8])
    }
}

/// Copies `src` to the start of `dst`; returns false (writing nothing) if it does not fit.
pub(crate) fn copy_into(dst: &mut [MaybeUninit<u8>], src: &[u8]) -> bool {
    let Some(dst) = dst.get_mut(..src.len()) else { return false };
    // SAFETY: `dst` has exactly `src.len()` elements, `MaybeUninit<u8>` has the layout of
    // `u8`, and a loaned slice cannot overlap a borrowed `src`.
    unsafe {
        std::ptr::copy_nonoverlapping(src.as_ptr(), dst.as_mut_ptr().cast::<u8>(), src.len())
    };
    true
}

/// Bytes before a lineage in a sample's trailer: its length (`u64`, little endian),
/// then zeros to the archive alignment.
pub(crate) const TRAILER_HEAD: usize = 16;

/// Where a sample's lineage trailer starts: the first 16-byte boundary after the
/// archive (`archive_len` bytes).
pub(crate) fn trailer_start(archive_len: usize) -> usize {
    archive_len.next_multiple_of(BLOCK_LEN)
}

/// Payload bytes a structure of `archive_len` bytes with a lineage of `lineage_len`
/// bytes needs.
pub(crate) fn with_trailer_len(archive_len: usize, lineage_len: usize) -> usize {
    trailer_start(archive_len) + TRAILER_HEAD + lineage_len
}

/// [`with_trailer_len`] of lengths another process wrote: `None` on overflow.
pub(crate) fn checked_trailer_len(archive_len: usize, lineage_len: usize) -> Option<usize> {
    trailer_start(archive_len).checked_add(TRAILER_HEAD)?.checked_add(lineage_len)
}

/// The lineage bytes of a payload whose header has [`SampleHeader::FLAG_LINEAGE`]: at
/// [`trailer_start`], a length, then that many bytes ([`esgm_core::codec::decode_lineage`]
/// reads them). An error says what is wrong with a trailer another process wrote.
pub(crate) fn lineage_trailer(payload: &[u8], archive_len: usize) -> Result<&[u8], String> {
    let at = trailer_start(archive_len);
    let head = payload
        .get(at..at + TRAILER_HEAD)
        .ok_or_else(|| format!("no lineage trailer at byte {at} of {}", payload.len()))?;
    let mut len = [0; 8];
    len.copy_from_slice(&head[..8]);
    let len = u64::from_le_bytes(len);
    let start = at + TRAILER_HEAD;
    usize::try_from(len)
        .ok()
        .and_then(|len| payload.get(start..start.checked_add(len)?))
        .ok_or_else(|| format!("a lineage of {len} bytes at byte {start} of {}", payload.len()))
}

/// The iceoryx2 user header of every trajectory sample (layout in the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[repr(C)]
#[type_name("esgm.SampleHeader.v1")]
pub struct SampleHeader {
    /// The structure's valid time (ns).
    pub valid_time: Time,
    /// The structure's create time (ns).
    pub create_time: Time,
    /// When the publisher sent the sample, on its clock (ns): the add time of the
    /// seed's trajectories for a structure added through shared memory.
    pub add_time: Time,
    /// Payload bytes in use, codec envelope included; the rest of the slice is zero.
    pub archive_len: u64,
    /// [`crate::data_plane::type_id::type_id()`] of the trajectory's entity structure type name.
    pub type_id: u64,
    /// Per-publisher sequence number, starting at 0; a gap means samples were dropped
    /// (overwritten in a full subscriber buffer).
    pub sequence: u64,
    /// What the payload holds; see the `KIND_*` constants. Zero (a header never
    /// written) is rejected.
    pub kind: u32,
    /// Properties of the payload; see the `FLAG_*` constants. Unknown bits are ignored.
    pub flags: u32,
    /// The structure's index in its trajectory's kept history, plus one
    /// ([`crate::unstable::KeptHistory`]; 0: not kept). A primitive trajectory's
    /// writer keeps each structure it admits and numbers it there; a reader that
    /// already holds an index (its history came from the kept file, or from the
    /// writer before it restarted) skips it, so a history handed over again is never
    /// entered twice.
    pub kept: u64,
}

const _: () = assert!(std::mem::size_of::<SampleHeader>() == 64);

impl SampleHeader {
    /// The payload is a codec-encoded entity structure (envelope + archive).
    pub const KIND_STRUCTURE: u32 = 1;

    /// The writer reset the trajectory (T5): readers forget every sample before this
    /// one. No payload (`archive_len` 0); it takes a sequence number like a structure,
    /// and sits in the publisher's history so a late reader forgets what came before.
    pub const KIND_RESET: u32 = 2;

    /// The structure is in the trajectory's kept history, written there once
    /// ([`crate::unstable::KeptHistory`]): the payload names the file (its id, a `u64`)
    /// and the entry's start position in the file's ring (a `u64`), `kept` the entry's
    /// index + 1 and `archive_len` its length. A reader reads the entry in place in the
    /// file, while the ring has not come round to it.
    pub const KIND_KEPT: u32 = 3;

    /// Bytes of a [`Self::KIND_KEPT`] sample's payload.
    pub const KEPT_PAYLOAD: usize = 16;

    /// The structure is an `Image` whose pixels the producer wrote straight into shared
    /// memory: a cache can keep the sample itself instead of copying the bytes out.
    pub const FLAG_IMAGE_IN_PLACE: u32 = 1;

    /// The payload carries the structure's lineage after the archive: from the first
    /// 16-byte boundary after it, its length (`u64`), 8 zero bytes, then the bytes
    /// [`esgm_core::codec::decode_lineage`] reads. Readers that do not know the flag
    /// read the archive alone.
    pub const FLAG_LINEAGE: u32 = 2;

    /// True if `flag` is set.
    pub fn has_flag(&self, flag: u32) -> bool {
        self.flags & flag == flag
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_layout_is_as_documented() {
        use std::mem::offset_of;
        assert_eq!(offset_of!(SampleHeader, valid_time), 0);
        assert_eq!(offset_of!(SampleHeader, create_time), 8);
        assert_eq!(offset_of!(SampleHeader, add_time), 16);
        assert_eq!(offset_of!(SampleHeader, archive_len), 24);
        assert_eq!(offset_of!(SampleHeader, type_id), 32);
        assert_eq!(offset_of!(SampleHeader, sequence), 40);
        assert_eq!(offset_of!(SampleHeader, kind), 48);
        assert_eq!(offset_of!(SampleHeader, flags), 52);
        assert_eq!(offset_of!(SampleHeader, kept), 56);
    }

    #[test]
    fn blocks_round_up() {
        assert_eq!(blocks_for(0), 0);
        assert_eq!(blocks_for(1), 1);
        assert_eq!(blocks_for(16), 1);
        assert_eq!(blocks_for(17), 2);
    }

    #[test]
    fn uninit_helpers_write_and_zero() {
        let mut blocks = [MaybeUninit::<Block16>::uninit(); 2];
        let bytes = as_uninit_bytes(&mut blocks);
        assert_eq!(bytes.len(), 32);
        assert!(!copy_into(bytes, &[1u8; 33]));
        let zeroed = zero_fill(bytes);
        assert!(zeroed.iter().all(|b| *b == 0));
        let bytes = as_uninit_bytes(&mut blocks);
        assert!(copy_into(bytes, &[7u8; 3]));
        let init = zero_fill(&mut bytes[3..]);
        assert_eq!(init.len(), 29);
        // SAFETY: every byte was written above.
        let all: [Block16; 2] = unsafe { [blocks[0].assume_init(), blocks[1].assume_init()] };
        assert_eq!(&as_bytes(&all)[..4], &[7, 7, 7, 0]);
    }
}
