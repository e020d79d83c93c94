//! A network namespace whose only interface is its own loopback, with multicast on:
//! where a test may run DDS discovery (multicast), since no packet can leave it.
//! Removed when dropped, also when the test fails.
//!
//! Shared by the esgm-cli tests (`common::netns`) and the esgm-ros2 and esgm-bridge
//! tests (included by `#[path]`).

#![allow(dead_code)] // each test binary uses what it needs

use std::process::Command;

/// Runs `ip ARGS`; the error names the command and what `ip` said.
pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip").args(args).output().map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
    }
}

/// A loopback-only network namespace (see the module docs).
#[derive(Debug)]
pub struct Namespace(String);

impl Namespace {
    /// Makes `esgm-<tag>-<pid>`: needs root and `ip` (the error says which is missing,
    /// for `capability::needs`).
    pub fn create(tag: &str) -> Result<Namespace, String> {
        super::capability::root()?;
        let name = format!("esgm-{tag}-{}", std::process::id());
        ip(&["netns", "add", &name])?;
        let ns = Namespace(name);
        ip(&["-n", &ns.0, "link", "set", "lo", "up"])?;
        ip(&["-n", &ns.0, "link", "set", "lo", "multicast", "on"])?;
        ip(&["-n", &ns.0, "route", "add", "239.0.0.0/8", "dev", "lo"])?;
        Ok(ns)
    }

    /// `program` run inside the namespace (its arguments are added by the caller).
    pub fn command(&self, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.0, program]);
        c
    }
}

impl Drop for Namespace {
    fn drop(&mut self) {
        if let Err(e) = ip(&["netns", "del", &self.0]) {
            eprintln!("cannot remove network namespace {}: {e}", self.0);
        }
    }
}
