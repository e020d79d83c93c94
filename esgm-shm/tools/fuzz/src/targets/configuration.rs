//! The configuration parser: [`esgm_cli::config::parse`], what `esgm apply` and
//! `esgm up --config` run on a system file, whoever wrote it.
//!
//! Promises checked beyond "no panic": an error names a line of the file (1 to one
//! past the last), and every seed parses.

use std::path::Path;

use esgm_cli::config;

use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};
use crate::text::mutate_text;

/// The configuration seeds: the tutorial `esgm demo` runs, and a file with every kind
/// of declaration and setting.
pub fn seed_files() -> [(&'static str, &'static str); 2] {
    [
        ("tutorial.toml", include_str!("../../../../apps/cli/tutorial.toml")),
        ("everything.toml", include_str!("../../seeds/everything.toml")),
    ]
}

/// TOML's punctuation and words, and the format's keys and values.
const TOML_TOKENS: [&str; 40] = [
    "[[trajectory]]\n",
    "[[type]]\n",
    "[[sensor]]\n",
    "[[unit]]\n",
    "[[robot]]\n",
    "[[bridge]]\nexport = [\"a\"]\nlisten = [\"tcp/0.0.0.0:7447\"]\n",
    "[trajectory]\n",
    "name = \"x\"\n",
    "name = \"\"\n",
    "primitive = \"Blob\"\n",
    "inputs = []\n",
    "sync = [\"a\", \"a\"]\n",
    "generate = [\"a:linear:median\", \":\", \"a::\"]\n",
    "function = \"BlobSelection\"\n",
    "camera = \"/\"\n",
    "exec = \"../x\"\n",
    "attributes = [\"a: EntityFrameSeq<Blob>\", \"b: Agg\", \": \", \"c: EntityFrameSeq<\"]\n",
    "policy = { cache = \"all\" }\n",
    "filter = \"size > 10 && (x < 3 || !(y == 2))\"",
    "period = \"0ns\"",
    "period = \"-1s\"",
    "\"18446744073709551615ns\"",
    "\"every 0ms\"",
    "tolerance = \"1y\"",
    "window = 0",
    "= ",
    "\"",
    "'''",
    "\"\"\"",
    "[",
    "]",
    "{",
    "}",
    ",",
    ".",
    "#",
    "\n",
    "\\u0000",
    "\r",
    "2024-02-30T25:61:61Z",
];

/// The configuration target.
#[derive(Debug)]
pub struct Configuration {
    seeds: Vec<Vec<u8>>,
}

impl Configuration {
    /// The seed files.
    pub fn new() -> Self {
        Self { seeds: seed_files().iter().map(|(_, text)| text.as_bytes().to_vec()).collect() }
    }
}

impl Default for Configuration {
    fn default() -> Self {
        Self::new()
    }
}

/// Relative paths in fuzzed files resolve under a directory that does not exist, so a
/// camera directory is found only where an absolute path names one.
const BASE: &str = "/nonexistent/esgm-fuzz";

fn parse(input: &[u8]) -> Result<Result<config::Plan, config::ConfigError>, Broken> {
    let text = String::from_utf8_lossy(input);
    let parsed = config::parse("fuzz.toml", &text, Path::new(BASE));
    if let Err(e) = &parsed {
        let lines = text.lines().count();
        if e.line == 0 || e.line > lines + 1 {
            return Err(Broken::new(
                "an error names a line of the file",
                format!("line {} of {lines}: {e}", e.line),
            ));
        }
    }
    Ok(parsed)
}

impl Target for Configuration {
    fn name(&self) -> &'static str {
        "config"
    }

    fn about(&self) -> &'static str {
        "esgm_cli::config::parse on system configuration files"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        if rng.chance(3) {
            let n = rng.len(4096);
            return rng.bytes(n);
        }
        let mut data = rng.pick(&self.seeds).clone();
        if rng.chance(85) {
            mutate_text(rng, &mut data, &self.seeds, &TOML_TOKENS);
        } else {
            mutate(rng, &mut data, &self.seeds);
        }
        data
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        if let Ok(plan) = parse(input)? {
            // What `esgm apply` lists as it goes.
            let _items = plan.items();
        }
        Ok(())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match parse(seed)? {
            Ok(_) => Ok(()),
            Err(e) => Err(Broken::new("a valid configuration parses", e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutated files must still parse now and then, so the checks after the syntax
    /// are reached.
    #[test]
    fn some_mutated_files_parse() {
        let target = Configuration::new();
        for seed in target.seeds() {
            assert_eq!(target.accepts(seed), Ok(()));
        }
        let parsed = (0..500)
            .filter(|i| matches!(parse(&target.input(&mut Rng::for_case(6, *i))), Ok(Ok(_))))
            .count();
        assert!(parsed > 25, "{parsed} of 500 parsed");
    }
}
