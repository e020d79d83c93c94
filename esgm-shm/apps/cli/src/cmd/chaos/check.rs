//! The end of `esgm chaos`: what every worker acknowledged, checked against what each
//! trajectory holds, read by the harness (a process that wrote nothing).
//!
//! A trajectory's writer numbers its structures on (the valid time is the number) and
//! logs each acknowledged one. Its cache keeps the last `cache` added, so each of the
//! last `cache` acknowledged numbers must be held; an older one is evicted by the
//! policy, not lost. Nothing is held twice, and nothing past the last number added: a
//! held number that was not logged was added by a writer killed between `add` and its
//! log line (counted).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use serde::Serialize;

/// What the check found, over every trajectory.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Checked {
    /// Structures acknowledged (log lines).
    pub acknowledged: u64,
    /// Acknowledged structures the policy kept room for, each checked to be held.
    pub checked: u64,
    /// Acknowledged structures evicted by the cache since (older than its last
    /// `cache`).
    pub evicted_by_policy: u64,
    /// Acknowledged, within the cache, and not held: each one is named.
    pub lost: Vec<String>,
    /// Held twice.
    pub duplicated: Vec<String>,
    /// Held, added and not logged: its writer was killed between `add` and the line.
    pub unlogged: u64,
    /// Held, and past anything its writer could have added (after the last number
    /// logged, or the one after it).
    pub unacknowledged: Vec<String>,
    /// Lines of the logs that were not whole (a kill in the middle of one write is
    /// not expected: each line is one write).
    pub malformed_lines: u64,
}

impl Checked {
    /// True if nothing acknowledged is missing, doubled or invented.
    #[cfg(test)]
    pub fn passed(&self) -> bool {
        self.lost.is_empty() && self.duplicated.is_empty() && self.unacknowledged.is_empty()
    }
}

/// The acknowledged numbers of every trajectory, from the logs of `workers` workers in
/// `run`.
pub fn read_acks(run: &Path, workers: usize) -> anyhow::Result<(BTreeMap<String, Vec<i64>>, u64)> {
    let mut acks: BTreeMap<String, Vec<i64>> = BTreeMap::new();
    let mut malformed = 0;
    for i in 0..workers {
        let path = super::worker::ack_log(run, i);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(anyhow::anyhow!("cannot read {}: {e}", path.display())),
        };
        for line in text.lines() {
            let mut words = line.split(' ');
            match (words.next(), words.next(), words.next().map(str::parse::<i64>), words.next()) {
                (Some("ACK"), Some(name), Some(Ok(n)), None) => {
                    acks.entry(name.to_owned()).or_default().push(n);
                }
                _ => malformed += 1,
            }
        }
    }
    Ok((acks, malformed))
}

/// Checks trajectory `name`, which keeps the last `cache` structures, holding the
/// numbers `held` (oldest first), against the numbers its writer acknowledged.
pub fn check_one(name: &str, cache: usize, acked: &[i64], held: &[i64], into: &mut Checked) {
    into.acknowledged += acked.len() as u64;
    let held_set: BTreeSet<i64> = held.iter().copied().collect();
    // The writer numbers on from what it holds: at most one past the last logged.
    let beyond = acked.last().map_or(0, |last| last + 1);
    // Every number up to the newest was added once, logged or not: the cache keeps the
    // last `cache` of them.
    let possible = held.iter().copied().filter(|n| *n <= beyond);
    let newest = acked.iter().copied().chain(possible).max().unwrap_or(-1);
    let oldest_kept = newest - cache as i64 + 1;
    for n in acked {
        if *n < oldest_kept {
            into.evicted_by_policy += 1;
            continue;
        }
        into.checked += 1;
        if !held_set.contains(n) {
            into.lost.push(format!("{name} #{n}"));
        }
    }
    if held_set.len() != held.len() {
        let mut seen = BTreeSet::new();
        for n in held {
            if !seen.insert(*n) {
                into.duplicated.push(format!("{name} #{n}"));
            }
        }
    }
    let acked_set: BTreeSet<i64> = acked.iter().copied().collect();
    for n in &held_set {
        if *n < 0 || *n > beyond {
            into.unacknowledged.push(format!("{name} #{n}"));
        } else if !acked_set.contains(n) {
            into.unlogged += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_cache_acknowledged_must_be_held() {
        let mut c = Checked::default();
        check_one("a", 3, &[0, 1, 2, 3, 4], &[2, 3, 4], &mut c);
        assert!(c.passed(), "{c:?}");
        assert_eq!((c.acknowledged, c.checked, c.evicted_by_policy), (5, 3, 2));
        // One the writer added and was killed before logging: allowed, counted.
        check_one("b", 3, &[0, 1, 2], &[1, 2, 3], &mut c);
        assert!(c.passed(), "{c:?}");
        assert_eq!(c.unlogged, 1);
        // One unlogged inside the window counts in the cache.
        let mut d = Checked::default();
        check_one("d", 3, &[0, 1, 2, 4, 5], &[3, 4, 5], &mut d);
        assert!(d.passed(), "{d:?}");
        assert_eq!((d.checked, d.evicted_by_policy, d.unlogged), (2, 3, 1));
        // A gap, a double and an invention are each named.
        check_one("c", 3, &[0, 1, 2, 3], &[1, 3, 3, 9], &mut c);
        assert_eq!(c.lost, ["c #2"]);
        assert_eq!(c.duplicated, ["c #3"]);
        assert_eq!(c.unacknowledged, ["c #9"]);
    }
}
