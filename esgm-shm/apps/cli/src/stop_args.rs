//! When a command that streams stops (`esgm echo`, `esgm violations`): after a number
//! of items, after a time, or when interrupted.

use std::time::{Duration, Instant};

/// `--count N` and `--seconds S`, shared by the streaming commands.
#[derive(Debug, Clone, clap::Args)]
pub struct StopArgs {
    /// Stop after this many.
    #[arg(long)]
    pub count: Option<usize>,
    /// Stop after this many seconds.
    #[arg(long, value_parser = crate::span_arg::seconds)]
    pub seconds: Option<f64>,
}

impl StopArgs {
    /// A stop that counts from now.
    pub fn start(&self) -> Stop {
        Stop {
            count: self.count,
            until: self.seconds.map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0))),
            seen: 0,
        }
    }
}

/// Whether a streaming command is done: [`StopArgs`] started.
#[derive(Debug)]
pub struct Stop {
    count: Option<usize>,
    until: Option<Instant>,
    seen: usize,
}

impl Stop {
    /// True once the count is reached or the time is up.
    pub fn done(&self) -> bool {
        self.count.is_some_and(|c| self.seen >= c)
            || self.until.is_some_and(|u| Instant::now() >= u)
    }

    /// Counts one item printed.
    pub fn seen_one(&mut self) {
        self.seen += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_counts_and_times() {
        let mut s = StopArgs { count: Some(2), seconds: None }.start();
        assert!(!s.done());
        s.seen_one();
        s.seen_one();
        assert!(s.done(), "two of two");
        let never = StopArgs { count: None, seconds: None }.start();
        assert!(!never.done());
        let now = StopArgs { count: None, seconds: Some(0.0) }.start();
        assert!(now.done(), "no time left");
    }
}
