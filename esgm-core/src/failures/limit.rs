//! Limits a runtime has to fix up front, and the error of reaching one (P6).
//!
//! The in-process runtime has none. Shared memory does: iceoryx2 sizes every service
//! for a number of ports and nodes when it is created, so a domain's transport fixes
//! how many processes may join it and how many may read one trajectory. Each such
//! number is a setting, and reaching it is this one error, naming the limit, its value
//! and the setting that raises it, for the process that would exceed it alone: every
//! other process keeps being served.

use std::fmt;

/// Which limit was reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Limit {
    /// Processes connected to one domain at once (`esgm up --max-processes N`).
    Processes,
    /// Processes reading one trajectory at once (the trajectory's `readers = N`,
    /// `esgm traj create --readers N`, `TrajectorySpec::readers`).
    Readers,
    /// Processes adding to one primitive trajectory that another process writes (the
    /// trajectory's `readers` setting too: an adder is a process using it).
    Adders,
    /// Threads waiting on one trajectory's updates at once, over every process (its
    /// `readers` setting: four waiting threads per reader).
    Waiters,
}

impl Limit {
    /// What is counted, in the plural (`processes of the domain`, …).
    pub fn counted(self) -> &'static str {
        match self {
            Self::Processes => "processes connected",
            Self::Readers => "reader processes",
            Self::Adders => "processes adding",
            Self::Waiters => "threads waiting on updates",
        }
    }

    /// The setting that raises it, as a user would type it.
    pub fn setting(self) -> &'static str {
        match self {
            Self::Processes => "`esgm up --max-processes N` (restart the domain)",
            Self::Readers | Self::Adders | Self::Waiters => {
                "the trajectory's `readers = N` (TOML), `esgm traj create --readers N` or \
                 `TrajectorySpec::readers` (create it again)"
            }
        }
    }
}

impl fmt::Display for Limit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Processes => "max-processes",
            Self::Readers => "readers",
            Self::Adders => "adders",
            Self::Waiters => "waiters",
        })
    }
}

/// A limit was reached: the operation that would exceed it was refused, and nothing
/// else changed. Raise the named setting, or stop a process that uses the resource.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[error(
    "{subject} has {value} {} already, its limit ({limit} = {value}); raise it with {}",
    limit.counted(),
    limit.setting()
)]
pub struct LimitReached {
    /// The limit.
    pub limit: Limit,
    /// Its value.
    pub value: usize,
    /// What it limits: `domain \`lab\`` or `trajectory \`tf\``.
    pub subject: String,
}

impl LimitReached {
    /// The process limit of `domain`, at `value`.
    pub fn processes(domain: &str, value: usize) -> Self {
        Self { limit: Limit::Processes, value, subject: format!("domain `{domain}`") }
    }

    /// A per-trajectory `limit` of `trajectory`, at `value`.
    pub fn trajectory(limit: Limit, trajectory: &str, value: usize) -> Self {
        Self { limit, value, subject: format!("trajectory `{trajectory}`") }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_names_the_limit_its_value_and_the_setting() {
        let e = LimitReached::trajectory(Limit::Readers, "tf", 64).to_string();
        assert!(e.contains("trajectory `tf`"), "{e}");
        assert!(e.contains("readers = 64"), "{e}");
        assert!(e.contains("--readers N"), "{e}");
        let e = LimitReached::processes("lab", 128).to_string();
        assert!(e.contains("domain `lab` has 128 processes connected"), "{e}");
        assert!(e.contains("--max-processes N"), "{e}");
        assert!(!e.to_lowercase().contains("exceeds"), "no iceoryx2 words: {e}");
    }
}
