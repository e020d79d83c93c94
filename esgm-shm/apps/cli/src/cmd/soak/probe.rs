//! What `esgm soak` reads of the host: a process's resident memory (`/proc/<pid>/status`),
//! the shared-memory files a set of processes maps (`/proc/<pid>/maps`), what those
//! files occupy in `/dev/shm`, and the load average. Linux only, as iceoryx2's
//! `/dev/shm` is.
//!
//! # Which shared memory is the domain's
//! iceoryx2 names its files by hashes of service names and by port and node ids
//! (`iox2_<hash>_<id>.data`, `.dynamic`, `.connection`), so a file name does not say
//! which domain it serves. What does say it: the file is mapped by a process of the
//! domain. A domain's processes open only their own domain's services (service names
//! are `esgm/<domain>/…`), so the `/dev/shm` files mapped by its coordinator, its
//! workers and the soak's own connection are the domain's, and no other domain's. A
//! file that no live process of the domain maps any more (one a dead process left) is
//! not counted while the run goes on; after the stop, every file the run saw must be
//! gone ([`still_present`]).

use std::collections::BTreeSet;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use anyhow::Context;

/// Where iceoryx2 keeps its shared memory (POSIX `shm_open` on Linux).
const SHM_DIR: &str = "/dev/shm";

/// Resident memory of one process, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Resident {
    /// `VmRSS`: every page the process has in memory, the shared-memory pages it
    /// touched among them.
    pub rss: u64,
    /// `RssAnon`: its private memory (heap, stacks) alone, where a leak of its own
    /// shows without the shared pages.
    pub anon: u64,
}

/// The resident memory of process `pid`.
pub fn resident(pid: u32) -> anyhow::Result<Resident> {
    let path = format!("/proc/{pid}/status");
    let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {path}"))?;
    parse_status(&text).with_context(|| format!("{path} has no VmRSS or RssAnon line"))
}

/// `VmRSS` and `RssAnon` of a `/proc/<pid>/status` text (kB there, bytes here).
fn parse_status(text: &str) -> Option<Resident> {
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':'))
            .and_then(|v| v.trim().strip_suffix("kB"))
            // Not a number: the caller reports the field as missing.
            .and_then(|v| v.trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    Some(Resident { rss: field("VmRSS")?, anon: field("RssAnon")? })
}

/// The `/dev/shm` files process `pid` maps now.
pub fn mapped_shm(pid: u32) -> anyhow::Result<BTreeSet<PathBuf>> {
    let path = format!("/proc/{pid}/maps");
    let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {path}"))?;
    Ok(shm_paths(&text).map(PathBuf::from).collect())
}

/// The `/dev/shm` paths of a `/proc/<pid>/maps` text. A mapping whose file was
/// unlinked ends in ` (deleted)`; it is left out, as it has no name to measure.
fn shm_paths(maps: &str) -> impl Iterator<Item = &str> {
    maps.lines().filter_map(|line| {
        // address perms offset dev inode path: the path is the sixth field, and may
        // hold spaces, so take what follows the fifth.
        let path = line.splitn(6, char::is_whitespace).nth(5)?.trim_start();
        (path.starts_with(SHM_DIR) && path.as_bytes().get(SHM_DIR.len()) == Some(&b'/'))
            .then_some(path)
            .filter(|p| !p.ends_with(" (deleted)"))
    })
}

/// What a set of shared-memory files occupies.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ShmUse {
    /// Files measured.
    pub files: usize,
    /// Bytes tmpfs has allocated to them (`st_blocks × 512`): the pages written, what
    /// the machine actually spends. iceoryx2 sizes a segment for its worst case up
    /// front and tmpfs commits pages as they are used, so this is far below
    /// `apparent`. A page stays allocated until its file is removed, so for a sample
    /// pool this is the high-water mark of the chunks ever in use at once: it steps up
    /// when a stalled reader holds more samples than ever before, never down, and
    /// never past `apparent`.
    pub allocated: u64,
    /// Their sizes as `ls -l` shows them (`st_size`).
    pub apparent: u64,
}

/// What `files` occupy now. A file that is gone (its owner removed it since it was
/// listed) is not counted; any other failure to look at one is an error.
pub fn usage<'a>(files: impl IntoIterator<Item = &'a PathBuf>) -> anyhow::Result<ShmUse> {
    let mut total = ShmUse::default();
    for path in files {
        match std::fs::metadata(path) {
            Ok(m) => {
                total.files += 1;
                total.allocated += m.blocks() * 512;
                total.apparent += m.size();
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e).with_context(|| format!("cannot stat {}", path.display())),
        }
    }
    Ok(total)
}

/// Every iceoryx2 file in `/dev/shm`, of any domain or program on this host: context
/// for the domain's own figure (other systems and tests come and go in it).
pub fn host_iceoryx2() -> anyhow::Result<ShmUse> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(SHM_DIR).with_context(|| format!("cannot list {SHM_DIR}"))? {
        let entry = entry.with_context(|| format!("cannot list {SHM_DIR}"))?;
        if entry.file_name().to_string_lossy().starts_with("iox2_") {
            files.push(entry.path());
        }
    }
    usage(&files)
}

/// Those of `files` that still exist.
pub fn still_present(files: &BTreeSet<PathBuf>) -> Vec<PathBuf> {
    files.iter().filter(|p| Path::new(p).exists()).cloned().collect()
}

/// The 1, 5 and 15 minute load averages (`/proc/loadavg`).
pub fn load_average() -> anyhow::Result<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").context("cannot read /proc/loadavg")?;
    parse_loadavg(&text).context("/proc/loadavg is not three numbers first")
}

fn parse_loadavg(text: &str) -> Option<[f64; 3]> {
    let mut it = text.split_whitespace().map(str::parse::<f64>);
    // Not a number: the caller reports the file as malformed.
    Some([it.next()?.ok()?, it.next()?.ok()?, it.next()?.ok()?])
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn status_lines_become_bytes() {
        let text = "Name:\tesgm\nVmRSS:\t    1612 kB\nRssAnon:\t     108 kB\nRssFile:\t1504 kB\n";
        assert_eq!(parse_status(text), Some(Resident { rss: 1612 * 1024, anon: 108 * 1024 }));
        assert_eq!(parse_status("VmRSS:\t1 kB\n"), None);
    }

    #[test]
    fn only_named_shm_mappings_count() {
        let maps = "\
7f00-7f10 rw-s 00000000 00:1a 42 /dev/shm/iox2_ab_1.data
7f10-7f20 rw-s 00000000 00:1a 43 /dev/shm/iox2_ab_2.dynamic (deleted)
7f20-7f30 r-xp 00000000 08:01 44 /usr/lib/libc.so.6
7f30-7f40 rw-p 00000000 00:00 0 
7f40-7f50 rw-s 00000000 00:1a 45 /dev/shmother/x
";
        assert_eq!(shm_paths(maps).collect::<Vec<_>>(), ["/dev/shm/iox2_ab_1.data"]);
    }

    #[test]
    fn this_process_is_measured() {
        let me = resident(std::process::id()).unwrap();
        assert!(me.rss > 0 && me.anon <= me.rss);
        let [one, five, fifteen] = load_average().unwrap();
        assert!(one >= 0.0 && five >= 0.0 && fifteen >= 0.0);
        assert_eq!(parse_loadavg("0.32 0.31 0.96 1/200 123"), Some([0.32, 0.31, 0.96]));
    }
}
