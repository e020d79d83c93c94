//! The writer of a kept history: where each entry goes in the file's ring, what the
//! trajectory's policy lets go, and when the writer moves to a new file.
//!
//! The area is a ring of positions that only grow (`head`); an entry is written at the
//! next position its bytes fit contiguously, and every entry — a structure, or a loan a
//! camera writes an image into before it is added — is a region the writer remembers in
//! position order. Writing at a position writes over whatever lay one area's length
//! before it; that is allowed only for regions the policy let go (an index below
//! `first`), loans given back, and bytes no reader holds (`holders.rs`). When a region
//! the policy keeps, a loan still being written, or a reader's hold is in the way, the
//! writer moves to a new file (its kept entries copied, the area doubled if they do not
//! fit) and renames it over the old one: readers holding entries of the old file read
//! them on, and the rest follow (`reader.rs`).

use std::collections::VecDeque;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use esgm_core::codec::ARCHIVE_ALIGNMENT;
use esgm_core::{SharedStructure, Time};

use super::file::{
    self, MAX_AREA, MAX_SLOTS, Mapping, OFF_FIRST, OFF_HEAD, OFF_NEWEST, OFF_NEXT, OFF_RECLAIM,
    SLOT_LINEAGE, Shape, Slot, align_up, corrupt, io,
};
use super::holders::held_below;
use super::reader::{KeptView, Taken};
use super::{KeepError, KeptEntries, Retention};
use crate::data_plane::encodable::Encodable;
use crate::data_plane::payload::{
    TRAILER_HEAD, checked_trailer_len, trailer_start, with_trailer_len,
};
use esgm_core::Lineage;

/// A new file's slots and area: small, since most trajectories keep few small
/// structures; each growth doubles what is short.
const FIRST_SLOTS: u64 = 64;
const FIRST_AREA: u64 = 64 * 1024;
/// The highest index a file may have reached: far beyond any writer's count (a
/// replaced file starts at the clock's nanoseconds, about 2^61 in this century), far
/// enough below `u64::MAX` that a writer never overflows it.
const MAX_INDEX: u64 = 1 << 62;

/// Where an entry was kept: what a reader needs to find it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeptLocation {
    /// Its index in the trajectory's kept history.
    pub index: u64,
    /// The file it is in (a reader follows the writer to newer ones).
    pub file_id: u64,
    /// Its start position in the file's ring.
    pub start: u64,
    /// Its codec bytes' length.
    pub len: usize,
    /// True if its lineage follows it (a structure made from others).
    pub lineage: bool,
}

/// The counters the writer moves, as it keeps them in its own memory: another process
/// may write the file's header, so the writer never reads its own counters back from
/// it, and publishes them after each change.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Counters {
    next: u64,
    first: u64,
    head: u64,
    newest: Time,
}

/// What a region of the ring holds.
#[derive(Debug, Clone)]
enum Held {
    /// Entry `.0`.
    Entry(u64),
    /// A loan being written, while its [`RingLoan`] lives (true).
    Loan(Arc<AtomicBool>),
    /// A loan given back: nothing.
    Free,
}

#[derive(Debug, Clone)]
struct Region {
    start: u64,
    held: Held,
}

/// A primitive trajectory's kept history, as its one writer maps it (see the module
/// docs of this module and its parent).
#[derive(Debug)]
pub struct KeptHistory {
    path: PathBuf,
    /// The writer's own file description (it tests holders' locks through it).
    file: File,
    map: Arc<Mapping>,
    shape: Shape,
    file_id: u64,
    retention: Retention,
    counters: Counters,
    /// `reclaim` as published.
    reclaim: u64,
    /// The ring's regions in position order, oldest first.
    regions: VecDeque<Region>,
    /// This process's own view of the file, to hold the entries its store keeps in
    /// place (a camera's images); made at the first.
    own: Option<Arc<KeptView>>,
}

/// A region of the ring lent to a producer (a camera's image): written in place, then
/// kept with [`KeptHistory::commit`] or given back with [`KeptHistory::give_back`].
#[derive(Debug)]
pub struct RingLoan {
    map: Arc<Mapping>,
    file_id: u64,
    start: u64,
    at: usize,
    len: usize,
    /// Cleared when the loan is dropped: a loan dropped unkept frees its region.
    live: Arc<AtomicBool>,
}

impl Drop for RingLoan {
    fn drop(&mut self) {
        self.live.store(false, Ordering::Release);
    }
}

impl RingLoan {
    /// The loaned bytes, to write.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        self.map.bytes_mut(self.at, self.len)
    }

    /// The loaned bytes.
    pub fn bytes(&self) -> &[u8] {
        self.map.bytes(self.at, self.len).unwrap_or_default()
    }
}

impl KeptHistory {
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
        let first_shape = Shape { slots: first_slots(retention), area: FIRST_AREA, type_id };
        let mut above = 0;
        match file::open(&path) {
            Ok(Some(opened)) if opened.shape.type_id == type_id => {
                let map = Mapping::map(&opened.file, 0, opened.shape.file_len(), true, &path)?;
                let mut kept = Self {
                    path: path.clone(),
                    file: opened.file,
                    map: Arc::new(map),
                    shape: opened.shape,
                    file_id: opened.file_id,
                    retention,
                    counters: Counters::default(),
                    reclaim: 0,
                    regions: VecDeque::new(),
                    own: None,
                };
                match kept.continued() {
                    Ok(()) => return Ok(kept),
                    Err(why) => {
                        above = kept.map.read_u64(OFF_NEXT).saturating_add(1).min(MAX_INDEX);
                        tracing::warn!(path = %path.display(), trajectory, why,
                            "a kept history whose counters contradict it is replaced");
                    }
                }
            }
            Ok(Some(_)) => {
                tracing::warn!(path = %path.display(), trajectory,
                    "a kept history of another type is replaced");
            }
            Ok(None) => return Self::create_at(&path, first_shape, 0, retention),
            Err(e) => tracing::warn!(error = %e, trajectory, "a kept history is replaced"),
        }
        let clock = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1 << 62, |d| d.as_nanos() as u64);
        Self::create_at(&path, first_shape, clock.max(above).min(MAX_INDEX), retention)
    }

    /// Takes the header's counters as this writer's, if they agree with the file: the
    /// kept entries lie below `next` and at most a file's slots back, each slot that
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
        if c.first > c.next || c.next - c.first > self.shape.slots || c.next > MAX_INDEX {
            return Err(format!(
                "first {} and next {} with {} slots",
                c.first, c.next, self.shape.slots
            ));
        }
        let mut regions = Vec::new();
        for index in c.first..c.next {
            let Some(slot) = self.map.slot(&self.shape, index) else { continue };
            let end = slot.start.checked_add(slot.len);
            if end.is_none_or(|end| {
                end > c.head || slot.start.saturating_add(self.shape.area) < c.head
            }) {
                return Err(format!("entry {index} lies outside the area before head {}", c.head));
            }
            regions.push(Region { start: slot.start, held: Held::Entry(index) });
        }
        regions.sort_by_key(|r| r.start);
        self.regions = regions.into();
        self.counters = c;
        self.reclaim = self.map.read_u64(OFF_RECLAIM);
        Ok(())
    }

    /// Writes a new file of `shape` at `path`, its next index `next`, with nothing
    /// kept (written beside it, then renamed).
    fn create_at(
        path: &Path,
        shape: Shape,
        next: u64,
        retention: Retention,
    ) -> Result<Self, KeepError> {
        let (file, temporary, map, file_id) = file::create_beside(path, shape)?;
        let kept = Self {
            path: path.to_owned(),
            file,
            map: Arc::new(map),
            shape,
            file_id,
            retention,
            counters: Counters { next, first: next, head: 0, newest: 0 },
            reclaim: 0,
            regions: VecDeque::new(),
            own: None,
        };
        kept.publish();
        rename(&temporary, path)?;
        Ok(kept)
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The index the next kept structure gets.
    pub fn next_index(&self) -> u64 {
        self.counters.next
    }

    /// How many entries the file keeps now.
    pub fn len(&self) -> u64 {
        self.counters.next.saturating_sub(self.counters.first)
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

    /// Writes the writer's counters into the header, `next` last (a reader that sees
    /// an index sees what comes before it).
    fn publish(&self) {
        let c = self.counters;
        self.map.write_u64(OFF_HEAD, c.head);
        self.map.write_u64(OFF_NEWEST, c.newest as u64);
        self.map.write_u64(OFF_FIRST, c.first);
        self.map.write_u64(OFF_NEXT, c.next);
    }

    /// Keeps `es`, added at `add_time`, and returns its index.
    pub fn append(
        &mut self,
        es: &esgm_core::EntityStructure,
        add_time: Time,
    ) -> Result<u64, KeepError> {
        self.write(es, add_time).map(|at| at.index)
    }

    /// Keeps `es`, added at `add_time`: its bytes written once, where readers read them
    /// (an archived structure's copied as they are). Entries the retention lets go make
    /// room first; the writer moves to a new file when the policy keeps more than this
    /// one holds, or a reader holds what is in the way. Called by the writer alone (the
    /// store's tap, under the store's lock), before the structure is published.
    pub(crate) fn write<'a>(
        &mut self,
        es: impl Into<Encodable<'a>>,
        add_time: Time,
    ) -> Result<KeptLocation, KeepError> {
        self.write_traced(es, add_time, None)
    }

    /// [`Self::write`] of a structure made from others: its lineage is kept after it,
    /// as a sample's payload carries it (`payload::lineage_trailer`).
    pub(crate) fn write_traced<'a>(
        &mut self,
        es: impl Into<Encodable<'a>>,
        add_time: Time,
        lineage: Option<&Lineage>,
    ) -> Result<KeptLocation, KeepError> {
        let es = es.into();
        let len = es.encoded_len()?;
        let lineage_len = lineage.map(esgm_core::codec::lineage_len);
        let total = lineage_len.map_or(len, |l| with_trailer_len(len, l));
        let padded = align_up(total, ARCHIVE_ALIGNMENT) as u64;
        let index = self.counters.next;
        let valid_time = es.times().0;
        self.let_go(index, valid_time);
        if self.out_of_slots(index) {
            self.move_to_new_file(padded)?;
        }
        let start = self.alloc(padded, Held::Entry(index))?;
        let at = self.shape.byte_at(start);
        let region = self.map.bytes_mut(at, padded as usize);
        let written = es.write_into(region)?;
        let mut flags = 0;
        if let (Some(lineage), Some(lineage_len)) = (lineage, lineage_len) {
            let t = trailer_start(written);
            let trailer = region
                .get_mut(t..t + TRAILER_HEAD + lineage_len)
                .ok_or_else(|| corrupt(&self.path, "a lineage longer than measured"))?;
            trailer[..8].copy_from_slice(&(lineage_len as u64).to_le_bytes());
            trailer[8..TRAILER_HEAD].fill(0);
            esgm_core::codec::encode_lineage_into(lineage, &mut trailer[TRAILER_HEAD..])?;
            flags = SLOT_LINEAGE;
        }
        self.enter(Slot { index, start, len: written as u64, add_time, valid_time, flags });
        let lineage = flags == SLOT_LINEAGE;
        Ok(KeptLocation { index, file_id: self.file_id, start, len: written, lineage })
    }

    /// Lends `len` bytes of the ring, for a producer to write a structure into in place
    /// (it is kept with [`Self::commit`], or given back).
    pub fn loan(&mut self, len: usize) -> Result<RingLoan, KeepError> {
        let padded = align_up(len, ARCHIVE_ALIGNMENT) as u64;
        let live = Arc::new(AtomicBool::new(true));
        let start = self.alloc(padded, Held::Loan(Arc::clone(&live)))?;
        Ok(RingLoan {
            map: Arc::clone(&self.map),
            file_id: self.file_id,
            start,
            at: self.shape.byte_at(start),
            len: padded as usize,
            live,
        })
    }

    /// Keeps the structure written into `loan` (its first `written` bytes), added at
    /// `add_time` and valid at `valid_time`, without copying it; one made in a file the
    /// writer has moved from since is copied into the new one.
    pub fn commit(
        &mut self,
        loan: RingLoan,
        written: usize,
        add_time: Time,
        valid_time: Time,
    ) -> Result<KeptLocation, KeepError> {
        let index = self.counters.next;
        self.let_go(index, valid_time);
        if self.out_of_slots(index) {
            self.move_to_new_file(0)?;
        }
        if loan.file_id != self.file_id || written > loan.len {
            let bytes = loan.bytes().get(..written).unwrap_or_default();
            let encodable = Encodable::Archived { bytes, valid_time, create_time: valid_time };
            return self.write(encodable, add_time);
        }
        if let Some(r) = self.regions.iter_mut().find(|r| r.start == loan.start) {
            r.held = Held::Entry(index);
        }
        let slot =
            Slot { index, start: loan.start, len: written as u64, add_time, valid_time, flags: 0 };
        self.enter(slot);
        Ok(KeptLocation {
            index,
            file_id: self.file_id,
            start: loan.start,
            len: written,
            lineage: false,
        })
    }

    /// Gives a loan back unused: its bytes are free for the next entries.
    pub fn give_back(&mut self, loan: RingLoan) {
        if loan.file_id != self.file_id {
            return;
        }
        if let Some(r) = self.regions.iter_mut().find(|r| r.start == loan.start) {
            r.held = Held::Free;
        }
    }

    /// The entry just kept at `at`, read in place through this process's own holder
    /// of the file (what the writer's store keeps of an image it wrote into a loan).
    pub(crate) fn hold_own(&mut self, at: &KeptLocation) -> Option<SharedStructure> {
        let current = self.own.as_ref().is_some_and(|v| v.file_id() == self.file_id);
        if !current {
            self.own = KeptView::open(&self.path)
                .map_err(|e| tracing::debug!(error = %e, "cannot read back the kept history"))
                .ok()
                .flatten();
        }
        let view = self.own.as_ref()?;
        match view.take_at(at.start, at.len, at.lineage)? {
            Taken::Held(hold) => SharedStructure::archived(Arc::new(hold)).ok(),
            Taken::Copied(mut bytes) => {
                bytes.resize(at.len, 0);
                SharedStructure::archived_buffer(bytes).ok()
            }
        }
    }

    /// An entry's bytes in the ring: its archive, and its lineage trailer if it has one;
    /// `None` if the trailer does not fit where it should.
    fn entry_len(&self, slot: &Slot) -> Option<usize> {
        let len = slot.len as usize;
        if slot.flags & SLOT_LINEAGE == 0 {
            return Some(len);
        }
        let area = self.shape.area as usize;
        let offset = (slot.start % self.shape.area) as usize;
        let head = offset.checked_add(trailer_start(len))?;
        if head + TRAILER_HEAD > area {
            return None;
        }
        let mut word = [0u8; 8];
        self.map.copy_out(self.shape.area_at() + head, &mut word);
        let lineage = usize::try_from(u64::from_le_bytes(word)).ok()?;
        let total = checked_trailer_len(len, lineage)?;
        (offset.checked_add(total)? <= area).then_some(total)
    }

    /// True if entry `index` would take the slot of an entry the policy still keeps.
    fn out_of_slots(&self, index: u64) -> bool {
        index.saturating_sub(self.counters.first) >= self.shape.slots
    }

    /// Writes entry `slot` (its bytes are in place) and publishes it.
    fn enter(&mut self, slot: Slot) {
        let end = slot.start + align_up(slot.len as usize, ARCHIVE_ALIGNMENT) as u64;
        self.counters.head = self.counters.head.max(end);
        // The slot before `next`: a reader sees the entry whole or not at all.
        self.map.write_slot(&self.shape, slot);
        self.counters.next = slot.index + 1;
        self.publish();
    }

    /// Lets every kept entry go (the trajectory was reset, T5); indices go on.
    pub fn reset(&mut self) {
        self.counters.first = self.counters.next;
        self.map.write_u64(OFF_FIRST, self.counters.first);
    }

    /// Lets go what the retention no longer keeps once the entry at `index`, valid at
    /// `valid_time`, is added, and indices never written at the front.
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
                while first < index
                    && self.map.slot(&self.shape, first).is_some_and(|s| s.valid_time < oldest_kept)
                {
                    first += 1;
                }
            }
        }
        while first < index && self.map.slot(&self.shape, first).is_none() {
            first += 1;
        }
        self.counters.first = first;
        self.counters.newest = newest;
        self.map.write_u64(OFF_FIRST, first);
        self.map.write_u64(OFF_NEWEST, newest as u64);
    }

    /// A start position for `len` bytes (a multiple of the alignment), where nothing
    /// kept, lent or held is written over; moves to a new file when there is none.
    fn alloc(&mut self, len: u64, held: Held) -> Result<u64, KeepError> {
        for _ in 0..3 {
            if len > self.shape.area {
                self.move_to_new_file(len)?;
                continue;
            }
            let head = self.counters.head;
            let offset = head % self.shape.area;
            let start = match offset + len > self.shape.area {
                true => head + (self.shape.area - offset),
                false => head,
            };
            // What lies one area before [start, start + len) is written over.
            let reclaim = (start + len).saturating_sub(self.shape.area);
            let first = self.counters.first;
            let blocked =
                self.regions.iter().take_while(|r| r.start < reclaim).any(|r| match &r.held {
                    Held::Entry(i) => *i >= first,
                    Held::Loan(live) => live.load(Ordering::Acquire),
                    Held::Free => false,
                });
            if blocked {
                self.move_to_new_file(len)?;
                continue;
            }
            if reclaim > self.reclaim {
                self.map.counter(OFF_RECLAIM).store(reclaim, Ordering::SeqCst);
                if held_below(&self.map, &self.file, reclaim) {
                    // A reader holds what is in the way: it reads on, the writer moves.
                    self.map.counter(OFF_RECLAIM).store(self.reclaim, Ordering::SeqCst);
                    self.move_to_new_file(len)?;
                    continue;
                }
                self.reclaim = reclaim;
            }
            while self.regions.front().is_some_and(|r| r.start < reclaim) {
                self.regions.pop_front();
            }
            self.regions.push_back(Region { start, held });
            self.counters.head = start + len;
            self.map.write_u64(OFF_HEAD, self.counters.head);
            return Ok(start);
        }
        Err(corrupt(&self.path, "changed by another process while kept"))
    }

    /// Moves to a new file with the kept entries and room for `len` more bytes: the
    /// same size if they fit, each of slots and area doubled until they do. Readers
    /// holding entries of the old file read them on; loans of it are copied when kept.
    fn move_to_new_file(&mut self, len: u64) -> Result<(), KeepError> {
        let first = self.counters.first;
        let next = self.counters.next;
        let live: Vec<(Slot, usize)> = (first..next)
            .filter_map(|i| self.map.slot(&self.shape, i))
            .filter_map(|s| Some((s, self.entry_len(&s)?)))
            .collect();
        let used: u64 = live.iter().map(|(_, len)| align_up(*len, ARCHIVE_ALIGNMENT) as u64).sum();
        let mut shape = self.shape;
        let slots_needed = (next.saturating_sub(first) + 1).next_power_of_two();
        shape.slots = shape.slots.max(slots_needed);
        // Room for the kept entries and as many again: readers a cache behind still
        // find an entry where its sample says it is, before the ring comes round.
        while shape.area < 2 * (used + len) {
            shape.area = shape.area.saturating_mul(2);
        }
        if shape.slots > MAX_SLOTS || shape.area > MAX_AREA {
            return Err(KeepError::Full {
                path: self.path.clone(),
                len: len as usize,
                max: MAX_AREA,
            });
        }
        let (file, temporary, map, file_id) = file::create_beside(&self.path, shape)?;
        let mut head = 0u64;
        let mut regions = VecDeque::new();
        for (slot, len) in &live {
            let padded = align_up(*len, ARCHIVE_ALIGNMENT) as u64;
            let mut bytes = vec![0u8; *len];
            self.map.copy_out(self.shape.byte_at(slot.start), &mut bytes);
            map.bytes_mut(shape.byte_at(head), bytes.len()).copy_from_slice(&bytes);
            map.write_slot(&shape, Slot { start: head, ..*slot });
            regions.push_back(Region { start: head, held: Held::Entry(slot.index) });
            head += padded;
        }
        let counters = Counters { next, first, head, newest: self.counters.newest };
        let moved = Self {
            path: self.path.clone(),
            file,
            map: Arc::new(map),
            shape,
            file_id,
            retention: self.retention,
            counters,
            reclaim: 0,
            regions,
            own: None,
        };
        moved.publish();
        rename(&temporary, &self.path)?;
        tracing::debug!(path = %self.path.display(), slots = shape.slots, area = shape.area,
            "kept history moved to a new file");
        *self = moved;
        Ok(())
    }

    /// Reads every kept entry, oldest first, in place (see [`KeptView::entries`]).
    pub fn entries(&self) -> KeptEntries {
        match KeptView::open(&self.path) {
            Ok(Some(view)) => view.entries(),
            Ok(None) => KeptEntries::default(),
            Err(e) => {
                tracing::warn!(error = %e, "cannot read the kept history back");
                KeptEntries::default()
            }
        }
    }

    /// The area's bytes at `at`, for tests that scribble on the file.
    #[cfg(test)]
    pub(super) fn scribble(&self, at: usize, len: usize) -> &mut [u8] {
        self.map.bytes_mut(self.shape.area_at() + at, len)
    }

    /// Writes `value` at `at` of the file, for tests that play another process.
    #[cfg(test)]
    pub(super) fn scribble_header(&self, at: usize, value: u64) {
        self.map.write_u64(at, value);
    }
}

fn first_slots(retention: Retention) -> u64 {
    match retention {
        Retention::Count(n) => n.clamp(1, FIRST_SLOTS),
        _ => FIRST_SLOTS,
    }
}

fn rename(temporary: &Path, path: &Path) -> Result<(), KeepError> {
    std::fs::rename(temporary, path).map_err(|e| {
        let _gone = std::fs::remove_file(temporary);
        io(path, e)
    })
}

/// An image under construction in a loan of the kept history's ring: what a camera of a
/// kept trajectory writes its pixels into, laid out as the codec completes an image
/// around them ([`esgm_core::codec::encode_image_into`]), so that the image is written
/// once, where every reader reads it.
#[derive(Debug)]
pub struct KeptImage {
    loan: RingLoan,
    size: (i64, i64, i64),
    pixel_len: usize,
}

impl KeptImage {
    /// Lends room in `kept` for an image of these sizes (`pixel_len` bytes of pixels).
    pub fn loan(
        kept: &mut KeptHistory,
        size: (i64, i64, i64),
        pixel_len: usize,
    ) -> Result<Self, KeepError> {
        let loan = kept.loan(crate::data_plane::image_layout::image_loan_len(pixel_len))?;
        Ok(Self { loan, size, pixel_len })
    }

    /// Width, height and format.
    pub fn size(&self) -> (i64, i64, i64) {
        self.size
    }

    /// The pixels, where the image will lie in the file.
    pub fn pixels_mut(&mut self) -> &mut [u8] {
        let at = esgm_core::codec::IMAGE_PIXELS_OFFSET;
        let len = self.pixel_len;
        let bytes = self.loan.bytes_mut();
        let end = (at + len).min(bytes.len());
        &mut bytes[at.min(end)..end]
    }

    /// Completes the image as entity `name` with the given times around its pixels, in
    /// place: the loan and the archive's length, to keep ([`KeptHistory::commit`]).
    pub fn complete(
        mut self,
        name: &str,
        valid_time: Time,
        create_time: Time,
    ) -> Result<(RingLoan, usize), esgm_core::codec::CodecError> {
        let (width, height, format) = self.size;
        let written = esgm_core::codec::encode_image_into(
            name,
            valid_time,
            create_time,
            width,
            height,
            format,
            self.pixel_len,
            self.loan.bytes_mut(),
        )?;
        Ok((self.loan, written))
    }

    /// What keeps the file's memory mapped: a holder of the pixels keeps it for as
    /// long as it may read them, even after the writer moved to a new file.
    pub(crate) fn mapping(&self) -> Arc<dyn std::any::Any + Send + Sync> {
        Arc::clone(&self.loan.map) as Arc<dyn std::any::Any + Send + Sync>
    }

    /// The loan, given back unused.
    pub fn into_loan(self) -> RingLoan {
        self.loan
    }
}

impl KeptHistory {
    /// The id of the file the writer writes now.
    pub fn file_id(&self) -> u64 {
        self.file_id
    }

    /// Where entry `index` is, if the file keeps it.
    pub fn location(&self, index: u64) -> Option<KeptLocation> {
        let slot = self.map.slot(&self.shape, index)?;
        Some(KeptLocation {
            index,
            file_id: self.file_id,
            start: slot.start,
            len: slot.len as usize,
            lineage: slot.flags & SLOT_LINEAGE != 0,
        })
    }
}
