//! Who may read and write a domain's shared memory.
//!
//! iceoryx2 0.10 creates every file of a service, port and node for its owner alone:
//! data segments, connections, dynamic configurations and event sockets `0600`, static
//! configurations and node files `0400`, its directories `0750`. It does so with an
//! explicit `fchmod` after creation, so the process umask neither widens nor narrows
//! them, and it has no run-time setting to share them: the only way it offers is the
//! `dev_permissions` cargo feature, which makes every file of every domain on the host
//! `0666` at build time. (One file is shared by design: the host-wide node-id counter
//! `/dev/shm/iox2_*.global_mgmt`, `0666`, which holds no data of any domain.)
//!
//! So a domain is private to its user by default, and esgm keeps it so. A domain
//! started to allow its group or everyone ([`ShmAccess`]; `esgm up --allow-group`,
//! `--allow-others`) is shared by widening the modes of the domain's files after
//! iceoryx2 created them: every process of the domain runs a [`Widener`], which
//! repeatedly finds the files belonging to the domain's services and to the ports of
//! its own nodes and mirrors the owner's read and write bits to the group (and to
//! others). Each process widens the files it owns, since only the owner may change a
//! mode; a process of a second user therefore takes part only when it runs with
//! [`ACCESS_ENV`] set too. Files iceoryx2 is still initialising (a static
//! configuration at `0600`, a dynamic one without the owner's read bit) are left
//! alone: their mode is how iceoryx2 tells them from finished ones.
//!
//! Node files (details, monitors, tags) are never widened: another user's process
//! does not need them to publish or subscribe, and they would let it tamper with the
//! dead-node detection of this user's processes.
//!
//! Limits, all of them iceoryx2's multi-user model showing through:
//! - A file becomes open up to 100 ms after iceoryx2 made it (a service listed while
//!   being created, up to 5 s): another user's port that meets a file not yet open
//!   fails with iceoryx2's `InsufficientPermissions` and may try again.
//! - A connection a second user's process created stays in `/dev/shm` after the
//!   domain stops: the directory is sticky, so only that user (or root) removes it.
//! - iceoryx2's shared directories (`/tmp/iceoryx2`, its `nodes` and `services`) are
//!   opened by whoever owns them; if another user made them first without opening
//!   them, only that user or root can (`chmod 1777`).
//! - Group access means a file's group, which is its creator's primary group: the
//!   users must share it (or start their processes under it, `sg GROUP -c …`).

use std::collections::HashSet;
use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime};

use iceoryx2::node::{Node, NodeState, NodeView as _};
use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::Service as _;

use crate::data_plane::service::ShmService;

/// The environment variable that makes an esgm process take part in sharing its
/// domain: `private` (the default), `group` or `others`. The coordinator sets it on
/// every worker it starts; a second user's process sets it itself.
pub const ACCESS_ENV: &str = "ESGM_SHM_ACCESS";

/// Where iceoryx2 keeps the shared-memory segments (POSIX shared memory on Linux).
const SHM_DIR: &str = "/dev/shm";

/// How often a [`Widener`] looks for new files: a port another user's process
/// connects to must become readable before its connection attempt gives up.
const WIDEN_EVERY: Duration = Duration::from_millis(100);

/// How often a [`Widener`] looks at the domain's files even if the directories that
/// hold them did not change (a port's tag lives in its node's own directory). A pass
/// reads /dev/shm and stats the domain's files: every 100 ms in every process of the
/// tutorial it cost 3–4 % of a core per process in a debug build; the directories'
/// times tell when there is nothing new.
const WIDEN_ALL_EVERY: Duration = Duration::from_secs(1);

pub use crate::data_plane::shm_access::ShmAccess;
pub(crate) use crate::data_plane::shm_access::belongs_to;

impl ShmAccess {
    /// The access [`ACCESS_ENV`] asks for: [`ShmAccess::Private`] when unset or empty.
    pub fn from_env() -> Result<Self, AccessError> {
        match std::env::var(ACCESS_ENV) {
            Ok(v) if v.is_empty() => Ok(ShmAccess::Private),
            Ok(v) => v.parse(),
            Err(std::env::VarError::NotPresent) => Ok(ShmAccess::Private),
            Err(std::env::VarError::NotUnicode(v)) => {
                Err(AccessError::Unknown { value: v.to_string_lossy().into_owned() })
            }
        }
    }
}

impl std::str::FromStr for ShmAccess {
    type Err = AccessError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "private" => Ok(ShmAccess::Private),
            "group" => Ok(ShmAccess::Group),
            "others" => Ok(ShmAccess::Others),
            other => Err(AccessError::Unknown { value: other.to_owned() }),
        }
    }
}

/// Sharing a domain's shared memory failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AccessError {
    /// [`ACCESS_ENV`] holds something else than `private`, `group` or `others`; fix it.
    #[error("{ACCESS_ENV}=`{value}` is not one of private, group, others")]
    Unknown {
        /// The value found.
        value: String,
    },
    /// iceoryx2's nodes could not be listed (its node directory is unreadable): the
    /// domain's ports are unknown, so nothing was widened.
    #[error("cannot list iceoryx2's nodes")]
    CannotListNodes(#[source] iceoryx2::node::NodeListFailure),
    /// iceoryx2's services could not be listed (its service directory is unreadable).
    #[error("cannot list iceoryx2's services")]
    CannotListServices(#[source] iceoryx2::service::ServiceListError),
    /// A directory holding the domain's files could not be read.
    #[error("cannot read {}", dir.display())]
    CannotReadDir {
        /// The directory.
        dir: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The thread that keeps the domain open could not be started.
    #[error("cannot start the shared-memory access thread")]
    CannotStartThread(#[source] std::io::Error),
    /// A file's mode could not be changed. For iceoryx2's shared directories this means
    /// another user created them first: only that user (or root) can open them to
    /// others, for example with `chmod 1777`.
    #[error("cannot change the mode of {}", path.display())]
    CannotChangeMode {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// What one pass of [`widen_domain`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Widened {
    /// Files whose mode it changed.
    pub changed: usize,
    /// Files of the domain it found already wide enough, or still being initialised.
    pub unchanged: usize,
}

/// Widens, once, the modes of the files of `domain` this process's user owns, as
/// `access` admits (see the module documentation for which files). Does nothing for
/// [`ShmAccess::Private`]. A file that disappears while it runs is not an error: ports
/// come and go.
pub fn widen_domain(domain: &str, access: ShmAccess) -> Result<Widened, AccessError> {
    DomainScan::new(domain).widen(access)
}

impl DomainScan {
    fn widen(&mut self, access: ShmAccess) -> Result<Widened, AccessError> {
        let mut widened = Widened::default();
        if access == ShmAccess::Private {
            return Ok(widened);
        }
        for dir in shared_dirs() {
            widen_shared_dir(&dir, access, self.me)?;
        }
        for (path, meta) in self.find(false)?.shared {
            match widen_file(&path, &meta, access, self.me)? {
                true => widened.changed += 1,
                false => widened.unchanged += 1,
            }
        }
        Ok(widened)
    }
}

/// iceoryx2's directories that every domain and user of the host shares: its root,
/// and the node and service directories in it.
pub fn shared_dirs() -> [PathBuf; 3] {
    let global = &crate::data_plane::service::iceoryx2_config().global;
    [global.root_path(), &global.node_dir(), &global.service_dir()]
        .map(|p| PathBuf::from(p.to_string()))
}

/// True if this process may create files in `dir` (write and search permission);
/// an error if it cannot tell (the directory is missing, say).
pub fn usable(dir: &Path) -> std::io::Result<bool> {
    use std::os::unix::ffi::OsStrExt as _;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes())?;
    // SAFETY: a valid NUL-terminated path; access only reads it.
    match unsafe { libc::access(path.as_ptr(), libc::W_OK | libc::X_OK) } {
        0 => Ok(true),
        _ => match std::io::Error::last_os_error() {
            e if e.kind() == std::io::ErrorKind::PermissionDenied => Ok(false),
            e => Err(e),
        },
    }
}

/// The files iceoryx2 made for a domain that this process's user owns.
#[derive(Debug, Clone, Default)]
pub struct DomainFiles {
    /// The files of the domain's services and of its ports: static and dynamic
    /// configurations, data segments, connections, event sockets. These are what
    /// another user's process needs to publish or subscribe, and what
    /// [`widen_domain`] widens.
    pub shared: Vec<PathBuf>,
    /// The files of the domain's nodes: their directories, details, tags and monitor
    /// files. Never widened.
    pub nodes: Vec<PathBuf>,
}

/// The files iceoryx2 made for `domain` that this user owns, found from the domain's
/// services and nodes (iceoryx2 names its files by hashes and ids, never by service
/// name). An error means they could not be listed; "none" is never answered for
/// "unknown".
pub fn domain_files(domain: &str) -> Result<DomainFiles, AccessError> {
    let found = DomainScan::new(domain).find(true)?;
    Ok(DomainFiles {
        shared: found.shared.into_iter().map(|(p, _)| p).collect(),
        nodes: found.nodes,
    })
}

/// What a [`DomainScan`] found: the shared files with their metadata (read once).
struct Found {
    shared: Vec<(PathBuf, std::fs::Metadata)>,
    nodes: Vec<PathBuf>,
}

/// How long after a directory last changed a listing of it is trusted while it does not
/// change again: its modification time is coarse (a few ms), so an entry added in the
/// same tick as the listing would go unnoticed.
const SETTLE: Duration = Duration::from_millis(50);

/// How long a listing of iceoryx2's services or nodes is trusted at most. iceoryx2
/// finishes a service's static configuration by changing its mode, which does not
/// change the directory: a service listed while being created is found again by this
/// time at the latest. (A node is listable before its monitor file changes the node
/// directory.) Listing every node and service of the host costs a debug build about
/// 0.1 s of CPU with the tutorial running, so not every pass.
const RELIST_EVERY: Duration = Duration::from_secs(5);

/// A listing, and when it was made.
struct Listed<T> {
    value: T,
    /// The listed directory's modification time when it was listed.
    dir_modified: SystemTime,
    /// When the directory's time was read: a change in the same tick after it would not
    /// change that time.
    checked_at: SystemTime,
    listed_at: Instant,
}

impl<T> Listed<T> {
    /// True if a new listing would say the same: the directory has not changed since,
    /// it had settled before the listing, and the listing is not old.
    fn fresh(&self, dir_modified: Option<SystemTime>) -> bool {
        dir_modified == Some(self.dir_modified)
            && self.checked_at.duration_since(self.dir_modified).is_ok_and(|d| d > SETTLE)
            && self.listed_at.elapsed() < RELIST_EVERY
    }
}

/// Finds a domain's files, again and again: listing iceoryx2's services and nodes (every
/// one of the host, each read and deserialised: about 0.1 s of a debug build's CPU for
/// the tutorial) only when their directory changed, or every few seconds.
struct DomainScan {
    domain: String,
    me: u32,
    /// The domain's services' hashes and unique ids.
    services: Option<Listed<HashSet<String>>>,
    /// The domain's nodes (every user's whose details are readable).
    nodes: Option<Listed<Vec<u128>>>,
}

/// When `dir` last changed; `None` if it does not exist (yet).
fn modified(dir: &Path) -> Result<Option<SystemTime>, AccessError> {
    match std::fs::metadata(dir).and_then(|m| m.modified()) {
        Ok(t) => Ok(Some(t)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(AccessError::CannotReadDir { dir: dir.to_owned(), source }),
    }
}

impl DomainScan {
    fn new(domain: &str) -> Self {
        Self { domain: domain.to_owned(), me: effective_uid(), services: None, nodes: None }
    }

    /// The domain's files; its node files only if `with_nodes` (the widener never
    /// touches them, and they are many: a tag per port).
    fn find(&mut self, with_nodes: bool) -> Result<Found, AccessError> {
        let [root, node_dir, service_dir] = shared_dirs();
        let me = self.me;
        let checked_at = SystemTime::now();
        let services_modified = modified(&service_dir)?;
        if !self.services.as_ref().is_some_and(|l| l.fresh(services_modified)) {
            self.services = match services_modified {
                Some(m) => Some(listed(service_tokens(&self.domain)?, m, checked_at)),
                None => None,
            };
        }
        let checked_at = SystemTime::now();
        let nodes_modified = modified(&node_dir)?;
        if !self.nodes.as_ref().is_some_and(|l| l.fresh(nodes_modified)) {
            self.nodes = match nodes_modified {
                Some(m) => Some(listed(domain_nodes(&self.domain)?, m, checked_at)),
                None => None,
            };
        }
        let mut tokens = self.services.as_ref().map(|l| l.value.clone()).unwrap_or_default();
        let all_nodes = self.nodes.as_ref().map(|l| l.value.as_slice()).unwrap_or_default();
        let mine = port_tokens(all_nodes, &node_dir, me, &mut tokens)?;
        let ids = DomainIds { tokens, nodes: mine };
        self.collect(&ids, &root, &node_dir, &service_dir, with_nodes)
    }

    fn collect(
        &self,
        ids: &DomainIds,
        root: &Path,
        node_dir: &Path,
        service_dir: &Path,
        with_nodes: bool,
    ) -> Result<Found, AccessError> {
        let me = self.me;
        let mut files = Found { shared: Vec::new(), nodes: Vec::new() };
        for dir in [Path::new(SHM_DIR), root, service_dir] {
            files.shared.extend(owned_entries(dir, me, |name| {
                name.starts_with("iox2_") && ids.matches(name)
            })?);
        }
        if !with_nodes {
            return Ok(files);
        }
        // `<nodes>/iox2_<node id>.node_monitor…`, and `<nodes>/<node id>/` with its files.
        let node_ids: HashSet<String> = ids.nodes.iter().map(u128::to_string).collect();
        files.nodes.extend(
            owned_entries(node_dir, me, |name| {
                name.split(separator).any(|p| node_ids.contains(p))
            })?
            .into_iter()
            .map(|(p, _)| p),
        );
        for node in &ids.nodes {
            let dir = node_dir.join(node.to_string());
            if dir.is_dir() {
                files.nodes.extend(owned_entries(&dir, me, |_| true)?.into_iter().map(|(p, _)| p));
            }
        }
        Ok(files)
    }
}

fn listed<T>(value: T, dir_modified: SystemTime, checked_at: SystemTime) -> Listed<T> {
    Listed { value, dir_modified, checked_at, listed_at: Instant::now() }
}

/// The entries of `dir` this user owns whose names `wanted` accepts. Entries that
/// vanish while listed (a port closed) are left out; a directory that vanished has
/// none.
fn owned_entries(
    dir: &Path,
    me: u32,
    wanted: impl Fn(&str) -> bool,
) -> Result<Vec<(PathBuf, std::fs::Metadata)>, AccessError> {
    let gone = |e: &std::io::Error| e.kind() == std::io::ErrorKind::NotFound;
    let failed = |source| AccessError::CannotReadDir { dir: dir.to_owned(), source };
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if gone(&e) => return Ok(Vec::new()),
        Err(e) => return Err(failed(e)),
    };
    let mut out = Vec::new();
    for entry in entries {
        let entry = match entry {
            Ok(entry) => entry,
            Err(e) if gone(&e) => continue,
            Err(e) => return Err(failed(e)),
        };
        let name = entry.file_name();
        if !name.to_str().is_some_and(&wanted) {
            continue;
        }
        match entry.metadata() {
            Ok(m) if m.uid() == me => out.push((entry.path(), m)),
            Ok(_) => {}
            Err(e) if gone(&e) => {}
            Err(e) => return Err(failed(e)),
        }
    }
    Ok(out)
}

/// What separates the ids in iceoryx2's file names: `iox2_<kind>_<id>_<id>.<suffix>`.
fn separator(c: char) -> bool {
    c == '_' || c == '.'
}

/// The identifiers that name the files of a domain: its services' hashes (static
/// configurations) and unique ids (dynamic configurations), and the port ids of this
/// user's nodes of the domain (data segments, connections, event sockets).
struct DomainIds {
    tokens: HashSet<String>,
    /// This user's nodes of the domain.
    nodes: Vec<u128>,
}

impl DomainIds {
    /// True if one of the `_`/`.`-separated parts of a file name is one of the ids.
    fn matches(&self, name: &str) -> bool {
        name.split(separator).any(|part| self.tokens.contains(part))
    }
}

/// The hashes (static configurations) and unique ids (dynamic configurations) of the
/// domain's services.
fn service_tokens(domain: &str) -> Result<HashSet<String>, AccessError> {
    let config = crate::data_plane::service::iceoryx2_config();
    let mut tokens = HashSet::new();

    ShmService::list(config, |service| {
        let s = &service.static_details;
        if belongs_to(domain, s.name().as_str()) {
            tokens.insert(s.service_hash().as_str().to_owned());
            tokens.insert(s.unique_service_id().value().to_string());
        }
        CallbackProgression::Continue
    })
    .map_err(AccessError::CannotListServices)?;
    Ok(tokens)
}

/// The domain's nodes, every user's whose details this user can read.
fn domain_nodes(domain: &str) -> Result<Vec<u128>, AccessError> {
    let config = crate::data_plane::service::iceoryx2_config();
    let mut nodes = Vec::new();
    Node::<ShmService>::list(config, |state| {
        let view_of = |id: u128, details: Option<&iceoryx2::node::NodeDetails>| {
            details.filter(|d| belongs_to(domain, d.name().as_str())).map(|_| id)
        };
        let id = match &state {
            NodeState::Alive(v) => view_of(v.id().value(), v.details().as_ref()),
            NodeState::Dead(v) => view_of(v.id().value(), v.details().as_ref()),
            // Another user's node (no details readable) or one being set up.
            _ => None,
        };
        nodes.extend(id);
        CallbackProgression::Continue
    })
    .map_err(AccessError::CannotListNodes)?;
    Ok(nodes)
}

/// Adds the port ids of this user's nodes among `nodes` to `tokens` (a node's directory
/// holds a tag file per port it owns: `iox2_<port id>.port_tag`); returns those nodes.
fn port_tokens(
    nodes: &[u128],
    node_dir: &Path,
    me: u32,
    tokens: &mut HashSet<String>,
) -> Result<Vec<u128>, AccessError> {
    let mut mine = Vec::new();
    for &node in nodes {
        let dir = node_dir.join(node.to_string());
        let gone = |e: &std::io::Error| e.kind() == std::io::ErrorKind::NotFound;
        // The node ended since it was listed: nothing to widen.
        let owner = match std::fs::metadata(&dir) {
            Ok(m) => m.uid(),
            Err(e) if gone(&e) => continue,
            Err(source) => return Err(AccessError::CannotReadDir { dir, source }),
        };
        if owner != me {
            continue;
        }
        mine.push(node);
        let entries = match std::fs::read_dir(&dir) {
            Ok(entries) => entries,
            Err(e) if gone(&e) => continue,
            Err(source) => return Err(AccessError::CannotReadDir { dir, source }),
        };
        for entry in entries {
            let entry = match entry {
                Ok(entry) => entry,
                Err(e) if gone(&e) => continue,
                Err(source) => return Err(AccessError::CannotReadDir { dir, source }),
            };
            let name = entry.file_name();
            let Some(port) = name.to_str().and_then(|n| n.strip_suffix(".port_tag")) else {
                continue;
            };
            if let Some(id) = port.strip_prefix("iox2_") {
                tokens.insert(id.to_owned());
            }
        }
    }
    Ok(mine)
}

/// Opens one of iceoryx2's shared directories to the users `access` admits, if this
/// user owns it. Another user's directory is left to that user: if it is not open, that
/// user's domain was not started to allow others, and iceoryx2 refuses this process's
/// nodes and ports with its own error.
fn widen_shared_dir(dir: &Path, access: ShmAccess, me: u32) -> Result<(), AccessError> {
    let meta = match std::fs::metadata(dir) {
        Ok(m) => m,
        // iceoryx2 creates it with the first node; the next pass widens it.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(source) => return Err(AccessError::CannotReadDir { dir: dir.to_owned(), source }),
    };
    let mode = meta.permissions().mode() & 0o7777;
    let wanted = mode | access.widen_dir();
    if wanted == mode {
        return Ok(());
    }
    if meta.uid() != me {
        tracing::debug!(dir = %dir.display(), mode = format!("{mode:o}"),
            "iceoryx2's directory belongs to another user; it opens it or not");
        return Ok(());
    }
    set_mode(dir, wanted)
}

/// Widens one file of the domain if this user owns it and iceoryx2 finished it:
/// `Ok(true)` if its mode changed.
fn widen_file(
    path: &Path,
    meta: &std::fs::Metadata,
    access: ShmAccess,
    me: u32,
) -> Result<bool, AccessError> {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    if meta.uid() != me || meta.is_dir() {
        return Ok(false);
    }
    let mode = meta.permissions().mode() & 0o7777;
    let owner = mode & 0o700;
    // Still being initialised: iceoryx2 reads "finished" from these modes (a static
    // configuration drops to read-only, a dynamic one gains the owner's read bit).
    let initialising = owner & 0o400 == 0 || (name.ends_with(".service") && owner & 0o200 != 0);
    if initialising {
        return Ok(false);
    }
    let wanted = mode | access.widen(owner);
    if wanted == mode {
        return Ok(false);
    }
    match set_mode(path, wanted) {
        Ok(()) => Ok(true),
        Err(AccessError::CannotChangeMode { source, .. })
            if source.kind() == std::io::ErrorKind::NotFound =>
        {
            Ok(false)
        }
        Err(e) => Err(e),
    }
}

fn set_mode(path: &Path, mode: u32) -> Result<(), AccessError> {
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(|source| AccessError::CannotChangeMode { path: path.to_owned(), source })
}

fn effective_uid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// Keeps a domain's files as open as its [`ShmAccess`] says, for as long as it lives:
/// a thread that runs [`widen_domain`] within 100 ms of a change to the directories
/// holding the domain's files, and every second regardless (listing iceoryx2's
/// services and nodes again only when their directories changed, or every 5 s). A failure is logged once, when it
/// starts (and again when a different one follows); the thread stops when dropped.
#[derive(Debug)]
pub struct Widener {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Widener {
    /// Starts widening `domain`'s files as `access` admits; `None` for
    /// [`ShmAccess::Private`], which needs nothing done. A pass that fails is logged
    /// (once, until another failure follows) and tried again: in a process of a second
    /// user, iceoryx2's directories may not be readable because the domain is not
    /// open, and iceoryx2's own refusal is what that process should report. A
    /// coordinator that must not start with its domain closed runs [`widen_domain`]
    /// first.
    pub fn start(domain: &str, access: ShmAccess) -> Result<Option<Self>, AccessError> {
        if access == ShmAccess::Private {
            return Ok(None);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let (d, s) = (domain.to_owned(), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("esgm-shm-access".into())
            .spawn(move || {
                let mut last_error = None::<String>;
                let mut scan = DomainScan::new(&d);
                let mut last_pass: Option<(DirTimes, Instant)> = None;
                while !s.load(Ordering::Relaxed) {
                    if last_pass.is_some() {
                        std::thread::sleep(WIDEN_EVERY);
                    }
                    let times = DirTimes::now();
                    if last_pass.as_ref().is_some_and(|(t, at)| {
                        t.settled() && *t == times && at.elapsed() < WIDEN_ALL_EVERY
                    }) {
                        continue;
                    }
                    last_pass = Some((times, Instant::now()));
                    match scan.widen(access) {
                        Ok(_) => last_error = None,
                        Err(e) => {
                            let line = crate::process::one_line(error_chain(&e));
                            if last_error.as_deref() != Some(line.as_str()) {
                                tracing::warn!(domain = %d, %access, error = %line,
                                    "cannot open the domain's shared memory to others");
                                last_error = Some(line);
                            }
                        }
                    }
                }
            })
            .map_err(AccessError::CannotStartThread)?;
        Ok(Some(Self { stop, thread: Some(thread) }))
    }
}

/// The modification times of the directories iceoryx2 adds the domain's files to, and
/// when they were read.
#[derive(Debug)]
struct DirTimes {
    times: Vec<Option<SystemTime>>,
    read_at: SystemTime,
}

impl DirTimes {
    fn now() -> Self {
        let read_at = SystemTime::now();
        let [root, nodes, services] = shared_dirs();
        let times = [PathBuf::from(SHM_DIR), root, nodes, services]
            .iter()
            // Unreadable counts as changed: the next pass says why.
            .map(|d| std::fs::metadata(d).and_then(|m| m.modified()).ok())
            .collect();
        Self { times, read_at }
    }

    /// True if no directory changed within [`SETTLE`] before they were read: a change
    /// in the same (coarse) tick after reading would not have moved a time.
    fn settled(&self) -> bool {
        self.times
            .iter()
            .all(|t| t.is_some_and(|t| self.read_at.duration_since(t).is_ok_and(|d| d > SETTLE)))
    }
}

impl PartialEq for DirTimes {
    fn eq(&self, other: &Self) -> bool {
        self.times == other.times
    }
}

impl Drop for Widener {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            if thread.join().is_err() {
                tracing::warn!("the shared-memory access thread panicked");
            }
        }
    }
}

fn error_chain<'a>(
    e: &'a (dyn std::error::Error + 'static),
) -> Vec<&'a (dyn std::error::Error + 'static)> {
    std::iter::successors(Some(e), |e| e.source()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_mirrors_owner_bits_only() {
        assert_eq!(ShmAccess::Private.widen(0o600), 0);
        assert_eq!(ShmAccess::Group.widen(0o600), 0o060);
        assert_eq!(ShmAccess::Others.widen(0o600), 0o066);
        assert_eq!(ShmAccess::Others.widen(0o400), 0o044);
        assert_eq!(ShmAccess::Others.widen(0o700), 0o066, "never execute");
    }

    #[test]
    fn access_round_trips_and_rejects_typos() {
        for a in [ShmAccess::Private, ShmAccess::Group, ShmAccess::Others] {
            assert_eq!(a.as_str().parse::<ShmAccess>().ok(), Some(a));
        }
        assert!(matches!("other".parse::<ShmAccess>(), Err(AccessError::Unknown { .. })));
    }

    #[test]
    fn services_of_a_domain_and_its_namespaces() {
        assert!(belongs_to("lab", "esgm/lab/traj/x"));
        assert!(belongs_to("lab", "esgm/lab.g12/traj/x"));
        assert!(belongs_to("lab", "esgm/lab:inbox/traj/x"));
        assert!(belongs_to("lab", "esgm/lab.g0:add/traj/x"));
        assert!(!belongs_to("lab", "esgm/lab:add.g0/traj/x"));
        assert!(!belongs_to("lab", "esgm/lab.g/traj/x"));
        assert!(belongs_to("lab", "esgm/lab/control"));
        assert!(!belongs_to("lab", "esgm/lab2/traj/x"));
        assert!(!belongs_to("lab", "esgm/lab.gx/traj/x"));
        assert!(!belongs_to("lab", "esgm/lab-b/traj/x"));
        assert!(!belongs_to("lab", "other/lab/traj/x"));
    }

    #[test]
    fn ids_match_whole_parts_of_names() {
        let ids = DomainIds { tokens: ["123".to_owned()].into_iter().collect(), nodes: vec![] };
        assert!(ids.matches("iox2_abc_123.data"));
        assert!(ids.matches("iox2_abc_9_123.connection"));
        assert!(ids.matches("iox2_abc_123__mgmt.data"));
        assert!(!ids.matches("iox2_abc_1234.data"));
    }
}
