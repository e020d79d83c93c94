//! A trajectory's futex word: the cheapest way to wake a reader in another process.
//!
//! # Why not only iceoryx2's event
//! iceoryx2 0.10 wakes a listener with a datagram on a Unix socket. On this kind of
//! machine that costs 13 µs one-way, where two processes ping-ponging through a futex
//! word in shared memory take 6 µs (`floor-futex` in BENCHMARKS.md). A futex is also
//! one system call for every sleeper of the word, where a datagram goes to each
//! listener in turn.
//!
//! # The word
//! Every trajectory has one page of POSIX shared memory, named after its domain and
//! wake-up service (`/dev/shm/esgm_wake@<domain>@<hash>`). It holds, on three cache
//! lines, and then the mappings' slots:
//! - `sequence`, the futex word: the writer adds one after every sample it sends;
//! - `sleepers`: readers asleep on `sequence` right now, so that a writer calls
//!   `FUTEX_WAKE` only when somebody sleeps (a publish nobody waits for costs one
//!   atomic add and a few loads, no system call); beside it, on the same line,
//!   `receivers` and `covered` (see "A notify nobody needs");
//! - `users`: processes that map the page, counted under an advisory lock; the last to
//!   leave removes the file;
//! - then one 32-bit slot per mapping (an open file description, locked by it with an
//!   OFD record lock for as long as it maps the page), counting the threads asleep
//!   through it, with two flags: its connection is counted among the receivers, and
//!   among the covered.
//!
//! A reader loads `sequence`, looks for a sample, and sleeps with `FUTEX_WAIT` only if
//! `sequence` still holds what it loaded: a sample sent after the look changed the
//! word, and the kernel refuses the sleep. The writer's add and the reader's count of
//! itself among the sleepers are both sequentially consistent, so either the writer
//! sees the sleeper and wakes it, or the reader's sleep sees the new sequence.
//!
//! # Where iceoryx2's event stays
//! The writer still notifies the trajectory's iceoryx2 event after ringing the word,
//! unless nobody needs it (below). Waits over many trajectories at once (a process's
//! receiver thread) and one-off waits (a new reader's history) sleep on listeners,
//! which have descriptors for
//! `poll(2)`; a notify with no listener asleep costs an atomic. A reader whose word
//! cannot be opened (no room in `/dev/shm`, another user's file) falls back to the
//! event, as does every reader when [`WAKE_ENV`] is `event`.
//!
//! # A notify nobody needs
//! A connection that reads another process's trajectory listens to its event on its
//! receiver thread, which feeds the connection's replica. When one of the
//! connection's threads sleeps on the word and feeds the replica itself once woken,
//! the notify only wakes a second thread for nothing: a datagram and a wake-up, 3–4 µs
//! of every hop on this machine (BENCHMARKS.md). So the page also counts, in one
//! 64-bit word of the sleepers' line:
//! - `receivers`: connections whose receiver listens to the event (counted in after
//!   its listener exists, out before it goes);
//! - `covered`: those of them with a thread asleep on the word, which feeds the replica
//!   once woken (counted in before that thread looks at the word for the last time, out
//!   before it feeds);
//! - and how many times either changed.
//!
//! The writer skips the notify only if, read at once after its add, every receiver is
//! covered; the ring woke at least as many threads as sleepers and as covered
//! connections were counted; iceoryx2 counts exactly as many listeners as receivers
//! (a listener nobody counts, a reader sleeping on the event, needs the notify); and
//! the counts did not change while the listeners were counted. All of it is read
//! before the `FUTEX_WAKE`: a thread woken counts itself out at once.
//!
//! Each connection's flags are kept in its mapping's slot too, set and cleared in the
//! orders that leave `receivers` too high and `covered` too low if its process dies
//! between the two steps: a notify sent for nothing, never one skipped. A dead
//! process's flags are counted out with its sleepers ([`WakeWord::count_out_the_dead`])
//! by a look, which the writer starts after [`FRUITLESS_RINGS`] rings that woke fewer
//! threads than sleepers were counted, as many sends that saw fewer listeners than
//! receivers (iceoryx2 cleaned a dead receiver's listener up), or as many notifies
//! skipped; after a look that finds none, it waits twice as many, up to 65,536. A
//! process killed inside one of its steps (between a total and its slot) can leave
//! `receivers` too high or `covered` too low where no look mends them: the writer
//! then always notifies, as it did before these counts existed. A process killed
//! between its cover and its sleep stays counted on both sides until a look; its
//! count could make a notify skipped only while another connection has two threads
//! asleep on the word (the ring must wake as many threads as covered connections) and
//! a listener nobody counts waits, and the look that skipped notifies start clears it.
//!
//! # A process killed while it slept
//! It leaves `sleepers` too high, and its writer would call `FUTEX_WAKE` after each
//! sample (about a microsecond, nobody woken) until the page is made anew. So a
//! sleeper counts itself in `sleepers` first and in its mapping's slot second, and out
//! in the reverse order: a death at any point leaves `sleepers` at least the sum of the
//! slots. The kernel drops a dead process's record locks; a writer whose rings woke
//! fewer threads than sleepers were counted [`FRUITLESS_RINGS`] times looks, under
//! the file's lock, for slots that hold sleepers but no lock, and counts them out of
//! `sleepers` (after a look that finds none, it waits twice as many rings for the
//! next, up to 65,536). A slot whose
//! lock is held belongs to a live open file description and is never touched, whatever
//! process or PID namespace it is in. A process killed between its two counts leaves one sleeper that
//! no slot holds; that stays, as before. A process killed while mapping it leaves
//! `users` too high and the
//! file (one page) in `/dev/shm` until the domain's end removes every word of the
//! domain ([`remove_domain`]: `esgm down`, the end of `esgm up` and of `esgm demo`,
//! and a coordinator asked to shut down).

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd as _;
use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::wake_protocol as protocol;
use crate::data_plane::shm_access::ShmAccess;

/// The environment variable that chooses how readers sleep: `futex` (the default) or
/// `event` (iceoryx2's event only), to measure one against the other or to rule the
/// word out when looking for a fault. Read once per process.
pub const WAKE_ENV: &str = "ESGM_WAKE";

/// Where the words live: POSIX shared memory, as iceoryx2's segments.
const SHM_DIR: &str = "/dev/shm";
/// The words' file names begin with this, then the domain and `SEPARATOR`:
/// `esgm_wake@<domain>@<hash>`, so that a domain's words can be found by name.
pub const FILE_PREFIX: &str = "esgm_wake@";
/// What ends the domain in a word's file name: a character no domain name has.
const SEPARATOR: char = '@';
/// The page's size.
const LEN: usize = 4096;
/// Where each counter is: a cache line apiece, so that sleepers counting themselves do
/// not slow the writer's add.
const SEQUENCE: usize = 0;
const SLEEPERS: usize = 64;
/// In the sleepers' line, one 64-bit word the writer reads at once after each ring:
/// the receivers (its low 16 bits), the covered (the next 16) and a count of changes
/// (the high 32), so that the writer sees whether either changed while it looked at
/// the event's listeners.
const COUNTS: usize = 72;
const USERS: usize = 128;
/// Where the mappings' slots begin, and how many there are: a 32-bit count each.
const SLOTS: usize = 192;
const SLOT_COUNT: usize = (LEN - SLOTS) / 4;
/// Rings that woke fewer threads than sleepers were counted (or sends that saw fewer
/// listeners than receivers, or notifies skipped) before the writer looks for the
/// counts of dead processes; doubled after each look that found none, up to
/// `MAX_FRUITLESS_RINGS`, so that a count nobody can mend costs the look rarely.
pub const FRUITLESS_RINGS: u32 = 64;
const MAX_FRUITLESS_RINGS: u32 = 1 << 16;
/// How often an open retries a file its last user removed meanwhile.
const OPEN_ATTEMPTS: usize = 8;
/// The most words [`sleep_any`] waits on (the kernel's limit for `futex_waitv`).
pub const MAX_WAIT_ANY: usize = 128;

/// True unless [`WAKE_ENV`] asks readers to sleep on iceoryx2's event.
pub fn futex_enabled() -> bool {
    static ENABLED: OnceLock<bool> = OnceLock::new();
    *ENABLED.get_or_init(|| std::env::var(WAKE_ENV).map_or(true, |v| v != "event"))
}

/// The path of the word of the wake-up service `service` (`esgm/<domain>/wake/<name>`).
pub fn path_for(service: &str) -> PathBuf {
    // The trajectory's name may hold any character: it is hashed (FNV-1a). The domain's
    // characters are all allowed in a file name.
    let hash = service
        .bytes()
        .fold(0xcbf2_9ce4_8422_2325_u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3));
    let domain = service.split('/').nth(1).unwrap_or_default();
    Path::new(SHM_DIR).join(format!("{}{hash:016x}", domain_prefix(domain)))
}

/// The beginning of the file names of `domain`'s words.
fn domain_prefix(domain: &str) -> String {
    format!("{FILE_PREFIX}{domain}{SEPARATOR}")
}

/// Removes every word of `domain` and of its derived namespaces (a re-pointed
/// trajectory's generation, `<domain>.g<N>`), at the domain's end: a process killed
/// while it mapped a word leaves it counted as a user, and its file in `/dev/shm`. A
/// process still in the domain keeps its mapping; one that joins later makes the word
/// anew. Returns how many were removed.
pub fn remove_domain(domain: &str) -> usize {
    crate::data_plane::shm_access::remove_files_of(Path::new(SHM_DIR), FILE_PREFIX, domain)
}

/// One trajectory's futex word, mapped (see the module docs). Unmapped, and its file
/// removed by the last process that used it, when dropped.
#[derive(Debug)]
pub struct WakeWord {
    base: NonNull<u8>,
    /// Held open so that the last user can lock the file to remove it; its open file
    /// description holds the record lock on `slot`.
    file: File,
    path: PathBuf,
    /// This mapping's slot, if one was free (the sleepers of a mapping without one are
    /// counted only in the total, and cannot be counted out if their process dies).
    slot: Option<usize>,
    /// The file's device and inode, to tell whether two mappings are of one file.
    identity: (u64, u64),
    /// This mapping's rings that woke fewer threads than sleepers were counted, since
    /// the last look for the dead.
    fruitless: AtomicU32,
    /// This mapping's sends that saw fewer listeners on the event than receivers
    /// counted ([`WakeWord::receivers_unheard`]), since the last look.
    unheard: AtomicU32,
    /// This mapping's notifies skipped ([`WakeWord::notify_spared`]), since the last
    /// look: a dead connection counted on both sides would go unseen otherwise.
    spared: AtomicU32,
    /// How many of any of those start the next look for the dead.
    look_after: AtomicU32,
    /// Held by the thread looking for dead sleepers: two threads of this mapping share
    /// its record and file locks, so a second look at once could count out a slot
    /// that the first emptied and a new mapping claimed meanwhile.
    looking: std::sync::Mutex<()>,
}

// SAFETY: the mapping is only used through atomics, and it lives as long as the value.
unsafe impl Send for WakeWord {}
// SAFETY: as above; every access is an atomic operation.
unsafe impl Sync for WakeWord {}

impl WakeWord {
    /// Maps the word of the wake-up service named `service`, making it if it is the
    /// first. Files are made with the mode the domain's access asks for
    /// ([`ShmAccess::from_env`]).
    pub fn open(service: &str) -> std::io::Result<WakeWord> {
        Self::open_at(path_for(service))
    }

    fn open_at(path: PathBuf) -> std::io::Result<WakeWord> {
        let mode = ShmAccess::from_env().unwrap_or_default().file_mode();
        for _ in 0..OPEN_ATTEMPTS {
            let file =
                OpenOptions::new().read(true).write(true).create(true).mode(mode).open(&path)?;
            if let Some((base, slot)) = Self::map_locked(&file, &path, mode)? {
                let meta = file.metadata()?;
                return Ok(WakeWord {
                    base,
                    identity: (meta.dev(), meta.ino()),
                    file,
                    path,
                    slot,
                    fruitless: AtomicU32::new(0),
                    unheard: AtomicU32::new(0),
                    spared: AtomicU32::new(0),
                    look_after: AtomicU32::new(FRUITLESS_RINGS),
                    looking: std::sync::Mutex::new(()),
                });
            }
        }
        Err(std::io::Error::new(
            std::io::ErrorKind::WouldBlock,
            format!("{} was removed and made again {OPEN_ATTEMPTS} times", path.display()),
        ))
    }

    /// Under the file's lock: maps it, counts this process among its users and claims
    /// a slot, or `None` if its last user removed it meanwhile (open the new one, or
    /// every process would not meet on the same word).
    fn map_locked(
        file: &File,
        path: &Path,
        mode: u32,
    ) -> std::io::Result<Option<(NonNull<u8>, Option<usize>)>> {
        let _lock = Flock::exclusive(file)?;
        let meta = file.metadata()?;
        let same =
            std::fs::metadata(path).is_ok_and(|m| m.ino() == meta.ino() && m.dev() == meta.dev());
        if meta.nlink() == 0 || !same {
            return Ok(None);
        }
        if meta.len() < LEN as u64 {
            // Made now: the umask may have narrowed the mode.
            std::fs::set_permissions(path, std::os::unix::fs::PermissionsExt::from_mode(mode))?;
            file.set_len(LEN as u64)?;
        }
        // SAFETY: a shared mapping of a file at least LEN long.
        let base = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                LEN,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if base == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        let base = NonNull::new(base.cast::<u8>()).ok_or(std::io::ErrorKind::Other)?;
        // SAFETY: just mapped, LEN long.
        unsafe { counter_at(base, USERS) }.fetch_add(1, Ordering::SeqCst);
        Ok(Some((base, Self::claim_slot(file, base))))
    }

    /// Under the file's lock: locks the first slot no live mapping holds, counting out
    /// the sleepers a dead holder left in it. `None` if every slot is held, or the
    /// kernel has no OFD locks (before Linux 3.15).
    fn claim_slot(file: &File, base: NonNull<u8>) -> Option<usize> {
        let start = std::process::id() as usize % SLOT_COUNT;
        for slot in (0..SLOT_COUNT).map(|i| (start + i) % SLOT_COUNT) {
            match slot_lock(file, slot, libc::F_WRLCK as libc::c_short) {
                Ok(()) => {
                    let page = PageAt { base, slot: None };
                    protocol::count_out(&page, page.slot_cell(slot));
                    return Some(slot);
                }
                Err(e) if matches!(e.raw_os_error(), Some(libc::EAGAIN | libc::EACCES)) => {}
                Err(e) => {
                    tracing::debug!(error = %e,
                        "no record lock on a wake-up word; its sleepers cannot be counted out");
                    return None;
                }
            }
        }
        None
    }

    fn counter(&self, offset: usize) -> &AtomicU32 {
        // SAFETY: the page lives as long as `self`.
        unsafe { counter_at(self.base, offset) }
    }

    /// The word's current sequence: load it before looking for a sample, and sleep
    /// with [`WakeWord::sleep`] on what it was.
    pub fn sequence(&self) -> u32 {
        self.counter(SEQUENCE).load(Ordering::SeqCst)
    }

    /// Tells every reader of the trajectory that a sample was sent (after the send):
    /// an atomic add, and a `FUTEX_WAKE` only if somebody sleeps.
    pub fn ring(&self) {
        let _nobody_counted = self.ring_counting(|| 0);
    }

    /// [`WakeWord::ring`], and whether the connections that listen to the trajectory's
    /// event need its notify too (see the module docs): `listeners` counts them
    /// (iceoryx2's count of the event's listeners).
    ///
    /// Everything is read before the wake-up: a thread woken counts itself out of
    /// `covered` at once, often before this thread is back from the system call.
    pub(crate) fn ring_counting(&self, listeners: impl FnOnce() -> usize) -> Ring {
        let rang = protocol::ring(&self.page(), listeners);
        if rang.fruitless {
            self.due(&self.fruitless);
        }
        Ring { receivers: rang.receivers, listeners: rang.listeners, covered: rang.covered }
    }

    /// This mapping's page, as the protocol's steps take it.
    fn page(&self) -> PageAt {
        PageAt { base: self.base, slot: self.slot }
    }

    /// The writer saw fewer listeners on the trajectory's event than receivers counted
    /// here: a receiver's process died (iceoryx2 cleaned its listener up), and its count
    /// stays until a look for the dead, which enough of these start.
    pub(crate) fn receivers_unheard(&self) {
        self.due(&self.unheard);
    }

    /// The writer skipped a notify: enough of these start a look for the dead too, so
    /// that a dead connection counted both as a receiver and as covered (killed between
    /// its cover and its sleep) is counted out even while every ring wakes somebody.
    pub(crate) fn notify_spared(&self) {
        self.due(&self.spared);
    }

    /// Counts one more reason to look for the dead in `reasons`, and looks once there
    /// are enough.
    fn due(&self, reasons: &AtomicU32) {
        let n = reasons.fetch_add(1, Ordering::Relaxed) + 1;
        if n >= self.look_after.load(Ordering::Relaxed) {
            reasons.store(0, Ordering::Relaxed);
            self.look();
        }
    }

    /// Looks for the dead ([`WakeWord::count_out_the_dead`]), and sets how many rings
    /// start the next look: twice as many after a look that found none.
    fn look(&self) {
        let look_after = self.look_after.load(Ordering::Relaxed);
        let next = match self.count_out_the_dead() {
            Ok(0) => look_after.saturating_mul(2).min(MAX_FRUITLESS_RINGS),
            Ok(_) => FRUITLESS_RINGS,
            // Another thread looks, or another process holds the file's lock (opening
            // or leaving): look again after as many rings.
            Err(_) => look_after,
        };
        self.look_after.store(next, Ordering::Relaxed);
    }

    /// Counts out of `sleepers` the threads that slept through a mapping that is gone
    /// (its process died asleep), and out of `receivers` and `covered` the receivers
    /// whose mapping is gone; returns how many of both. Under the file's lock, taken
    /// without waiting (`WouldBlock` if another process holds it, or another thread of
    /// this mapping looks), so that no mapping claims a slot meanwhile. A writer calls
    /// it itself when its rings wake nobody; it is public for diagnostics and tests.
    pub fn count_out_the_dead(&self) -> std::io::Result<u32> {
        let _looking = match self.looking.try_lock() {
            Ok(guard) => guard,
            // Nothing a look leaves half-done matters to the next one.
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => {
                return Err(std::io::ErrorKind::WouldBlock.into());
            }
        };
        let _lock = Flock::try_exclusive(&self.file)?;
        let mut counted_out = 0;
        for slot in (0..SLOT_COUNT).filter(|&s| Some(s) != self.slot) {
            if self.counter(SLOTS + 4 * slot).load(Ordering::SeqCst) == 0 {
                continue;
            }
            // A lock this description can take is held by no live mapping.
            if slot_lock(&self.file, slot, libc::F_WRLCK as libc::c_short).is_ok() {
                let page = self.page();
                counted_out += protocol::count_out(&page, page.slot_cell(slot));
                let _ = slot_lock(&self.file, slot, libc::F_UNLCK as libc::c_short);
            }
        }
        Ok(counted_out)
    }

    /// How many threads are counted asleep on the word, in every process: for
    /// diagnostics and tests.
    pub fn sleepers(&self) -> u32 {
        self.counter(SLEEPERS).load(Ordering::SeqCst)
    }

    /// How many connections are counted as receivers of the trajectory's event, and
    /// how many of them as covered by a sleeper (see the module docs): for diagnostics
    /// and tests.
    pub fn receivers(&self) -> (u32, u32) {
        protocol::decode(self.counts().load(Ordering::SeqCst))
    }

    /// True if `other` maps the same file: a connection covers only a word its
    /// receiver is counted in.
    pub(crate) fn same_file(&self, other: &WakeWord) -> bool {
        self.identity == other.identity
    }

    fn counts(&self) -> &AtomicU64 {
        // SAFETY: the page lives as long as `self`.
        unsafe { counts_at(self.base) }
    }

    /// Counts this mapping's connection among the receivers
    /// ([`protocol::receiver_in`]). False, and nothing counted, for a mapping without a
    /// slot: nothing could count it out if its process died.
    pub(crate) fn count_receiver_in(&self) -> bool {
        protocol::receiver_in(&self.page())
    }

    /// Counts this mapping's connection out of the receivers.
    pub(crate) fn count_receiver_out(&self) {
        protocol::receiver_out(&self.page());
    }

    /// Counts this mapping's connection as covered ([`protocol::covered_in`]). Only for
    /// a mapping counted among the receivers.
    pub(crate) fn count_covered_in(&self) {
        protocol::covered_in(&self.page());
    }

    /// Counts this mapping's connection out of the covered.
    pub(crate) fn count_covered_out(&self) {
        protocol::covered_out(&self.page());
    }

    /// Counts the calling thread asleep until the result is dropped
    /// ([`protocol::asleep_in`]).
    fn count_in(&self) -> CountedAsleep<'_> {
        protocol::asleep_in(&self.page());
        CountedAsleep(self)
    }

    /// Sleeps until the sequence is no longer `seen`, at most `timeout`; returns at
    /// once if it already changed. A wake-up is not a promise of a sample (a signal,
    /// a ring for another reason): look, then sleep again.
    pub fn sleep(&self, seen: u32, timeout: Duration) {
        protocol::sleep(&self.page(), seen, timeout);
    }

    /// True if this word's file is no longer the one its path names (removed while
    /// the domain was stopped with this process still in it): open it again to meet
    /// the trajectory's new writer.
    pub fn stale(&self) -> bool {
        let Ok(meta) = self.file.metadata() else { return true };
        !std::fs::metadata(&self.path).is_ok_and(|m| m.ino() == meta.ino() && m.dev() == meta.dev())
    }
}

/// A thread counted asleep on a word ([`WakeWord::count_in`]); counted out, slot
/// first, when dropped.
struct CountedAsleep<'a>(&'a WakeWord);

impl Drop for CountedAsleep<'_> {
    fn drop(&mut self) {
        protocol::asleep_out(&self.0.page());
    }
}

/// The page of one mapping as the protocol's steps take it ([`protocol::Page`]): the
/// mapped page's cells, the mapping's slot, and the kernel's futex.
#[derive(Debug, Clone, Copy)]
struct PageAt {
    base: NonNull<u8>,
    slot: Option<usize>,
}

impl PageAt {
    /// Slot `slot`'s cell.
    fn slot_cell(&self, slot: usize) -> &AtomicU32 {
        // SAFETY: a `PageAt` is made from a live mapping of [`LEN`] bytes and used
        // while it lives; every slot lies within the page.
        unsafe { counter_at(self.base, SLOTS + 4 * slot) }
    }
}

impl protocol::Page for PageAt {
    type C32 = AtomicU32;
    type C64 = AtomicU64;

    fn sequence(&self) -> &AtomicU32 {
        // SAFETY: as in `slot_cell`.
        unsafe { counter_at(self.base, SEQUENCE) }
    }

    fn sleepers(&self) -> &AtomicU32 {
        // SAFETY: as in `slot_cell`.
        unsafe { counter_at(self.base, SLEEPERS) }
    }

    fn counts(&self) -> &AtomicU64 {
        // SAFETY: as in `slot_cell`.
        unsafe { counts_at(self.base) }
    }

    fn own_slot(&self) -> Option<&AtomicU32> {
        self.slot.map(|slot| self.slot_cell(slot))
    }

    fn wake_all(&self) -> i64 {
        futex_wake(self.sequence())
    }

    fn wait(&self, seen: u32, timeout: Duration) {
        futex_wait(self.sequence(), seen, timeout);
    }
}

impl Drop for WakeWord {
    fn drop(&mut self) {
        // Counted out under the lock, so an open cannot count itself in between the
        // last user's count and its removal of the file.
        if let Ok(_lock) = Flock::exclusive(&self.file) {
            let last = self.counter(USERS).fetch_sub(1, Ordering::SeqCst) == 1;
            if last && !self.stale() {
                let _ = std::fs::remove_file(&self.path);
            }
        }
        // SAFETY: mapped in `open_at` with this length; nothing borrows it any more.
        unsafe { libc::munmap(self.base.as_ptr().cast(), LEN) };
    }
}

/// The counter at `offset` of the page at `base`.
///
/// # Safety
/// `base` is a live mapping of [`LEN`] bytes for as long as the result is used.
unsafe fn counter_at<'a>(base: NonNull<u8>, offset: usize) -> &'a AtomicU32 {
    debug_assert!(offset + 4 <= LEN && offset % 4 == 0);
    // SAFETY: within the page, 4-aligned (the page is page-aligned); other processes
    // use it atomically too.
    unsafe { AtomicU32::from_ptr(base.as_ptr().add(offset).cast::<u32>()) }
}

/// The 64-bit word of receivers and covered of the page at `base` (see [`COUNTS`]).
///
/// # Safety
/// `base` is a live mapping of [`LEN`] bytes for as long as the result is used.
unsafe fn counts_at<'a>(base: NonNull<u8>) -> &'a AtomicU64 {
    // SAFETY: within the page, 8-aligned (the page is page-aligned); other processes
    // use it atomically too.
    unsafe { AtomicU64::from_ptr(base.as_ptr().add(COUNTS).cast::<u64>()) }
}

/// What a ring tells the writer about the connections that listen to the
/// trajectory's event (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ring {
    /// The connections counted as receivers.
    pub receivers: u32,
    /// The event's listeners the writer counted (0 if no receiver was counted):
    /// fewer than `receivers` means one of them died
    /// (`WakeWord::receivers_unheard`).
    pub listeners: usize,
    /// The notify is needed by nobody: every listener is a receiver's, every
    /// receiver was counted as covered, the counts did not change while the listeners
    /// were counted, and the ring woke at least as many threads as sleepers and as
    /// covered connections were counted.
    pub covered: bool,
}

/// Takes (`F_WRLCK`) or releases (`F_UNLCK`) the OFD record lock on `slot`'s bytes,
/// without waiting. An OFD lock belongs to the open file description, so that two
/// mappings in one process hold two slots, and the kernel drops it with the
/// description's last descriptor: when its process dies.
fn slot_lock(file: &File, slot: usize, kind: libc::c_short) -> std::io::Result<()> {
    let lock = libc::flock {
        l_type: kind,
        l_whence: libc::SEEK_SET as libc::c_short,
        l_start: (SLOTS + 4 * slot) as libc::off_t,
        l_len: 4,
        l_pid: 0,
    };
    // SAFETY: a valid descriptor and a valid `struct flock` for the call.
    if unsafe { libc::fcntl(file.as_raw_fd(), libc::F_OFD_SETLK, &lock) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Sleeps until any of `words` is no longer at its `seen` sequence, at most
/// `timeout`: one `futex_waitv(2)` (Linux 5.16) whatever their number. `Err` if the
/// kernel cannot (too old, or more than [`MAX_WAIT_ANY`] words): wait another way.
pub fn sleep_any(words: &[(&WakeWord, u32)], timeout: Duration) -> std::io::Result<()> {
    if words.len() > MAX_WAIT_ANY {
        return Err(std::io::Error::from_raw_os_error(libc::E2BIG));
    }
    /// The kernel's `struct futex_waitv`.
    #[repr(C)]
    struct FutexWaitv {
        val: u64,
        uaddr: u64,
        flags: u32,
        reserved: u32,
    }
    /// `FUTEX2_SIZE_U32`, without `FUTEX2_PRIVATE`: the words are shared.
    const FUTEX2_SIZE_U32: u32 = 0x02;
    let waiters: Vec<FutexWaitv> = words
        .iter()
        .map(|(w, seen)| FutexWaitv {
            val: u64::from(*seen),
            uaddr: w.counter(SEQUENCE).as_ptr() as u64,
            flags: FUTEX2_SIZE_U32,
            reserved: 0,
        })
        .collect();
    let until = monotonic_after(timeout);
    let asleep: Vec<CountedAsleep<'_>> = words.iter().map(|(w, _)| w.count_in()).collect();
    // SAFETY: `waiters` and `until` outlive the call; every address is a mapped word.
    let r = unsafe {
        libc::syscall(
            libc::SYS_futex_waitv,
            waiters.as_ptr(),
            waiters.len() as libc::c_uint,
            0 as libc::c_uint,
            &until as *const libc::timespec,
            libc::CLOCK_MONOTONIC,
        )
    };
    let error = (r < 0).then(std::io::Error::last_os_error);
    drop(asleep);
    match error.and_then(|e| e.raw_os_error()) {
        // Woken, a word changed before the sleep, the deadline, or a signal: the
        // caller looks at what arrived either way.
        None | Some(libc::EAGAIN | libc::ETIMEDOUT | libc::EINTR) => Ok(()),
        Some(code) => Err(std::io::Error::from_raw_os_error(code)),
    }
}

/// `CLOCK_MONOTONIC` now plus `timeout`, for `futex_waitv`'s absolute deadline.
fn monotonic_after(timeout: Duration) -> libc::timespec {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `now` is a valid timespec to write.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) };
    let timeout = timeout.min(Duration::from_secs(365 * 24 * 3600));
    let nanos = now.tv_nsec + i64::from(timeout.subsec_nanos());
    libc::timespec {
        tv_sec: now.tv_sec + timeout.as_secs() as libc::time_t + (nanos / 1_000_000_000),
        tv_nsec: (nanos % 1_000_000_000) as libc::c_long,
    }
}

/// `FUTEX_WAIT` on a shared word for at most `timeout`. Every ending (woken, the word
/// changed, the timeout, a signal) returns: the caller looks, then sleeps again. An
/// unexpected failure sleeps out a millisecond, so that a reader never spins on it.
fn futex_wait(word: &AtomicU32, seen: u32, timeout: Duration) {
    let timeout = timeout.min(Duration::from_secs(365 * 24 * 3600));
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    let started = Instant::now();
    // SAFETY: the word is mapped for the call's duration; `ts` outlives it.
    let r = unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAIT,
            seen,
            &ts as *const libc::timespec,
            std::ptr::null::<u32>(),
            0u32,
        )
    };
    if r < 0 {
        let e = std::io::Error::last_os_error();
        if !matches!(e.raw_os_error(), Some(libc::EAGAIN | libc::ETIMEDOUT | libc::EINTR)) {
            tracing::debug!(error = %e, "FUTEX_WAIT failed; sleeping a millisecond instead");
            std::thread::sleep(
                Duration::from_millis(1).min(timeout.saturating_sub(started.elapsed())),
            );
        }
    }
}

/// `FUTEX_WAKE` of every sleeper of a shared word; returns how many it woke (-1 on
/// an error).
fn futex_wake(word: &AtomicU32) -> libc::c_long {
    // SAFETY: the word is mapped for the call's duration.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAKE,
            i32::MAX,
            0usize,
            0usize,
            0u32,
        )
    }
}

/// An exclusive `flock(2)` on a file, released when dropped.
struct Flock<'a>(&'a File);

impl<'a> Flock<'a> {
    fn exclusive(file: &'a File) -> std::io::Result<Self> {
        loop {
            // SAFETY: a valid open descriptor.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } == 0 {
                return Ok(Flock(file));
            }
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e);
            }
        }
    }
}

impl<'a> Flock<'a> {
    /// The lock if no other open file description holds it now.
    fn try_exclusive(file: &'a File) -> std::io::Result<Self> {
        // SAFETY: a valid open descriptor.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            Ok(Flock(file))
        } else {
            Err(std::io::Error::last_os_error())
        }
    }
}

impl Drop for Flock<'_> {
    fn drop(&mut self) {
        // SAFETY: a valid open descriptor, locked by this value.
        unsafe { libc::flock(self.0.as_raw_fd(), libc::LOCK_UN) };
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "a failure is a failed test")]
mod tests {
    use super::*;

    fn unique() -> String {
        let domain = crate::data_plane::service_name::unique_domain("wake-word");
        crate::data_plane::service_name::wake_service_name(&domain, "t")
    }

    #[test]
    fn a_domains_words_are_found_by_name_and_removed_at_its_end() {
        let domain = crate::data_plane::service_name::unique_domain("wake-end");
        let generation = format!("{domain}.g3");
        let other = format!("{domain}.b");
        let words: Vec<_> = [&domain, &generation, &other]
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let service =
                    crate::data_plane::service_name::wake_service_name(d, &format!("t/{i}"));
                assert!(path_for(&service).to_string_lossy().contains(d.as_str()));
                WakeWord::open(&service).unwrap()
            })
            .collect();
        assert_eq!(
            remove_domain(&domain),
            2,
            "its own and its generation's; the other domain's stays"
        );
        assert!(words[0].stale() && words[1].stale() && !words[2].stale());
        drop(words);
        assert_eq!(remove_domain(&other), 0, "its last user removed it");
    }

    #[test]
    fn two_maps_meet_on_one_word_and_the_last_removes_it() {
        let name = unique();
        let a = WakeWord::open(&name).unwrap();
        let b = WakeWord::open(&name).unwrap();
        let before = b.sequence();
        a.ring();
        assert_eq!(b.sequence(), before.wrapping_add(1));
        let path = path_for(&name);
        drop(a);
        assert!(path.exists(), "b still maps it");
        drop(b);
        assert!(!path.exists(), "the last user removed it");
    }

    #[test]
    fn a_sleeper_is_woken_by_a_ring_and_sleeps_out_its_timeout_otherwise() {
        let name = unique();
        let word = std::sync::Arc::new(WakeWord::open(&name).unwrap());

        let start = Instant::now();
        word.sleep(word.sequence(), Duration::from_millis(30));
        assert!(start.elapsed() >= Duration::from_millis(30));

        // A changed sequence refuses the sleep at once.
        let seen = word.sequence();
        word.ring();
        let start = Instant::now();
        word.sleep(seen, Duration::from_secs(20));
        assert!(start.elapsed() < Duration::from_secs(20));

        let seen = word.sequence();
        let ringer = std::sync::Arc::clone(&word);
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            ringer.ring();
        });
        let start = Instant::now();
        word.sleep(seen, Duration::from_secs(20));
        assert!(start.elapsed() < Duration::from_secs(20));
        t.join().unwrap();
    }

    #[test]
    fn a_dead_receivers_counts_are_counted_out_by_a_look_and_a_sleeper_not_woken_is_notified() {
        let name = unique();
        let writer = WakeWord::open(&name).unwrap();
        let dead = WakeWord::open(&name).unwrap();
        assert!(dead.count_receiver_in());
        dead.count_covered_in();
        let ring = writer.ring_counting(|| 1);
        assert_eq!((ring.receivers, ring.covered), (1, false), "covered, but no thread woken");
        // Counted asleep, but in no futex wait: a ring cannot wake it.
        let asleep = dead.count_in();
        assert!(!writer.ring_counting(|| 1).covered, "a counted sleeper the ring did not wake");
        std::mem::forget(asleep);
        // As if its process died: the mapping and its record lock go, its counts stay.
        drop(dead);
        assert_eq!(writer.receivers(), (1, 1), "nothing counts a dead mapping out by itself");
        assert_eq!(writer.count_out_the_dead().unwrap(), 2, "one sleeper, one receiver");
        assert_eq!((writer.receivers(), writer.sleepers()), ((0, 0), 0));
        let ring = writer.ring_counting(|| 1);
        assert_eq!((ring.receivers, ring.listeners, ring.covered), (0, 0, false), "none left");
    }

    #[test]
    fn sleep_any_wakes_on_whichever_word_rings() {
        let (a, b) = (WakeWord::open(&unique()).unwrap(), WakeWord::open(&unique()).unwrap());
        let start = Instant::now();
        sleep_any(&[(&a, a.sequence()), (&b, b.sequence())], Duration::from_millis(30)).unwrap();
        assert!(start.elapsed() >= Duration::from_millis(30));

        let seen = [(a.sequence()), (b.sequence())];
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(Duration::from_millis(50));
                b.ring();
            });
            let start = Instant::now();
            sleep_any(&[(&a, seen[0]), (&b, seen[1])], Duration::from_secs(20)).unwrap();
            assert!(start.elapsed() < Duration::from_secs(20));
        });
        assert_ne!(b.sequence(), seen[1]);
    }
}
