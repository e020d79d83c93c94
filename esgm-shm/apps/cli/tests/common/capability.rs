//! Tests that need something of the machine: root, network namespaces, `unshare`, a
//! binary built beside `esgm`. In CI (`CI` set) a missing capability fails the test, so
//! CI never reports a claim as verified without running it; elsewhere the test is
//! skipped with a note written straight to the terminal (libtest hides what a passing
//! test prints through `eprintln!`).
//!
//! Shared by the esgm-cli tests (`common::capability`) and the esgm-bridge tests
//! (included by `#[path]`).

#![allow(dead_code)] // each test binary uses what it needs
#![allow(clippy::panic)] // a missing capability in CI is a failed test

use std::io::Write as _;
use std::process::{Command, Stdio};

/// `found`, when the machine has what the calling test needs (`what`); when it lacks it
/// (`Err(why)`), in CI the test fails naming it, elsewhere this prints that the test
/// is skipped and returns `None` (the test then returns).
pub fn needs<T>(what: &str, found: Result<T, String>) -> Option<T> {
    let why = match found {
        Ok(t) => return Some(t),
        Err(why) => why,
    };
    let current = std::thread::current();
    let test = current.name().unwrap_or("a test");
    if std::env::var_os("CI").is_some() {
        panic!("{test} needs {what}, which CI must provide ({why})");
    }
    // Not `eprintln!`: libtest captures it and shows it only for a failed test.
    let note = format!("\nSKIPPED {test}: needs {what} ({why}); with CI set it fails\n");
    if let Err(e) = std::io::stderr().lock().write_all(note.as_bytes()) {
        // Nowhere left to say it: the skip must not pass unnoticed.
        panic!("cannot say that {test} is skipped ({e}): {note}");
    }
    None
}

/// Whether the effective user is root, as [`needs`] takes it (read from
/// `/proc/self/status`: the bridge's tests have no `libc`).
pub fn root() -> Result<(), String> {
    let status = std::fs::read_to_string("/proc/self/status")
        .map_err(|e| format!("cannot read /proc/self/status: {e}"))?;
    // `Uid:  real  effective  saved  filesystem`
    let effective = status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|ids| ids.split_whitespace().nth(1))
        .ok_or("no effective uid in /proc/self/status")?;
    if effective == "0" { Ok(()) } else { Err(format!("running as uid {effective}, not root")) }
}

/// Whether `program args…` runs and succeeds here, as [`needs`] takes it: a probe for
/// a tool and what it needs of the kernel (e.g. `unshare -rm true`).
pub fn runs(program: &str, args: &[&str]) -> Result<(), String> {
    let shown = std::iter::once(program).chain(args.iter().copied()).collect::<Vec<_>>().join(" ");
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run `{shown}`: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{shown}` failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Whether `path` is a file, as [`needs`] takes it (a binary the workspace builds).
pub fn built(path: &std::path::Path) -> Result<(), String> {
    if path.is_file() { Ok(()) } else { Err(format!("{} is not built", path.display())) }
}
