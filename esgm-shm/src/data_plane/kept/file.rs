//! A kept history's file: its layout, its mappings, and how one is made, opened and
//! checked. What the numbers in it mean is the writer's (`writer.rs`) and the readers'
//! (`reader.rs`) business; this file only says where they are.
//!
//! Layout (native endianness):
//! - page 0, the header: magic, version, the slot count, the area's length, the
//!   trajectory's type id and the file's id (fixed when the file is made), then the
//!   counters the writer moves, each on a line of its own: `next` (the index the next
//!   entry gets), `first` (the oldest entry kept), `head` (where the next entry's
//!   bytes go: a position that only grows, at `head % area` in the area), `newest`
//!   (the newest valid time kept) and `reclaim` (positions below it may be written
//!   over: what a reader checks after it holds an entry);
//! - page 1, the holders: [`HOLDERS`] slots of [`HOLDER_LEN`] bytes, one per process
//!   that holds entries of the file, each claimed with an OFD record lock on its bytes
//!   and holding the lowest position that process reads in place (`u64::MAX`: none);
//! - the slots, from page 2: entry `i` is described in slot `i % slots` (its index,
//!   start position, length, add time and valid time);
//! - the area, page-aligned: each entry's codec bytes, contiguous and aligned to
//!   [`ARCHIVE_ALIGNMENT`].
//!
//! A reader maps the whole file read-only and the holders' page, alone, writable: the
//! kernel keeps it from changing an entry it reads.

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::codec::ARCHIVE_ALIGNMENT;

use super::KeepError;
use crate::data_plane::shm_access::ShmAccess;

pub(super) const MAGIC: u64 = u64::from_le_bytes(*b"esgmkeep");
/// The layout's version: 2 keeps entries in place for readers (holders, reclaim).
pub(super) const VERSION: u32 = 2;
/// A page: the header's length, and the holders'.
pub(super) const PAGE: usize = 4096;
/// A slot's length: index, start, length, add time, valid time (and room).
pub const SLOT_LEN: usize = 48;
/// Where the holders' page begins.
pub(super) const HOLDERS_AT: usize = PAGE;
/// A holder's slot: the lowest position it holds (`u64`), its process id (`u32`).
pub const HOLDER_LEN: usize = 16;
/// Processes that may hold entries of one file at once; a process that finds none free
/// reads copies of the entries instead (counted).
pub const HOLDERS: usize = PAGE / HOLDER_LEN;
pub(super) const OFF_MAGIC: usize = 0;
pub(super) const OFF_VERSION: usize = 8;
pub(super) const OFF_SLOTS: usize = 16;
pub(super) const OFF_AREA: usize = 24;
pub(super) const OFF_TYPE: usize = 32;
pub(super) const OFF_FILE_ID: usize = 40;
/// The fixed fields' bytes.
pub(super) const FIXED_LEN: usize = 48;
pub(super) const OFF_NEXT: usize = 64;
pub(super) const OFF_FIRST: usize = 128;
pub(super) const OFF_HEAD: usize = 192;
/// The newest valid time kept (meaningful while something is kept), beside `head`:
/// both are the writer's alone.
pub(super) const OFF_NEWEST: usize = 200;
pub(super) const OFF_RECLAIM: usize = 256;
/// The most a file's area may grow to (a policy that keeps everything of a camera
/// stops here, and what is added past it is counted, not kept).
pub const MAX_AREA: u64 = 16 << 30;
/// The most slots a file may have.
pub(super) const MAX_SLOTS: u64 = 1 << 28;

/// The fixed part of a file's header, as checked on opening.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Shape {
    pub slots: u64,
    pub area: u64,
    pub type_id: u64,
}

impl Shape {
    pub fn slots_at(&self) -> usize {
        2 * PAGE
    }

    pub fn area_at(&self) -> usize {
        align_up(self.slots_at() + self.slots as usize * SLOT_LEN, PAGE)
    }

    pub fn file_len(&self) -> usize {
        self.area_at() + self.area as usize
    }

    /// Where entry `index`'s slot is.
    pub fn slot_at(&self, index: u64) -> usize {
        self.slots_at() + (index % self.slots) as usize * SLOT_LEN
    }

    /// Where position `position`'s byte is.
    pub fn byte_at(&self, position: u64) -> usize {
        self.area_at() + (position % self.area) as usize
    }
}

/// A slot, as read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Slot {
    pub index: u64,
    pub start: u64,
    /// The archive's length (a lineage trailer, if any, follows it).
    pub len: u64,
    pub add_time: i64,
    pub valid_time: i64,
    /// [`SLOT_LINEAGE`] if a lineage trailer follows the archive.
    pub flags: u64,
}

/// A slot's flag: the entry's lineage follows its archive, as in a sample's payload
/// (`crate::data_plane::payload::lineage_trailer`).
pub(crate) const SLOT_LINEAGE: u64 = 1;

/// A mapping of (part of) a file.
#[derive(Debug)]
pub(super) struct Mapping {
    base: NonNull<u8>,
    len: usize,
    writable: bool,
}

// SAFETY: the mapping is plain shared memory; every access through it is an atomic
// counter, a copy or a read of bytes the readers' protocol keeps unchanged (see
// `reader.rs`), and the pointer stays valid until `Drop`.
unsafe impl Send for Mapping {}
// SAFETY: as above.
unsafe impl Sync for Mapping {}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: `base..base + len` is the mapping `map` made, unmapped once here.
        unsafe { libc::munmap(self.base.as_ptr().cast(), self.len) };
    }
}

impl Mapping {
    /// Maps `len` bytes of `file` from `offset` (page-aligned), writable or not.
    pub fn map(
        file: &File,
        offset: usize,
        len: usize,
        writable: bool,
        path: &Path,
    ) -> Result<Self, KeepError> {
        let prot = match writable {
            true => libc::PROT_READ | libc::PROT_WRITE,
            false => libc::PROT_READ,
        };
        // SAFETY: a fresh shared mapping of `len` bytes of an open file at a page-aligned
        // offset; the kernel picks the address. The file is at least `offset + len`
        // long (checked or sized by the caller), so no access within it faults.
        let base = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                prot,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                offset as libc::off_t,
            )
        };
        if base == libc::MAP_FAILED {
            return Err(io(path, std::io::Error::last_os_error()));
        }
        let base = NonNull::new(base.cast()).ok_or_else(|| corrupt(path, "mapped at null"))?;
        Ok(Self { base, len, writable })
    }

    /// The counter at `offset` (8-aligned, in the mapping).
    pub fn counter(&self, offset: usize) -> &AtomicU64 {
        assert!(offset % 8 == 0 && offset + 8 <= self.len);
        // SAFETY: `offset` is 8-aligned inside the mapping (page-aligned); shared memory
        // is only ever accessed as this atomic at this offset, by every process. A
        // read-only mapping is only loaded from.
        unsafe { &*self.base.as_ptr().add(offset).cast::<AtomicU64>() }
    }

    pub fn read_u64(&self, offset: usize) -> u64 {
        self.counter(offset).load(Ordering::Acquire)
    }

    pub fn write_u64(&self, offset: usize, value: u64) {
        debug_assert!(self.writable);
        self.counter(offset).store(value, Ordering::Release);
    }

    /// The bytes at `offset..offset + len`, if they lie in the mapping: shared memory,
    /// which only the file's writer writes (see the readers' protocol).
    pub fn bytes(&self, offset: usize, len: usize) -> Option<&[u8]> {
        let end = offset.checked_add(len)?;
        (end <= self.len).then(|| {
            // SAFETY: in bounds (checked), mapped for the mapping's life.
            unsafe { std::slice::from_raw_parts(self.base.as_ptr().add(offset), len) }
        })
    }

    /// Copies `out.len()` bytes at `offset` out (the caller checked the bounds).
    pub fn copy_out(&self, offset: usize, out: &mut [u8]) {
        assert!(offset.checked_add(out.len()).is_some_and(|end| end <= self.len));
        // SAFETY: in bounds (asserted). Another process may write these bytes at the
        // same time; what is copied is then checked before use.
        unsafe {
            std::ptr::copy_nonoverlapping(
                self.base.as_ptr().add(offset),
                out.as_mut_ptr(),
                out.len(),
            )
        };
    }

    /// The bytes at `offset..offset + len`, for the file's writer to write (the caller
    /// is the only writer, and checked the bounds).
    #[allow(clippy::mut_from_ref)]
    pub fn bytes_mut(&self, offset: usize, len: usize) -> &mut [u8] {
        assert!(self.writable);
        assert!(offset.checked_add(len).is_some_and(|end| end <= self.len));
        // SAFETY: in bounds (asserted) of a writable mapping; the writer alone writes
        // the area and the slots, and never holds two of these views of the same bytes
        // at once.
        unsafe { std::slice::from_raw_parts_mut(self.base.as_ptr().add(offset), len) }
    }

    /// Slot `index` as it is (it may describe another entry).
    pub fn raw_slot(&self, shape: &Shape, index: u64) -> Slot {
        let mut bytes = [0u8; SLOT_LEN];
        self.copy_out(shape.slot_at(index), &mut bytes);
        let field =
            |i: usize| u64::from_ne_bytes(bytes[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
        Slot {
            index: field(0),
            start: field(1),
            len: field(2),
            add_time: field(3) as i64,
            valid_time: field(4) as i64,
            flags: field(5),
        }
    }

    /// Entry `index`'s slot, if it describes that entry and its bytes lie in the area.
    pub fn slot(&self, shape: &Shape, index: u64) -> Option<Slot> {
        let slot = self.raw_slot(shape, index);
        let area = shape.area;
        let fits = slot.index == index
            && (esgm_core::codec::ENVELOPE_LEN as u64..=area).contains(&slot.len)
            && slot.start % ARCHIVE_ALIGNMENT as u64 == 0
            && (slot.start % area) + slot.len <= area;
        fits.then_some(slot)
    }

    pub fn write_slot(&self, shape: &Shape, slot: Slot) {
        let bytes = self.bytes_mut(shape.slot_at(slot.index), SLOT_LEN);
        let fields = [
            slot.index,
            slot.start,
            slot.len,
            slot.add_time as u64,
            slot.valid_time as u64,
            slot.flags,
        ];
        for (i, v) in fields.into_iter().enumerate() {
            bytes[i * 8..i * 8 + 8].copy_from_slice(&v.to_ne_bytes());
        }
    }
}

/// A file's header as read by [`open`].
#[derive(Debug)]
pub(super) struct Opened {
    pub file: File,
    pub shape: Shape,
    pub file_id: u64,
}

/// Opens the file at `path` (for writing its holders' page, at least), checks its
/// header; `None` if there is none.
pub(super) fn open(path: &Path) -> Result<Option<Opened>, KeepError> {
    let file = match OpenOptions::new().read(true).write(true).open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(path, e)),
    };
    let len = file.metadata().map_err(|e| io(path, e))?.len();
    if len < (HOLDERS_AT + PAGE) as u64 {
        return Err(corrupt(path, format!("{len} bytes, shorter than a header")));
    }
    let mut header = [0u8; FIXED_LEN];
    read_at(&file, &mut header, path)?;
    let field = |at: usize| u64::from_ne_bytes(header[at..at + 8].try_into().unwrap_or([0; 8]));
    if field(OFF_MAGIC) != MAGIC {
        return Err(corrupt(path, "no kept-history magic"));
    }
    let version = field(OFF_VERSION) as u32;
    if version != VERSION {
        return Err(corrupt(path, format!("version {version}, this build reads {VERSION}")));
    }
    let shape = Shape { slots: field(OFF_SLOTS), area: field(OFF_AREA), type_id: field(OFF_TYPE) };
    if !(1..=MAX_SLOTS).contains(&shape.slots)
        || !(PAGE as u64..=MAX_AREA).contains(&shape.area)
        || shape.area % ARCHIVE_ALIGNMENT as u64 != 0
    {
        return Err(corrupt(
            path,
            format!("{} slots, an area of {} bytes", shape.slots, shape.area),
        ));
    }
    if len != shape.file_len() as u64 {
        return Err(corrupt(path, format!("{len} bytes, its header says {}", shape.file_len())));
    }
    Ok(Some(Opened { file, shape, file_id: field(OFF_FILE_ID) }))
}

/// A new file of `shape` beside `path` (named for this process and moment, to be
/// renamed over it), sized and with its fixed header written; every holder free.
pub(super) fn create_beside(
    path: &Path,
    shape: Shape,
) -> Result<(File, PathBuf, Mapping, u64), KeepError> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let mut name = path.as_os_str().to_owned();
    name.push(format!(".{}.{n}.tmp", std::process::id()));
    let temporary = PathBuf::from(name);
    let mode = ShmAccess::from_env().unwrap_or_default().file_mode();
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create_new(true)
        .mode(mode)
        .open(&temporary)
        .map_err(|e| io(&temporary, e))?;
    let made = (|| {
        file.set_len(shape.file_len() as u64).map_err(|e| io(path, e))?;
        let map = Mapping::map(&file, 0, shape.file_len(), true, path)?;
        let file_id = new_file_id();
        let header = map.bytes_mut(0, FIXED_LEN);
        header[OFF_MAGIC..OFF_MAGIC + 8].copy_from_slice(&MAGIC.to_ne_bytes());
        header[OFF_VERSION..OFF_VERSION + 8].copy_from_slice(&u64::from(VERSION).to_ne_bytes());
        header[OFF_SLOTS..OFF_SLOTS + 8].copy_from_slice(&shape.slots.to_ne_bytes());
        header[OFF_AREA..OFF_AREA + 8].copy_from_slice(&shape.area.to_ne_bytes());
        header[OFF_TYPE..OFF_TYPE + 8].copy_from_slice(&shape.type_id.to_ne_bytes());
        header[OFF_FILE_ID..OFF_FILE_ID + 8].copy_from_slice(&file_id.to_ne_bytes());
        // Slot 0 is the holders' count (0: none claimed); every other, nothing held.
        for k in 1..HOLDERS {
            map.write_u64(HOLDERS_AT + k * HOLDER_LEN, u64::MAX);
        }
        Ok((map, file_id))
    })();
    match made {
        Ok((map, file_id)) => Ok((file, temporary, map, file_id)),
        Err(e) => {
            let _gone = std::fs::remove_file(&temporary);
            Err(e)
        }
    }
}

/// An id no other file of any trajectory had: the clock's nanoseconds, this process and
/// a counter, mixed.
fn new_file_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let mixed = nanos
        ^ (u64::from(std::process::id()) << 40)
        ^ NEXT.fetch_add(1, Ordering::Relaxed).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    mixed.max(1)
}

fn read_at(file: &File, out: &mut [u8], path: &Path) -> Result<(), KeepError> {
    use std::os::unix::fs::FileExt as _;
    file.read_exact_at(out, 0).map_err(|e| io(path, e))
}

pub(super) fn align_up(n: usize, to: usize) -> usize {
    n.div_ceil(to) * to
}

pub(super) fn io(path: &Path, source: std::io::Error) -> KeepError {
    KeepError::Io { path: path.to_owned(), source }
}

pub(super) fn corrupt(path: &Path, reason: impl Into<String>) -> KeepError {
    KeepError::Corrupt { path: path.to_owned(), reason: reason.into() }
}
