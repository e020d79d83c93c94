//! External subcommands: `esgm view …` runs the `esgm-view` executable, as git and
//! cargo run theirs, so a heavy dependency (the Foxglove SDK) stays out of this
//! command's build. The executable is looked for next to this one first (where cargo
//! puts both), then on `PATH`.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;

fn executable_in(dir: &Path, program: &str) -> Option<PathBuf> {
    let candidate = dir.join(format!("{program}{}", std::env::consts::EXE_SUFFIX));
    candidate.is_file().then_some(candidate)
}

/// Where `program` is: next to this executable, else on `PATH`; the error names the
/// executable, where it was looked for and the crate that builds it.
pub fn find(program: &str, package: &str) -> anyhow::Result<PathBuf> {
    // No path to this executable: `PATH` is searched next, and the error names both.
    let here = std::env::current_exe().ok().and_then(|e| e.parent().map(Path::to_path_buf));
    if let Some(found) = here.as_deref().and_then(|d| executable_in(d, program)) {
        return Ok(found);
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    if let Some(found) = std::env::split_paths(&path).find_map(|d| executable_in(&d, program)) {
        return Ok(found);
    }
    anyhow::bail!(
        "this command runs the `{program}` executable, found neither next to this one ({}) \
         nor on PATH; build it with `cargo build -p {package}`",
        here.map_or_else(|| "?".into(), |d| d.display().to_string())
    )
}

/// Becomes `program --domain <domain> args…` (the process image is replaced, as
/// `exec` does): the subcommand *is* this process, with its pid, its signals and its
/// exit code, so a SIGTERM to `esgm view` stops `esgm-view`, and no child is left
/// mapping the domain when the command is stopped. Returns only if it cannot run.
pub fn run(
    program: &'static str,
    package: &str,
    domain: &str,
    args: &[String],
) -> anyhow::Result<()> {
    let exe = find(program, package)?;
    let failed = Command::new(&exe).args(["--domain", domain]).args(args).exec();
    Err(anyhow::Error::new(failed).context(format!("cannot run {}", exe.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_executable_is_named_with_its_crate() {
        let e = find("esgm-no-such-tool", "esgm-no-such-crate")
            .map_or_else(|e| e.to_string(), |p| p.display().to_string());
        assert!(e.contains("`esgm-no-such-tool` executable"), "{e}");
        assert!(e.contains("cargo build -p esgm-no-such-crate"), "{e}");
    }
}
