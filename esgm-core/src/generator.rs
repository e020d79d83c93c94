//! Fluent generators over a trajectory (G1, seed 3.3.4): a total function from time to
//! value, built from a stream by an approximation rule and a merge rule.

use std::sync::Arc;

use crate::approximation::{MergeRule, ValueApproximation, interpolated, merge};
use crate::sample::Sample;
use crate::store::{QueryError, TrajectoryStore};
use crate::time::Time;
use crate::value::frame::EntityStructure;

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
    /// The merged structure of the samples valid exactly at `t`, if any.
    fn group_at(&self, t: Time) -> Option<EntityStructure> {
        let group = self.store.history.exactly_at(t);
        let refs: Vec<&EntityStructure> = group.iter().map(|e| e.es.as_ref()).collect();
        merge(&refs, self.policy.merge)
    }

    /// The value at `t`: the merged samples valid at `t`, or else the approximation of
    /// the merged neighbours. The answer is stamped with the query time.
    pub fn value_at(&self, t: Time) -> Result<Sample, QueryError> {
        let now = self.store.clock().now();
        let wrap = |es: EntityStructure| Sample::new(Arc::new(es), now, now);
        if let Some(es) = self.group_at(t) {
            return Ok(wrap(es));
        }
        let h = &self.store.history;
        let before = h.before(t).and_then(|e| self.group_at(e.vt));
        let after = h.after(t).and_then(|e| self.group_at(e.vt));
        let fail = |why: &str| self.store.not_available(format!("value_at({t}): {why}"));
        match &self.policy.approximation {
            rule @ (ValueApproximation::Linear | ValueApproximation::LinearStrict) => {
                match (before, after) {
                    (Some(b), Some(a)) => interpolated(&b, &a, t, now, rule).map_err(|w| fail(&w)),
                    _ => Err(fail("linear needs samples on both sides")),
                }
            }
            ValueApproximation::MostRecent => {
                before.map(wrap).ok_or_else(|| fail("nothing before"))
            }
            ValueApproximation::Closest => match (before, after) {
                (Some(b), Some(a)) => Ok(wrap(
                    if i128::from(t) - i128::from(b.valid_time)
                        <= i128::from(a.valid_time) - i128::from(t)
                    {
                        b
                    } else {
                        a
                    },
                )),
                (Some(x), None) | (None, Some(x)) => Ok(wrap(x)),
                (None, None) => Err(fail("the trajectory is empty")),
            },
            // Default and none do not depend on neighbours: reuse the query's rules.
            other => self.store.get_at_approximating(t, other),
        }
    }
}
