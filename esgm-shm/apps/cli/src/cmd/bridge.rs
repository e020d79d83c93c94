//! `esgm bridge …` and `esgm --remote <endpoint> latest|nth|between|at|closest …`:
//! run the `esgm-bridge` executable, as git and cargo run their external subcommands.
//!
//! The bridge joins Zenoh, which takes minutes to build on two cores; keeping it a
//! binary of its own (crate `esgm-bridge`) keeps Zenoh out of this command's build
//! ([`crate::external`] finds and runs it).

use super::query;
use crate::time_arg::TimeArg;

/// The bridge's executable, and the crate that builds it.
pub const BRIDGE: (&str, &str) = ("esgm-bridge", "esgm-bridge");

/// `esgm bridge` options: everything is the bridge's own (`esgm bridge --help`).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Arguments of `esgm-bridge` (e.g. `--listen tcp/10.0.0.1:7447 --export robot_state`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

fn run_bridge(domain: &str, json: bool, args: &[String]) -> anyhow::Result<()> {
    let mut all = Vec::with_capacity(args.len() + 1);
    if json {
        all.push("--json".to_owned());
    }
    all.extend_from_slice(args);
    crate::external::run(BRIDGE.0, BRIDGE.1, domain, &all)
}

/// `esgm bridge …`.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    run_bridge(domain, json, &a.args)
}

/// A time as the bridge takes it: nanoseconds, or relative to the latest (`-5000ns`).
fn time(t: &TimeArg) -> String {
    match t {
        TimeArg::Absolute(ns) => ns.to_string(),
        TimeArg::Relative(d) if *d < 0 => format!("-{}ns", d.unsigned_abs()),
        TimeArg::Relative(d) => format!("+{d}ns"),
    }
}

/// A query of `esgm --remote`.
#[derive(Debug)]
pub enum Remote<'a> {
    /// `latest`.
    Latest(&'a query::One),
    /// `nth`.
    Nth(&'a query::Nth),
    /// `between`.
    Between(&'a query::Between),
    /// `at` (`closest: false`) or `closest`.
    At(&'a query::At, bool),
}

/// `esgm --remote <endpoint> …`: the query answered by the bridge of the domain at
/// `endpoint` (`esgm-bridge query`), without importing the trajectory.
pub fn remote(domain: &str, json: bool, endpoint: &str, q: Remote<'_>) -> anyhow::Result<()> {
    let mut args: Vec<String> = vec!["query".into(), "--connect".into(), endpoint.into()];
    match q {
        Remote::Latest(a) => args.extend(["latest".into(), a.trajectory.clone()]),
        Remote::Nth(a) => args.extend(["nth".into(), a.trajectory.clone(), a.n.to_string()]),
        Remote::Between(a) => {
            args.extend(["between".into(), a.trajectory.clone(), time(&a.from), time(&a.to)])
        }
        Remote::At(a, closest) => args.extend([
            if closest { "closest" } else { "at" }.into(),
            a.trajectory.clone(),
            time(&a.time),
        ]),
    }
    run_bridge(domain, json, &args)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_reach_the_bridge_exactly() {
        assert_eq!(time(&TimeArg::Absolute(42)), "42");
        assert_eq!(time(&TimeArg::Relative(-5_000_000_000)), "-5000000000ns");
        assert_eq!(time(&TimeArg::Relative(0)), "+0ns");
    }
}
