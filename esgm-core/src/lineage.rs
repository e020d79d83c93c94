//! Lineage (SPEC X1): which input structures an output was made from.
//!
//! Every structure that a computed, sync, merge or generated trajectory adds carries
//! the inputs it was made from, so that "which inputs made this output?" is a lookup,
//! not a guess from timestamps. An input is named so that any process can find it
//! again in its trajectory's history: by the trajectory, the trajectory's generation
//! (a trajectory destroyed and created again under the same name is another stream),
//! and the structure's valid time and add time. The add time is the writer's gate
//! stamp, the same in every process that holds the trajectory, so it identifies the
//! structure among others valid at the same time; a process-local add sequence would
//! not.
//!
//! Pushed and sampled structures have no lineage: they are where a trace ends.

use crate::time::Time;

/// One input structure an output was made from.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct InputRef {
    /// The input trajectory's name.
    pub trajectory: String,
    /// The input trajectory's generation when the structure was read: in the
    /// in-process runtime a number each created trajectory gets, across processes the
    /// coordinator's registry generation.
    pub generation: u64,
    /// The input structure's valid time.
    pub valid_time: Time,
    /// When the input structure entered its trajectory (the writer's add time).
    pub add_time: Time,
}

/// The input structures one output was made from, in input order.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct Lineage {
    /// The inputs, one per input trajectory for a unit or a sync, one for a merge, the
    /// samples a generator's value was taken or interpolated from.
    pub inputs: Vec<InputRef>,
    /// True if `inputs` is everything the producer read. A computational unit is handed
    /// its inputs, but it may also query other trajectories through handles it holds;
    /// esgm does not see those reads, so a unit's lineage says `false`. Syncs, merges
    /// and generators read only what they list.
    pub complete: bool,
}

impl Lineage {
    /// Lineage naming `inputs`, complete (`complete` is true).
    pub fn of(inputs: Vec<InputRef>) -> Self {
        Self { inputs, complete: true }
    }

    /// The same inputs, marked as possibly incomplete (a unit's).
    #[must_use]
    pub fn with_unrecorded_reads(mut self) -> Self {
        self.complete = false;
        self
    }

    /// The latest add time among the inputs: what the output waited for. `None` with
    /// no inputs.
    pub fn last_input_added(&self) -> Option<Time> {
        self.inputs.iter().map(|i| i.add_time).max()
    }
}
