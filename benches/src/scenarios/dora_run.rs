//! One dora ping-pong run for [`super::dora_peer`]: the dataflow file, `dora run`,
//! its deadline and its teardown, and the figures the ping node wrote.

use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use super::ros1_peer::{command, read_all, which};
use crate::latency::Latency;
use crate::wait_mode::WaitMode;

/// How long one `dora run` may take, start-up and teardown included.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);
/// How long `dora run` has to stop its nodes after a Ctrl-C before it is killed (its
/// nodes then end themselves: they watch for their `dora run` parent).
const STOP_GRACE: Duration = Duration::from_secs(10);

/// What one run measures.
#[derive(Debug)]
pub struct Pair<'a> {
    /// The `dora` CLI.
    pub cli: &'a Path,
    /// The node binary (both roles).
    pub node: &'a Path,
    /// Spin or block, in both nodes.
    pub mode: WaitMode,
    /// The payload's size.
    pub bytes: usize,
    /// Measured hops.
    pub samples: u64,
    /// Unmeasured hops first.
    pub warmup: u64,
    /// (measuring, peer) cores under `--pin`.
    pub cores: Option<(usize, usize)>,
}

/// Runs the pair once in a temporary folder (dora's logs go there too) and returns
/// ping's figures; an error if dora fails, a node fails, or the run passes its
/// deadline (dora is then stopped, killed if need be).
pub fn run(pair: &Pair) -> anyhow::Result<Latency> {
    let dir = tempfile::Builder::new().prefix("esgm-bench-dora-").tempdir().context("temp dir")?;
    let out = dir.path().join("ping.txt");
    let dataflow = dir.path().join("dataflow.yml");
    std::fs::write(&dataflow, descriptor(pair, &out)).context("writing the dataflow")?;
    let both = match pair.cores {
        Some((m, p)) if which("taskset").is_some() => Some(format!("{m},{p}")),
        Some(_) => bail!("--pin needs taskset (util-linux) to place dora's daemon"),
        None => None,
    };
    let mut dora = command(pair.cli, both);
    dora.arg("run")
        .arg(&dataflow)
        .args(["--log-level", "warn"])
        .current_dir(dir.path())
        // A failure's message, not dora's backtrace of it.
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LIB_BACKTRACE", "0")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut dora = Running(dora.spawn().context("starting `dora run`")?);
    let stdout = read_all(dora.0.stdout.take().context("dora's stdout")?);
    let stderr = read_all(dora.0.stderr.take().context("dora's stderr")?);
    let status = dora.wait(RUN_TIMEOUT);
    let said = |h: std::thread::JoinHandle<String>| h.join().unwrap_or_default();
    let said = format!("{}{}", said(stdout), said(stderr));
    let status = status.with_context(|| tail(&said))?;
    if !status.success() {
        bail!("`dora run` failed ({status}): {}", tail(&said));
    }
    let text = std::fs::read_to_string(&out)
        .with_context(|| format!("the ping node wrote no figures; dora said: {}", tail(&said)))?;
    let mut latency = Latency::new()?;
    for line in text.lines() {
        let ns = line.strip_prefix("r ").and_then(|v| v.trim().parse::<u64>().ok());
        latency.record_ns(ns.with_context(|| format!("a bad line from ping: {line:?}"))?);
    }
    if latency.is_empty() {
        bail!("the ping node wrote no figures");
    }
    Ok(latency)
}

/// The dataflow: ping's output to pong's input and back, each node's settings in its
/// environment (the node's docs list them). Paths are quoted as YAML double-quoted
/// scalars (JSON strings are those).
fn descriptor(pair: &Pair, out: &Path) -> String {
    let quote = |p: &Path| serde_json::Value::from(p.display().to_string()).to_string();
    let wait = if pair.mode == WaitMode::Spin { "spin" } else { "block" };
    let core =
        |c: Option<usize>| c.map_or(String::new(), |c| format!("\n      ESGM_DORA_CORE: \"{c}\""));
    let (ping_core, pong_core) = (pair.cores.map(|c| c.0), pair.cores.map(|c| c.1));
    format!(
        "nodes:
  - id: ping
    path: {node}
    inputs:
      answer: pong/out
    outputs:
      - out
    env:
      ESGM_DORA_ROLE: ping
      ESGM_DORA_WAIT: {wait}
      ESGM_DORA_BYTES: \"{bytes}\"
      ESGM_DORA_SAMPLES: \"{samples}\"
      ESGM_DORA_WARMUP: \"{warmup}\"
      ESGM_DORA_OUT: {out}{ping_core}
  - id: pong
    path: {node}
    inputs:
      question: ping/out
    outputs:
      - out
    env:
      ESGM_DORA_ROLE: pong
      ESGM_DORA_WAIT: {wait}{pong_core}
",
        node = quote(pair.node),
        bytes = pair.bytes,
        samples = pair.samples,
        warmup = pair.warmup,
        out = quote(out),
        ping_core = core(ping_core),
        pong_core = core(pong_core),
    )
}

/// What dora printed that explains a failure, for an error message: the nodes' own
/// error lines (dora quotes a failed node's stderr), else dora's errors, else its last
/// lines.
fn tail(said: &str) -> String {
    let lines: Vec<&str> = said.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    let node: Vec<&str> =
        lines.iter().copied().filter(|l| l.starts_with("esgm-dora-pingpong:")).collect();
    if !node.is_empty() {
        return node.join(" | ");
    }
    let errors: Vec<&str> = lines.iter().copied().filter(|l| l.contains("ERROR")).collect();
    let chosen = if errors.is_empty() { &lines } else { &errors };
    chosen[chosen.len().saturating_sub(8)..].join(" | ")
}

/// `dora run`, stopped when dropped before it exited: Ctrl-C first (dora stops its
/// nodes and daemon), then a kill past [`STOP_GRACE`].
struct Running(Child);

impl Running {
    /// Waits for the exit, at most `timeout`.
    fn wait(&mut self, timeout: Duration) -> anyhow::Result<std::process::ExitStatus> {
        let started = Instant::now();
        loop {
            if let Some(status) = self.0.try_wait().context("waiting for `dora run`")? {
                return Ok(status);
            }
            if started.elapsed() > timeout {
                bail!("`dora run` did not finish within {timeout:?} (stopped)");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if !matches!(self.0.try_wait(), Ok(None)) {
            return;
        }
        if let Ok(pid) = libc::pid_t::try_from(self.0.id()) {
            // SAFETY: kill(2) on our own child's pid, which has not been reaped (it is
            // still running), so the pid is not reused.
            unsafe { libc::kill(pid, libc::SIGINT) };
        }
        if self.wait(STOP_GRACE).is_err() {
            if let Err(e) = self.0.kill() {
                eprintln!("esgm-bench: cannot kill `dora run`: {e}");
            }
            if let Err(e) = self.0.wait() {
                eprintln!("esgm-bench: cannot reap `dora run`: {e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_is_explained_by_the_node_s_own_line() {
        let said = "ping: DEBUG building node\nNode `ping` failed: exited with code 2\n\
                    ----\nesgm-dora-pingpong: answer to 7: nothing received within 20s\n\
                    ----\n  29: __libc_start_main_impl\n  30: _start\n";
        assert_eq!(tail(said), "esgm-dora-pingpong: answer to 7: nothing received within 20s");
        assert_eq!(tail("a\nb ERROR c\nd\n"), "b ERROR c");
        assert_eq!(tail("a\nb\n"), "a | b");
    }

    #[test]
    fn the_descriptor_names_both_roles_and_pins_each_node() {
        let pair = Pair {
            cli: Path::new("/x/dora"),
            node: Path::new("/a b/node"),
            mode: WaitMode::Spin,
            bytes: 120,
            samples: 5,
            warmup: 1,
            cores: Some((0, 1)),
        };
        let text = descriptor(&pair, Path::new("/t/ping.txt"));
        assert!(text.contains("path: \"/a b/node\""), "{text}");
        assert!(text.contains("ESGM_DORA_ROLE: ping"), "{text}");
        assert!(text.contains("ESGM_DORA_ROLE: pong"), "{text}");
        assert!(text.contains("ESGM_DORA_BYTES: \"120\""), "{text}");
        assert!(text.contains("ESGM_DORA_OUT: \"/t/ping.txt\""), "{text}");
        assert_eq!(text.matches("ESGM_DORA_CORE").count(), 2, "{text}");
        assert!(text.contains("ESGM_DORA_CORE: \"1\""), "{text}");
    }
}
