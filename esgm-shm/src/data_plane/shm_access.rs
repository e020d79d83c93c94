//! Who may open a domain's shared memory, and the files esgm keeps in `/dev/shm`
//! beside iceoryx2's (wake words, kept histories) that belong to a domain. Data-plane
//! facts: the files that carry samples are made with these modes and removed by these
//! rules. Widening iceoryx2's own files for other users is the process layer's
//! (`process::access`), which builds on this.

use crate::data_plane::service_name::SERVICE_PREFIX;

/// Who may read and write a domain's shared memory.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum ShmAccess {
    /// Only the user that runs the domain (iceoryx2's own modes, `0600`/`0400`).
    #[default]
    Private,
    /// The owner's group too (`0660`/`0440`): for processes of several users that
    /// share a primary group, such as a robot's service accounts.
    Group,
    /// Every user of the host (`0666`/`0444`). Any local process can then publish
    /// into the domain's services; use it only on a host whose users are all trusted.
    Others,
}

impl ShmAccess {
    /// The value of `ESGM_SHM_ACCESS` (`process::access::ACCESS_ENV`) for this access.
    pub fn as_str(self) -> &'static str {
        match self {
            ShmAccess::Private => "private",
            ShmAccess::Group => "group",
            ShmAccess::Others => "others",
        }
    }

    /// The mode of a file esgm makes itself in the domain's shared memory (a
    /// trajectory's [`crate::data_plane::wake_word`]): read and write for the owner and for the
    /// classes this access admits.
    pub(crate) fn file_mode(self) -> u32 {
        0o600 | self.widen(0o600)
    }

    /// The mode bits to add to a file whose owner bits are `owner` (`0o600`, `0o400`,
    /// …): the owner's read and write bits, mirrored to the classes this access
    /// admits. Execute bits are never added to files.
    pub(crate) fn widen(self, owner: u32) -> u32 {
        let rw = owner & 0o600;
        match self {
            ShmAccess::Private => 0,
            ShmAccess::Group => rw >> 3,
            ShmAccess::Others => (rw >> 3) | (rw >> 6),
        }
    }

    /// The mode bits to add to iceoryx2's shared directories, so the admitted users
    /// can create their own nodes and services in them; sticky, as `/tmp` is, so
    /// nobody removes another user's files.
    pub(crate) fn widen_dir(self) -> u32 {
        match self {
            ShmAccess::Private => 0,
            ShmAccess::Group => 0o1070,
            ShmAccess::Others => 0o1077,
        }
    }
}

impl std::fmt::Display for ShmAccess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Removes the files of `dir` named `<prefix><namespace>@<rest>` whose namespace is
/// `domain` or one of its derived namespaces ([`belongs_to`]): the files esgm keeps in
/// `/dev/shm` beside iceoryx2's (wake words, kept histories), at the domain's end.
/// Returns how many were removed.
pub(crate) fn remove_files_of(dir: &std::path::Path, prefix: &str, domain: &str) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(namespace) = name
            .to_str()
            .and_then(|n| n.strip_prefix(prefix))
            .and_then(|n| n.split_once('@'))
            .map(|(namespace, _)| namespace)
        else {
            continue;
        };
        // The domain's rule for services, applied to the file's namespace.
        if !belongs_to(domain, &format!("{SERVICE_PREFIX}/{namespace}/file")) {
            continue;
        }
        match std::fs::remove_file(entry.path()) {
            Ok(()) => removed += 1,
            Err(e) => tracing::debug!(path = %entry.path().display(), error = %e,
                "cannot remove a file of the domain"),
        }
    }
    removed
}

/// True if the service or node `name` is one of `domain`'s: `esgm/<domain>/…`, or one
/// of the domain's derived namespaces, `esgm/<domain>.g<generation>/…` (a mirrored
/// trajectory's generation) and `esgm/<domain>:<kind>/…` (inboxes, joins).
pub(crate) fn belongs_to(domain: &str, name: &str) -> bool {
    let Some(rest) = name.strip_prefix(SERVICE_PREFIX).and_then(|r| r.strip_prefix('/')) else {
        return false;
    };
    let Some(rest) = rest.strip_prefix(domain) else { return false };
    let Some((mut namespace, _)) = rest.split_once('/') else { return false };
    // Each suffix once at most, generation first: `.g3`, `:add`, `.g3:add`.
    let mut part = |tag: &str, allowed: fn(&u8) -> bool| {
        let Some(tail) = namespace.strip_prefix(tag) else { return true };
        let len = tail.bytes().take_while(allowed).count();
        namespace = &tail[len..];
        len > 0
    };
    part(".g", u8::is_ascii_digit) && part(":", u8::is_ascii_lowercase) && namespace.is_empty()
}
