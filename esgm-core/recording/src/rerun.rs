//! Deterministic replay in one process: a configuration's units on recorded inputs
//! (`esgm replay FILE --in-process --config system.toml --record out.mcap`).
//!
//! The live runtime runs each unit on its own thread, so what a multi-input unit sees
//! depends on thread timing. A rerun does the same work on one thread, in recorded add
//! order, under a [`SimClock`] set to each input's recorded add time: each recorded
//! input is added to its trajectory (its policy applies), and every update then
//! propagates breadth-first: each computed trajectory reading the updated one records
//! it as that input's latest sample and, once every input has one, calls its unit
//! with the latest sample of each input and the simulated time, exactly as the
//! runtime's unit worker does, and adds the result (its policy applies). Nothing
//! depends on a thread or the wall clock, so the same recording rerun twice gives
//! byte-identical trajectories, and files.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind, TrajectorySource};
use esgm_core::{
    AddOutcome, CompUnit, ComputeError, EntityStructureType, EntityTrajectoryStructure, Esgm,
    InProcessEsgm, InProcessTrajectory, InputRef, InputType, Lineage, Sample, SimClock,
    SubscribeOptions, Subscription, TrajectorySpec,
};

use crate::layout::TypeSchema;
use crate::reader::{ReadError, Recording};
use crate::replay::{AddOrder, ReplayError, check_and_register_types};
use crate::type_diff::type_difference;
use crate::writer::{RecordError, RecordingWriter, WriteSummary};

/// A unit a rerun can call: its name, output type, input types and implementation.
#[derive(Clone)]
pub struct RerunUnit {
    /// The name trajectories use.
    pub name: String,
    /// Its output type.
    pub output_type: String,
    /// Its input types, in order.
    pub inputs: Vec<InputType>,
    /// The unit.
    pub unit: Arc<dyn CompUnit>,
}

impl std::fmt::Debug for RerunUnit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RerunUnit").field("name", &self.name).finish_non_exhaustive()
    }
}

/// What to run: types, units and trajectories, as a configuration declares them.
#[derive(Debug, Clone, Default)]
pub struct RerunPlan {
    /// Types to register (besides the recording's own).
    pub types: Vec<(String, EntityStructureType)>,
    /// Units.
    pub units: Vec<RerunUnit>,
    /// Trajectories, in declaration order. Primitive and sampled ones are fed from the
    /// recording; computed ones are computed.
    pub trajectories: Vec<TrajectorySpec>,
}

/// Why a rerun was refused or stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RerunError {
    /// The recording cannot be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// A type or trajectory does not fit the recording.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// Writing the output failed.
    #[error(transparent)]
    Write(#[from] RecordError),
    /// The configuration asks for something a rerun cannot do.
    #[error("`{trajectory}`: {reason}")]
    Plan {
        /// The trajectory.
        trajectory: String,
        /// Why.
        reason: String,
    },
}

/// What a rerun did, per trajectory.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RerunReport {
    /// Per trajectory.
    pub trajectories: BTreeMap<String, RerunCounts>,
    /// The output files, if one was written.
    pub written: Option<WriteSummary>,
}

/// One trajectory of a [`RerunReport`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RerunCounts {
    /// Recorded structures fed in (inputs) or unit results offered (computed).
    pub offered: u64,
    /// Structures that entered the trajectory.
    pub added: u64,
    /// Dropped by its policy.
    pub dropped: u64,
    /// Held for reordering (released by the runtime's clock, not by the rerun).
    pub held: u64,
    /// Unit calls.
    pub calls: u64,
    /// Calls that answered "no value".
    pub no_value: u64,
    /// Calls that failed.
    pub failures: u64,
}

/// A computed trajectory's unit, its inputs (node indexes) and each input's latest
/// sample (the runtime's unit worker keeps the same).
type Computing = (Arc<dyn CompUnit>, Vec<usize>, Vec<Option<Sample>>);

/// One trajectory of the rerun.
struct Node {
    info: TrajectoryInfo,
    handle: InProcessTrajectory,
    updates: Subscription<Sample>,
    /// For computed ones: the unit, its inputs and their latest samples.
    unit: Option<Computing>,
    counts: RerunCounts,
    written: Option<crate::writer::TrajectoryId>,
}

/// Runs `plan` on the inputs recorded in `rec`, writing every trajectory into `out`:
/// see the [module docs](self).
pub fn rerun(
    rec: &Recording,
    plan: &RerunPlan,
    mut out: Option<RecordingWriter>,
) -> Result<RerunReport, RerunError> {
    // The clock starts before anything recorded, valid or added: a trajectory whose
    // duration starts "when created" (from = 0) then admits the first recorded
    // structure, as the live one, created before it, did.
    let start = rec
        .trajectories
        .iter()
        .flat_map(|t| [t.add_range.map(|r| r.0), t.valid_range.map(|r| r.0)])
        .flatten()
        .min()
        .map_or(0, |t| t.saturating_sub(1));
    let clock = SimClock::shared(start);
    let esgm = InProcessEsgm::builder().clock(clock.clone()).create();
    let plan_err = |trajectory: &str, reason: String| RerunError::Plan {
        trajectory: trajectory.to_owned(),
        reason,
    };

    for (name, t) in &plan.types {
        match esgm.get_entity_structure_type(name) {
            Ok(have) => {
                if let Some(d) =
                    type_difference(name, t, &have, ("in the configuration", "in the library"))
                {
                    return Err(ReplayError::TypeMismatch {
                        type_name: name.clone(),
                        detail: d.to_string(),
                    }
                    .into());
                }
            }
            // Not in the library (or unreadable): creating it reports any real failure.
            Err(_) => esgm
                .create_entity_structure_type(name, t.clone())
                .map_err(|e| plan_err(name, e.to_string()))?,
        }
    }
    let fed: Vec<&str> = plan
        .trajectories
        .iter()
        .filter(|s| {
            matches!(
                s.source,
                TrajectorySource::Primitive { .. } | TrajectorySource::Sampled { .. }
            )
        })
        .map(|s| s.name.as_str())
        .collect();
    check_and_register_types(&esgm, rec, &fed)?;
    for u in &plan.units {
        esgm.add_comp_unit(&u.name, &u.output_type, u.inputs.clone(), Arc::clone(&u.unit))
            .map_err(|e| plan_err(&u.name, e.to_string()))?;
    }

    let mut nodes: Vec<Node> = Vec::new();
    let mut by_name: BTreeMap<String, usize> = BTreeMap::new();
    for spec in &plan.trajectories {
        let name = spec.name.as_str();
        let (info, unit) = match &spec.source {
            TrajectorySource::Primitive { .. } | TrajectorySource::Sampled { .. } => {
                let recorded = rec.trajectory(name).ok_or_else(|| {
                    plan_err(
                        name,
                        "it is an input of the configuration, and the recording does not have it"
                            .into(),
                    )
                })?;
                let mut info = recorded.info.clone();
                info.policy = spec.policy.clone();
                (info, None)
            }
            TrajectorySource::Computed { unit, inputs } => {
                let u = plan
                    .units
                    .iter()
                    .find(|u| &u.name == unit)
                    .ok_or_else(|| plan_err(name, format!("unit `{unit}` is not declared")))?;
                let mut ids = Vec::new();
                for i in inputs {
                    ids.push(*by_name.get(i).ok_or_else(|| {
                        plan_err(name, format!("input `{i}` must be declared before it"))
                    })?);
                }
                let info = TrajectoryInfo {
                    name: name.to_owned(),
                    kind: TrajectoryKind::Computed,
                    type_name: u.output_type.clone(),
                    source: Some(unit.clone()),
                    inputs: inputs.clone(),
                    policy: spec.policy.clone(),
                };
                let n = ids.len();
                (info, Some((Arc::clone(&u.unit), ids, vec![None; n])))
            }
            other => {
                return Err(plan_err(
                    name,
                    format!(
                        "{other:?} trajectories are not rerun (only primitive, sampled and computed ones)"
                    ),
                ));
            }
        };
        esgm.create_trajectory(
            TrajectorySpec::primitive(name, &info.type_name).policy(info.policy.clone()),
        )
        .map_err(|e| plan_err(name, e.to_string()))?;
        let handle = esgm
            .get_entity_trajectory_structure(name)
            .map_err(|e| plan_err(name, e.to_string()))?;
        let updates = handle
            .subscribe(SubscribeOptions::default().capacity(1 << 16))
            .map_err(|e| plan_err(name, e.to_string()))?;
        let written = match out.as_mut() {
            Some(w) => {
                let root = esgm
                    .get_entity_structure_type(&info.type_name)
                    .map_err(|e| plan_err(name, e.to_string()))?;
                // A nested type the registry cannot give is left out, with a warning.
                let lookup = |n: &str| {
                    esgm.get_entity_structure_type(n)
                        .inspect_err(|e| {
                            tracing::warn!(type_name = n, error = %e,
                                "a nested type is left out of the schema")
                        })
                        .ok()
                };
                Some(w.add_trajectory(info.clone(), TypeSchema::collect(root, &lookup))?)
            }
            None => None,
        };
        by_name.insert(name.to_owned(), nodes.len());
        nodes.push(Node { info, handle, updates, unit, counts: RerunCounts::default(), written });
    }

    let recorded_index: BTreeMap<usize, usize> = rec
        .trajectories
        .iter()
        .enumerate()
        .filter_map(|(i, t)| {
            by_name.get(&t.info.name).filter(|n| nodes[**n].unit.is_none()).map(|n| (i, *n))
        })
        .collect();
    for sample in AddOrder::of(rec, Duration::from_secs(2))? {
        let sample = sample?;
        let Some(&node) = recorded_index.get(&sample.trajectory) else { continue };
        clock.set(sample.header.add_time);
        offer(&mut nodes[node], sample.structure, None)?;
        propagate(&mut nodes, node, &clock, &mut out)?;
    }
    let mut report = RerunReport::default();
    for n in &nodes {
        report.trajectories.insert(n.info.name.clone(), n.counts);
    }
    if let Some(w) = out {
        report.written = Some(w.finish()?);
    }
    esgm.shutdown();
    Ok(report)
}

/// Adds a structure to a node's trajectory (with the inputs it was made from, a unit's
/// output) and counts how its policy took it.
fn offer(
    node: &mut Node,
    es: esgm_core::EntityStructure,
    lineage: Option<Arc<Lineage>>,
) -> Result<(), RerunError> {
    node.counts.offered += 1;
    match node.handle.add_produced(es, lineage) {
        Ok(AddOutcome::Added) => node.counts.added += 1,
        Ok(AddOutcome::Held { .. }) => node.counts.held += 1,
        Ok(AddOutcome::Dropped(_)) => node.counts.dropped += 1,
        Ok(_) => node.counts.added += 1,
        Err(e) => {
            return Err(RerunError::Plan {
                trajectory: node.info.name.clone(),
                reason: e.to_string(),
            });
        }
    }
    Ok(())
}

/// Delivers every update of `first` (and of what it causes), breadth-first.
fn propagate(
    nodes: &mut [Node],
    first: usize,
    clock: &SimClock,
    out: &mut Option<RecordingWriter>,
) -> Result<(), RerunError> {
    let names: Vec<String> = nodes.iter().map(|n| n.info.name.clone()).collect();
    let mut queue = VecDeque::from([first]);
    while let Some(i) = queue.pop_front() {
        while let Some(update) = nodes[i].updates.try_recv() {
            if let (Some(w), Some(id)) = (out.as_mut(), nodes[i].written) {
                w.write_sample(id, &update, clock.now())?;
            }
            #[allow(clippy::needless_range_loop)] // `offer` below needs `nodes[d]` mutably
            for d in 0..nodes.len() {
                let Some((unit, inputs, latest)) = nodes[d].unit.as_mut() else { continue };
                let mut touched = false;
                for (pos, input) in inputs.iter().enumerate() {
                    if *input == i {
                        latest[pos] = Some(update.clone());
                        touched = true;
                    }
                }
                if !touched {
                    continue;
                }
                let Some(args) = latest.iter().cloned().collect::<Option<Vec<Sample>>>() else {
                    continue;
                };
                let unit = Arc::clone(unit);
                // What the unit is given, named as the live runtime names it.
                let from: Vec<InputRef> = inputs
                    .iter()
                    .zip(&args)
                    .map(|(&input, s)| InputRef {
                        trajectory: names.get(input).cloned().unwrap_or_default(),
                        generation: 0,
                        valid_time: s.valid_time(),
                        add_time: s.add_time,
                    })
                    .collect();
                nodes[d].counts.calls += 1;
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    unit.compute(&args, clock.now())
                }));
                match result {
                    Ok(Ok(es)) => {
                        let lineage = Lineage::of(from).with_unrecorded_reads();
                        offer(&mut nodes[d], es, Some(Arc::new(lineage)))?;
                        if !queue.contains(&d) {
                            queue.push_back(d);
                        }
                    }
                    Ok(Err(ComputeError::ValueNotAvailable)) => nodes[d].counts.no_value += 1,
                    Ok(Err(e)) => {
                        nodes[d].counts.failures += 1;
                        tracing::warn!(trajectory = %nodes[d].info.name, error = %e, "unit failed");
                    }
                    // A panic: its payload was printed by the panic hook; counted and logged here.
                    Err(_) => {
                        nodes[d].counts.failures += 1;
                        tracing::error!(trajectory = %nodes[d].info.name, "unit panicked");
                    }
                }
            }
        }
    }
    Ok(())
}
