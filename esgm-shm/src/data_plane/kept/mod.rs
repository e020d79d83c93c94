//! A primitive trajectory's kept history: a file in `/dev/shm` where the writer keeps
//! every structure it acknowledged, so that the history outlives the writer (SPEC D1),
//! and where readers read the structures in place (P7).
//!
//! Why a file of the writer's and not a keeper process: a file in POSIX shared memory
//! outlives whichever process crashes — the writer, a reader, the coordinator — with no
//! second copy to keep in step and no process whose own death would lose it.
//!
//! **Written once.** A kept structure's bytes are written into the file and nowhere
//! else: the writer publishes, on the trajectory's iceoryx2 service, a small sample
//! that says where the entry is ([`crate::SampleHeader::KIND_KEPT`]), and every reader
//! reads the entry in place in the file, mapped read-only. A camera writes an image
//! straight into a loan of the file ([`KeptHistory::loan`]). So keeping costs no copy
//! of the payload, whatever its size; readers after the writer's death read the same
//! bytes.
//!
//! **Held while read.** A reader holds the entries it reads in place (`holders.rs`),
//! and the writer never writes over a held entry: it moves to a new file instead
//! (`writer.rs`), which it renames over the old one; readers of the old file read on.
//!
//! **Crash safety.** The writer writes an entry's bytes and slot, then publishes `next`
//! (release); it moves `first` past entries before their bytes or slots are reused. A
//! writer killed at any instant leaves `[first, next)` readable, and an entry it had
//! not published was not acknowledged: the add had not returned.
//!
//! **Bytes from elsewhere.** Any process of the domain may write the file, so a reader
//! trusts nothing in it: every count, slot and entry is bounds-checked and every entry
//! checked by the codec, and what fails is skipped and counted
//! ([`KeptEntries::skipped`]), never read out of bounds.
//!
//! Files: `file.rs` (layout, mappings), `holders.rs` (readers' holds), `writer.rs`,
//! `reader.rs`.

mod file;
mod holders;
mod reader;
mod writer;

use std::path::{Path, PathBuf};

use esgm_core::codec::CodecError;
use esgm_core::{CacheConstraint, SharedStructure, Time};

pub use file::HOLDERS;
pub use reader::KeptView;
pub(crate) use reader::{KeptAt, KeptHold, KeptReader, Taken};
pub use writer::{KeptHistory, KeptImage, KeptLocation, RingLoan};

/// Where the files live: POSIX shared memory, as iceoryx2's segments.
const SHM_DIR: &str = "/dev/shm";
/// The files' names begin with this, then the generation's domain and `@`:
/// `esgm_keep@<domain>.g<N>@<hash>`, so that a domain's files can be found by name.
pub const FILE_PREFIX: &str = "esgm_keep@";
const SEPARATOR: char = '@';

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
#[non_exhaustive]
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
    /// Keeping the structure would grow the file past its largest size (16 GiB).
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

/// One kept structure, read back in place.
#[derive(Debug, Clone)]
pub struct KeptEntry {
    /// Its index in the trajectory's kept history (the order in which it was added).
    pub index: u64,
    /// When it was added (the gate's add time).
    pub add_time: Time,
    /// The structure, read where it lies in the file.
    pub structure: SharedStructure,
    /// The input structures it was made from, kept with it (a structure a bridge
    /// imported with its lineage); `None` for a pushed one.
    pub lineage: Option<esgm_core::Lineage>,
}

/// What [`KeptView::entries`] read.
#[derive(Debug, Default)]
pub struct KeptEntries {
    /// The entries, oldest first.
    pub entries: Vec<KeptEntry>,
    /// The index the next entry will get: every entry below it was kept once.
    pub next: u64,
    /// Entries that could not be read (bad slot, bad bytes, overwritten meanwhile).
    pub skipped: u64,
    /// Indices never written: their writer died before keeping them (or failed to),
    /// so they were never acknowledged.
    pub unwritten: u64,
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

    /// Opens the kept history of `trajectory` to read it; `None` if there is none.
    pub fn open(
        domain: &str,
        trajectory: &str,
    ) -> Result<Option<std::sync::Arc<KeptView>>, KeepError> {
        KeptView::open(&Self::path_for(domain, trajectory))
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

#[cfg(test)]
mod tests;
