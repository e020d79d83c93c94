//! Samples: entity structures as answers (M3, Definition 3.3.7).

use std::ops::Deref;
use std::sync::Arc;

use crate::lineage::Lineage;
use crate::structure::SharedStructure;
use crate::time::Time;

/// An entity structure as stored in a trajectory or returned by a query.
///
/// The structure is a [`SharedStructure`]: shared, never copied, between the store,
/// its subscribers and computational units, and for a structure another process wrote,
/// read in place where it arrived (P7): nothing is decoded until a reader asks for an
/// owned [`crate::EntityStructure`] ([`SharedStructure::to_structure`]). `Sample` derefs
/// to it, so `sample.valid_time()` and `sample.get("x")` work directly.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The structure (name, valid time, create time, attributes).
    pub structure: SharedStructure,
    /// When the structure entered the trajectory (Definition 3.3.9's add time).
    pub add_time: Time,
    /// When the query this sample answers was asked (Definition 3.3.6). For a sample
    /// delivered to a subscriber, the add time.
    pub query_time: Time,
    /// For an answer interpolated by [`crate::ValueApproximation::Linear`]: the
    /// attributes that could not be interpolated (sequences whose lengths differ, a
    /// value of another sort on one side) and hold the most recent value before the
    /// query time instead, by path (`blobs`, `pose.points`). `None` for a stored sample
    /// and for an answer interpolated throughout, so a caller can tell the two apart;
    /// [`crate::ValueApproximation::LinearStrict`] refuses such an answer instead.
    pub not_interpolated: Option<Arc<[String]>>,
    /// The input structures this one was made from, for a structure a computed, sync,
    /// merge or generated trajectory added ([`crate::lineage`]); `None` for a pushed or
    /// sampled structure, and for an answer interpolated from several.
    pub lineage: Option<Arc<Lineage>>,
}

impl Sample {
    /// A stored (or delivered) structure: added at `add_time`, answering a query asked
    /// at `query_time`.
    pub fn new(structure: impl Into<SharedStructure>, add_time: Time, query_time: Time) -> Self {
        Self {
            structure: structure.into(),
            add_time,
            query_time,
            not_interpolated: None,
            lineage: None,
        }
    }

    /// The same sample, naming the inputs it was made from.
    #[must_use]
    pub fn with_lineage(mut self, lineage: Option<Arc<Lineage>>) -> Self {
        self.lineage = lineage;
        self
    }

    /// Delay between the valid time and the add time: what a delay constraint bounds.
    pub fn add_delay(&self) -> Time {
        // Both times come from writers, possibly other processes or hosts: an extreme
        // valid time saturates instead of overflowing.
        self.add_time.saturating_sub(self.structure.valid_time())
    }

    /// The same sample answering a query asked at `query_time`.
    #[must_use]
    pub fn at_query_time(mut self, query_time: Time) -> Self {
        self.query_time = query_time;
        self
    }
}

impl Deref for Sample {
    type Target = SharedStructure;
    fn deref(&self) -> &SharedStructure {
        &self.structure
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Any writer chooses the valid time: the extreme one must not panic a reader that
    /// shows the add delay (`esgm latest`, `echo`, `hz`, the demo).
    #[test]
    fn the_add_delay_of_an_extreme_valid_time_saturates() {
        let es = crate::EntityStructure::new("x", Time::MIN, 0);
        assert_eq!(Sample::new(es, 5, 5).add_delay(), Time::MAX);
        let es = crate::EntityStructure::new("x", Time::MAX, 0);
        assert_eq!(Sample::new(es, -5, -5).add_delay(), Time::MIN);
    }
}
