//! The raw command line of `esgm-bench`, as clap parses it; [`Args::into_config`]
//! turns it into a validated [`RunConfig`].

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Parser;

use crate::config::RunConfig;
use crate::pin::Pinning;

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

    /// Pin the measuring thread to the first core and its peers (echo threads, unit
    /// and sampler workers) to the second.
    #[arg(long)]
    pub pin: bool,

    /// Run only the scenarios whose name contains this text.
    #[arg(long, value_name = "NAME-SUBSTRING")]
    pub only: Option<String>,

    /// Samples per scenario and wait strategy, overriding the defaults (a sampled
    /// scenario takes one sample per period, so N samples take N periods).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: Option<u64>,

    /// List the scenarios and exit.
    #[arg(long)]
    pub list: bool,
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
        let pin = if self.pin { Some(Pinning::detect().context("--pin")?) } else { None };
        Ok(RunConfig {
            quick: self.quick,
            json: self.json,
            pin,
            only,
            samples: self.samples,
            list: self.list,
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
    fn bad_values_are_refused() {
        assert!(parse(&["--samples", "0"]).is_err());
        assert!(parse(&["--only", " "]).unwrap().into_config().is_err());
        let e = parse(&["--json", "/no/such/folder/x.json"]).unwrap().into_config().unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
    }
}
