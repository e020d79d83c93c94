//! A ping-pong between two programs that are not `esgm-bench` (the C++ program of the
//! `cpp-*` rows, the C program of the `iceoryx-c-*` rows), run and watched together.
//!
//! The `ping` program measures and prints its figures on stdout; the `pong` program
//! answers it and may print notes. Neither can tell that the other died (a subscriber
//! just waits), so this process watches both: a pong that exits with a failure ends the
//! pair at once with its stderr, instead of leaving ping to time out; every wait here
//! has a deadline, and a program still running when the pair ends is killed.

use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};

use super::ros1_peer::{Guard, read_all, which};
use crate::peer_process::FINISH_TIMEOUT;
use crate::scenario::Context;

/// What the two programs printed on stdout.
#[derive(Debug)]
pub struct Printed {
    /// The measuring side's.
    pub ping: String,
    /// The answering side's.
    pub pong: String,
}

/// The cores of the two programs under `--pin` (ping on the measuring core, pong on
/// the peer core), as `taskset` arguments; none without it.
pub fn cores(ctx: &Context) -> anyhow::Result<(Option<String>, Option<String>)> {
    let Some(pin) = ctx.pinning() else { return Ok((None, None)) };
    if which("taskset").is_none() {
        bail!("--pin needs taskset (util-linux) to pin the programs of a pair");
    }
    Ok((Some(pin.measuring_core().to_string()), Some(pin.peer_core().to_string())))
}

/// `program`, after `prefix` (a wrapper and its arguments, such as `nsenter …`), pinned
/// to `core` with `taskset` when given. A child inherits the affinity of the (pinned)
/// measuring thread, so without `taskset` under `--pin` both programs would share the
/// measuring core.
pub fn command(prefix: &[&str], program: &Path, core: Option<&str>) -> Command {
    let mut words: Vec<OsString> = Vec::new();
    if let Some(core) = core {
        words.extend(["taskset", "-c", core].map(OsString::from));
    }
    words.extend(prefix.iter().map(OsString::from));
    words.push(program.into());
    let mut c = Command::new(&words[0]);
    c.args(&words[1..]);
    c
}

/// A started program and the threads reading its output.
struct Running {
    what: String,
    guard: Guard,
    stdout: JoinHandle<String>,
    stderr: JoinHandle<String>,
}

impl Running {
    fn start(what: &str, mut command: Command) -> anyhow::Result<Self> {
        command.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
        let mut guard =
            Guard::new(command.spawn().with_context(|| format!("starting the {what}"))?);
        let stdout = read_all(guard.child()?.stdout.take().context("a child's stdout")?);
        let stderr = read_all(guard.child()?.stderr.take().context("a child's stderr")?);
        Ok(Self { what: what.to_owned(), guard, stdout, stderr })
    }

    fn exited(&mut self) -> anyhow::Result<Option<ExitStatus>> {
        let what = &self.what;
        self.guard.child()?.try_wait().with_context(|| format!("waiting for the {what}"))
    }

    /// Its stdout, once it exited with success; else an error with its stderr.
    fn output(self, status: ExitStatus) -> anyhow::Result<String> {
        if status.success() {
            // What was read before a read error is all there is.
            return Ok(self.stdout.join().unwrap_or_default());
        }
        Err(self.failure(status))
    }

    /// The error of a program that exited with `status`, with its stderr.
    fn failure(self, status: ExitStatus) -> anyhow::Error {
        let stderr = self.stderr.join().unwrap_or_default();
        anyhow!("the {} failed ({status}): {}", self.what, stderr.trim())
    }
}

/// Starts `ping`, then `pong` (both named `what` in errors: `C++`, `iceoryx`), and
/// waits for ping to finish within `timeout`, then for pong within
/// [`FINISH_TIMEOUT`]. Either failing fails the pair with its stderr.
pub fn run(what: &str, ping: Command, pong: Command, timeout: Duration) -> anyhow::Result<Printed> {
    let mut ping = Running::start(&format!("{what} ping process"), ping)?;
    let mut pong = Running::start(&format!("{what} pong process"), pong)?;
    let started = Instant::now();
    let ping_status = loop {
        if let Some(status) = ping.exited()? {
            break status;
        }
        if let Some(status) = pong.exited()? {
            if !status.success() {
                // ping is killed when its guard drops.
                return Err(pong.failure(status));
            }
        }
        if started.elapsed() > timeout {
            bail!("the {what} pair did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let ping_out = ping.output(ping_status)?;
    let pong_status = pong.guard.wait(&pong.what, FINISH_TIMEOUT)?;
    let pong_out = pong.output(pong_status)?;
    Ok(Printed { ping: ping_out, pong: pong_out })
}
