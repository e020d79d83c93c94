//! Fluent generators over a trajectory (G1, seed 3.3.4): a total function from time to
//! value, built from a stream by an approximation rule and a merge rule.

use crate::approximation::{MergeRule, ValueApproximation, interpolated, merge_shared};
use crate::sample::Sample;
use crate::store::{QueryError, TrajectoryStore};
use crate::structure::SharedStructure;
use crate::time::Time;

/// The constraints of a fluent generator: how to approximate between samples and how
/// to merge samples sharing a valid time.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct GeneratorPolicy {
    /// Value approximation constraint.
    pub approximation: ValueApproximation,
    /// Merge constraint.
    pub merge: MergeRule,
}

/// A read-only generator view of a trajectory's current content.
#[derive(Debug, Clone, Copy)]
pub struct FluentGenerator<'a> {
    store: &'a TrajectoryStore,
    policy: &'a GeneratorPolicy,
}

impl TrajectoryStore {
    /// A generator view of this trajectory under `policy`.
    pub fn generator<'a>(&'a self, policy: &'a GeneratorPolicy) -> FluentGenerator<'a> {
        FluentGenerator { store: self, policy }
    }
}

impl FluentGenerator<'_> {
    /// The merged structure of the samples valid exactly at `t`, if any, and the
    /// (valid time, add time) of each.
    fn group_at(&self, t: Time) -> Option<(SharedStructure, Sources)> {
        let group = self.store.history.exactly_at(t);
        let refs: Vec<&SharedStructure> = group.iter().map(|e| &e.es).collect();
        let sources = group.iter().map(|e| (e.vt, e.add_time)).collect();
        merge_shared(&refs, self.policy.merge).map(|es| (es, sources))
    }

    /// The value at `t`: the merged samples valid at `t`, or else the approximation of
    /// the merged neighbours. The answer is stamped with the query time.
    pub fn value_at(&self, t: Time) -> Result<Sample, QueryError> {
        self.value_at_from(t).map(|(sample, _)| sample)
    }

    /// [`Self::value_at`], and the stored samples the value was taken or interpolated
    /// from, each as its (valid time, add time): what a generated structure's lineage
    /// names ([`crate::lineage`]).
    pub fn value_at_from(&self, t: Time) -> Result<(Sample, Sources), QueryError> {
        let now = self.store.clock().now();
        let wrap = |(es, from): (SharedStructure, Sources)| (Sample::new(es, now, now), from);
        if let Some(group) = self.group_at(t) {
            return Ok(wrap(group));
        }
        let h = &self.store.history;
        let before = h.before(t).and_then(|e| self.group_at(e.vt));
        let after = h.after(t).and_then(|e| self.group_at(e.vt));
        let fail = |why: &str| self.store.not_available(format!("value_at({t}): {why}"));
        match &self.policy.approximation {
            rule @ (ValueApproximation::Linear | ValueApproximation::LinearStrict) => {
                match (before, after) {
                    (Some((b, mut from)), Some((a, after_from))) => {
                        from.extend(after_from);
                        interpolated(&b, &a, t, now, rule)
                            .map(|sample| (sample, from))
                            .map_err(|w| fail(&w))
                    }
                    _ => Err(fail("linear needs samples on both sides")),
                }
            }
            ValueApproximation::MostRecent => {
                before.map(wrap).ok_or_else(|| fail("nothing before"))
            }
            ValueApproximation::Closest => match (before, after) {
                (Some(b), Some(a)) => Ok(wrap(
                    if i128::from(t) - i128::from(b.0.valid_time())
                        <= i128::from(a.0.valid_time()) - i128::from(t)
                    {
                        b
                    } else {
                        a
                    },
                )),
                (Some(x), None) | (None, Some(x)) => Ok(wrap(x)),
                (None, None) => Err(fail("the trajectory is empty")),
            },
            // Default and none do not depend on neighbours: reuse the query's rules,
            // whose answer is a stored sample.
            other => self.store.get_at_approximating(t, other).map(|sample| {
                let from = vec![(sample.valid_time(), sample.add_time)];
                (sample, from)
            }),
        }
    }
}

/// The stored samples a generator's value came from, each as its (valid time, add
/// time).
pub type Sources = Vec<(Time, Time)>;
