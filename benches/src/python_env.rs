//! The Python environment of the `python-*` rows: a venv that `esgm-bench` makes and
//! owns (`target/bench-py-venv`), with the pinned packages of
//! `benches/python/requirements.txt` (iceoryx2's and Zenoh's Python packages, numpy,
//! maturin) and esgm's own package built into it from this checkout.
//!
//! It is made once per run, on first use, and reused across runs: the packages are
//! installed again only when the requirements file changed (a copy of it is kept in the
//! venv as `.esgm-requirements`, as `.ci/run` does for the test venv), while esgm's
//! package is rebuilt every run (`maturin develop`; cargo makes that a no-op when
//! nothing changed), so the rows always measure the checkout's code. A release
//! `esgm-bench` builds the package in release, a debug one (the CI smoke run) in debug,
//! which reuses what `cargo test` built for the Python tests and keeps the smoke run
//! short.
//!
//! A venv that cannot be made (no `python3`, no package registry) leaves the rows
//! unmeasured with the reason; under CI (`CI` set) it fails the run instead, so the
//! rows are never silently missing there (as the end-to-end tests treat a missing tool).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

use anyhow::{Context as _, bail};

use crate::scenarios::ros1_peer::{Guard, read_all};

/// How long installing the packages may take (a cold download of a few wheels).
const INSTALL_TIMEOUT: Duration = Duration::from_secs(900);
/// How long building esgm's package may take (a cold release build on two cores).
const BUILD_TIMEOUT: Duration = Duration::from_secs(1800);
/// How long a quick check of the venv may take.
const CHECK_TIMEOUT: Duration = Duration::from_secs(60);

/// A venv with every package the `python-*` rows import.
#[derive(Debug, Clone)]
pub struct PythonEnv {
    /// Its interpreter.
    pub python: PathBuf,
    /// The folder of the ping-pong scripts (`benches/python`).
    pub scripts: PathBuf,
}

/// The venv, made on the first call of a run (see the module docs); later calls get the
/// same result, the reason it could not be made included.
pub fn get() -> &'static Result<PythonEnv, String> {
    static ENV: OnceLock<Result<PythonEnv, String>> = OnceLock::new();
    ENV.get_or_init(|| make().map_err(|e| format!("{e:#}")))
}

/// True under CI, where a row that cannot run fails the run.
pub fn in_ci() -> bool {
    std::env::var_os("CI").is_some()
}

fn make() -> anyhow::Result<PythonEnv> {
    let benches = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let root = benches.parent().context("the benches crate has no parent folder")?;
    let scripts = benches.join("python");
    let requirements = scripts.join("requirements.txt");
    let venv = std::env::var_os("ESGM_BENCH_VENV")
        .map_or_else(|| root.join("target/bench-py-venv"), PathBuf::from);
    let python = venv.join("bin/python");
    let wanted = std::fs::read_to_string(&requirements)
        .with_context(|| format!("reading {}", requirements.display()))?;
    let marker = venv.join(".esgm-requirements");
    let current = std::fs::read_to_string(&marker).ok();
    if !python.is_file() || current.as_deref() != Some(wanted.as_str()) {
        eprintln!("\nesgm-bench: making the Python venv {} (once)", venv.display());
        if venv.exists() {
            std::fs::remove_dir_all(&venv)
                .with_context(|| format!("removing the stale venv {}", venv.display()))?;
        }
        let mut create = Command::new("python3");
        create.arg("-m").arg("venv").arg(&venv);
        run(create, "python3 -m venv", CHECK_TIMEOUT)?;
        let mut install = Command::new(&python);
        install
            .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r"])
            .arg(&requirements);
        run(install, "pip install -r benches/python/requirements.txt", INSTALL_TIMEOUT)?;
        std::fs::write(&marker, &wanted)
            .with_context(|| format!("writing {}", marker.display()))?;
    }
    let mut build = Command::new(venv.join("bin/maturin"));
    build.args(["develop", "--quiet"]);
    if !cfg!(debug_assertions) {
        build.arg("--release");
    }
    build.arg("-m").arg(root.join("esgm-shm/python/Cargo.toml")).env("VIRTUAL_ENV", &venv);
    run(build, "maturin develop (esgm's Python package)", BUILD_TIMEOUT)?;
    let mut check = Command::new(&python);
    check.args(["-c", "import esgm, iceoryx2, zenoh, numpy"]).current_dir(&scripts);
    run(check, "importing esgm, iceoryx2, zenoh and numpy", CHECK_TIMEOUT)?;
    Ok(PythonEnv { python, scripts })
}

/// Runs `command` to its end within `timeout`; fails with what it wrote on stderr.
fn run(mut command: Command, what: &str, timeout: Duration) -> anyhow::Result<()> {
    command.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = Guard::new(command.spawn().with_context(|| format!("starting {what}"))?);
    let out = read_all(child.child()?.stdout.take().context("stdout")?);
    let err = read_all(child.child()?.stderr.take().context("stderr")?);
    let status = child.wait(what, timeout)?;
    let stderr = err.join().unwrap_or_default();
    let stdout = out.join().unwrap_or_default();
    if !status.success() {
        bail!("{what} failed ({status}): {}", tail(&format!("{stdout}\n{stderr}")));
    }
    Ok(())
}

/// The last lines of a tool's output: where its error is.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(6)..].join(" | ")
}

#[cfg(test)]
mod tests {
    use super::tail;

    #[test]
    fn a_failure_shows_the_last_lines() {
        let text = (1..=10).map(|i| format!("line {i}")).collect::<Vec<_>>().join("\n\n");
        assert_eq!(tail(&text), "line 5 | line 6 | line 7 | line 8 | line 9 | line 10");
    }
}
