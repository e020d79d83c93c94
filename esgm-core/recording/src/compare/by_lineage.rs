//! Which recorded input an output differs by (issue 42): a differing output's lineage
//! followed back through both recordings.
//!
//! For the first differing pair of a produced trajectory, each input its lineage names
//! is looked up in both files (A's by its lineage, B's by B's lineage when it has one,
//! else at A's valid time) and compared as the outputs were. An input that differs
//! and was itself produced is followed in turn, level by level (one read of each file
//! per level, at most [`MAX_DEPTH`] levels). Where it ends, the difference has an
//! origin: a recorded source structure that differs (the recordings were given other
//! inputs), or a producer whose inputs are the same in both (the unit computed
//! something else: a code change, or a non-deterministic unit).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use esgm_core::time::Time;
use esgm_core::{EntityStructure, Lineage};

use super::{CompareError, CompareOptions};
use crate::reader::Recording;
use crate::value_diff::diff_structures;

/// How many levels of inputs are followed back from a differing output.
pub const MAX_DEPTH: usize = 16;

/// One input of a differing structure, compared across the two recordings.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct InputComparison {
    /// The input trajectory.
    pub trajectory: String,
    /// The input structure's valid time in A.
    pub valid_time: Time,
    /// The valid time of the input B's structure was made from, where B's lineage
    /// names another one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub valid_time_b: Option<Time>,
    /// What the comparison found.
    pub verdict: InputVerdict,
    /// It was produced (A recorded its lineage): a unit's, sync's, merge's or
    /// generator's output, not a source.
    pub produced: bool,
    /// If it differs and was itself produced: its own inputs, compared.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<InputComparison>,
}

/// How one input compares.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "verdict")]
pub enum InputVerdict {
    /// The same structure in both recordings.
    Same,
    /// The two differ; the first difference.
    Differs {
        /// The attribute path.
        attribute: String,
        /// A's value.
        a: String,
        /// B's value.
        b: String,
    },
    /// B's output was made from an input structure of another valid time: the two
    /// runs paired their inputs differently (timing, a sync, a dropped structure).
    OtherStructure,
    /// The input structure is not in A (the recording began later, or did not hold
    /// the trajectory).
    NotInA,
    /// The input structure is not in B.
    NotInB,
}

/// Where a difference comes from, as far as the recordings tell.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "origin")]
pub enum DifferenceOrigin {
    /// A recorded structure nothing in the recordings produced (pushed or sampled)
    /// differs: the two runs had other inputs.
    Source {
        /// Its trajectory.
        trajectory: String,
        /// Its valid time in A.
        valid_time: Time,
    },
    /// This trajectory's producer was given the same inputs in both, and made
    /// different structures.
    Producer {
        /// The produced trajectory.
        trajectory: String,
        /// The structure's valid time in A.
        valid_time: Time,
    },
    /// The two runs made it from other input structures (their valid times differ).
    Pairing {
        /// The input trajectory.
        trajectory: String,
        /// A's input's valid time.
        valid_time: Time,
        /// B's input's valid time.
        valid_time_b: Time,
    },
    /// The trail ends at a structure one recording does not hold, or at the depth
    /// limit.
    Unresolved {
        /// Its trajectory.
        trajectory: String,
        /// Its valid time in A.
        valid_time: Time,
    },
}

impl DifferenceOrigin {
    /// The origin in words, as `esgm compare` prints it.
    pub fn words(&self) -> String {
        match self {
            DifferenceOrigin::Source { trajectory, valid_time } => format!(
                "the difference comes from `{trajectory}` at valid time {valid_time}: a recorded input that differs"
            ),
            DifferenceOrigin::Producer { trajectory, valid_time } => format!(
                "the difference comes from the producer of `{trajectory}` at valid time {valid_time}: its inputs are the same in both"
            ),
            DifferenceOrigin::Pairing { trajectory, valid_time, valid_time_b } => format!(
                "the runs made it from other structures of `{trajectory}`: valid time {valid_time} in A, {valid_time_b} in B"
            ),
            DifferenceOrigin::Unresolved { trajectory, valid_time } => format!(
                "the trail ends at `{trajectory}` at valid time {valid_time}: not in both recordings, or too deep"
            ),
        }
    }
}

impl InputComparison {
    /// The comparison in words, one line (without its own inputs).
    pub fn words(&self) -> String {
        let at = match self.valid_time_b {
            Some(b) => format!("{} (B: {b})", self.valid_time),
            None => self.valid_time.to_string(),
        };
        let verdict = match &self.verdict {
            InputVerdict::Same => "the same".to_owned(),
            InputVerdict::Differs { attribute, a, b } => {
                format!("differs: {attribute} = {a} in A, {b} in B")
            }
            InputVerdict::OtherStructure => "another structure in B".to_owned(),
            InputVerdict::NotInA => "not in A".to_owned(),
            InputVerdict::NotInB => "not in B".to_owned(),
        };
        format!("made from `{}` at valid time {at}: {verdict}", self.trajectory)
    }
}

/// A differing output to explain: its trajectory, valid time, and both lineages.
pub(super) struct Differing {
    pub trajectory: String,
    pub valid_time: Time,
    pub lineage_a: Option<Arc<Lineage>>,
    pub lineage_b: Option<Arc<Lineage>>,
}

/// One input to look up in both files, and where its comparison goes.
struct Pending {
    /// Which output (index into the list explained).
    root: usize,
    /// The path of input indexes from the root's inputs down to this one.
    path: Vec<usize>,
    trajectory: String,
    valid_time: Time,
    add_time: Time,
    valid_time_b: Time,
    add_time_b: Option<Time>,
}

/// A structure found by a lookup, with what identifies it.
struct Found {
    structure: EntityStructure,
    add_time: Time,
    lineage: Option<Arc<Lineage>>,
}

/// One output's inputs, compared, and the origins they lead to.
pub(super) type Explained = (Vec<InputComparison>, Vec<DifferenceOrigin>);

/// The inputs of each differing output, compared, and the origins they lead to.
pub(super) fn explain(
    a: &Recording,
    b: &Recording,
    options: &CompareOptions,
    outputs: &[Differing],
) -> Result<Vec<Explained>, CompareError> {
    let mut trees: Vec<Vec<InputComparison>> = vec![Vec::new(); outputs.len()];
    let mut level: Vec<Pending> = Vec::new();
    for (root, out) in outputs.iter().enumerate() {
        if let Some(la) = &out.lineage_a {
            level.extend(pending_of(root, &[], la, out.lineage_b.as_deref()));
        }
    }
    for _ in 0..MAX_DEPTH {
        if level.is_empty() {
            break;
        }
        let wanted_a = wanted(level.iter().map(|p| (&p.trajectory, p.valid_time)));
        let wanted_b = wanted(level.iter().map(|p| (&p.trajectory, p.valid_time_b)));
        let in_a = lookup(a, &wanted_a)?;
        let in_b = lookup(b, &wanted_b)?;
        let mut next = Vec::new();
        for p in level {
            let fa = pick(&in_a, &p.trajectory, p.valid_time, Some(p.add_time));
            let fb = pick(&in_b, &p.trajectory, p.valid_time_b, p.add_time_b);
            let verdict = match (fa, fb) {
                (None, _) => InputVerdict::NotInA,
                (_, None) => InputVerdict::NotInB,
                _ if p.valid_time_b != p.valid_time => InputVerdict::OtherStructure,
                (Some(fa), Some(fb)) => {
                    let d = diff_structures(
                        &fa.structure,
                        &fb.structure,
                        options.value_tolerance,
                        options.create_time,
                    );
                    match d.first {
                        None => InputVerdict::Same,
                        Some(first) => InputVerdict::Differs {
                            attribute: first.attribute,
                            a: first.a,
                            b: first.b,
                        },
                    }
                }
            };
            let follow = matches!(verdict, InputVerdict::Differs { .. });
            if follow {
                if let Some(la) = fa.and_then(|f| f.lineage.as_ref()) {
                    let lb = fb.and_then(|f| f.lineage.as_deref());
                    let mut path = p.path.clone();
                    path.push(child_index(&trees[p.root], &p.path));
                    next.extend(pending_of(p.root, &path, la, lb));
                }
            }
            let node = InputComparison {
                trajectory: p.trajectory,
                valid_time: p.valid_time,
                valid_time_b: (p.valid_time_b != p.valid_time).then_some(p.valid_time_b),
                verdict,
                produced: fa.is_some_and(|f| f.lineage.is_some()),
                inputs: Vec::new(),
            };
            children_at(&mut trees[p.root], &p.path).push(node);
        }
        level = next;
    }
    Ok(outputs
        .iter()
        .zip(trees)
        .map(|(out, tree)| {
            let mut origins = Vec::new();
            if out.lineage_a.is_some() {
                origins_of(&out.trajectory, out.valid_time, &tree, &mut origins);
            }
            (tree, origins)
        })
        .collect())
}

/// The inputs `la` names, each paired with B's input of the same trajectory (the
/// n-th of that trajectory in B's lineage), or A's valid time where B has none.
fn pending_of(root: usize, path: &[usize], la: &Lineage, lb: Option<&Lineage>) -> Vec<Pending> {
    let mut seen: BTreeMap<&str, usize> = BTreeMap::new();
    la.inputs
        .iter()
        .map(|ra| {
            let n = seen.entry(ra.trajectory.as_str()).or_default();
            let rb = lb
                .and_then(|lb| lb.inputs.iter().filter(|r| r.trajectory == ra.trajectory).nth(*n));
            *n += 1;
            Pending {
                root,
                path: path.to_vec(),
                trajectory: ra.trajectory.clone(),
                valid_time: ra.valid_time,
                add_time: ra.add_time,
                valid_time_b: rb.map_or(ra.valid_time, |r| r.valid_time),
                add_time_b: rb.map(|r| r.add_time),
            }
        })
        .collect()
}

fn wanted<'a>(keys: impl Iterator<Item = (&'a String, Time)>) -> BTreeMap<String, BTreeSet<Time>> {
    let mut out: BTreeMap<String, BTreeSet<Time>> = BTreeMap::new();
    for (t, vt) in keys {
        out.entry(t.clone()).or_default().insert(vt);
    }
    out
}

/// Every structure of `rec` at the wanted trajectories and valid times, in one read.
fn lookup(
    rec: &Recording,
    wanted: &BTreeMap<String, BTreeSet<Time>>,
) -> Result<BTreeMap<(String, Time), Vec<Found>>, CompareError> {
    let mut out: BTreeMap<(String, Time), Vec<Found>> = BTreeMap::new();
    let index: BTreeMap<usize, &BTreeSet<Time>> = rec
        .trajectories
        .iter()
        .enumerate()
        .filter_map(|(i, t)| wanted.get(&t.info.name).map(|w| (i, w)))
        .collect();
    if index.is_empty() {
        return Ok(out);
    }
    for sample in rec.samples()? {
        let sample = sample?;
        let Some(times) = index.get(&sample.trajectory) else { continue };
        if !times.contains(&sample.structure.valid_time) {
            continue;
        }
        let name = rec.trajectories[sample.trajectory].info.name.clone();
        out.entry((name, sample.structure.valid_time)).or_default().push(Found {
            add_time: sample.header.add_time,
            lineage: sample.lineage.map(Arc::new),
            structure: sample.structure,
        });
    }
    Ok(out)
}

/// The structure at `valid_time` whose add time is `add_time` (the one a lineage
/// names), else the first recorded there.
fn pick<'a>(
    found: &'a BTreeMap<(String, Time), Vec<Found>>,
    trajectory: &str,
    valid_time: Time,
    add_time: Option<Time>,
) -> Option<&'a Found> {
    let all = found.get(&(trajectory.to_owned(), valid_time))?;
    all.iter().find(|f| Some(f.add_time) == add_time).or_else(|| all.first())
}

/// The children list at `path` (input indexes from the root's inputs down). Paths
/// are built from nodes already pushed, so each index is there.
fn children_at<'a>(
    mut tree: &'a mut Vec<InputComparison>,
    path: &[usize],
) -> &'a mut Vec<InputComparison> {
    for &i in path {
        if tree.is_empty() {
            break;
        }
        let at = i.min(tree.len() - 1);
        tree = &mut tree[at].inputs;
    }
    tree
}

/// The index the node being pushed at `path` will have: how many are there already.
fn child_index(tree: &[InputComparison], path: &[usize]) -> usize {
    let mut list = tree;
    for &i in path {
        match list.get(i) {
            Some(node) => list = &node.inputs,
            None => return 0,
        }
    }
    list.len()
}

/// The origins a differing structure's compared inputs lead to.
fn origins_of(
    trajectory: &str,
    valid_time: Time,
    inputs: &[InputComparison],
    out: &mut Vec<DifferenceOrigin>,
) {
    let mut any = false;
    for input in inputs {
        let at = (input.trajectory.clone(), input.valid_time);
        match &input.verdict {
            InputVerdict::Same => continue,
            InputVerdict::Differs { .. } if !input.produced => {
                out.push(DifferenceOrigin::Source { trajectory: at.0, valid_time: at.1 });
            }
            // Produced, and not followed (the depth limit).
            InputVerdict::Differs { .. } if input.inputs.is_empty() => {
                out.push(DifferenceOrigin::Unresolved { trajectory: at.0, valid_time: at.1 });
            }
            InputVerdict::Differs { .. } => {
                origins_of(&input.trajectory, input.valid_time, &input.inputs, out);
            }
            InputVerdict::OtherStructure => out.push(DifferenceOrigin::Pairing {
                trajectory: at.0,
                valid_time: at.1,
                valid_time_b: input.valid_time_b.unwrap_or(at.1),
            }),
            InputVerdict::NotInA | InputVerdict::NotInB => {
                out.push(DifferenceOrigin::Unresolved { trajectory: at.0, valid_time: at.1 });
            }
        }
        any = true;
    }
    if !any {
        out.push(DifferenceOrigin::Producer { trajectory: trajectory.to_owned(), valid_time });
    }
}
