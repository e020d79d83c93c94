//! The C++ program of `cpp-small` and `cpp-image` ([`super::ipc_cpp`]): found, or built
//! on first use, beside `esgm-bench`.
//!
//! `benches/cpp/cpp_pingpong.cpp` is compiled with `c++ -O2 -std=c++17` (or `$CXX`)
//! against the C ABI's header (`esgm-shm/c/include/esgm.h`) and the C ABI's static
//! library, `libesgm_c.a`. That library is the one cargo built with this `esgm-bench`
//! (esgm-benches depends on esgm-c for that): same profile, same sources, in this
//! executable's target directory. So a debug `esgm-bench` (CI's smoke run) measures a
//! debug library, as its `connect-*` rows measure a debug esgm, and a release one the
//! release library. Linked statically, the program needs no library path to run.
//!
//! The program is put in `<target>/<profile>/esgm-bench-cpp/` and built again whenever
//! the source, the header or the library is newer than it, so an edit to any of them
//! is measured. `ESGM_CPP_PINGPONG` names a program built some other way instead.
//! Whatever stops the build (no compiler, no library, a compile error) is returned as
//! the reason its rows are skipped.

use std::fs::Permissions;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, SystemTime};

use anyhow::{Context as _, bail};

use super::ros1_peer::{Guard, read_all, which};

/// The program's source.
const SOURCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/cpp/cpp_pingpong.cpp");
/// The C ABI's header directory.
const INCLUDE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../esgm-shm/c/include");
/// The static library, as cargo names it.
const LIBRARY: &str = "libesgm_c.a";
/// What the Rust standard library in `libesgm_c.a` needs from the system, as esgm's
/// pkg-config file lists it (`Libs.private`; libgcc_s and libc come with `c++`).
const SYSTEM_LIBS: [&str; 5] = ["-lutil", "-lrt", "-lpthread", "-lm", "-ldl"];
/// How long a build may take (a debug library is over 100 MB to link).
const BUILD_TIMEOUT: Duration = Duration::from_secs(300);

/// The program to run: `ESGM_CPP_PINGPONG`, or the one built beside this executable
/// (built now if missing or older than its inputs). An error says why there is none.
pub fn program() -> anyhow::Result<PathBuf> {
    if let Some(path) = std::env::var_os("ESGM_CPP_PINGPONG").filter(|p| !p.is_empty()) {
        let path = PathBuf::from(path);
        if !path.is_file() {
            bail!("ESGM_CPP_PINGPONG names {}, which is not a file", path.display());
        }
        return Ok(path);
    }
    let exe = std::env::current_exe().context("finding the esgm-bench executable")?;
    let dir = exe.parent().context("esgm-bench's executable has no directory")?;
    let library = library(dir)?;
    let source = Path::new(SOURCE);
    let header = Path::new(INCLUDE).join("esgm.h");
    for input in [source, header.as_path()] {
        if !input.is_file() {
            bail!("{} is missing (run esgm-bench from its checkout)", input.display());
        }
    }
    let out_dir = dir.join("esgm-bench-cpp");
    let program = out_dir.join("cpp_pingpong");
    let newest_input = [source, header.as_path(), library.as_path()]
        .iter()
        .map(|p| modified(p))
        .collect::<anyhow::Result<Vec<_>>>()?
        .into_iter()
        .max()
        .unwrap_or(SystemTime::UNIX_EPOCH);
    if program.is_file() && modified(&program)? >= newest_input {
        return Ok(program);
    }
    std::fs::create_dir_all(&out_dir)
        .and_then(|()| std::fs::set_permissions(&out_dir, Permissions::from_mode(0o755)))
        .with_context(|| format!("creating {}", out_dir.display()))?;
    build(&library, &out_dir, &program)?;
    Ok(program)
}

/// The newest `libesgm_c.a` of this executable's directory: `deps/`, where cargo
/// builds it as esgm-bench's dependency, or the directory itself, where
/// `cargo build -p esgm-c` puts it.
fn library(dir: &Path) -> anyhow::Result<PathBuf> {
    let mut found: Vec<(SystemTime, PathBuf)> = Vec::new();
    for candidate in [dir.join("deps").join(LIBRARY), dir.join(LIBRARY)] {
        if candidate.is_file() {
            found.push((modified(&candidate)?, candidate));
        }
    }
    found.into_iter().max_by_key(|(time, _)| *time).map(|(_, path)| path).with_context(|| {
        format!(
            "no {LIBRARY} in {} or its deps/ (esgm-bench built by cargo builds it; \
             or `cargo build -p esgm-c` with the same profile)",
            dir.display()
        )
    })
}

fn modified(path: &Path) -> anyhow::Result<SystemTime> {
    std::fs::metadata(path)
        .and_then(|m| m.modified())
        .with_context(|| format!("reading the time of {}", path.display()))
}

/// Compiles the program into a file of its own, then renames it into place: a run
/// that starts meanwhile never sees half a program.
fn build(library: &Path, out_dir: &Path, program: &Path) -> anyhow::Result<()> {
    let compiler = match std::env::var_os("CXX") {
        Some(cxx) => PathBuf::from(cxx),
        None => which("c++").context("no C++ compiler: install g++ or clang++ (or set CXX)")?,
    };
    let partial = out_dir.join(format!("cpp_pingpong.{}.partial", std::process::id()));
    let mut command = Command::new(&compiler);
    command
        .args(["-O2", "-std=c++17", "-I", INCLUDE, "-o"])
        .arg(&partial)
        .arg(SOURCE)
        .arg(library)
        .args(SYSTEM_LIBS)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let mut child =
        Guard::new(command.spawn().with_context(|| format!("starting {}", compiler.display()))?);
    let errors = read_all(child.child()?.stderr.take().context("the compiler's stderr")?);
    let status = child.wait("the C++ compiler", BUILD_TIMEOUT)?;
    let errors = errors.join().unwrap_or_default();
    if !status.success() {
        // Half an output is no program.
        if partial.exists() {
            std::fs::remove_file(&partial)
                .with_context(|| format!("removing {}", partial.display()))?;
        }
        let first: Vec<&str> = errors.lines().take(8).collect();
        bail!(
            "{} could not build {SOURCE} against {} ({status}): {}",
            compiler.display(),
            library.display(),
            first.join(" / ")
        );
    }
    // The compiler makes the file as the process umask says, and iceoryx2 narrows the
    // umask of this process (to 0o177) around each socket it binds; threads binding at
    // once can leave it narrowed after they return (seen after the connect rows: a
    // 0600 program, "Permission denied"). So the mode is set here.
    std::fs::set_permissions(&partial, Permissions::from_mode(0o755))
        .with_context(|| format!("making {} executable", partial.display()))?;
    std::fs::rename(&partial, program)
        .with_context(|| format!("moving the program into {}", program.display()))
}
