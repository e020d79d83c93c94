//! A private RouDi (classic iceoryx's daemon) for one pair of the `iceoryx-c-*` rows.
//!
//! iceoryx 2.0 has one RouDi per machine: its management shared memory (`/dev/shm`)
//! and its socket and lock (`/tmp`) have fixed names. So that a run neither disturbs
//! a RouDi a user runs nor trips over one left behind, each pair gets a RouDi in a mount
//! namespace of its own (`unshare --mount`, root only): a fresh tmpfs on `/dev/shm` and
//! a directory of this run bound on `/tmp`, which also holds its configuration (a pool
//! of 1 MiB chunks for the image, which the built-in one has too few of). The pair's
//! programs join that namespace (`nsenter --mount`). Dropping the RouDi stops it
//! (SIGTERM, then SIGKILL) and removes its directory; its shared memory goes with the
//! namespace.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use super::ros1_peer::{Guard, which};

/// RouDi's mempools: the pair's signals, the small payload, the image (921,600 bytes
/// plus the chunk's headers).
const CONFIG: &str = "[general]\nversion = 1\n\n[[segment]]\n\n\
                      [[segment.mempool]]\nsize = 128\ncount = 1024\n\n\
                      [[segment.mempool]]\nsize = 1024\ncount = 1024\n\n\
                      [[segment.mempool]]\nsize = 1048576\ncount = 64\n";
/// Mounts the namespace's `/tmp` (`$0`) and `/dev/shm`, then becomes RouDi.
const SCRIPT: &str = "mount --bind \"$0\" /tmp && mount -t tmpfs -o size=256m tmpfs /dev/shm \
                      && exec iox-roudi -c /tmp/roudi.toml -l warning";
/// What RouDi prints once clients can register.
const READY: &str = "RouDi is ready for clients";
/// How long RouDi may take to be ready, and to stop.
const PATIENCE: Duration = Duration::from_secs(10);

/// A running private RouDi (see the module docs).
pub(super) struct Roudi {
    dir: PathBuf,
    pid: u32,
    process: Guard,
}

impl Roudi {
    /// Starts one (under `taskset -c cores` when given) and waits until it is ready.
    pub fn start(cores: Option<&str>) -> anyhow::Result<Self> {
        for tool in ["iox-roudi", "unshare", "nsenter"] {
            if which(tool).is_none() {
                bail!("{tool} is not installed");
            }
        }
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("esgm-bench-iox-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        std::fs::write(dir.join("roudi.toml"), CONFIG).context("writing RouDi's configuration")?;
        let log = std::fs::File::create(dir.join("roudi.log")).context("creating RouDi's log")?;
        let err = log.try_clone().context("RouDi's log")?;
        let mut command = match cores {
            Some(cores) => {
                let mut c = Command::new("taskset");
                c.args(["-c", cores, "unshare"]);
                c
            }
            None => Command::new("unshare"),
        };
        command
            .args(["--mount", "--propagation", "private", "--", "sh", "-c", SCRIPT])
            .arg(&dir)
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(err);
        let child = match command.spawn() {
            Ok(child) => child,
            Err(e) => {
                remove(&dir);
                return Err(e).context("starting unshare for RouDi");
            }
        };
        let pid = child.id();
        let mut this = Self { dir, pid, process: Guard::new(child) };
        this.wait_ready()?;
        Ok(this)
    }

    fn wait_ready(&mut self) -> anyhow::Result<()> {
        let started = Instant::now();
        loop {
            let log = std::fs::read_to_string(self.dir.join("roudi.log")).unwrap_or_default();
            if log.contains(READY) {
                return Ok(());
            }
            if let Some(status) = self.process.child()?.try_wait().context("waiting for RouDi")? {
                bail!(
                    "RouDi could not start in a mount namespace of its own ({status}; needs root \
                     for unshare --mount): {}",
                    log.trim()
                );
            }
            if started.elapsed() > PATIENCE {
                bail!("RouDi was not ready within {PATIENCE:?}: {}", log.trim());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The words that run a program in RouDi's namespace: `nsenter … --`.
    pub fn enter(&self) -> [String; 5] {
        ["nsenter".into(), "-t".into(), self.pid.to_string(), "--mount".into(), "--".into()]
    }
}

impl Drop for Roudi {
    fn drop(&mut self) {
        // RouDi cleans up on SIGTERM; the guard kills it if it does not stop in time.
        if let Ok(pid) = i32::try_from(self.pid) {
            // SAFETY: kill(2) with a pid this process started and has not reaped.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        }
        if let Err(e) = self.process.wait("RouDi", PATIENCE) {
            eprintln!("esgm-bench: {e:#}; killing it");
        }
        self.process = Guard::none();
        remove(&self.dir);
    }
}

fn remove(dir: &Path) {
    if let Err(e) = std::fs::remove_dir_all(dir) {
        eprintln!("esgm-bench: cannot remove {}: {e}", dir.display());
    }
}
