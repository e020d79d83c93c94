//! Tracing one structure back to the sensors and pushed trajectories it came from
//! (SPEC X1): the tree of inputs that [`crate::lineage`] records, looked up hop by hop
//! in each input trajectory's history, with the time each hop took.
//!
//! It runs on the [`Esgm`] interface, so the same trace answers in process and across
//! processes (where every lookup reads this process's replica, without a round trip).

use crate::lineage::InputRef;
use crate::sample::Sample;
use crate::time::Time;

use super::{EntityTrajectoryStructure, Esgm};

/// At most this many hops back from the structure traced: a pipeline deeper than a
/// robot's is cut off there (and says so), never followed without end.
pub const MAX_TRACE_DEPTH: usize = 32;

/// At most this many structures in one trace: a wide fan-in (a merge of many inputs,
/// each a sync of many) is cut off there and says so.
pub const MAX_TRACE_NODES: usize = 4096;

/// One structure in a trace, and the structures it was made from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TraceNode {
    /// The trajectory that holds it.
    pub trajectory: String,
    /// The generation the output that read it named (`None` for the structure traced).
    pub generation: Option<u64>,
    /// Its valid time.
    pub valid_time: Time,
    /// When it entered its trajectory.
    pub add_time: Time,
    /// How long this hop took: its add time minus the latest add time of its inputs
    /// (the time the producer and the way to it added). `None` for a structure with no
    /// inputs found.
    pub hop: Option<Time>,
    /// How it was found.
    pub found: Found,
    /// True if its inputs are everything its producer read (see
    /// [`crate::lineage::Lineage::complete`]); true for a structure with no lineage.
    pub complete: bool,
    /// The structures it was made from, in input order; empty for a pushed or sampled
    /// structure (where the trace ends).
    pub inputs: Vec<TraceNode>,
}

/// Whether a structure named in a lineage was found in its trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Found {
    /// Found in its trajectory's history.
    Stored,
    /// Its trajectory no longer holds it: its cache evicted it, or it was reset. Its
    /// own inputs are unknown.
    Evicted,
    /// No trajectory of that name exists any more (destroyed), or this process cannot
    /// reach it.
    NoTrajectory,
    /// Not followed: the trace reached [`MAX_TRACE_DEPTH`] or [`MAX_TRACE_NODES`].
    CutOff,
}

impl TraceNode {
    /// Every hop's structures from this one back, depth first: for summing or
    /// printing.
    pub fn walk(&self) -> Vec<(usize, &TraceNode)> {
        let mut out = Vec::new();
        let mut stack = vec![(0, self)];
        while let Some((depth, node)) = stack.pop() {
            out.push((depth, node));
            stack.extend(node.inputs.iter().rev().map(|n| (depth + 1, n)));
        }
        out
    }

    /// The structures where the trace ends: the sensors' and pushed trajectories'
    /// (and those not found).
    pub fn sources(&self) -> Vec<&TraceNode> {
        self.walk().into_iter().map(|(_, n)| n).filter(|n| n.inputs.is_empty()).collect()
    }

    /// The end-to-end latency: from the earliest found source entering its
    /// trajectory to this structure entering its own, with that source. `None` if no
    /// source was found.
    pub fn end_to_end(&self) -> Option<(Time, &TraceNode)> {
        let sources = self.sources();
        let first =
            sources.into_iter().filter(|n| n.found == Found::Stored).min_by_key(|n| n.add_time)?;
        Some((self.add_time.saturating_sub(first.add_time), first))
    }

    /// Each produced trajectory's hop time in this trace, in the order first met
    /// (depth first from this structure); where one appears more than once, its
    /// longest hop: the per-stage split of [`TraceNode::end_to_end`].
    pub fn stage_times(&self) -> Vec<(&str, Time)> {
        let mut out: Vec<(&str, Time)> = Vec::new();
        for (_, node) in self.walk() {
            let Some(hop) = node.hop else { continue };
            match out.iter_mut().find(|(t, _)| *t == node.trajectory) {
                Some((_, longest)) => *longest = (*longest).max(hop),
                None => out.push((&node.trajectory, hop)),
            }
        }
        out
    }
}

/// Traces `sample`, read from `trajectory`, back through the lineage of every
/// structure it was made from.
pub fn trace<E: Esgm>(esgm: &E, trajectory: &str, sample: &Sample) -> TraceNode {
    trace_with(|name| esgm.get_entity_trajectory_structure(name).ok(), trajectory, sample)
}

/// [`trace`], opening each input trajectory with `open` (`None`: it does not exist
/// or cannot be reached): a tool that connects late waits there for each history to
/// arrive, and may keep the handles it opened.
pub fn trace_with<T: EntityTrajectoryStructure>(
    mut open: impl FnMut(&str) -> Option<T>,
    trajectory: &str,
    sample: &Sample,
) -> TraceNode {
    let mut budget = MAX_TRACE_NODES;
    node(&mut open, trajectory, None, sample, 0, &mut budget)
}

fn node<T: EntityTrajectoryStructure>(
    open: &mut impl FnMut(&str) -> Option<T>,
    trajectory: &str,
    generation: Option<u64>,
    sample: &Sample,
    depth: usize,
    budget: &mut usize,
) -> TraceNode {
    *budget = budget.saturating_sub(1);
    let mut out = TraceNode {
        trajectory: trajectory.to_owned(),
        generation,
        valid_time: sample.valid_time(),
        add_time: sample.add_time,
        hop: None,
        found: Found::Stored,
        complete: true,
        inputs: Vec::new(),
    };
    let Some(lineage) = &sample.lineage else { return out };
    out.complete = lineage.complete;
    out.hop = lineage.last_input_added().map(|last| sample.add_time.saturating_sub(last));
    for input in &lineage.inputs {
        let child = if depth + 1 >= MAX_TRACE_DEPTH || *budget == 0 {
            leaf(input, Found::CutOff)
        } else {
            match find(open, input) {
                Ok(found) => {
                    node(open, &input.trajectory, Some(input.generation), &found, depth + 1, budget)
                }
                Err(why) => leaf(input, why),
            }
        };
        out.inputs.push(child);
    }
    out
}

/// A structure named in a lineage, not followed further.
fn leaf(input: &InputRef, found: Found) -> TraceNode {
    TraceNode {
        trajectory: input.trajectory.clone(),
        generation: Some(input.generation),
        valid_time: input.valid_time,
        add_time: input.add_time,
        hop: None,
        found,
        complete: true,
        inputs: Vec::new(),
    }
}

/// The structure `input` names, looked up by valid time and told apart from others
/// valid then by its add time.
fn find<T: EntityTrajectoryStructure>(
    open: &mut impl FnMut(&str) -> Option<T>,
    input: &InputRef,
) -> Result<Sample, Found> {
    let handle = open(&input.trajectory).ok_or(Found::NoTrajectory)?;
    let candidates =
        handle.get_between(input.valid_time, input.valid_time).map_err(|e| match e {
            crate::store::QueryError::NoSuchEntityStructure { .. } => Found::NoTrajectory,
            _ => Found::Evicted,
        })?;
    candidates.into_iter().find(|s| s.add_time == input.add_time).ok_or(Found::Evicted)
}
