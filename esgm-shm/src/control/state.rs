//! The coordinator's state on disk, so a coordinator that crashed comes back whole.
//!
//! ## Why a state file, and not the processes re-registering
//! The registry holds what nobody else holds in full: types declared from the command
//! line, trajectories created by processes that have since left, policies, the
//! supervised process table with its pids and restart counts, and each trajectory's
//! *generation*. The generation is the one that cannot be rebuilt from the live
//! processes: every process compares what it mirrors with the registry's placements
//! once a second and drops what no longer matches, so a coordinator that came back
//! with fresh generations (or an empty table while processes trickle back) would make
//! every reader drop every trajectory — the data plane would stop because the control
//! plane restarted. With the registry read back from disk, the new coordinator answers
//! exactly what the old one did, at once, and the running processes never notice.
//!
//! The state changes at human rates (declarations, creations, process reports), so it
//! is written after every change: a JSON file replaced atomically (written beside,
//! synced, renamed over, the directory synced), never half-written.
//!
//! ## Where
//! One directory per domain: `--state-dir DIR`, else `$XDG_STATE_HOME/esgm/<domain>`,
//! else `$HOME/.local/state/esgm/<domain>` (the XDG default). It holds
//! - `registry.json`: the registry ([`Snapshot`]);
//! - `coordinator.lock`: held (an advisory lock, released by the kernel when the
//!   process dies, `kill -9` included) by the coordinator serving the domain, so two
//!   coordinators never serve one domain;
//! - `logs/`: each supervised process's output (`<process>.log`), for `esgm logs`.
//!
//! An orderly stop (`esgm down`) removes `registry.json`: the next `esgm up` starts an
//! empty system, and workers that see no coordinator and no state know the system was
//! stopped on purpose and leave. After a crash the file stays: workers wait for a new
//! coordinator and re-attach, and `esgm up` recovers the registry from it.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use esgm_core::EntityStructureType;
use esgm_core::catalog::{SensorRecord, UnitRecord};
use esgm_core::esgm::{TrajectoryInfo, TrajectorySpec};
use serde::{Deserialize, Serialize};

use super::processes::ProcessRecord;

/// The environment variable naming a domain's state directory; the supervisor sets it
/// for every process it starts ([`StateDir::from_env`]).
pub const STATE_DIR_ENV: &str = "ESGM_STATE_DIR";

/// The state file's format version (a newer coordinator refuses an unknown one rather
/// than misreading it).
pub const SNAPSHOT_VERSION: u32 = 1;

/// A trajectory as the registry holds it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SavedTrajectory {
    /// The listing.
    pub info: TrajectoryInfo,
    /// What it was created from (its writer builds it from this).
    pub spec: TrajectorySpec,
    /// The process that writes it.
    pub writer: String,
    /// Its generation.
    pub generation: u64,
    /// Its writer's publisher port: the writer a recovered coordinator adopts keeps
    /// writing with it, and readers that join later must know it.
    #[serde(default)]
    pub port: Option<super::protocol::WriterPort>,
}

/// Everything the registry holds that a new coordinator needs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Snapshot {
    /// [`SNAPSHOT_VERSION`].
    pub version: u32,
    /// Every registered type (library types too; they are skipped when equal).
    pub types: Vec<(String, EntityStructureType)>,
    /// Sensors.
    pub sensors: Vec<SensorRecord>,
    /// Units.
    pub units: Vec<UnitRecord>,
    /// Trajectories, oldest generation first.
    pub trajectories: Vec<SavedTrajectory>,
    /// The next generation to give.
    pub next_generation: u64,
    /// The supervised processes and their last reported status.
    pub processes: Vec<ProcessRecord>,
}

/// Reading or writing the state failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StateError {
    /// No state directory could be chosen: set `XDG_STATE_HOME` or `HOME`, or pass
    /// `--state-dir`.
    #[error("no state directory: set XDG_STATE_HOME or HOME, or pass --state-dir")]
    NoDirectory,
    /// A file or directory could not be read or written.
    #[error("{action} {}: {source}", path.display())]
    Io {
        /// What was being done.
        action: &'static str,
        /// Where.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The state file is not a snapshot at all (damaged or not esgm's): move it away
    /// to start afresh.
    #[error("{} is not a registry state this esgm can read: {source}", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// What did not parse.
        source: serde_json::Error,
    },
    /// The state file is a snapshot of another format version (another esgm): use
    /// that esgm, or move the file away to start afresh.
    #[error(
        "{} is a registry state of format version {found}; this esgm reads {expected}",
        path.display()
    )]
    OtherVersion {
        /// The file.
        path: PathBuf,
        /// Its format version.
        found: u32,
        /// The version this esgm reads.
        expected: u32,
    },
    /// The registry could not be written out as a snapshot (a bug: every part of it
    /// is serialisable).
    #[error("cannot write the registry as a snapshot: {0}")]
    Unwritable(#[source] serde_json::Error),
    /// Another coordinator serves this domain (it holds the lock).
    #[error("another coordinator holds {}", path.display())]
    Locked {
        /// The lock file.
        path: PathBuf,
    },
}

fn io(action: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> StateError {
    let path = path.to_owned();
    move |source| StateError::Io { action, path, source }
}

/// One domain's state directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StateDir {
    dir: PathBuf,
}

impl StateDir {
    /// `dir` itself.
    pub fn at(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The default for `domain`: `$XDG_STATE_HOME/esgm/<domain>`, else
    /// `$HOME/.local/state/esgm/<domain>`.
    pub fn default_for(domain: &str) -> Result<Self, StateError> {
        let base = match std::env::var_os("XDG_STATE_HOME").filter(|v| !v.is_empty()) {
            Some(x) => PathBuf::from(x),
            None => match std::env::var_os("HOME").filter(|v| !v.is_empty()) {
                Some(home) => PathBuf::from(home).join(".local").join("state"),
                None => return Err(StateError::NoDirectory),
            },
        };
        Ok(Self { dir: base.join("esgm").join(domain) })
    }

    /// The directory [`STATE_DIR_ENV`] names (set by the supervisor), else the default
    /// for `domain`.
    pub fn from_env(domain: &str) -> Result<Self, StateError> {
        match std::env::var_os(STATE_DIR_ENV).filter(|v| !v.is_empty()) {
            Some(dir) => Ok(Self::at(dir)),
            None => Self::default_for(domain),
        }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The registry file.
    pub fn registry_file(&self) -> PathBuf {
        self.dir.join("registry.json")
    }

    /// The per-process log directory.
    pub fn log_dir(&self) -> PathBuf {
        self.dir.join("logs")
    }

    /// True while a registry is kept here: the system was not stopped on purpose.
    pub fn has_registry(&self) -> bool {
        self.registry_file().exists()
    }

    /// Creates the directory (and its parents) if missing, private to the user.
    pub fn create(&self) -> Result<(), StateError> {
        std::fs::create_dir_all(&self.dir).map_err(io("cannot create", &self.dir))?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&self.dir, std::fs::Permissions::from_mode(0o700))
                .map_err(io("cannot make private", &self.dir))?;
        }
        Ok(())
    }

    /// Takes the domain's coordinator lock, held until the returned file is dropped
    /// (or the process dies).
    pub fn lock(&self) -> Result<File, StateError> {
        self.create()?;
        let path = self.dir.join("coordinator.lock");
        let file = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(io("cannot open", &path))?;
        // flock(2) (std's File::try_lock needs Rust 1.89; the workspace supports
        // 1.85): released by the kernel when the holder dies, however it dies.
        use std::os::fd::AsRawFd;
        // SAFETY: flock takes a descriptor this function owns (open for the call).
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            return Ok(file);
        }
        let e = std::io::Error::last_os_error();
        if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
            return Err(StateError::Locked { path });
        }
        Err(io("cannot lock", &path)(e))
    }

    /// The registry kept here, if any.
    pub fn load(&self) -> Result<Option<Snapshot>, StateError> {
        let path = self.registry_file();
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(io("cannot read", &path)(e)),
        };
        let snapshot: Snapshot = serde_json::from_slice(&bytes)
            .map_err(|source| StateError::Unreadable { path: path.clone(), source })?;
        if snapshot.version != SNAPSHOT_VERSION {
            return Err(StateError::OtherVersion {
                path,
                found: snapshot.version,
                expected: SNAPSHOT_VERSION,
            });
        }
        Ok(Some(snapshot))
    }

    /// Replaces the registry file atomically with `snapshot`.
    pub fn save(&self, snapshot: &Snapshot) -> Result<(), StateError> {
        let path = self.registry_file();
        let tmp = self.dir.join("registry.json.tmp");
        let bytes = serde_json::to_vec_pretty(snapshot).map_err(StateError::Unwritable)?;
        let mut file = File::create(&tmp).map_err(io("cannot create", &tmp))?;
        file.write_all(&bytes).map_err(io("cannot write", &tmp))?;
        file.sync_all().map_err(io("cannot sync", &tmp))?;
        drop(file);
        std::fs::rename(&tmp, &path).map_err(io("cannot replace", &path))?;
        File::open(&self.dir).and_then(|d| d.sync_all()).map_err(io("cannot sync", &self.dir))?;
        Ok(())
    }

    /// Forgets the registry (an orderly stop): the next coordinator starts empty.
    pub fn remove_registry(&self) -> Result<(), StateError> {
        let path = self.registry_file();
        match std::fs::remove_file(&path) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(io("cannot remove", &path)(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    fn temp_dir(name: &str) -> StateDir {
        let dir =
            std::env::temp_dir().join(format!("esgm-state-test-{name}-{}", std::process::id()));
        let _removed = std::fs::remove_dir_all(&dir);
        StateDir::at(dir)
    }

    fn snapshot() -> Snapshot {
        Snapshot {
            version: SNAPSHOT_VERSION,
            types: Vec::new(),
            sensors: Vec::new(),
            units: Vec::new(),
            trajectories: Vec::new(),
            next_generation: 7,
            processes: Vec::new(),
        }
    }

    #[test]
    fn saved_state_loads_back_and_removal_forgets_it() {
        let dir = temp_dir("roundtrip");
        assert!(dir.load().unwrap().is_none());
        dir.create().unwrap();
        dir.save(&snapshot()).unwrap();
        assert!(dir.has_registry());
        assert_eq!(dir.load().unwrap().unwrap().next_generation, 7);
        assert!(!dir.path().join("registry.json.tmp").exists());
        dir.remove_registry().unwrap();
        assert!(dir.load().unwrap().is_none());
        std::fs::remove_dir_all(dir.path()).unwrap();
    }

    #[test]
    fn a_damaged_or_newer_file_is_an_error_not_an_empty_registry() {
        let dir = temp_dir("damaged");
        dir.create().unwrap();
        std::fs::write(dir.registry_file(), b"{\"version\": 1, \"types\": [").unwrap();
        assert!(matches!(dir.load(), Err(StateError::Unreadable { .. })));
        let mut newer = snapshot();
        newer.version = SNAPSHOT_VERSION + 1;
        dir.save(&newer).unwrap();
        assert!(matches!(
            dir.load(),
            Err(StateError::OtherVersion { found, expected: SNAPSHOT_VERSION, .. })
                if found == SNAPSHOT_VERSION + 1
        ));
        std::fs::remove_dir_all(dir.path()).unwrap();
    }

    #[test]
    fn one_coordinator_holds_the_lock() {
        let dir = temp_dir("lock");
        let held = dir.lock().unwrap();
        assert!(matches!(dir.lock(), Err(StateError::Locked { .. })));
        drop(held);
        dir.lock().unwrap();
        std::fs::remove_dir_all(dir.path()).unwrap();
    }
}
