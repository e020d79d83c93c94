//! What is fuzzed: a [`Target`] makes inputs and runs the code under test on one.

use crate::rng::Rng;

/// An invariant the code under test broke on an input: a finding, like a panic.
///
/// A decoder returning its typed error for bad bytes is never one; these are the
/// promises that can fail without a panic (an archive the validator accepts must
/// decode, a valid encoding must be accepted, an answer must be readable).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broken {
    /// The promise, in a few words.
    pub invariant: &'static str,
    /// What happened instead.
    pub detail: String,
}

impl Broken {
    /// The promise `invariant` failed, as `detail` says.
    pub fn new(invariant: &'static str, detail: impl std::fmt::Display) -> Self {
        Self { invariant, detail: detail.to_string() }
    }
}

impl std::fmt::Display for Broken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.invariant, self.detail)
    }
}

/// Something that decodes bytes from another process, and how to attack it.
///
/// `input` must depend on `rng` alone, so that a case is made again from its seed and
/// index (a case that aborted the process is recovered that way).
pub trait Target: Send + Sync {
    /// The name `--target` takes.
    fn name(&self) -> &'static str;

    /// What it runs, in one line.
    fn about(&self) -> &'static str;

    /// The valid inputs the mutations start from; [`Target::run`] must accept each.
    fn seeds(&self) -> &[Vec<u8>];

    /// One input: a mutated seed, a generated or a random one.
    fn input(&self, rng: &mut Rng) -> Vec<u8>;

    /// Runs the code under test on `input`: `Err` when it broke a promise. A panic
    /// is caught by the runner.
    fn run(&self, input: &[u8]) -> Result<(), Broken>;

    /// Runs a seed, which must also be accepted, not only survived.
    fn accepts(&self, seed: &[u8]) -> Result<(), Broken>;

    /// Forgets state kept between cases (the registry of the request target); called
    /// every [`RESET_EVERY`] cases and after a finding, so a case's outcome depends on
    /// at most that many before it.
    fn reset(&self) {}
}

/// How many cases share state before [`Target::reset`].
pub const RESET_EVERY: u64 = 256;
