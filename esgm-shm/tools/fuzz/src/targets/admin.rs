//! The admin channel ([`esgm_shm::unstable::AdminReader`]): what a process does with the
//! bytes any other process of the domain publishes on it. A question is decoded and
//! answered (the reply encoded and read back, as the asker reads it); the answers to
//! this process's question are collected and combined as `domain_stats`,
//! `domain_memory`, a flush round and a domain reset combine them, which add up
//! counts other processes chose.
//!
//! An input is one message per line (several processes answering one question; the
//! same answer twice adds its counts twice). Promises checked beyond "no panic": every
//! reply this process makes reads back, and every seed decodes.

use std::sync::LazyLock;

use esgm_core::esgm::{Esgm, MemoryStats, TrajectorySpec};
use esgm_core::{DropCause, InProcessEsgm};
use esgm_shm::unstable::AdminReader;
use serde_json::json;

use crate::json::{json_tokens, mutate_json};
use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};
use crate::text::mutate_text;

/// The asker this process is, and its question, as the seeds' answers name them.
const HOST: &str = "esgm-fuzz";
const QUESTION: u64 = 1;

/// JSON's tokens, the channel's variant names and a duration at its limit.
static TOKENS: LazyLock<Vec<&str>> = LazyLock::new(|| {
    json_tokens(&[
        "\"Ask\"",
        "\"Answer\"",
        "\"Flush\"",
        "\"Stats\"",
        "\"Memory\"",
        "\"Done\"",
        "\"Failed\"",
        "\"Lost\"",
        "{\"secs\":18446744073709551615,\"nanos\":999999999}",
        "\"esgm-fuzz\"",
        "\n",
    ])
});

/// The admin target.
#[derive(Debug)]
pub struct Admin {
    reader: AdminReader,
    /// Valid messages, one each, to mutate and splice from.
    messages: Vec<Vec<u8>>,
    seeds: Vec<Vec<u8>>,
}

/// Answers to this process's question as a writer and a reader of one trajectory send
/// them: statistics of a real trajectory, with drops a reader saw, and memory.
fn generated_answers() -> Result<Vec<Vec<u8>>, Broken> {
    let local = InProcessEsgm::default();
    local
        .create_trajectory(TrajectorySpec::primitive("robot_state", "RobotState"))
        .map_err(|e| Broken::new("a trajectory is created for the seeds", e))?;
    let report = local
        .stats_here()
        .trajectories
        .remove("robot_state")
        .ok_or_else(|| Broken::new("a new trajectory has statistics", "none"))?;
    let answer = |from: &str, answer: serde_json::Value| json!({"from": from, "id": QUESTION, "body": {"Answer": {"to": HOST, "answer": answer}}});
    // A row as a process sends it: name, writes, the store's counts (added,
    // dropped_total, violations, evicted, stored, held, subscribers, overflow, missed
    // sample points), drops by cause, rate, add delays, the worker's counters.
    let row = |writes: bool| {
        json!([
            report.info.name,
            writes,
            [1_000, 3, 0, 0, 5, 0, 1, 0, 0],
            [[DropCause::Lost, 3]],
            report.stats.rate_hz,
            [report.stats.add_delay_p50, null, null, report.stats.add_delay_max],
            [7, 7, 0, 0, 0, 0, 0, 0, 0, 0]
        ])
    };
    let memory =
        MemoryStats { trajectories: 1, stored_samples: 10, held_samples: 0, approx_bytes: 4096 };
    let messages = [
        answer("robot-robot", json!({"Stats": [row(true)]})),
        answer("unit-detector", json!({"Stats": [row(false)]})),
        answer("unit-detector", json!({"Memory": memory})),
    ];
    messages
        .iter()
        .map(|m| serde_json::to_vec(m).map_err(|e| Broken::new("a seed answer encodes", e)))
        .collect()
}

impl Admin {
    /// The messages of `seeds/admin.jsonl` (every question and answer kind) and
    /// generated statistics answers; each alone, and all together.
    pub fn new() -> Result<Self, Broken> {
        let mut messages: Vec<Vec<u8>> = include_str!("../../seeds/admin.jsonl")
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| l.as_bytes().to_vec())
            .collect();
        messages.extend(generated_answers()?);
        let mut seeds = messages.clone();
        seeds.push(messages.join(&b'\n'));
        Ok(Self { reader: AdminReader::default(), messages, seeds })
    }

    /// One mutated message.
    fn message(&self, rng: &mut Rng, message: &[u8]) -> Vec<u8> {
        match rng.below(10) {
            0 => {
                let n = rng.len(1024);
                rng.bytes(n)
            }
            1..=5 => mutate_json(rng, message, &self.messages).unwrap_or_else(|| message.to_vec()),
            6..=8 => {
                let mut data = message.to_vec();
                mutate_text(rng, &mut data, &self.messages, &TOKENS);
                data
            }
            _ => {
                let mut data = message.to_vec();
                mutate(rng, &mut data, &self.messages);
                data
            }
        }
    }
}

impl Target for Admin {
    fn name(&self) -> &'static str {
        "admin"
    }

    fn about(&self) -> &'static str {
        "admin channel: questions answered, answers combined (AdminReader::read)"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        // Half the time every message at once: answers to sum, as a domain gives them.
        let seed = if rng.chance(50) {
            self.seeds.last().unwrap_or_else(|| rng.pick(&self.seeds))
        } else {
            rng.pick(&self.seeds)
        };
        let mut lines: Vec<Vec<u8>> = seed.split(|b| *b == b'\n').map(<[u8]>::to_vec).collect();
        for _ in 0..1 + rng.below(2) {
            let at = rng.below(lines.len());
            lines[at] = self.message(rng, &lines[at]);
        }
        // Another process may answer any number of times.
        if rng.chance(30) {
            let line = rng.pick(&lines).clone();
            lines.push(line);
        }
        lines.join(&b'\n')
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        let messages: Vec<&[u8]> = input.split(|b| *b == b'\n').collect();
        self.reader
            .read(HOST, QUESTION, &messages)
            .map(|_| ())
            .map_err(|e| Broken::new("every reply this process makes reads back", e))
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        let messages: Vec<&[u8]> = seed.split(|b| *b == b'\n').collect();
        let read = self
            .reader
            .read(HOST, QUESTION, &messages)
            .map_err(|e| Broken::new("every reply this process makes reads back", e))?;
        if read.malformed > 0 {
            return Err(Broken::new("every seed message decodes", format!("{read:?}")));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutated inputs must still carry answers to the question often enough to reach
    /// the sums.
    #[test]
    fn many_inputs_reach_the_sums() {
        let target = Admin::new().unwrap_or_else(|e| panic!("{e}"));
        let answered = (0..1_000)
            .filter(|i| {
                let input = target.input(&mut Rng::for_case(5, *i));
                let messages: Vec<&[u8]> = input.split(|b| *b == b'\n').collect();
                target.reader.read(HOST, QUESTION, &messages).is_ok_and(|r| r.answers > 0)
            })
            .count();
        assert!(answered > 200, "{answered} of 1000 reached the sums");
    }
}
