//! Why a trajectory has not produced (SPEC X2): what esgm knows of a silent pipeline,
//! in one answer. A producer's calls and their outcomes, each input's latest structure
//! and age, what a sync waits for, each constraint's drops with the last structure it
//! dropped, missed sample points, and whether the writer is alive: the counters esgm
//! always kept, joined with the recent events behind them, and read as reasons.

use crate::operators::sync::InputDrops;
use crate::store::{DropCause, DropRecord};
use crate::time::{Time, for_people as seconds};

use super::{TrajectoryKind, WorkerStats};

/// How many of a producer's most recent calls are remembered, with their outcomes.
pub const RECENT_CALLS: usize = 16;

/// The answer to "why has this trajectory not produced since `since`?".
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Why {
    /// The trajectory.
    pub trajectory: String,
    /// Primitive, sampled, computed, sync, merge or generated.
    pub kind: TrajectoryKind,
    /// The time asked about.
    pub since: Time,
    /// When the answer was made (the writer's clock).
    pub now: Time,
    /// When a structure last entered the trajectory (`None`: never).
    pub last_added: Option<Time>,
    /// Structures that entered since `since`, as far as the recent adds remembered
    /// reach back (the last 128).
    pub added_since: u64,
    /// Every input: its latest structure, its age, its writer.
    pub inputs: Vec<InputHealth>,
    /// The producer's (sensor's, unit's or operator's) counters, if it has one.
    pub worker: Option<WorkerStats>,
    /// Its most recent calls, oldest first.
    pub recent_calls: Vec<CallRecord>,
    /// A sync's wait: which input it waits for, and how far apart the inputs are.
    pub sync: Option<SyncWait>,
    /// A sampled (or sampled generator) trajectory's recent skips of sample points
    /// (the last [`RECENT_CALLS`]), oldest first, each with its cause.
    #[serde(default)]
    pub missed: Vec<MissedPoints>,
    /// The trajectory's drops since `since`, per cause, with the last one's detail.
    pub drops: Vec<DropSummary>,
    /// Whether the process that writes the trajectory is alive (`None`: this runtime
    /// has one process, or it could not tell).
    pub writer_alive: Option<bool>,
    /// The last time another process became the writer (a restart, or a take-over
    /// of a trajectory whose writer was gone): what the trajectory holds since then is
    /// the new writer's. `None`: one writer since it was made, or one process.
    #[serde(default)]
    pub writer_changed: Option<WriterChange>,
    /// The reasons, most telling first, in words.
    pub reasons: Vec<String>,
}

/// Another process became a trajectory's writer.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WriterChange {
    /// How it came to write it.
    pub how: HowWriterChanged,
    /// The process (by its registry name) that wrote it before.
    pub from: String,
    /// That process's id, if it had reported one.
    pub from_pid: Option<u32>,
    /// The process that writes it now.
    pub to: String,
    /// Its id, once it has reported its publisher.
    pub to_pid: Option<u32>,
    /// When the registry recorded the change (the coordinator's clock).
    pub at: Time,
}

/// How a trajectory's writer changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HowWriterChanged {
    /// The writer's process ended and a new process of the same name (the supervisor's
    /// restart, or a program run again) reported itself as the writer.
    Restarted,
    /// The writer's process was gone (or had released it), and another process took
    /// the trajectory over to add to it.
    TakenOver,
}

/// One input of a produced trajectory, as the producer sees it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InputHealth {
    /// The input trajectory.
    pub trajectory: String,
    /// False if no trajectory of that name exists any more.
    pub exists: bool,
    /// Its latest structure's valid time (`None`: it holds none).
    pub latest_valid_time: Option<Time>,
    /// When that structure entered it.
    pub latest_add_time: Option<Time>,
    /// How long ago that was, at [`Why::now`].
    pub age: Option<Time>,
    /// Whether the process that writes it is alive (`None`: could not tell).
    pub writer_alive: Option<bool>,
}

/// One call of a producer and what came of it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CallRecord {
    /// When it returned.
    pub at: Time,
    /// What came of it (in JSON beside `at`: `"outcome": "failed", "detail": "…"`).
    #[serde(flatten)]
    pub outcome: CallOutcome,
}

/// What came of a producer's call.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "outcome", content = "detail")]
pub enum CallOutcome {
    /// It produced a structure, and the trajectory took it in (or held it).
    Produced,
    /// It produced a structure that the trajectory's policy dropped.
    Dropped(String),
    /// It said it had no value (`ValueNotAvailable`).
    NoValue,
    /// It failed, with this error.
    Failed(String),
    /// It panicked (or raised), with this message; the trajectory went on.
    Panicked(String),
    /// Its output did not fit the trajectory's type.
    InvalidOutput(String),
}

/// Sample points a sampler skipped at once, and why.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MissedPoints {
    /// When the sampler woke and found them past.
    pub at: Time,
    /// How many sample points it skipped.
    pub missed: u64,
    /// Why.
    pub cause: MissCause,
}

/// Why a sampler skipped sample points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MissCause {
    /// The producer's previous call (the sensor's `get_current_value`, or a
    /// generator's unit) took `took`, a period or more: the calls cannot keep up.
    SlowCall {
        /// How long it took.
        took: Time,
        /// The trajectory's period.
        period: Time,
    },
    /// The calls took less than the period, but the sampler's thread woke `late` after
    /// the sample time: the machine was busy, or the process was held (stopped,
    /// swapped, debugged).
    LateWakeUp {
        /// How late it woke.
        late: Time,
        /// The trajectory's period.
        period: Time,
    },
}

/// What a sync waits for.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SyncWait {
    /// The input whose latest structure is the oldest (or that holds none): the one a
    /// set waits for.
    pub waits_for: Option<String>,
    /// The newest input's latest valid time minus the waited-for input's.
    pub gap: Option<Time>,
    /// How far apart a set's members may be (`None`: exact times, or unbounded).
    pub tolerance: Option<Time>,
    /// Structures the sync gave up on (ApproximateTime's drops and queue overflow, as
    /// message_filters counts them), since the trajectory was made.
    pub discarded: u64,
    /// The same, per input and reason: which input's structures found no set, and
    /// why (its queue overflowed, no partner within the tolerance, passed over for a
    /// better set, …), with the last one's valid time.
    #[serde(default)]
    pub dropped: Vec<SyncInputDrops>,
}

/// One sync input's discarded structures.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SyncInputDrops {
    /// The input.
    pub input: String,
    /// Its drops, by reason.
    #[serde(flatten)]
    pub drops: InputDrops,
}

/// The drops of one cause since [`Why::since`].
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DropSummary {
    /// The cause (a constraint, a wrong type, …).
    pub cause: DropCause,
    /// How many the remembered drops hold since `since`.
    pub since: u64,
    /// How many in all, since the trajectory was made.
    pub total: u64,
    /// The last one.
    pub last: Option<DropRecord>,
}

impl Why {
    /// True if the trajectory produced since [`Why::since`].
    pub fn produced(&self) -> bool {
        self.last_added.is_some_and(|t| t >= self.since)
    }

    /// Works out [`Why::reasons`] from the rest: what a person debugging a silent
    /// pipeline reads first.
    pub fn explain(&mut self) {
        let mut out = Vec::new();
        if self.writer_alive == Some(false) {
            out.push(
                "its writer process is gone: nothing writes it until one takes it over".into(),
            );
        }
        if let Some(change) = &self.writer_changed {
            out.push(change.words(self.now, self.since));
        }
        match self.last_added {
            Some(t) if t >= self.since => out.push(format!(
                "it produced: {} structure(s) since the time asked, the last {} ago",
                self.added_since,
                seconds(self.now - t)
            )),
            Some(t) => out.push(format!(
                "nothing since the time asked; the last {} ago",
                seconds(self.now - t)
            )),
            None => out.push("it has never produced".into()),
        }
        for input in &self.inputs {
            let name = &input.trajectory;
            if !input.exists {
                out.push(format!("input `{name}` does not exist any more"));
            } else if input.writer_alive == Some(false) {
                out.push(format!("input `{name}`'s writer process is gone"));
            }
            match (input.latest_add_time, input.age) {
                (None, _) if input.exists => {
                    out.push(format!("input `{name}` holds no structure: the producer waits for it"))
                }
                (Some(t), Some(age)) if t < self.since => out.push(format!(
                    "input `{name}` has had nothing new since the time asked (its latest entered {} ago)",
                    seconds(age)
                )),
                _ => {}
            }
        }
        if let Some(sync) = &self.sync {
            if let Some(input) = &sync.waits_for {
                let gap = sync.gap.map(|g| format!(", {} behind the newest input", seconds(g)));
                let tolerance = sync
                    .tolerance
                    .map(|t| format!(" (tolerance {})", seconds(t)))
                    .unwrap_or_default();
                out.push(format!(
                    "the sync waits for `{input}`{}{tolerance}",
                    gap.unwrap_or_default()
                ));
            }
            if sync.discarded > 0 {
                out.push(format!(
                    "the sync gave up on {} structure(s) that found no set",
                    sync.discarded
                ));
            }
            for input in sync.dropped.iter().filter(|d| d.drops.total() > 0) {
                let reasons: Vec<String> = input
                    .drops
                    .by_reason()
                    .iter()
                    .map(|(reason, n)| format!("{n} {}", reason.words()))
                    .collect();
                let last = input
                    .drops
                    .last
                    .map(|(vt, _)| format!("; the last valid {} ago", seconds(self.now - vt)))
                    .unwrap_or_default();
                out.push(format!(
                    "the sync dropped {} of `{}`'s structure(s): {}{last}",
                    input.drops.total(),
                    input.input,
                    reasons.join(", ")
                ));
            }
        }
        if let Some(w) = &self.worker {
            if w.calls == 0
                && matches!(self.kind, TrajectoryKind::Sampled | TrajectoryKind::Computed)
            {
                out.push("its producer was never called".into());
            }
            let misses: Vec<&MissedPoints> =
                self.missed.iter().filter(|m| m.at >= self.since).collect();
            // The remembered skips reach back far enough, or the count is a floor.
            let all = self.missed.len() < RECENT_CALLS
                || self.missed.first().is_some_and(|m| m.at < self.since);
            if let Some(words) = missed_words(&misses, all) {
                out.push(words);
            } else if w.missed_periods > 0 {
                out.push(format!(
                    "{} sample point(s) were missed since it was made, none since the time asked",
                    w.missed_periods
                ));
            }
        }
        let since: Vec<&CallRecord> =
            self.recent_calls.iter().filter(|c| c.at >= self.since).collect();
        if let Some(last) = since.last() {
            let n = since.iter().filter(|c| c.outcome == last.outcome).count();
            match &last.outcome {
                CallOutcome::Produced => {}
                CallOutcome::NoValue => out.push(format!("its last {n} call(s) returned no value")),
                CallOutcome::Failed(e) => out.push(format!("its last call failed: {e}")),
                CallOutcome::Panicked(e) => out.push(format!("its last call raised: {e}")),
                CallOutcome::InvalidOutput(e) => {
                    out.push(format!("its last output did not fit the type: {e}"))
                }
                CallOutcome::Dropped(e) => {
                    out.push(format!("its last output was dropped by the policy: {e}"))
                }
            }
        } else if self.worker.as_ref().is_some_and(|w| w.calls > 0) && !self.produced() {
            out.push("its producer was not called since the time asked".into());
        }
        for d in &self.drops {
            if d.since == 0 {
                continue;
            }
            let last =
                d.last.as_ref().map(|l| format!("; the last: {}", l.detail)).unwrap_or_default();
            out.push(format!(
                "{} dropped {} structure(s) since the time asked{last}",
                cause_words(d.cause),
                d.since
            ));
        }
        self.reasons = out;
    }
}

impl WriterChange {
    /// The change as a reason: who writes it now, instead of whom, since when.
    fn words(&self, now: Time, since: Time) -> String {
        let pid = |p: Option<u32>| p.map(|p| format!(" (pid {p})")).unwrap_or_default();
        let when = if self.at >= since { "since the time asked" } else { "before the time asked" };
        let ago = seconds(now.saturating_sub(self.at));
        match self.how {
            HowWriterChanged::Restarted => format!(
                "its writer `{}` was restarted {ago} ago, {when}: process{} ended, process{} writes it now",
                self.to,
                pid(self.from_pid),
                pid(self.to_pid)
            ),
            HowWriterChanged::TakenOver => format!(
                "it was taken over {ago} ago, {when}: `{}`{} writes it now, instead of `{}`{}, which was gone; what it holds since is the new writer's",
                self.to,
                pid(self.to_pid),
                self.from,
                pid(self.from_pid)
            ),
        }
    }
}

/// The skips of sample points since the time asked, as one reason: how many, and the
/// cause of the worst of each kind.
fn missed_words(misses: &[&MissedPoints], all: bool) -> Option<String> {
    let n: u64 = misses.iter().map(|m| m.missed).sum();
    // The worst of each cause: (how long, the period).
    let worst = |slow_call: bool| {
        let of_cause = |m: &&&MissedPoints| match m.cause {
            MissCause::SlowCall { took, period } if slow_call => Some((took, period)),
            MissCause::LateWakeUp { late, period } if !slow_call => Some((late, period)),
            _ => None,
        };
        misses.iter().filter_map(|m| of_cause(&m)).max()
    };
    let (slowest, latest_wake) = (worst(true), worst(false));
    let mut causes = Vec::new();
    if let Some((took, period)) = slowest {
        causes.push(format!(
            "its producer's calls took up to {}, longer than its {} period",
            seconds(took),
            seconds(period)
        ));
    }
    if let Some((late, period)) = latest_wake {
        causes.push(format!(
            "its sampler woke up to {} late with calls shorter than its {} period (the machine was busy, or the process held)",
            seconds(late),
            seconds(period)
        ));
    }
    let floor = if all { "" } else { "at least " };
    (n > 0).then(|| {
        format!(
            "{floor}{n} sample point(s) were missed since the time asked: {}",
            causes.join("; ")
        )
    })
}

/// What dropped a structure, as a subject.
fn cause_words(cause: DropCause) -> String {
    match cause {
        DropCause::Violation(c) => format!("the {c} constraint"),
        DropCause::InvalidType => "the type check".into(),
        other => format!("{other:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missed_points_name_the_worst_of_each_cause_and_say_when_the_count_is_a_floor() {
        let slow = MissedPoints {
            at: 10,
            missed: 2,
            cause: MissCause::SlowCall { took: 30_000_000, period: 10_000_000 },
        };
        let late = MissedPoints {
            at: 20,
            missed: 4,
            cause: MissCause::LateWakeUp { late: 40_000_000, period: 10_000_000 },
        };
        let words = missed_words(&[&slow, &late], true).unwrap_or_default();
        assert!(words.starts_with("6 sample point(s) were missed since the time asked: its producer's calls took up to 30.0 ms, longer than its 10.0 ms period; its sampler woke up to 40.0 ms late"), "{words}");
        let floor = missed_words(&[&slow], false).unwrap_or_default();
        assert!(floor.starts_with("at least 2 sample point(s)"), "{floor}");
        assert_eq!(missed_words(&[], true), None);
    }
}
