//! The raw command line of `esgm-bench`, as clap parses it; [`Args::into_config`]
//! turns it into a validated [`RunConfig`].

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Parser;

use crate::config::RunConfig;
use crate::peer_role::PeerRole;
use crate::pin::Pinning;
use crate::wait_mode::WaitMode;

/// Latency benchmarks of esgm, each next to a baseline measured in the same run.
///
/// Prints a table (p50, p99, p99.9, max and the ratio to each row's baseline) and,
/// with --json, writes the figures for comparison across runs.
#[derive(Debug, Parser)]
#[command(name = "esgm-bench", version)]
pub struct Args {
    /// Fewer samples: the whole run takes under a minute (the default run takes a few).
    #[arg(long)]
    pub quick: bool,

    /// Also write the results to FILE as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,

    /// Also draw PNG charts (latency vs payload size, latency CDFs) into DIR.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,

    /// Pin the measuring thread to the first core and its peers (echo threads, unit
    /// and sampler workers, peer processes) to the second.
    #[arg(long)]
    pub pin: bool,

    /// Run only the scenarios whose name contains this text, or one of several texts
    /// separated by commas (`record,file-write,replay`).
    #[arg(long, value_name = "NAME-SUBSTRING[,…]")]
    pub only: Option<String>,

    /// Samples per scenario and wait strategy, overriding the defaults (a sampled
    /// scenario takes one sample per period, so N samples take N periods).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: Option<u64>,

    /// List the scenarios and exit.
    #[arg(long)]
    pub list: bool,

    /// Hold idle cores' wake-up within this many microseconds for the whole run (0:
    /// idle cores poll), as `esgm up --cpu-latency` does for a robot; needs root. Every
    /// blocking row is mostly the woken core leaving its idle state, so a run with it
    /// and one without say how much of a row is the machine's idle policy.
    #[arg(long, value_name = "MICROSECONDS", value_parser = esgm_shm::process::cpu_latency::parse_micros)]
    pub cpu_latency: Option<std::time::Duration>,

    /// Internal: run as the peer process of cross-process scenario SCENARIO (esgm-bench
    /// starts itself this way; see `peer_role`).
    #[arg(long, hide = true, value_name = "SCENARIO", requires_all = ["peer_wait", "peer_domain"])]
    pub peer: Option<String>,

    /// Internal: how the peer waits.
    #[arg(long, hide = true, value_enum, requires = "peer")]
    pub peer_wait: Option<WaitMode>,

    /// Internal: the domain (service namespace, socket name) the peer meets in.
    #[arg(long, hide = true, requires = "peer")]
    pub peer_domain: Option<String>,

    /// Internal: the core to pin the peer to.
    #[arg(long, hide = true, requires = "peer")]
    pub peer_core: Option<usize>,

    /// Internal: which of several peers of one measurement this is.
    #[arg(long, hide = true, requires = "peer")]
    pub peer_arg: Option<String>,
}

impl Args {
    /// Checks the arguments and resolves what they name (cores, the JSON file's folder).
    pub fn into_config(self) -> anyhow::Result<RunConfig> {
        let only = match self.only {
            Some(s) if s.trim().is_empty() => bail!("--only needs a non-empty name substring"),
            other => other,
        };
        if let Some(path) = &self.json {
            let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
            if let Some(dir) = dir {
                if !dir.is_dir() {
                    bail!("--json {}: folder {} does not exist", path.display(), dir.display());
                }
            }
        }
        let peer = match (self.peer, self.peer_wait, self.peer_domain) {
            (Some(scenario), Some(wait), Some(domain)) => {
                Some(PeerRole { scenario, wait, domain, core: self.peer_core, arg: self.peer_arg })
            }
            // clap's `requires` rules out the other combinations.
            _ => None,
        };
        // A peer is pinned to the core it is given, not to the ones it can see.
        let pin = if self.pin && peer.is_none() {
            Some(Pinning::detect().context("--pin")?)
        } else {
            None
        };
        Ok(RunConfig {
            quick: self.quick,
            json: self.json,
            plots: self.plots,
            pin,
            only,
            samples: self.samples,
            list: self.list,
            cpu_latency: self.cpu_latency.filter(|_| peer.is_none()),
            peer,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Args, clap::Error> {
        Args::try_parse_from(std::iter::once("esgm-bench").chain(args.iter().copied()))
    }

    #[test]
    fn options_parse_into_a_config() {
        let c =
            parse(&["--quick", "--only", "hop", "--samples", "5"]).unwrap().into_config().unwrap();
        assert!(c.quick);
        assert_eq!(c.only.as_deref(), Some("hop"));
        assert_eq!(c.samples, Some(5));
        assert!(c.pin.is_none());
    }

    #[test]
    fn a_peer_role_round_trips_through_its_arguments() {
        let role = PeerRole {
            scenario: "esgm-small".into(),
            wait: WaitMode::SpinThenBlock,
            domain: "esgm-bench-1-0".into(),
            core: Some(1),
            arg: Some("coordinator".into()),
        };
        let args = Args::try_parse_from(std::iter::once("esgm-bench".into()).chain(role.to_args()))
            .unwrap();
        assert_eq!(args.into_config().unwrap().peer, Some(role));
        assert!(parse(&["--peer", "esgm-small"]).is_err(), "wait and domain are required");
        assert!(parse(&["--peer-wait", "spin"]).is_err(), "only with --peer");
    }

    #[test]
    fn bad_values_are_refused() {
        assert!(parse(&["--samples", "0"]).is_err());
        assert!(parse(&["--only", " "]).unwrap().into_config().is_err());
        let e = parse(&["--json", "/no/such/folder/x.json"]).unwrap().into_config().unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
    }
}
