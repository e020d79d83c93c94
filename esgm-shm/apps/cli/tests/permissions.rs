//! Who can read and write a domain's shared memory, end to end: a domain is its user's
//! alone unless started with `--allow-others`; a second user's process publishes into
//! it only then. Real processes, unique domains and state directories, a watchdog on
//! every command. The second-user half needs root (to run processes as two other
//! users, created if missing: `esgm-other` publishes, `esgm-owner` runs a domain) and
//! says loudly when it is skipped.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use common::{ESGM, Output, capability, finish};
use esgm_shm::process::access::{ACCESS_ENV, domain_files, shared_dirs};

const TUTORIAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tutorial.toml");

/// The second user the tests run processes as (created if missing).
const OTHER_USER: &str = "esgm-other";

/// One system at a time: each is several processes on a 2-core machine, and the
/// second-user test opens iceoryx2's shared directories while it runs.
static ONE_SYSTEM: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_system() -> std::sync::MutexGuard<'static, ()> {
    // This process lists iceoryx2's files too; its "no config file" warning is not news.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    ONE_SYSTEM.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A test's domain and state home, stopped and removed when the test ends; run by
/// this process's user, or by `user` through `runuser` (with the binary `esgm`).
struct Domain {
    name: String,
    state_home: PathBuf,
    user: Option<(&'static str, PathBuf)>,
}

impl Domain {
    fn new(prefix: &str) -> Self {
        let name = esgm_shm::unique_domain(prefix);
        let state_home = std::env::temp_dir().join(format!("esgm-test-state-{name}"));
        Self { name, state_home, user: None }
    }

    fn run_by(mut self, user: &'static str, esgm: &Path) -> Self {
        self.user = Some((user, esgm.to_owned()));
        self
    }

    /// `esgm --domain d args…`, as the domain's user.
    fn command(&self, args: &[&str]) -> Command {
        let state_home = format!("XDG_STATE_HOME={}", self.state_home.display());
        let mut c = match &self.user {
            None => Command::new(ESGM),
            Some((user, esgm)) => {
                let mut c = Command::new("runuser");
                c.args(["-u", user, "--", "env", &state_home]).arg(esgm).current_dir("/");
                c
            }
        };
        c.args(["--domain", &self.name])
            .args(args)
            .env("XDG_STATE_HOME", &self.state_home)
            .env_remove("ESGM_STATE_DIR")
            .env_remove(ACCESS_ENV)
            .stdin(Stdio::null());
        c
    }

    fn state_dir(&self) -> PathBuf {
        self.state_home.join("esgm").join(&self.name)
    }

    /// Runs `esgm --domain d args…` as this user, killing it after a minute.
    fn run(&self, args: &[&str]) -> Output {
        let child =
            self.command(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
        finish(child, Duration::from_secs(60), &args.join(" "))
    }

    fn ok(&self, args: &[&str]) -> String {
        let o = self.run(args);
        assert_eq!(
            o.code,
            Some(0),
            "`esgm {}` failed:\n{}\n{}",
            args.join(" "),
            o.stdout,
            o.stderr
        );
        o.stdout
    }

    /// Polls `esgm latest traj` until it answers, or fails after `limit`.
    fn wait_for_sample(&self, traj: &str, limit: Duration) {
        let deadline = Instant::now() + limit;
        loop {
            let o = self.run(&["latest", traj]);
            if o.code == Some(0) && !o.stdout.trim().is_empty() {
                return;
            }
            assert!(Instant::now() < deadline, "no sample in `{traj}`: {}{}", o.stdout, o.stderr);
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Domain {
    fn drop(&mut self) {
        let down = self.command(&["down"]).stdout(Stdio::null()).stderr(Stdio::null()).status();
        if let Err(e) = down {
            eprintln!("cannot run `esgm down`: {e}");
        }
        if let Err(e) = std::fs::remove_dir_all(&self.state_home) {
            if e.kind() != std::io::ErrorKind::NotFound {
                eprintln!("cannot remove {}: {e}", self.state_home.display());
            }
        }
    }
}

fn mode(path: &Path) -> Option<(u32, bool)> {
    match std::fs::symlink_metadata(path) {
        Ok(m) => Some((m.permissions().mode() & 0o7777, m.is_dir())),
        // A port closed since the listing.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => panic!("cannot stat {}: {e}", path.display()),
    }
}

/// The kind of an iceoryx2 file, from its suffix (`data`, `connection`, `service`, …).
fn kind(path: &Path) -> String {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    match name.rsplit_once('.') {
        Some((_, suffix)) => suffix.to_owned(),
        None if path.is_dir() => "node directory".to_owned(),
        None => name.to_owned(),
    }
}

/// A file has no bit for its group or others; a directory (iceoryx2 makes node
/// directories 0750) none for others and no group write.
fn private(mode: u32, is_dir: bool) -> bool {
    if is_dir { mode & 0o027 == 0 } else { mode & 0o077 == 0 }
}

#[test]
fn a_domain_is_private_to_its_user_by_default() {
    let _one = one_system();
    let started = SystemTime::now();
    let d = Domain::new("permissions_private");
    d.ok(&["up", "--detach"]);
    d.ok(&["apply", TUTORIAL]);
    // Data flowing through units: data segments, connections and events exist.
    d.wait_for_sample("driving_direction", Duration::from_secs(90));

    let files = domain_files(&d.name).expect("cannot list the domain's files");
    assert!(!files.shared.is_empty(), "found no service or port file of `{}`", d.name);
    assert!(!files.nodes.is_empty(), "found no node file of `{}`", d.name);
    let mut seen = std::collections::BTreeMap::<String, std::collections::BTreeSet<String>>::new();
    for path in files.shared.iter().chain(&files.nodes) {
        let Some((mode, is_dir)) = mode(path) else { continue };
        assert!(private(mode, is_dir), "{} is {mode:o}", path.display());
        seen.entry(kind(path)).or_default().insert(format!("{mode:o}"));
    }
    eprintln!("modes of the files of `{}`: {seen:?}", d.name);
    for wanted in ["service", "dynamic", "data", "connection", "event", "node_monitor", "details"] {
        assert!(seen.contains_key(wanted), "no `{wanted}` file found among {seen:?}");
    }

    // The same without trusting the domain listing: every iceoryx2 file this user made
    // since the test started (other domains' too), but the host-wide node-id counter
    // iceoryx2 shares with every user by design (0666, no data of any domain).
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    let [root, nodes, services] = shared_dirs();
    let mut checked = 0;
    for dir in [Path::new("/dev/shm"), &root, &nodes, &services] {
        for entry in std::fs::read_dir(dir).expect("cannot list iceoryx2's files") {
            let entry = entry.expect("cannot list iceoryx2's files");
            let name = entry.file_name().to_string_lossy().into_owned();
            let Ok(meta) = entry.metadata() else { continue };
            let new = meta.modified().is_ok_and(|t| t >= started);
            if !name.starts_with("iox2_") || name.ends_with(".global_mgmt") || meta.uid() != me {
                continue;
            }
            if new && !meta.is_dir() {
                let mode = meta.permissions().mode() & 0o7777;
                assert!(private(mode, false), "{} is {mode:o}", entry.path().display());
                checked += 1;
            }
        }
    }
    assert!(checked > 0, "found no iceoryx2 file made since the test started");

    // The registry and the processes' logs: the state directory is the user's alone.
    let (state_mode, _) = mode(&d.state_dir()).expect("no state directory");
    assert_eq!(state_mode & 0o077, 0, "state directory is {state_mode:o}");
}

#[test]
fn allow_group_opens_the_domain_to_the_group_only() {
    let _one = one_system();
    let _dirs = RestoreModes::of(shared_dirs());
    let d = Domain::new("permissions_group");
    d.ok(&["up", "--detach", "--allow-group"]);
    d.ok(&["type", "add", "Reading", "value:Double"]);
    d.ok(&["traj", "create", "reading", "--primitive", "Reading"]);
    d.ok(&["push", "reading", "value=1.5"]);
    // Within a pass or two of the coordinator's widener (every 100 ms on a change).
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let files = domain_files(&d.name).expect("cannot list the domain's files");
        assert!(!files.shared.is_empty(), "found no service or port file of `{}`", d.name);
        let modes: Vec<(PathBuf, u32)> =
            files.shared.into_iter().filter_map(|p| mode(&p).map(|(m, _)| (p, m))).collect();
        for (path, m) in &modes {
            assert_eq!(m & 0o007, 0, "{} is {m:o}: open to others", path.display());
        }
        // The group gets what the owner has (read, and write where the owner writes).
        let closed: Vec<_> =
            modes.iter().filter(|(_, m)| (m >> 3) & 0o7 != (m >> 6) & 0o6).collect();
        if closed.is_empty() {
            break;
        }
        assert!(Instant::now() < deadline, "not opened to the group: {closed:?}");
        std::thread::sleep(Duration::from_millis(200));
    }
    // Node files stay the owner's.
    for path in domain_files(&d.name).expect("cannot list the domain's files").nodes {
        if let Some((m, is_dir)) = mode(&path) {
            assert!(private(m, is_dir), "{} is {m:o}", path.display());
        }
    }
}

#[test]
fn a_second_user_publishes_only_into_a_domain_that_allows_others() {
    // Running processes as two other users (made here if missing) needs root.
    if capability::needs("root", capability::root()).is_none() {
        return;
    }
    let _one = one_system();
    ensure_user(OTHER_USER);
    ensure_user(OWNER_USER);
    let other_bin = Executable::for_user(OTHER_USER);
    let owner_bin = Executable::for_user(OWNER_USER);
    let _dirs = RestoreModes::of(shared_dirs());
    let _leftovers = RemoveFilesOf(&[OTHER_USER, OWNER_USER]);

    // Run by root, private: the second user is refused.
    let d = Domain::new("permissions_own");
    assert!(
        !publish_as_other(&d, &["up", "--detach"], &other_bin.0),
        "published into a private domain"
    );

    // Run by root, open to others: the second user publishes.
    let d = Domain::new("permissions_others");
    assert!(publish_as_other(&d, &["up", "--detach", "--allow-others"], &other_bin.0));
    let files = domain_files(&d.name).expect("cannot list the domain's files");
    let open = files.shared.iter().filter_map(|p| mode(p)).filter(|(m, _)| m & 0o004 != 0);
    assert!(open.count() > 0, "no file of `{}` is readable by others", d.name);
    drop(d);

    // Run by a user who is not root (who cannot read the second user's files unless
    // that user's process opens them), open to others. iceoryx2's shared directories
    // were made by root here: opened as an administrator of a shared host would.
    for dir in shared_dirs() {
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o1777)).unwrap();
    }
    let d = Domain::new("permissions_users").run_by(OWNER_USER, &owner_bin.0);
    assert!(publish_as_other(&d, &["up", "--detach", "--allow-others"], &other_bin.0));
}

/// The user that runs a domain in the test where its owner is not root.
const OWNER_USER: &str = "esgm-owner";

/// Starts `d` with `up`, adds a sample of its own to a new trajectory, and lets
/// [`OTHER_USER`] (with `ESGM_SHM_ACCESS=others`: the second user asks to take part;
/// only the domain decides) push another: true if it was added, false if refused (and
/// the domain's own sample is still the latest).
fn publish_as_other(d: &Domain, up: &[&str], other_esgm: &Path) -> bool {
    d.ok(up);
    d.ok(&["type", "add", "Reading", "value:Double"]);
    d.ok(&["traj", "create", "reading", "--primitive", "Reading"]);
    d.ok(&["push", "reading", "value=1.5"]);
    let o = as_user(OTHER_USER, other_esgm, &d.name, &["push", "reading", "value=7.5"]);
    let latest = d.ok(&["latest", "reading"]);
    if o.code == Some(0) {
        assert!(latest.contains("value=7.5"), "{OTHER_USER}'s sample not the latest: {latest}");
        true
    } else {
        assert!(latest.contains("value=1.5"), "the domain's sample changed: {latest}");
        // Refused for want of permission, not for another failure.
        let why = o.stderr.trim();
        assert!(
            why.contains("not open to you") || why.contains("cannot create a node"),
            "{OTHER_USER} failed otherwise: {why}"
        );
        eprintln!("{OTHER_USER} refused in `{}`: {why}", d.name);
        false
    }
}

/// Runs `esgm --domain d args…` as `user`, with `ESGM_SHM_ACCESS=others`, killing it
/// after a minute.
fn as_user(user: &str, esgm: &Path, domain: &str, args: &[&str]) -> Output {
    let child = Command::new("runuser")
        .args(["-u", user, "--", "env", &format!("{ACCESS_ENV}=others")])
        .arg(esgm)
        .args(["--domain", domain])
        .args(args)
        .current_dir("/")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot run runuser");
    finish(child, Duration::from_secs(60), &format!("{} (as {user})", args.join(" ")))
}

/// Creates `user` (a system user without a home or shell) unless it exists.
fn ensure_user(user: &str) {
    let exists = Command::new("id").arg("-u").arg(user).output().expect("cannot run id");
    if exists.status.success() {
        return;
    }
    let made = Command::new("useradd")
        .args(["--system", "--no-create-home", "--shell", "/usr/sbin/nologin", user])
        .status()
        .expect("cannot run useradd");
    assert!(made.success(), "cannot create the user {user}");
}

/// The esgm binary where `user` can run it: in place if it can, else a copy in a
/// temporary directory (removed when dropped) that everyone may read and run.
struct Executable(PathBuf, #[allow(dead_code)] Option<tempfile::TempDir>);

impl Executable {
    fn for_user(user: &str) -> Self {
        let runs = Command::new("runuser")
            .args(["-u", user, "--", "test", "-x", ESGM])
            .status()
            .expect("cannot run runuser");
        if runs.success() {
            return Self(PathBuf::from(ESGM), None);
        }
        let dir = tempfile::Builder::new().prefix("esgm-other-bin").tempdir().unwrap();
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let copy = dir.path().join("esgm");
        std::fs::copy(ESGM, &copy).unwrap();
        std::fs::set_permissions(&copy, std::fs::Permissions::from_mode(0o755)).unwrap();
        Self(copy, Some(dir))
    }
}

/// Removes, when dropped, the iceoryx2 files the test users left (a connection a
/// second user's process created stays in the sticky /dev/shm after it ends: only
/// that user or root may remove it), saying how many.
struct RemoveFilesOf(&'static [&'static str]);

impl Drop for RemoveFilesOf {
    fn drop(&mut self) {
        let uids: Vec<u32> = self.0.iter().filter_map(|u| uid_of(u)).collect();
        let [root, nodes, services] = shared_dirs();
        let mut removed = 0;
        for dir in [Path::new("/dev/shm"), &root, &nodes, &services] {
            let Ok(entries) = std::fs::read_dir(dir) else { continue };
            for entry in entries.flatten() {
                let Ok(meta) = entry.metadata() else { continue };
                if !uids.contains(&meta.uid()) {
                    continue;
                }
                let path = entry.path();
                let result = if meta.is_dir() {
                    std::fs::remove_dir_all(&path)
                } else {
                    std::fs::remove_file(&path)
                };
                match result {
                    Ok(()) => removed += 1,
                    Err(e) => eprintln!("cannot remove {}: {e}", path.display()),
                }
            }
        }
        if removed > 0 {
            eprintln!("removed {removed} iceoryx2 files the test users {:?} left", self.0);
        }
    }
}

fn uid_of(user: &str) -> Option<u32> {
    let out = Command::new("id").arg("-u").arg(user).output().ok()?;
    String::from_utf8(out.stdout).ok()?.trim().parse().ok()
}

/// Puts iceoryx2's shared directories back to their modes when dropped: a domain that
/// allows others opens them (sticky, like /tmp), and the test leaves the host as it
/// found it.
struct RestoreModes(Vec<(PathBuf, u32)>);

impl RestoreModes {
    fn of(dirs: impl IntoIterator<Item = PathBuf>) -> Self {
        Self(dirs.into_iter().filter_map(|d| mode(&d).map(|(m, _)| (d, m))).collect())
    }
}

impl Drop for RestoreModes {
    fn drop(&mut self) {
        for (dir, m) in &self.0 {
            if let Err(e) = std::fs::set_permissions(dir, std::fs::Permissions::from_mode(*m)) {
                eprintln!("cannot restore the mode of {}: {e}", dir.display());
            }
        }
    }
}
