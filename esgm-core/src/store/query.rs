//! Queries on a trajectory (T1, T2): by position in the stream and by valid time.
//!
//! Every answer is a [`Sample`] sharing the stored structure (no copy) and stamped
//! with the query time. Time lookups are O(log n); `get_between` is O(log n + k).

use super::TrajectoryStore;
use super::history::Entry;
use crate::approximation::{ValueApproximation, interpolated};
use crate::sample::Sample;
use crate::time::Time;
use crate::type_check::InvalidType;
use crate::value::frame::EntityStructure;

/// Errors of the query operations.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum QueryError {
    /// No sample answers the query (the seed's `ValueNotAvailable`): the trajectory is
    /// empty, the time is outside what the cache holds, or no approximation applies.
    #[error("value not available in `{trajectory}`: {query}")]
    ValueNotAvailable {
        /// The trajectory.
        trajectory: String,
        /// The query and why it has no answer.
        query: String,
    },
    /// The trajectory behind this handle was destroyed; get a new handle by name.
    #[error("no entity trajectory structure `{trajectory}` (destroyed)")]
    NoSuchEntityStructure {
        /// The trajectory's name.
        trajectory: String,
    },
    /// A default value for approximation does not fit the trajectory's type.
    #[error("default value for `{trajectory}` does not fit its type: {source}")]
    InvalidDefault {
        /// The trajectory.
        trajectory: String,
        /// What did not fit.
        source: InvalidType,
    },
    /// The trajectory lives in other processes too and they could not be reached (see
    /// the reason): a reset through a replica, whose writer is elsewhere, or a
    /// blocking reset whose readers did not all answer.
    #[error("trajectory `{trajectory}`: other processes cannot be reached: {reason}")]
    Unavailable {
        /// The trajectory.
        trajectory: String,
        /// Why.
        reason: crate::failures::Unreachable,
    },
}

impl TrajectoryStore {
    pub(crate) fn not_available(&self, query: impl Into<String>) -> QueryError {
        QueryError::ValueNotAvailable { trajectory: self.name.clone(), query: query.into() }
    }

    pub(crate) fn sample_of(&self, e: &Entry, now: Time) -> Sample {
        Sample::new(e.es.clone(), e.add_time, now).with_lineage(e.lineage.clone())
    }

    /// Number of stored samples.
    pub fn len(&self) -> usize {
        self.history.len()
    }

    /// True if no sample is stored.
    pub fn is_empty(&self) -> bool {
        self.history.is_empty()
    }

    /// The latest sample added.
    pub fn get_latest(&self) -> Result<Sample, QueryError> {
        self.get_nth_latest(0)
            .map_err(|_| self.not_available("get_latest: the trajectory is empty"))
    }

    /// The `n`-th latest sample in add order (0 = latest).
    pub fn get_nth_latest(&self, n: usize) -> Result<Sample, QueryError> {
        let now = self.clock.now();
        self.history.nth_latest(n).map(|e| self.sample_of(e, now)).ok_or_else(|| {
            self.not_available(format!(
                "get_nth_latest({n}): {} samples stored",
                self.history.len()
            ))
        })
    }

    /// Every sample with valid time in `[from, to]`, ordered by valid time (ties in add
    /// order). Empty if none (or if `from > to`).
    pub fn get_between(&self, from: Time, to: Time) -> Vec<Sample> {
        let now = self.clock.now();
        self.history.between(from, to).into_iter().map(|e| self.sample_of(e, now)).collect()
    }

    /// The sample valid exactly at `t` (the latest added if several are).
    pub fn get_at(&self, t: Time) -> Result<Sample, QueryError> {
        let now = self.clock.now();
        self.history
            .at_or_before(t)
            .filter(|e| e.vt == t)
            .map(|e| self.sample_of(e, now))
            .ok_or_else(|| self.not_available(format!("get_at({t}): no sample valid at {t}")))
    }

    /// The sample with the largest valid time not after `t`.
    pub fn get_closest_at_or_before(&self, t: Time) -> Result<Sample, QueryError> {
        let now = self.clock.now();
        self.history.at_or_before(t).map(|e| self.sample_of(e, now)).ok_or_else(|| {
            self.not_available(format!("get_closest_at_or_before({t}): no sample at or before {t}"))
        })
    }

    /// The most current value (the seed's `get_latest_vtime`): the sample with the
    /// latest valid time (of several, the one added last).
    pub fn get_latest_vtime(&self) -> Result<Sample, QueryError> {
        let now = self.clock.now();
        self.history
            .at_or_before(Time::MAX)
            .map(|e| self.sample_of(e, now))
            .ok_or_else(|| self.not_available("get_latest_vtime: the trajectory is empty"))
    }

    /// The value at `t`, approximated by `aprx` when no sample is valid exactly at `t`.
    /// Interpolated and default values are new structures valid at `t` and created at
    /// the query time.
    pub fn get_at_approximating(
        &self,
        t: Time,
        aprx: &ValueApproximation,
    ) -> Result<Sample, QueryError> {
        let now = self.clock.now();
        // The exact sample, if any, without building get_at's error on a miss.
        if let Some(e) = self.history.at_or_before(t).filter(|e| e.vt == t) {
            return Ok(self.sample_of(e, now));
        }
        let q = |what: &str| format!("get_at_approximating({t}, {what})");
        match aprx {
            ValueApproximation::None => {
                Err(self.not_available(q("none: no sample valid at that time")))
            }
            ValueApproximation::MostRecent => self
                .history
                .before(t)
                .map(|e| self.sample_of(e, now))
                .ok_or_else(|| self.not_available(q("most recent: nothing before it"))),
            ValueApproximation::Closest => {
                let before = self.history.before(t);
                let after = self.history.after(t);
                let pick = match (before, after) {
                    (Some(b), Some(a)) => {
                        // In i128: distances between extreme i64 times overflow i64.
                        if i128::from(t) - i128::from(b.vt) <= i128::from(a.vt) - i128::from(t) {
                            b
                        } else {
                            a
                        }
                    }
                    (Some(x), None) | (None, Some(x)) => x,
                    (None, None) => {
                        return Err(self.not_available(q("closest: the trajectory is empty")));
                    }
                };
                Ok(self.sample_of(pick, now))
            }
            ValueApproximation::Default(attributes) => {
                self.checker.check(attributes).map_err(|source| QueryError::InvalidDefault {
                    trajectory: self.name.clone(),
                    source,
                })?;
                let es = EntityStructure {
                    name: self.name.clone(),
                    valid_time: t,
                    create_time: now,
                    attributes: attributes.clone(),
                };
                Ok(Sample::new(es, now, now))
            }
            ValueApproximation::Linear | ValueApproximation::LinearStrict => {
                match (self.history.before(t), self.history.after(t)) {
                    (Some(b), Some(a)) => interpolated(&b.es, &a.es, t, now, aprx)
                        .map_err(|why| self.not_available(q(&why))),
                    (None, _) => Err(self.not_available(q("linear: nothing before it"))),
                    (_, None) => Err(self.not_available(q("linear: nothing after it"))),
                }
            }
        }
    }

    /// The earliest valid time stored (the start of the trajectory's interval).
    pub fn start_time(&self) -> Result<Time, QueryError> {
        self.history.min_valid_time().ok_or_else(|| self.not_available("start_time: empty"))
    }

    /// The latest valid time stored (the end of the trajectory's interval).
    pub fn end_time(&self) -> Result<Time, QueryError> {
        self.history.max_valid_time().ok_or_else(|| self.not_available("end_time: empty"))
    }

    /// Approximate bytes held by stored samples; octet buffers in `seen` are not
    /// counted again.
    pub fn approx_bytes(&self, seen: &mut std::collections::HashSet<usize>) -> usize {
        self.history.iter().map(|e| e.es.approx_bytes(seen)).sum()
    }

    /// Every stored sample in add order (for recording and inspection).
    pub fn samples(&self) -> Vec<Sample> {
        let now = self.clock.now();
        self.history.iter().map(|e| self.sample_of(e, now)).collect()
    }
}
