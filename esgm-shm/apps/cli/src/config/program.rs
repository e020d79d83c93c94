//! A user's own program serving a unit or a sensor: `program = "NAME_OR_PATH"` (or
//! `exec`, its older name), a C, C++ or Rust executable that connects with the client
//! library and registers what it serves.
//!
//! The program is found when the file is loaded (`esgm apply`, `esgm up --config`,
//! `esgm demo --config`), before anything changes: a typo or a program not built yet
//! is one error naming the file, the line and the program, not a worker the
//! supervisor restarts forever. A bare name (no `/`) is looked up on the `PATH` of the
//! process that loads the file, as a shell would; a path is taken from the file's
//! directory. Either way the supervisor is given the absolute path found here, not the
//! name: `esgm up` may run with another `PATH` (started by systemd, from another shell),
//! and what was checked is what runs.
//!
//! [`super::parse`] records the program as written and does not look at the disk
//! (the fuzzer parses files whose programs exist nowhere); [`super::load`] finds it.

use std::ffi::OsStr;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

/// A program as a declaration names it, to be found before the system changes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UserProgram {
    /// The key it was given under: `program`, or its older name `exec`.
    pub key: &'static str,
    /// As written: a bare name, or a path.
    pub declared: String,
    /// The directory a relative path is taken from (the configuration file's).
    pub base: PathBuf,
}

/// A declared program that cannot be run: what the user can fix.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramError {
    /// A bare name found in no directory of `PATH`: install it, put its directory on
    /// `PATH`, or give a path.
    #[error("{key} `{program}` is not on PATH ({})", path.as_deref().map_or_else(|| "PATH is not set".to_owned(), |p| format!("PATH={p}")))]
    NotOnPath {
        /// The key it was declared under.
        key: &'static str,
        /// The name, as written.
        program: String,
        /// The `PATH` searched, if set.
        path: Option<String>,
    },
    /// A path to nothing: build the program, or fix the path.
    #[error("{key} `{program}` does not exist ({})", path.display())]
    Missing {
        /// The key it was declared under.
        key: &'static str,
        /// The path, as written.
        program: String,
        /// Where it was looked for.
        path: PathBuf,
    },
    /// A path to a directory or another non-file: name the executable in it.
    #[error("{key} `{program}` is not a file ({})", path.display())]
    NotAFile {
        /// The key it was declared under.
        key: &'static str,
        /// The path, as written.
        program: String,
        /// What it names.
        path: PathBuf,
    },
    /// A file nobody may execute: `chmod +x` it.
    #[error("{key} `{program}` is not executable ({}); chmod +x it", path.display())]
    NotExecutable {
        /// The key it was declared under.
        key: &'static str,
        /// The path, as written.
        program: String,
        /// The file.
        path: PathBuf,
    },
    /// The file could not be examined (a directory on the way is not readable, …).
    #[error("{key} `{program}`: cannot read {}: {source}", path.display())]
    Unreadable {
        /// The key it was declared under.
        key: &'static str,
        /// The path, as written.
        program: String,
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The program's absolute path is not UTF-8, which a process declaration carries:
    /// move it, or give a path that is.
    #[error("{key} `{program}` is found at {}, which is not UTF-8", path.display())]
    NotUtf8 {
        /// The key it was declared under.
        key: &'static str,
        /// The program, as written.
        program: String,
        /// Where it was found.
        path: PathBuf,
    },
}

impl UserProgram {
    /// The absolute path of the program to run, looked up on this process's `PATH`
    /// if it is a bare name.
    pub fn find(&self) -> Result<String, ProgramError> {
        self.find_in(std::env::var_os("PATH").as_deref())
    }

    /// [`Self::find`] with the given `PATH`.
    pub fn find_in(&self, path: Option<&OsStr>) -> Result<String, ProgramError> {
        let found = if self.declared.contains('/') {
            self.check(&self.base.join(&self.declared))?
        } else {
            let dirs = path.map(std::env::split_paths).into_iter().flatten();
            // As execvp: the first directory holding an executable file of this name.
            dirs.map(|d| d.join(&self.declared))
                .find(|c| executable(c).unwrap_or(false))
                .ok_or_else(|| ProgramError::NotOnPath {
                    key: self.key,
                    program: self.declared.clone(),
                    path: path.map(|p| p.to_string_lossy().into_owned()),
                })?
        };
        // Relative to this process's directory, which the supervisor's need not be.
        let absolute = std::path::absolute(&found).map_err(|source| ProgramError::Unreadable {
            key: self.key,
            program: self.declared.clone(),
            path: found.clone(),
            source,
        })?;
        match absolute.to_str() {
            Some(s) => Ok(s.to_owned()),
            None => Err(ProgramError::NotUtf8 {
                key: self.key,
                program: self.declared.clone(),
                path: absolute,
            }),
        }
    }

    /// `path` if it is an executable file, else why not.
    fn check(&self, path: &Path) -> Result<PathBuf, ProgramError> {
        let (key, program, path_buf) = (self.key, self.declared.clone(), path.to_path_buf());
        match std::fs::metadata(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                Err(ProgramError::Missing { key, program, path: path_buf })
            }
            Err(source) => Err(ProgramError::Unreadable { key, program, path: path_buf, source }),
            Ok(m) if !m.is_file() => Err(ProgramError::NotAFile { key, program, path: path_buf }),
            Ok(m) if m.permissions().mode() & 0o111 == 0 => {
                Err(ProgramError::NotExecutable { key, program, path: path_buf })
            }
            Ok(_) => Ok(path_buf),
        }
    }
}

/// Whether `path` is a file with an execute bit (a directory of `PATH` that cannot be
/// read hides its files, as it does from a shell).
fn executable(path: &Path) -> std::io::Result<bool> {
    let m = std::fs::metadata(path)?;
    Ok(m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// The program a declaration names, under `program` or its older name `exec`; giving
/// both is an error naming both (`what`: `unit `X``).
pub fn declared(
    what: &str,
    program: Option<&str>,
    exec: Option<&str>,
    base: &Path,
) -> anyhow::Result<Option<UserProgram>> {
    let (key, declared) = match (program, exec) {
        (Some(p), Some(e)) => anyhow::bail!(
            "{what}: give program = \"{p}\" or exec = \"{e}\" (its older name), not both"
        ),
        (Some(p), None) => ("program", p),
        (None, Some(e)) => ("exec", e),
        (None, None) => return Ok(None),
    };
    if declared.trim().is_empty() {
        anyhow::bail!("{what}: {key} is empty; name a program on PATH or give a path");
    }
    Ok(Some(UserProgram { key, declared: declared.to_owned(), base: base.to_path_buf() }))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn program(declared: &str, base: &Path) -> UserProgram {
        UserProgram { key: "program", declared: declared.into(), base: base.into() }
    }

    fn write(path: &Path, mode: u32) {
        std::fs::write(path, "#!/bin/sh\n").unwrap();
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn a_bare_name_is_the_first_executable_of_that_name_on_path() {
        let dir = tempfile::tempdir().unwrap();
        let (first, second) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::create_dir_all(&first).unwrap();
        std::fs::create_dir_all(&second).unwrap();
        // Not executable in the first directory: skipped, as a shell skips it.
        write(&first.join("unit"), 0o644);
        write(&second.join("unit"), 0o755);
        let path = std::env::join_paths([&first, &second]).unwrap();
        let found = program("unit", Path::new("/elsewhere")).find_in(Some(&path)).unwrap();
        assert_eq!(found, second.join("unit").to_str().unwrap());
    }

    #[test]
    fn a_name_not_on_path_is_named_with_the_path() {
        let e = program("driving_direction_unit", Path::new("."))
            .find_in(Some(OsStr::new("/no/such:/nor/this")))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "program `driving_direction_unit` is not on PATH (PATH=/no/such:/nor/this)");
        let e = program("x", Path::new(".")).find_in(None).unwrap_err().to_string();
        assert!(e.contains("PATH is not set"), "{e}");
    }

    #[test]
    fn a_path_is_taken_from_the_files_directory_and_made_absolute() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("bin")).unwrap();
        write(&dir.path().join("bin/unit"), 0o700);
        let found = program("bin/unit", dir.path()).find_in(None).unwrap();
        assert_eq!(found, dir.path().join("bin/unit").to_str().unwrap());
        let absolute = dir.path().join("bin/unit");
        let found =
            program(absolute.to_str().unwrap(), Path::new("/elsewhere")).find_in(None).unwrap();
        assert_eq!(found, absolute.to_str().unwrap());
    }

    #[test]
    fn a_path_that_cannot_run_says_why() {
        let dir = tempfile::tempdir().unwrap();
        write(&dir.path().join("plain"), 0o644);
        std::fs::create_dir(dir.path().join("dir")).unwrap();
        let why = |p: &str| program(p, dir.path()).find_in(None).unwrap_err().to_string();
        assert!(
            why("./missing").contains("program `./missing` does not exist"),
            "{}",
            why("./missing")
        );
        assert!(why("./plain").contains("is not executable"), "{}", why("./plain"));
        assert!(why("./dir").contains("is not a file"), "{}", why("./dir"));
    }

    #[test]
    fn program_and_exec_are_one_key_under_two_names() {
        let base = Path::new("/b");
        let p = declared("unit `U`", Some("u"), None, base).unwrap().unwrap();
        assert_eq!((p.key, p.declared.as_str()), ("program", "u"));
        let p = declared("unit `U`", None, Some("./u"), base).unwrap().unwrap();
        assert_eq!((p.key, p.declared.as_str()), ("exec", "./u"));
        assert!(declared("unit `U`", None, None, base).unwrap().is_none());
        let e = declared("unit `U`", Some("u"), Some("v"), base).unwrap_err().to_string();
        assert!(e.contains("unit `U`") && e.contains("program") && e.contains("exec"), "{e}");
        let e = declared("sensor `S`", Some(" "), None, base).unwrap_err().to_string();
        assert!(e.contains("program is empty"), "{e}");
    }
}
