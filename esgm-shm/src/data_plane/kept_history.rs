//! A primitive trajectory's kept history: a file in `/dev/shm` where the writer keeps
//! every structure it acknowledged, so that the history outlives the writer (SPEC D1).
//!
//! Why a file of the writer's and not a keeper process: a file in POSIX shared memory
//! outlives whichever process crashes — the writer, a reader, the coordinator — with no
//! second copy to keep in step and no process whose own death would lose it. Its cost
//! is one encode into memory the writer already maps, on the adding thread (see
//! ARCHITECTURE.md, "Kept history").
//!
//! Layout (native endianness; one writer, any number of readers):
//! - a header of [`HEADER_LEN`] bytes: magic, version, the slot count, the area's
//!   length and the trajectory's type id (fixed when the file is made), then the
//!   counters the writer moves: `next` (the index the next entry gets; an index is
//!   never given twice in a file), `first` (the oldest entry kept) and `head` (where
//!   the next entry's bytes go: a position that only grows, at `head % area` in the
//!   area);
//! - `slots` records of [`SLOT_LEN`] bytes: entry `i` is described in slot
//!   `i % slots` (its index, start, length, add time and valid time);
//! - the area: each entry's codec bytes (envelope and archive), contiguous and
//!   aligned to [`ARCHIVE_ALIGNMENT`].
//!
//! **Crash safety.** The writer writes an entry's bytes and slot, then publishes `next`
//! (release); it moves `first` past entries before their bytes or slots are reused. A
//! writer killed at any instant leaves `[first, next)` readable, and an entry it had
//! not published was not acknowledged: the add had not returned.
//!
//! **Growth.** When the trajectory's policy keeps more than the file holds, the writer
//! writes a larger file beside it with the kept entries and renames it over the old
//! one, which is atomic: a reader that mapped the old one reads a consistent, older
//! view.
//!
//! **Bytes from elsewhere.** Any process of the domain may write the file, so a reader
//! trusts nothing in it: every count, slot and entry is bounds-checked and every entry
//! validated by the codec, and what fails is skipped and counted
//! ([`KeptEntries::skipped`]), never read out of bounds.

use std::fs::{File, OpenOptions};
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::codec::{self, ARCHIVE_ALIGNMENT, CodecError, ENVELOPE_LEN};
use esgm_core::{CacheConstraint, EntityStructure, Time};

use crate::data_plane::encodable::Encodable;
use crate::data_plane::shm_access::ShmAccess;

/// Where the files live: POSIX shared memory, as iceoryx2's segments.
const SHM_DIR: &str = "/dev/shm";
/// The files' names begin with this, then the generation's domain and `@`:
/// `esgm_keep@<domain>.g<N>@<hash>`, so that a domain's files can be found by name.
pub const FILE_PREFIX: &str = "esgm_keep@";
const SEPARATOR: char = '@';
const MAGIC: u64 = u64::from_le_bytes(*b"esgmkeep");
const VERSION: u32 = 1;
/// The header's length: the fixed fields, then each counter on a line of its own.
pub const HEADER_LEN: usize = 256;
/// A slot's length: index, start, length, add time, valid time (and room).
pub const SLOT_LEN: usize = 48;
const OFF_MAGIC: usize = 0;
const OFF_VERSION: usize = 8;
const OFF_SLOTS: usize = 16;
const OFF_AREA: usize = 24;
const OFF_TYPE: usize = 32;
const OFF_NEXT: usize = 64;
const OFF_FIRST: usize = 128;
const OFF_HEAD: usize = 192;
/// The newest valid time kept (meaningful while something is kept), beside `head`:
/// both are the writer's alone.
const OFF_NEWEST: usize = 200;
/// A new file's slots and area: small, since most trajectories keep few small
/// structures; each growth doubles what is short.
const FIRST_SLOTS: u64 = 64;
const FIRST_AREA: u64 = 64 * 1024;
/// The most a file's area may grow to (a policy that keeps everything of a camera
/// stops here, and what is added past it is counted, not kept).
pub const MAX_AREA: u64 = 16 << 30;
/// The highest index a file may have reached: far beyond any writer's count (a
/// replaced file starts at the clock's nanoseconds, about 2^61 in this century), far
/// enough below `u64::MAX` that a writer never overflows it.
const MAX_INDEX: u64 = 1 << 62;
/// The most slots a file may have.
const MAX_SLOTS: u64 = 1 << 28;

/// What a trajectory's policy keeps, as the file needs it to let entries go: the
/// store applies the same constraint to what it holds, and the file keeps at least
/// that (add order is the store's eviction order for a count; for a duration, an entry
/// goes once it is the oldest added and too old).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Retention {
    /// Everything.
    All,
    /// The last `n` added.
    Count(u64),
    /// What lies less than this long before the newest valid time.
    Window(Time),
}

impl Retention {
    /// The retention of a trajectory whose cache constraint is `cache`.
    pub fn of(cache: &CacheConstraint) -> Self {
        match *cache {
            CacheConstraint::All | CacheConstraint::Elements(0) => Retention::All,
            CacheConstraint::Elements(n) => Retention::Count(n as u64),
            CacheConstraint::Duration(t) => Retention::Window(t),
        }
    }
}

/// The kept history could not be opened, written or read.
#[derive(Debug, thiserror::Error)]
pub enum KeepError {
    /// The file could not be opened, sized, mapped or renamed.
    #[error("kept history {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a kept history of this trajectory, or its header contradicts
    /// itself (another process wrote it).
    #[error("kept history {path} is not usable: {reason}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        reason: String,
    },
    /// The structure could not be encoded.
    #[error("cannot keep a structure: {0}")]
    Encode(#[from] CodecError),
    /// Keeping the structure would grow the file past `MAX_AREA`.
    #[error("kept history {path} would exceed {max} bytes to keep a structure of {len}")]
    Full {
        /// The file.
        path: PathBuf,
        /// The structure's encoded length.
        len: usize,
        /// The bound.
        max: u64,
    },
}

/// One kept structure, read back.
#[derive(Debug, Clone)]
pub struct KeptEntry {
    /// Its index in the trajectory's kept history (the order in which it was added).
    pub index: u64,
    /// When it was added (the gate's add time).
    pub add_time: Time,
    /// The structure.
    pub structure: EntityStructure,
}

/// What [`KeptHistory::entries`] read.
#[derive(Debug, Default)]
pub struct KeptEntries {
    /// The entries, oldest first.
    pub entries: Vec<KeptEntry>,
    /// The index the next entry will get: every entry below it was kept once.
    pub next: u64,
    /// Entries that could not be read (bad slot, bad bytes, overwritten meanwhile).
    pub skipped: u64,
    /// Indices reserved and never written: published, then their writer died (or
    /// failed to keep them) before `add` returned, so never acknowledged.
    pub unwritten: u64,
}

/// A mapping of a whole file.
#[derive(Debug)]
struct Mapping {
    base: NonNull<u8>,
    len: usize,
}

// SAFETY: the mapping is plain shared memory; every access through it is either an
// atomic counter or a copy whose result is validated, and the pointer stays valid
// until `Drop` (no thread-local state is involved).
unsafe impl Send for Mapping {}
// SAFETY: as above; `&Mapping` only reads the counters atomically and copies bytes.
unsafe impl Sync for Mapping {}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: `base..base + len` is the mapping `map` made, unmapped once here.
        unsafe { libc::munmap(self.base.as_ptr().cast(), self.len) };
    }
}

impl Mapping {
    fn map(file: &File, len: usize, path: &Path) -> Result<Self, KeepError> {
        use std::os::fd::AsRawFd as _;
        // SAFETY: a fresh shared mapping of `len` bytes of an open file; the kernel
        // picks the address. The file is at least `len` long (checked or sized by the
        // caller), so no access within it faults.
        let base = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if base == libc::MAP_FAILED {
            return Err(io(path, std::io::Error::last_os_error()));
        }
        let base = NonNull::new(base.cast()).ok_or_else(|| corrupt(path, "mapped at null"))?;
        Ok(Self { base, len })
    }

    /// The counter at `offset` (8-aligned, inside the header).
    fn counter(&self, offset: usize) -> &AtomicU64 {
        debug_assert!(offset % 8 == 0 && offset + 8 <= HEADER_LEN);
        // SAFETY: `offset` is 8-aligned inside the header, which lies in the mapping
        // (page-aligned, at least `HEADER_LEN` long); shared memory is only ever
        // accessed as this atomic at this offset, by every process.
        unsafe { &*self.base.as_ptr().add(offset).cast::<AtomicU64>() }
    }

    fn read_u64(&self, offset: usize) -> u64 {
        self.counter(offset).load(Ordering::Acquire)
    }

    fn write_u64(&self, offset: usize, value: u64) {
        self.counter(offset).store(value, Ordering::Release);
    }

    /// Copies `len` bytes at `offset` out (the caller checked the bounds).
    fn copy_out(&self, offset: usize, out: &mut [u8]) {
        assert!(offset.checked_add(out.len()).is_some_and(|end| end <= self.len));
        // SAFETY: in bounds (asserted). Another process may write these bytes at the
        // same time; what is copied is then validated before use, and a torn copy is
        // rejected by the codec or by the index check that follows.
        unsafe {
            std::ptr::copy_nonoverlapping(
                self.base.as_ptr().add(offset),
                out.as_mut_ptr(),
                out.len(),
            )
        };
    }

    /// The bytes at `offset..offset + len`, for this process to write (the caller is
    /// the file's only writer, and checked the bounds).
    #[allow(clippy::mut_from_ref)]
    fn bytes_mut(&self, offset: usize, len: usize) -> &mut [u8] {
        assert!(offset.checked_add(len).is_some_and(|end| end <= self.len));
        // SAFETY: in bounds (asserted); the writer alone writes the area and the slots,
        // and never holds two of these views of the same bytes at once.
        unsafe { std::slice::from_raw_parts_mut(self.base.as_ptr().add(offset), len) }
    }
}

/// The fixed part of a file's header, as checked on opening.
#[derive(Debug, Clone, Copy)]
struct Shape {
    slots: u64,
    area: u64,
    type_id: u64,
}

impl Shape {
    fn slots_at(&self) -> usize {
        HEADER_LEN
    }

    fn area_at(&self) -> usize {
        align_up(HEADER_LEN + self.slots as usize * SLOT_LEN, 4096)
    }

    fn file_len(&self) -> usize {
        self.area_at() + self.area as usize
    }
}

/// A slot, as read.
#[derive(Debug, Clone, Copy)]
struct Slot {
    index: u64,
    start: u64,
    len: u64,
    add_time: Time,
    valid_time: Time,
}

/// The counters the writer moves, as it keeps them in its own memory: another process
/// may write the file's header, so the writer never reads its own counters back from
/// it, and publishes them after each change.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Counters {
    /// The index the next entry gets.
    next: u64,
    /// The oldest index kept.
    first: u64,
    /// Where the next entry's bytes go (a position that only grows).
    head: u64,
    /// The newest valid time kept (while something is).
    newest: Time,
}

/// A trajectory's kept history, mapped.
#[derive(Debug)]
pub struct KeptHistory {
    path: PathBuf,
    map: Mapping,
    shape: Shape,
    retention: Retention,
    /// The writer's counters (a reader reads the header's).
    counters: Counters,
}

impl KeptHistory {
    /// The file of `trajectory` in `domain` (the generation's domain,
    /// `<domain>.g<N>`, so that a name destroyed and created again starts empty).
    pub fn path_for(domain: &str, trajectory: &str) -> PathBuf {
        // The trajectory's name may hold any character: it is hashed (FNV-1a). The
        // domain's characters are all allowed in a file name.
        let hash = trajectory.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
        Path::new(SHM_DIR).join(format!("{FILE_PREFIX}{domain}{SEPARATOR}{hash:016x}"))
    }

    /// Opens the kept history of `trajectory` to write it, making it if there is none.
    /// An existing file is continued (a writer restarted, or another process taking
    /// the trajectory over): its entries stay, and its indices go on. One that is not
    /// usable (another type, a header that contradicts itself) is replaced, and its
    /// next index starts above any it could have given (the clock's nanoseconds).
    pub fn open_or_create(
        domain: &str,
        trajectory: &str,
        type_id: u64,
        retention: Retention,
    ) -> Result<Self, KeepError> {
        let path = Self::path_for(domain, trajectory);
        let mut above = 0;
        match Self::open_path(&path, retention) {
            Ok(Some(mut kept)) if kept.shape.type_id == type_id => match kept.continued() {
                Ok(()) => return Ok(kept),
                Err(why) => {
                    above = kept.map.read_u64(OFF_NEXT).saturating_add(1).min(MAX_INDEX);
                    tracing::warn!(path = %path.display(), trajectory, why,
                        "a kept history whose counters contradict it is replaced");
                }
            },
            Ok(Some(_)) => {
                tracing::warn!(path = %path.display(), trajectory,
                    "a kept history of another type is replaced");
            }
            Ok(None) => {
                let shape = Shape { slots: first_slots(retention), area: FIRST_AREA, type_id };
                return Self::create_at(&path, shape, 0, retention);
            }
            Err(e) => tracing::warn!(error = %e, trajectory, "a kept history is replaced"),
        }
        let shape = Shape { slots: first_slots(retention), area: FIRST_AREA, type_id };
        let clock = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1 << 62, |d| d.as_nanos() as u64);
        Self::create_at(&path, shape, clock.max(above).min(MAX_INDEX), retention)
    }

    /// Takes the header's counters as this writer's, if they agree with the file: the
    /// kept entries lie below `next` and at most a file's slots back (one more while an
    /// index is reserved), each slot that
    /// names its entry within the area's last `area` bytes before `head`. Else why not.
    fn continued(&mut self) -> Result<(), String> {
        let c = Counters {
            next: self.map.read_u64(OFF_NEXT),
            first: self.map.read_u64(OFF_FIRST),
            head: self.map.read_u64(OFF_HEAD),
            newest: self.map.read_u64(OFF_NEWEST) as Time,
        };
        if c.head % ARCHIVE_ALIGNMENT as u64 != 0 {
            return Err(format!("head {} is not {ARCHIVE_ALIGNMENT}-aligned", c.head));
        }
        // One more than the slots: a writer killed between reserving an index and
        // letting the oldest go.
        if c.first > c.next || c.next - c.first > self.shape.slots + 1 || c.next > MAX_INDEX {
            return Err(format!(
                "first {} and next {} with {} slots",
                c.first, c.next, self.shape.slots
            ));
        }
        for index in c.first..c.next {
            let Some(slot) = self.slot(index) else { continue };
            let end = slot.start.checked_add(slot.len);
            if end.is_none_or(|end| {
                end > c.head || slot.start.saturating_add(self.shape.area) < c.head
            }) {
                return Err(format!("entry {index} lies outside the area before head {}", c.head));
            }
        }
        self.counters = c;
        Ok(())
    }

    /// Opens the kept history of `trajectory` to read it; `None` if there is none.
    pub fn open(domain: &str, trajectory: &str) -> Result<Option<Self>, KeepError> {
        Self::open_path(&Self::path_for(domain, trajectory), Retention::All)
    }

    fn open_path(path: &Path, retention: Retention) -> Result<Option<Self>, KeepError> {
        let file = match OpenOptions::new().read(true).write(true).open(path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io(path, e)),
        };
        let len = file.metadata().map_err(|e| io(path, e))?.len();
        if len < HEADER_LEN as u64 {
            return Err(corrupt(path, format!("{len} bytes, shorter than a header")));
        }
        let mut header = [0u8; 40];
        read_at(&file, &mut header, path)?;
        let field = |at: usize| u64::from_ne_bytes(header[at..at + 8].try_into().unwrap_or([0; 8]));
        if field(OFF_MAGIC) != MAGIC {
            return Err(corrupt(path, "no kept-history magic"));
        }
        let version = field(OFF_VERSION) as u32;
        if version != VERSION {
            return Err(corrupt(path, format!("version {version}, this build reads {VERSION}")));
        }
        let shape =
            Shape { slots: field(OFF_SLOTS), area: field(OFF_AREA), type_id: field(OFF_TYPE) };
        if !(1..=MAX_SLOTS).contains(&shape.slots)
            || !(4096..=MAX_AREA).contains(&shape.area)
            || shape.area % ARCHIVE_ALIGNMENT as u64 != 0
        {
            return Err(corrupt(
                path,
                format!("{} slots, an area of {} bytes", shape.slots, shape.area),
            ));
        }
        if len != shape.file_len() as u64 {
            return Err(corrupt(
                path,
                format!("{len} bytes, its header says {}", shape.file_len()),
            ));
        }
        let map = Mapping::map(&file, shape.file_len(), path)?;
        Ok(Some(Self {
            path: path.to_owned(),
            map,
            shape,
            retention,
            counters: Counters::default(),
        }))
    }

    /// Writes a new file of `shape` at `path`, its next index `next`, with nothing
    /// kept (atomically: written beside it, then renamed).
    fn create_at(
        path: &Path,
        shape: Shape,
        next: u64,
        retention: Retention,
    ) -> Result<Self, KeepError> {
        Self::build(path, shape, next, retention)?.commit()
    }

    /// A new file of `shape` beside `path`, its next index `next`, to be filled and
    /// then renamed over `path` ([`Unrenamed::commit`]).
    fn build(
        path: &Path,
        shape: Shape,
        next: u64,
        retention: Retention,
    ) -> Result<Unrenamed, KeepError> {
        let (file, temporary) = temporary_file(path)?;
        let made = (|| {
            file.set_len(shape.file_len() as u64).map_err(|e| io(path, e))?;
            let map = Mapping::map(&file, shape.file_len(), path)?;
            let counters = Counters { next, first: next, head: 0, newest: 0 };
            let kept = Self { path: path.to_owned(), map, shape, retention, counters };
            kept.write_shape();
            kept.publish();
            Ok(kept)
        })();
        match made {
            Ok(kept) => Ok(Unrenamed { kept: Some(kept), temporary }),
            Err(e) => {
                let _gone = std::fs::remove_file(&temporary);
                Err(e)
            }
        }
    }

    fn write_shape(&self) {
        let header = self.map.bytes_mut(0, 40);
        header[OFF_MAGIC..OFF_MAGIC + 8].copy_from_slice(&MAGIC.to_ne_bytes());
        header[OFF_VERSION..OFF_VERSION + 8].copy_from_slice(&u64::from(VERSION).to_ne_bytes());
        header[OFF_SLOTS..OFF_SLOTS + 8].copy_from_slice(&self.shape.slots.to_ne_bytes());
        header[OFF_AREA..OFF_AREA + 8].copy_from_slice(&self.shape.area.to_ne_bytes());
        header[OFF_TYPE..OFF_TYPE + 8].copy_from_slice(&self.shape.type_id.to_ne_bytes());
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The index the next kept structure gets.
    pub fn next_index(&self) -> u64 {
        self.map.read_u64(OFF_NEXT)
    }

    /// How many entries the file keeps now.
    pub fn len(&self) -> u64 {
        self.next_index().saturating_sub(self.map.read_u64(OFF_FIRST))
    }

    /// True if the file keeps nothing.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How many entries the file has room for now (it grows when its policy keeps
    /// more).
    pub fn capacity(&self) -> u64 {
        self.shape.slots
    }

    /// The file's length in bytes (what it costs in `/dev/shm` at most: tmpfs
    /// commits only the pages written).
    pub fn file_len(&self) -> usize {
        self.shape.file_len()
    }

    /// Keeps `es`, added at `add_time`, and returns its index: [`Self::reserve`] then
    /// `write`.
    pub fn append(&mut self, es: &EntityStructure, add_time: Time) -> Result<u64, KeepError> {
        let index = self.reserve();
        self.write(index, es, add_time)?;
        Ok(index)
    }

    /// Takes the next index for a structure about to be written with `write`:
    /// the writer publishes the structure under it first (readers are woken before
    /// the copy), then keeps it, and `add` returns after both. An index reserved and
    /// never written (the writer died between the two, or the write failed) is skipped
    /// by readers and never given again.
    pub fn reserve(&mut self) -> u64 {
        let index = self.counters.next;
        self.counters.next = index + 1;
        self.map.write_u64(OFF_NEXT, self.counters.next);
        index
    }

    /// Writes the writer's counters into the header, `next` last (a reader that sees
    /// an index sees what comes before it).
    fn publish(&self) {
        let c = self.counters;
        self.map.write_u64(OFF_HEAD, c.head);
        self.map.write_u64(OFF_NEWEST, c.newest as u64);
        self.map.write_u64(OFF_FIRST, c.first);
        self.map.write_u64(OFF_NEXT, c.next);
    }

    /// Keeps `es`, added at `add_time`, at `index`, the index [`Self::reserve`] gave
    /// last. Entries the retention lets go make room first; the file grows (doubling)
    /// when the policy keeps more than it holds. Called by the writer alone (the
    /// store's tap, under the store's lock).
    pub(crate) fn write<'a>(
        &mut self,
        index: u64,
        es: impl Into<Encodable<'a>>,
        add_time: Time,
    ) -> Result<(), KeepError> {
        debug_assert_eq!(index + 1, self.counters.next, "the index reserved last");
        let es = es.into();
        let len = es.encoded_len()?;
        let padded = align_up(len, ARCHIVE_ALIGNMENT) as u64;
        let valid_time = es.times().0;
        self.let_go(index, valid_time);
        let mut grown = 0;
        let start = loop {
            if let Some(start) = self.room_for(index, padded) {
                break start;
            }
            // Twice is always enough for this writer's own file: a third is a file
            // another process scribbles on while it is written.
            if grown == 2 {
                return Err(corrupt(&self.path, "changed by another process while kept"));
            }
            self.grow(index, padded)?;
            grown += 1;
        };
        let at = self.shape.area_at() + (start % self.shape.area) as usize;
        let written = es.write_into(self.map.bytes_mut(at, padded as usize))?;
        self.counters.head = start + padded;
        self.map.write_u64(OFF_HEAD, self.counters.head);
        // The slot last: a reader (or a writer after a crash) sees the entry whole or
        // not at all (a slot that names another index).
        self.write_slot(Slot { index, start, len: written as u64, add_time, valid_time });
        Ok(())
    }

    /// Lets every kept entry go (the trajectory was reset, T5); indices go on.
    pub fn reset(&mut self) {
        self.counters.first = self.counters.next;
        self.map.write_u64(OFF_FIRST, self.counters.first);
    }

    /// Where the entry at `index` (reserved), of `len` bytes, goes now, if it fits
    /// beside the kept ones: its start (a position that only grows), skipping the
    /// area's tail if it would wrap.
    fn room_for(&self, index: u64, len: u64) -> Option<u64> {
        let first = self.counters.first;
        if index.checked_sub(first)? >= self.shape.slots || len > self.shape.area {
            return None;
        }
        let head = self.counters.head;
        let offset = head % self.shape.area;
        let start =
            if offset + len > self.shape.area { head + (self.shape.area - offset) } else { head };
        let oldest = if first < index { self.slot(first)?.start } else { start };
        (start.checked_add(len)?.checked_sub(oldest)? <= self.shape.area).then_some(start)
    }

    /// Lets go what the retention no longer keeps once the entry at `index`, valid at
    /// `valid_time`, is added, and indices reserved and never written at the front.
    fn let_go(&mut self, index: u64, valid_time: Time) {
        let mut first = self.counters.first.min(index);
        let newest = match first < index {
            true => self.counters.newest.max(valid_time),
            false => valid_time,
        };
        match self.retention {
            Retention::All => {}
            Retention::Count(n) => first = first.max((index + 1).saturating_sub(n)),
            Retention::Window(t) => {
                let oldest_kept = newest.saturating_sub(t).saturating_add(1);
                while first < index && self.slot(first).is_some_and(|s| s.valid_time < oldest_kept)
                {
                    first += 1;
                }
            }
        }
        while first < index && self.slot(first).is_none() {
            first += 1;
        }
        self.counters.first = first;
        self.counters.newest = newest;
        self.map.write_u64(OFF_FIRST, first);
        self.map.write_u64(OFF_NEWEST, newest as u64);
    }

    /// Rewrites the file with room for the entry at `index` (reserved), of `len`
    /// bytes: each of slots and area doubled until it fits.
    fn grow(&mut self, index: u64, len: u64) -> Result<(), KeepError> {
        let first = self.counters.first;
        let live: Vec<Slot> = (first..index).filter_map(|i| self.slot(i)).collect();
        let first = live.first().map_or(index, |s| s.index);
        let used: u64 =
            live.iter().map(|s| align_up(s.len as usize, ARCHIVE_ALIGNMENT) as u64).sum();
        let mut shape = self.shape;
        let slots_needed = (index.saturating_sub(first) + 1).next_power_of_two();
        shape.slots = shape.slots.max(slots_needed);
        while shape.area < used + len {
            shape.area = shape.area.saturating_mul(2);
        }
        if shape.slots > MAX_SLOTS || shape.area > MAX_AREA {
            return Err(KeepError::Full {
                path: self.path.clone(),
                len: len as usize,
                max: MAX_AREA,
            });
        }
        let mut grown = Self::build(&self.path, shape, index + 1, self.retention)?;
        let Some(new) = grown.kept.as_ref() else { unreachable!("built, not yet renamed") };
        let mut head = 0u64;
        for slot in &live {
            let padded = align_up(slot.len as usize, ARCHIVE_ALIGNMENT);
            let mut bytes = vec![0u8; slot.len as usize];
            self.map.copy_out(
                self.shape.area_at() + (slot.start % self.shape.area) as usize,
                &mut bytes,
            );
            let at = new.shape.area_at() + head as usize;
            new.map.bytes_mut(at, bytes.len()).copy_from_slice(&bytes);
            new.write_slot(Slot { start: head, ..*slot });
            head += padded as u64;
        }
        let counters = Counters { next: index + 1, first, head, newest: self.counters.newest };
        grown.set_counters(counters);
        let grown = grown.commit()?;
        tracing::debug!(path = %self.path.display(), slots = shape.slots, area = shape.area,
            "kept history grown");
        *self = grown;
        Ok(())
    }

    fn slot_at(&self, index: u64) -> usize {
        self.shape.slots_at() + (index % self.shape.slots) as usize * SLOT_LEN
    }

    fn write_slot(&self, slot: Slot) {
        let at = self.slot_at(slot.index);
        let bytes = self.map.bytes_mut(at, SLOT_LEN);
        for (i, v) in
            [slot.index, slot.start, slot.len, slot.add_time as u64, slot.valid_time as u64]
                .into_iter()
                .enumerate()
        {
            bytes[i * 8..i * 8 + 8].copy_from_slice(&v.to_ne_bytes());
        }
    }

    /// Entry `index`'s slot, if it describes that entry and its bytes lie where a kept
    /// entry's may.
    fn slot(&self, index: u64) -> Option<Slot> {
        let slot = self.raw_slot(index);
        let area = self.shape.area;
        let fits = slot.index == index
            && (ENVELOPE_LEN as u64..=area).contains(&slot.len)
            && slot.start % ARCHIVE_ALIGNMENT as u64 == 0
            && (slot.start % area) + slot.len <= area;
        fits.then_some(slot)
    }

    /// The slot where entry `index` is described, as it is (it may describe another).
    fn raw_slot(&self, index: u64) -> Slot {
        let mut bytes = [0u8; SLOT_LEN];
        self.map.copy_out(self.slot_at(index), &mut bytes);
        let field =
            |i: usize| u64::from_ne_bytes(bytes[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
        Slot {
            index: field(0),
            start: field(1),
            len: field(2),
            add_time: field(3) as Time,
            valid_time: field(4) as Time,
        }
    }

    /// Reads every kept entry, oldest first. Indices reserved and never written (their
    /// writer died between publishing and keeping: not acknowledged) are counted apart;
    /// entries whose slot or bytes do not check, or that the writer let go while they
    /// were read, are skipped and counted.
    pub fn entries(&self) -> KeptEntries {
        let next = self.next_index();
        let first = self.map.read_u64(OFF_FIRST).min(next);
        // At most a file's worth of slots is looked at, whatever the counters say.
        let first = first.max(next.saturating_sub(self.shape.slots));
        let mut out = KeptEntries { next, ..KeptEntries::default() };
        for index in first..next {
            match self.read(index) {
                Some(entry) => out.entries.push(entry),
                None if self.raw_slot(index).index != index => out.unwritten += 1,
                None => out.skipped += 1,
            }
        }
        // Let go meanwhile (a writer still at work): not part of this reading.
        let now_first = self.map.read_u64(OFF_FIRST);
        let before = out.entries.len();
        out.entries.retain(|e| e.index >= now_first);
        out.skipped += (before - out.entries.len()) as u64;
        out
    }

    fn read(&self, index: u64) -> Option<KeptEntry> {
        let slot = self.slot(index)?;
        // Copied out first: the writer may reuse the bytes meanwhile (decoded from the
        // copy, then checked against the slot again).
        let mut bytes = vec![0u8; slot.len as usize];
        self.map
            .copy_out(self.shape.area_at() + (slot.start % self.shape.area) as usize, &mut bytes);
        let structure = codec::decode_bytes(&bytes)
            .map_err(|e| {
                tracing::debug!(path = %self.path.display(), index, error = %e,
                "a kept entry does not decode; skipped")
            })
            .ok()?;
        // The slot again: the same entry still, or it was overwritten meanwhile.
        let again = self.slot(index)?;
        (again.start == slot.start
            && again.len == slot.len
            && structure.valid_time == slot.valid_time)
            .then_some(KeptEntry { index, add_time: slot.add_time, structure })
    }

    /// Removes the kept history of `trajectory` in `domain` (its generation's): it was
    /// destroyed or re-pointed. True if there was one.
    pub fn remove(domain: &str, trajectory: &str) -> bool {
        std::fs::remove_file(Self::path_for(domain, trajectory)).is_ok()
    }

    /// Removes every kept history of `domain` and of its generations, at the domain's
    /// end (`esgm down`, the end of `esgm up`). Returns how many were removed.
    pub fn remove_domain(domain: &str) -> usize {
        crate::data_plane::shm_access::remove_files_of(Path::new(SHM_DIR), FILE_PREFIX, domain)
    }
}

/// A file written beside its place and not renamed over it yet: removed if dropped so.
#[derive(Debug)]
struct Unrenamed {
    kept: Option<KeptHistory>,
    temporary: PathBuf,
}

impl Unrenamed {
    /// Gives the file the writer's counters (and the header).
    fn set_counters(&mut self, counters: Counters) {
        if let Some(kept) = &mut self.kept {
            kept.counters = counters;
            kept.publish();
        }
    }

    /// Renames the file over its place: readers that open it from now on read it.
    fn commit(mut self) -> Result<KeptHistory, KeepError> {
        let Some(kept) = self.kept.take() else { unreachable!("committed once") };
        std::fs::rename(&self.temporary, &kept.path).map_err(|e| io(&kept.path, e))?;
        Ok(kept)
    }
}

impl Drop for Unrenamed {
    fn drop(&mut self) {
        if self.kept.is_some() {
            let _gone = std::fs::remove_file(&self.temporary);
        }
    }
}

fn first_slots(retention: Retention) -> u64 {
    match retention {
        Retention::Count(n) => n.clamp(1, FIRST_SLOTS),
        _ => FIRST_SLOTS,
    }
}

/// A new file beside `path`, named for this process and moment, to be renamed over it.
fn temporary_file(path: &Path) -> Result<(File, PathBuf), KeepError> {
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
    Ok((file, temporary))
}

fn read_at(file: &File, out: &mut [u8], path: &Path) -> Result<(), KeepError> {
    use std::os::unix::fs::FileExt as _;
    file.read_exact_at(out, 0).map_err(|e| io(path, e))
}

fn align_up(n: usize, to: usize) -> usize {
    n.div_ceil(to) * to
}

fn io(path: &Path, source: std::io::Error) -> KeepError {
    KeepError::Io { path: path.to_owned(), source }
}

fn corrupt(path: &Path, reason: impl Into<String>) -> KeepError {
    KeepError::Corrupt { path: path.to_owned(), reason: reason.into() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::value::Value;

    fn domain(tag: &str) -> String {
        format!("keep-test-{tag}-{}.g0", std::process::id())
    }

    fn es(vt: Time, text: &str) -> EntityStructure {
        let mut es = EntityStructure::new("Blob", vt, vt);
        es.set("name", Value::String(text.into()));
        es
    }

    struct Removed(String);
    impl Drop for Removed {
        fn drop(&mut self) {
            KeptHistory::remove_domain(&self.0);
        }
    }

    #[test]
    fn entries_outlive_the_writer_and_indices_go_on() {
        let d = domain("outlive");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "odo", 7, Retention::All).unwrap();
        for i in 0..3 {
            assert_eq!(w.append(&es(i, "a"), 100 + i).unwrap(), i as u64);
        }
        drop(w);
        let r = KeptHistory::open(&d, "odo").unwrap().expect("kept");
        let read = r.entries();
        assert_eq!(read.skipped, 0);
        assert_eq!(read.next, 3);
        let times: Vec<_> =
            read.entries.iter().map(|e| (e.index, e.add_time, e.structure.valid_time)).collect();
        assert_eq!(times, [(0, 100, 0), (1, 101, 1), (2, 102, 2)]);
        // A writer that comes back continues the same indices.
        let mut w = KeptHistory::open_or_create(&d, "odo", 7, Retention::All).unwrap();
        assert_eq!(w.append(&es(3, "b"), 103).unwrap(), 3);
        assert_eq!(w.len(), 4);
    }

    #[test]
    fn a_count_keeps_the_last_n_and_a_reset_lets_all_go() {
        let d = domain("count");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(5)).unwrap();
        for i in 0..50 {
            w.append(&es(i, "abc"), i).unwrap();
        }
        let read = w.entries();
        let idx: Vec<_> = read.entries.iter().map(|e| e.index).collect();
        assert_eq!(idx, [45, 46, 47, 48, 49]);
        assert_eq!(
            w.file_len(),
            Shape { slots: 5, area: FIRST_AREA, type_id: 1 }.file_len(),
            "never grew"
        );
        w.reset();
        assert!(w.entries().entries.is_empty());
        assert_eq!(w.append(&es(60, "c"), 60).unwrap(), 50);
    }

    #[test]
    fn a_window_lets_go_what_is_too_old() {
        let d = domain("window");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Window(10)).unwrap();
        for vt in [0, 5, 9, 12, 20] {
            w.append(&es(vt, "x"), vt).unwrap();
        }
        let vts: Vec<_> = w.entries().entries.iter().map(|e| e.structure.valid_time).collect();
        assert_eq!(vts, [12, 20], "kept: valid less than 10 before the newest (20)");
    }

    #[test]
    fn growing_keeps_every_entry_and_wraps_the_area() {
        let d = domain("grow");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
        let big = "y".repeat(20_000);
        for i in 0..40 {
            w.append(&es(i, &big), i).unwrap();
        }
        let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
        assert_eq!(read.entries.len(), 40);
        assert_eq!(read.skipped, 0);
        // A bounded count over a small area wraps around it many times.
        let mut w = KeptHistory::open_or_create(&d, "wrap", 1, Retention::Count(3)).unwrap();
        for i in 0..200 {
            w.append(&es(i, &big[..(i as usize * 97) % 15_000]), i).unwrap();
        }
        let read = w.entries();
        assert_eq!(read.entries.iter().map(|e| e.index).collect::<Vec<_>>(), [197, 198, 199]);
        assert_eq!(read.skipped, 0);
    }

    #[test]
    fn an_index_reserved_and_never_written_is_skipped_and_never_given_again() {
        let d = domain("reserved");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
        // A writer that died between publishing and keeping.
        assert_eq!(w.reserve(), 0);
        drop(w);
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
        let big = "z".repeat(30_000);
        for i in 1..10 {
            assert_eq!(w.append(&es(i, &big), i).unwrap(), i as u64);
        }
        let read = w.entries();
        assert_eq!(
            read.entries.iter().map(|e| e.index).collect::<Vec<_>>(),
            (1..10).collect::<Vec<_>>()
        );
        assert_eq!((read.skipped, read.unwritten), (0, 0), "let go once the next was written");
        // One in the middle is skipped and counted by a reader.
        let hole = w.reserve();
        w.append(&es(20, "a"), 20).unwrap();
        let read = w.entries();
        assert!(read.entries.iter().all(|e| e.index != hole));
        assert_eq!((read.entries.len(), read.skipped, read.unwritten), (10, 0, 1));
    }

    #[test]
    fn a_writer_killed_after_reserving_at_a_full_count_is_continued() {
        let d = domain("full");
        let _end = Removed(d.clone());
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(4)).unwrap();
        for i in 0..10 {
            w.append(&es(i, "a"), i).unwrap();
        }
        // Killed after publishing index 10, before keeping it.
        assert_eq!(w.reserve(), 10);
        drop(w);
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::Count(4)).unwrap();
        let kept: Vec<u64> = w.entries().entries.iter().map(|e| e.index).collect();
        assert_eq!(kept, [7, 8, 9], "continued, not replaced");
        assert_eq!(w.append(&es(11, "b"), 11).unwrap(), 11);
        let kept: Vec<u64> = w.entries().entries.iter().map(|e| e.index).collect();
        assert_eq!(kept, [8, 9, 11]);
    }

    #[test]
    fn bytes_from_elsewhere_are_refused_or_skipped() {
        let d = domain("corrupt");
        let _end = Removed(d.clone());
        let path = KeptHistory::path_for(&d, "x");
        std::fs::write(&path, b"not a kept history at all, just bytes").unwrap();
        assert!(matches!(KeptHistory::open(&d, "x"), Err(KeepError::Corrupt { .. })));
        // The writer replaces it, with indices above any it could have given.
        let mut w = KeptHistory::open_or_create(&d, "x", 1, Retention::All).unwrap();
        assert!(w.append(&es(1, "a"), 1).unwrap() > 1 << 40);
        w.append(&es(2, "b"), 2).unwrap();
        // Scribbled entries are skipped and counted, never read out of bounds.
        let area_at = w.shape.area_at();
        w.map.bytes_mut(area_at, 64).fill(0xAB);
        let read = KeptHistory::open(&d, "x").unwrap().unwrap().entries();
        assert_eq!((read.entries.len(), read.skipped), (1, 1));
        // A header that claims more than the file holds is refused.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[OFF_AREA..OFF_AREA + 8].copy_from_slice(&(1u64 << 33).to_ne_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert!(matches!(KeptHistory::open(&d, "x"), Err(KeepError::Corrupt { .. })));
    }
}
