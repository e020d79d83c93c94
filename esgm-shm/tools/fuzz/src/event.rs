//! What a child process tells the parent, one line each on its stdout, and the
//! findings both report.

use std::fmt;
use std::path::{Path, PathBuf};

/// What kind of failure a finding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The code under test panicked (caught with `catch_unwind`).
    Panic,
    /// One case ran past the hang limit (seen by the child's watchdog).
    Hang,
    /// The process died: a stack overflow, an abort, a failed allocation, a signal.
    Abort,
    /// A promise the target checks was broken ([`crate::target::Broken`]).
    Broken,
}

impl Kind {
    fn word(self) -> &'static str {
        match self {
            Kind::Panic => "panic",
            Kind::Hang => "hang",
            Kind::Abort => "abort",
            Kind::Broken => "broken",
        }
    }

    fn from_word(word: &str) -> Option<Self> {
        [Kind::Panic, Kind::Hang, Kind::Abort, Kind::Broken].into_iter().find(|k| k.word() == word)
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.word())
    }
}

/// One failure, with the input that caused it saved to a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// What failed.
    pub kind: Kind,
    /// The case's index in its run (with the run's seed it makes the input again), or
    /// the seed's number for a seed that failed.
    pub index: u64,
    /// Where the input was saved (empty if it could not be found again).
    pub file: PathBuf,
    /// The panic message, broken promise or exit status, on one line.
    pub message: String,
}

/// A line from a child.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event {
    /// Case `next` is about to run; `cases` ran in this process so far.
    Progress {
        /// The next case's index.
        next: u64,
        /// Cases run by this process.
        cases: u64,
    },
    /// Case `index` is about to run (only with `--trace`).
    Case {
        /// Its index.
        index: u64,
    },
    /// Something failed.
    Found(Finding),
    /// The budget is spent: `cases` ran in `millis` ms.
    Done {
        /// Cases run by this process.
        cases: u64,
        /// Milliseconds spent.
        millis: u64,
    },
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Event::Progress { next, cases } => write!(f, "progress {next} {cases}"),
            Event::Case { index } => write!(f, "case {index}"),
            Event::Found(x) => {
                // Tab-separated: a path or a message may hold spaces.
                let message = x.message.replace(['\n', '\r', '\t'], " ");
                write!(f, "finding\t{}\t{}\t{}\t{message}", x.kind, x.index, x.file.display())
            }
            Event::Done { cases, millis } => write!(f, "done {cases} {millis}"),
        }
    }
}

impl Event {
    /// Reads a line written by [`Event`]'s `Display`; `None` for anything else.
    pub fn parse(line: &str) -> Option<Self> {
        if let Some(rest) = line.strip_prefix("finding\t") {
            let mut fields = rest.splitn(4, '\t');
            let kind = Kind::from_word(fields.next()?)?;
            let index = fields.next()?.parse().ok()?;
            let file = Path::new(fields.next()?).to_path_buf();
            let message = fields.next().unwrap_or_default().to_owned();
            return Some(Event::Found(Finding { kind, index, file, message }));
        }
        let (head, rest) = line.split_once(' ')?;
        let numbers = |n: usize| -> Option<Vec<u64>> {
            let v: Option<Vec<u64>> = rest.split(' ').map(|w| w.parse().ok()).collect();
            v.filter(|v| v.len() == n)
        };
        Some(match head {
            "progress" => match numbers(2)?[..] {
                [next, cases] => Event::Progress { next, cases },
                _ => return None,
            },
            "case" => Event::Case { index: *numbers(1)?.first()? },
            "done" => match numbers(2)?[..] {
                [cases, millis] => Event::Done { cases, millis },
                _ => return None,
            },
            _ => return None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_read_back_as_written() {
        let finding = Finding {
            kind: Kind::Panic,
            index: 7,
            file: PathBuf::from("/tmp/a dir/x.bin"),
            message: "index out of bounds: the len is 3".into(),
        };
        for e in [
            Event::Progress { next: 256, cases: 200 },
            Event::Case { index: 9 },
            Event::Found(finding),
            Event::Done { cases: 5, millis: 1000 },
        ] {
            assert_eq!(Event::parse(&e.to_string()), Some(e));
        }
        assert_eq!(Event::parse("garbage"), None);
    }
}
