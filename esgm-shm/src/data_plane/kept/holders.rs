//! Who reads a kept history's entries in place, so that its writer never writes over
//! them: the holders' page (see `file.rs`).
//!
//! # The protocol
//! A process that reads entries of a file in place claims one holder slot in it (an
//! OFD record lock on the slot's bytes, which the kernel drops when the process dies)
//! and publishes there the lowest start position among the entries it holds. The
//! writer publishes `reclaim`, the position below which its next write may land, and
//! then looks at every claimed slot; a reader publishes its lowest position and then
//! looks at `reclaim`. Both with sequentially consistent atomics, so at least one of
//! them sees the other: either the writer sees the hold and does not write there (it
//! moves to a new file instead), or the reader sees `reclaim` past its entry and gives
//! the entry up (counted as lost; the bytes may be changing). A reader that saw
//! `reclaim` at or below its entry reads it unchanged until it lets go.
//!
//! A slot whose lock nobody holds belongs to a process that died: the writer counts it
//! out (and frees it) when it finds it in its way. [`HOLDERS`] − 1 processes may hold
//! entries of one file at once.

use std::collections::VecDeque;
use std::fs::File;
use std::os::fd::AsRawFd as _;
use std::path::Path;
use std::sync::atomic::Ordering;

use parking_lot::Mutex;

use super::KeepError;
use super::file::{HOLDER_LEN, HOLDERS, HOLDERS_AT, Mapping, OFF_RECLAIM, PAGE};

/// Nothing held.
const NONE: u64 = u64::MAX;
/// In the holders' page, slot 0 is not a holder's: its first word counts the slots
/// ever claimed (a high-water mark), so the writer looks at no more than those.
const USED: usize = 0;

/// This process's claim on one holder slot of one file, and the entries it holds there
/// (counted by start position).
#[derive(Debug)]
pub(super) struct Holder {
    /// The open file description whose OFD lock is the claim.
    file: File,
    /// The holders' page, writable.
    page: Mapping,
    slot: usize,
    /// Holds per start position, lowest first; the lowest is published in the slot.
    /// Positions are mostly held in the order they were written and let go in it: new
    /// ones go at the back, old ones leave at the front, and nothing is allocated once
    /// the queue has grown to what the process holds at once.
    counts: Mutex<Holds>,
}

impl Holder {
    /// Claims a free holder slot of the file `file` (opened for reading and writing,
    /// an open file description of its own): `None` if every slot is taken.
    pub fn claim(file: File, path: &Path) -> Result<Option<Self>, KeepError> {
        let page = Mapping::map(&file, HOLDERS_AT, PAGE, true, path)?;
        for slot in 1..HOLDERS {
            if lock(&file, slot, libc::F_WRLCK).is_ok() {
                page.write_u64(slot * HOLDER_LEN, NONE);
                page.write_u64(slot * HOLDER_LEN + 8, u64::from(std::process::id()));
                // The writer looks at the slots below this mark only.
                page.counter(USED).fetch_max(slot as u64 + 1, Ordering::SeqCst);
                return Ok(Some(Self { file, page, slot, counts: Mutex::default() }));
            }
        }
        Ok(None)
    }

    /// Holds the entry starting at `start`, if the writer has not begun to write over
    /// it: `header` maps the file's header, whose `reclaim` says (see the module docs).
    /// True if held; it must be [`Self::release`]d.
    pub fn hold(&self, start: u64, header: &Mapping) -> bool {
        let mut counts = self.counts.lock();
        let lowest = counts.lowest();
        counts.add(start);
        let min = self.page.counter(self.slot * HOLDER_LEN);
        if start < lowest {
            min.store(start, Ordering::SeqCst);
        }
        if header.counter(OFF_RECLAIM).load(Ordering::SeqCst) > start {
            // The writer may be writing over it: given up.
            Self::forget(&mut counts, start, min);
            return false;
        }
        true
    }

    /// Lets go of one hold of the entry starting at `start`.
    pub fn release(&self, start: u64) {
        let mut counts = self.counts.lock();
        Self::forget(&mut counts, start, self.page.counter(self.slot * HOLDER_LEN));
    }

    fn forget(counts: &mut Holds, start: u64, min: &std::sync::atomic::AtomicU64) {
        let lowest = counts.lowest();
        counts.remove(start);
        let now = counts.lowest();
        if now != lowest {
            min.store(now, Ordering::Release);
        }
    }
}

/// Positions held and how many times each, lowest first.
#[derive(Debug, Default)]
struct Holds(VecDeque<(u64, u32)>);

impl Holds {
    /// The lowest position held, or [`NONE`].
    fn lowest(&self) -> u64 {
        self.0.front().map_or(NONE, |(p, _)| *p)
    }

    fn add(&mut self, position: u64) {
        match self.0.back_mut() {
            Some((p, n)) if *p == position => *n += 1,
            Some((p, _)) if *p > position => {
                match self.0.binary_search_by_key(&position, |e| e.0) {
                    Ok(i) => self.0[i].1 += 1,
                    Err(i) => self.0.insert(i, (position, 1)),
                }
            }
            _ => self.0.push_back((position, 1)),
        }
    }

    fn remove(&mut self, position: u64) {
        let at = match self.0.front() {
            Some((p, _)) if *p == position => Some(0),
            _ => self.0.binary_search_by_key(&position, |e| e.0).ok(),
        };
        if let Some(i) = at {
            self.0[i].1 -= 1;
            if self.0[i].1 == 0 {
                self.0.remove(i);
            }
        }
    }
}

impl Drop for Holder {
    fn drop(&mut self) {
        self.page.write_u64(self.slot * HOLDER_LEN, NONE);
        // The lock goes with the file description, closed after this.
        let _released = lock(&self.file, self.slot, libc::F_UNLCK);
    }
}

/// True if a live process holds an entry starting below `position` in the file whose
/// header and holders the writer maps as `map` (through its own file description,
/// `file`). A slot whose lock nobody holds is a dead process's: freed.
pub(super) fn held_below(map: &Mapping, file: &File, position: u64) -> bool {
    let used = map.counter(HOLDERS_AT + USED).load(Ordering::SeqCst).min(HOLDERS as u64);
    for slot in 1..used as usize {
        let min = map.counter(HOLDERS_AT + slot * HOLDER_LEN);
        if min.load(Ordering::SeqCst) >= position {
            continue;
        }
        // Held below: by a live process, unless the slot's lock is free.
        if lock(file, slot, libc::F_WRLCK).is_ok() {
            min.store(NONE, Ordering::SeqCst);
            let _released = lock(file, slot, libc::F_UNLCK);
            continue;
        }
        return true;
    }
    false
}

/// Takes (`F_WRLCK`) or releases (`F_UNLCK`) the OFD record lock on holder `slot`'s
/// bytes, without waiting.
fn lock(file: &File, slot: usize, kind: libc::c_int) -> std::io::Result<()> {
    let lock = libc::flock {
        l_type: kind as libc::c_short,
        l_whence: libc::SEEK_SET as libc::c_short,
        l_start: (HOLDERS_AT + slot * HOLDER_LEN) as libc::off_t,
        l_len: HOLDER_LEN as libc::off_t,
        l_pid: 0,
    };
    // SAFETY: a valid descriptor and a valid `struct flock` for the call.
    if unsafe { libc::fcntl(file.as_raw_fd(), libc::F_OFD_SETLK, &lock) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_keep_their_lowest_position_in_any_order() {
        let mut h = Holds::default();
        assert_eq!(h.lowest(), NONE);
        for p in [10, 20, 20, 5, 30, 15] {
            h.add(p);
        }
        assert_eq!(h.lowest(), 5);
        h.remove(5);
        assert_eq!(h.lowest(), 10);
        h.remove(20);
        h.remove(10);
        assert_eq!(h.lowest(), 15);
        h.remove(15);
        assert_eq!(h.lowest(), 20, "held twice, let go once");
        h.remove(20);
        h.remove(30);
        h.remove(99);
        assert_eq!(h.lowest(), NONE);
    }
}
