//! Reading a kept history's entries in place: a [`KeptView`] maps one file read-only
//! (and its holders' page writable), holds the entries it hands out (see `holders.rs`)
//! and checks each before it is read; a [`KeptReader`] follows a trajectory's file
//! across the writer's moves to a new one.
//!
//! What an in-place read relies on: an entry is never written over while a process
//! holds it (the holders' protocol), and only the file's writer writes the file (its
//! mode; a reader maps it read-only, so not even a bug in the reader's process can
//! change it). A writer that breaks the protocol can change what a reader reads while
//! it reads it: the reader checked the bytes once, when it held them, and a later
//! change could make a relative pointer of the archive point elsewhere in the mapping.
//! The reader never reads outside the file it mapped (the slot's bounds are checked
//! against the area, and every archive against its own bytes), and no reader of
//! another trajectory or of another file is affected.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use esgm_core::SharedStructure;
use esgm_core::value::OctetsHolder;

use std::sync::atomic::Ordering;

use super::file::{self, Mapping, OFF_FIRST, OFF_NEXT, OFF_RECLAIM, SLOT_LINEAGE, Shape, Slot};
use crate::data_plane::payload::{
    TRAILER_HEAD, checked_trailer_len, lineage_trailer, trailer_start,
};
use esgm_core::codec::CodecError;

/// An entry as [`KeptView::structure`] found it: the structure, its slot, its lineage.
pub(crate) type Found = (SharedStructure, Slot, Option<esgm_core::Lineage>);
use super::holders::Holder;
use super::{KeepError, KeptEntries, KeptEntry};

/// One file of a kept history, mapped to read its entries in place.
#[derive(Debug)]
pub struct KeptView {
    path: PathBuf,
    map: Mapping,
    shape: Shape,
    file_id: u64,
    /// This process's holder slot in the file; `None` if every slot was taken (entries
    /// are then read from copies).
    holder: Option<Holder>,
}

/// An entry of a kept history held in place: its bytes stay unchanged while this
/// lives (see the module docs), and the file stays mapped.
#[derive(Debug)]
pub(crate) struct KeptHold {
    view: Arc<KeptView>,
    start: u64,
    at: usize,
    /// The archive's bytes.
    len: usize,
    /// With what follows it (a lineage trailer).
    total: usize,
}

impl KeptHold {
    /// The archive and what follows it (its lineage trailer, if any).
    pub(crate) fn all_bytes(&self) -> &[u8] {
        // Checked in bounds when the hold was made; the mapping lives as long as the view.
        self.view.map.bytes(self.at, self.total).unwrap_or_default()
    }
}

impl OctetsHolder for KeptHold {
    /// The archive's bytes: what a structure read from the hold reads.
    fn bytes(&self) -> &[u8] {
        self.all_bytes().get(..self.len).unwrap_or_default()
    }
}

impl Drop for KeptHold {
    fn drop(&mut self) {
        if let Some(holder) = &self.view.holder {
            holder.release(self.start);
        }
    }
}

/// An entry as [`KeptView::take`] found it.
#[derive(Debug)]
pub(crate) enum Taken {
    /// Held in place.
    Held(KeptHold),
    /// Copied out (no holder slot was free): the codec bytes.
    Copied(esgm_core::codec::ArchiveBuffer),
}

/// Where a sample of [`crate::SampleHeader::KIND_KEPT`] says its entry is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct KeptAt {
    /// The entry's index.
    pub index: u64,
    /// The file it was kept in.
    pub file_id: u64,
    /// Its start position in that file's ring.
    pub start: u64,
    /// Its codec bytes' length.
    pub len: usize,
    /// True if its lineage follows it.
    pub lineage: bool,
}

impl KeptView {
    /// Maps the file at `path`; `None` if there is none.
    pub fn open(path: &Path) -> Result<Option<Arc<Self>>, KeepError> {
        let Some(opened) = file::open(path)? else { return Ok(None) };
        let map = Mapping::map(&opened.file, 0, opened.shape.file_len(), false, path)?;
        let holder = Holder::claim(opened.file, path)?;
        if holder.is_none() {
            tracing::debug!(path = %path.display(),
                "every holder slot of a kept history is taken; its entries are read from copies");
        }
        Ok(Some(Arc::new(Self {
            path: path.to_owned(),
            map,
            shape: opened.shape,
            file_id: opened.file_id,
            holder,
        })))
    }

    /// The file's id: a new file (the writer moved) has another.
    pub fn file_id(&self) -> u64 {
        self.file_id
    }

    /// How many entries the file can describe at once (its slots).
    pub fn capacity(&self) -> u64 {
        self.shape.slots
    }

    /// The index the next entry will get: every entry below it was kept once.
    pub fn next(&self) -> u64 {
        self.map.read_u64(OFF_NEXT)
    }

    /// Takes entry `index`: held in place if this process holds a slot of the file,
    /// copied otherwise; `None` if the file does not keep it (let go and written over,
    /// or never written).
    ///
    /// The entry's slot is read until two reads agree (the writer reuses a slot for a
    /// later index, and a read may be torn by that write): then `start` and `len` are
    /// the entry's. Its bytes are protected by position, not by slot: once the hold is
    /// published and `reclaim` is still at or below `start`, the writer writes nothing
    /// over them until the hold is let go (`holders.rs`), whatever it does to the slot.
    pub(crate) fn take(self: &Arc<Self>, index: u64) -> Option<(Taken, Slot)> {
        let slot = self.settled_slot(index)?;
        let len = usize::try_from(slot.len).ok()?;
        let lineage = slot.flags & SLOT_LINEAGE != 0;
        self.take_at(slot.start, len, lineage).map(|taken| (taken, slot))
    }

    /// The entry whose archive of `len` bytes is at position `start` of the ring (where
    /// a sample said it is), with its lineage trailer if it has one: held, or copied,
    /// if the ring has not come round to it; `None` if it has, or if the bytes do not
    /// lie in the area.
    pub(crate) fn take_at(
        self: &Arc<Self>,
        start: u64,
        len: usize,
        lineage: bool,
    ) -> Option<Taken> {
        let area = self.shape.area;
        let fits = (esgm_core::codec::ENVELOPE_LEN..=area as usize).contains(&len)
            && start % esgm_core::codec::ARCHIVE_ALIGNMENT as u64 == 0
            && (start % area) + len as u64 <= area;
        if !fits {
            return None;
        }
        let at = self.shape.byte_at(start);
        let total = match lineage {
            true => self.trailed_len(start, len)?,
            false => len,
        };
        let taken = self.take_bytes(start, at, len, total)?;
        // The trailer's length was read before the hold: it must not have changed.
        if lineage && self.trailed_len(start, len) != Some(total) {
            return None;
        }
        Some(taken)
    }

    /// The bytes of an archive of `len` bytes at `start` and its lineage trailer;
    /// `None` if the trailer does not lie in the area.
    fn trailed_len(&self, start: u64, len: usize) -> Option<usize> {
        let area = self.shape.area as usize;
        let offset = (start % self.shape.area) as usize;
        let head = offset.checked_add(trailer_start(len))?;
        if head.checked_add(TRAILER_HEAD)? > area {
            return None;
        }
        let word = self.map.bytes(self.shape.area_at() + head, 8)?;
        let lineage = usize::try_from(u64::from_le_bytes(word.try_into().ok()?)).ok()?;
        let total = checked_trailer_len(len, lineage)?;
        (offset.checked_add(total)? <= area).then_some(total)
    }

    /// The `total` bytes at position `start` (byte `at` of the file), an archive of
    /// `len` and what follows it: held, or copied.
    fn take_bytes(
        self: &Arc<Self>,
        start: u64,
        at: usize,
        len: usize,
        total: usize,
    ) -> Option<Taken> {
        let Some(holder) = &self.holder else {
            let mut bytes = esgm_core::codec::ArchiveBuffer::new();
            bytes.resize(total, 0);
            self.map.copy_out(at, &mut bytes);
            // Not written over while it was copied: the writer publishes `reclaim`
            // before it writes below it. The fence keeps the copy's loads before the
            // counter's (a seqlock's read side), on every architecture.
            std::sync::atomic::fence(Ordering::Acquire);
            let reclaim = self.map.counter(OFF_RECLAIM).load(Ordering::SeqCst);
            return (reclaim <= start).then_some(Taken::Copied(bytes));
        };
        if !holder.hold(start, &self.map) {
            return None;
        }
        Some(Taken::Held(KeptHold { view: Arc::clone(self), start, at, len, total }))
    }

    /// Entry `index`'s slot as two reads in a row agree on it; `None` if it describes
    /// another entry (or no valid one).
    fn settled_slot(&self, index: u64) -> Option<Slot> {
        let mut slot = self.map.slot(&self.shape, index)?;
        for _ in 0..8 {
            let again = self.map.slot(&self.shape, index)?;
            if again == slot {
                return Some(slot);
            }
            slot = again;
        }
        None
    }

    /// Entry `index` as a structure read in place (or from a copy), checked; `None` if
    /// the file does not keep it, `Err` if its bytes are not a structure.
    pub(crate) fn structure(self: &Arc<Self>, index: u64) -> Option<Result<Found, CodecError>> {
        let (taken, slot) = self.take(index)?;
        let len = slot.len as usize;
        let lineage_of = |all: &[u8]| -> Result<Option<esgm_core::Lineage>, CodecError> {
            if slot.flags & SLOT_LINEAGE == 0 {
                return Ok(None);
            }
            let bytes = lineage_trailer(all, len)
                .map_err(|reason| CodecError::Malformed { len: all.len(), reason })?;
            esgm_core::codec::decode_lineage(bytes).map(Some)
        };
        Some((|| match taken {
            Taken::Held(hold) => {
                let lineage = lineage_of(hold.all_bytes())?;
                Ok((SharedStructure::archived(Arc::new(hold))?, slot, lineage))
            }
            Taken::Copied(mut bytes) => {
                let lineage = lineage_of(&bytes)?;
                bytes.resize(len, 0);
                Ok((SharedStructure::archived_buffer(bytes)?, slot, lineage))
            }
        })())
    }

    /// Reads every kept entry, oldest first, in place. Indices never written (their
    /// writer died before keeping them: never acknowledged) are counted apart; entries
    /// whose slot or bytes do not check, or that the writer let go while they were
    /// read, are skipped and counted.
    pub fn entries(self: &Arc<Self>) -> KeptEntries {
        let next = self.next();
        let first = self.map.read_u64(OFF_FIRST).min(next);
        // At most a file's worth of slots is looked at, whatever the counters say.
        let first = first.max(next.saturating_sub(self.shape.slots));
        let mut out = KeptEntries { next, ..KeptEntries::default() };
        for index in first..next {
            match self.structure(index) {
                Some(Ok((structure, slot, lineage)))
                    if structure.valid_time() == slot.valid_time =>
                {
                    out.entries.push(KeptEntry {
                        index,
                        add_time: slot.add_time,
                        structure,
                        lineage,
                    });
                }
                Some(Ok(_)) => out.skipped += 1,
                Some(Err(e)) => {
                    tracing::debug!(path = %self.path.display(), index, error = %e,
                        "a kept entry does not check; skipped");
                    out.skipped += 1;
                }
                None if self.map.raw_slot(&self.shape, index).index != index => out.unwritten += 1,
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
}

/// A trajectory's kept history as a reader follows it: the file at its path, opened
/// again when the writer moved to a new one.
#[derive(Debug)]
pub(crate) struct KeptReader {
    path: PathBuf,
    view: Option<Arc<KeptView>>,
}

impl KeptReader {
    /// The kept history of `trajectory` in `domain` (the generation's domain).
    pub fn new(domain: &str, trajectory: &str) -> Self {
        Self { path: super::KeptHistory::path_for(domain, trajectory), view: None }
    }

    /// The entry a sample named: held in place where it is, in its file. The writer
    /// may have moved to a new file since (its kept entries moved with it), where the
    /// entry is looked up by its index. `None` if no file keeps it any more.
    ///
    /// The file this reader maps is tried first, whichever file the sample names (a
    /// late joiner's history names files the writer has left since): the path is
    /// opened and mapped again only when it holds another file, so a reader maps each
    /// file once and takes one of its holder slots, not one per sample.
    pub fn take(&mut self, at: KeptAt) -> Result<Option<Taken>, KeepError> {
        if let Some(view) = self.view.clone() {
            if let Some(taken) = Self::take_from(&view, at) {
                return Ok(Some(taken));
            }
            match super::file::open(&self.path)? {
                Some(opened) if opened.file_id != view.file_id => {}
                // The same file, which does not keep the entry, or none at all.
                _ => return Ok(None),
            }
        }
        self.view = KeptView::open(&self.path)?;
        Ok(self.view.clone().and_then(|view| Self::take_from(&view, at)))
    }

    /// The entry `at` names, from `view`: at its position in the file it was kept in,
    /// by its index in another.
    fn take_from(view: &Arc<KeptView>, at: KeptAt) -> Option<Taken> {
        match view.file_id == at.file_id {
            true => view.take_at(at.start, at.len, at.lineage),
            false => view.take(at.index).map(|(taken, _)| taken),
        }
    }
}
