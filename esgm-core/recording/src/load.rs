//! Loading a recording into an ESGM (`esgm load`): recorded trajectories become
//! trajectories that answer queries (latest, between, at, approximating), in process
//! or in a running system.
//!
//! # Steps
//! Everything is checked before anything is created:
//! 1. every type the loaded trajectories need (each root and nested type) is either
//!    absent from the ESGM or equal to the recorded one; a type of the same name that
//!    differs is refused ([`LoadError::TypeConflict`], naming the type and its first
//!    differing attribute);
//! 2. no loaded trajectory's name exists, unless [`LoadOptions::replace`] is set
//!    ([`LoadError::TrajectoryExists`]).
//!
//! Then the missing types are registered, and each trajectory is created as a
//! **primitive** trajectory of its recorded type with its **recorded policy** (a
//! computed or sampled trajectory is loaded as the structures it produced, not
//! recomputed), and its recorded structures are added in recorded add order (by add
//! time, then sequence), across trajectories.
//!
//! # Time
//! The policy's delay constraint compares add time with valid time, so *when* a
//! structure is added matters:
//! - **Simulated clock** ([`LoadOptions::sim_clock`], the clock an
//!   [`esgm_core::InProcessEsgm`] was built with): before each add the clock is set to
//!   the structure's recorded add time, so the recorded policy applies as it did when
//!   it was recorded, delay included. The clock only moves forward: if it is already
//!   past a recorded add time, that add happens later than recorded and is counted in
//!   [`LoadedTrajectory::late_adds`]. Before the trajectories are created the clock is
//!   set to the earliest recorded time, so a duration constraint starting "at
//!   creation" (`from = 0`) admits what it admitted then. One known difference: with a
//!   monotone order, a maximum delay and reordering, a recorded add time is the time
//!   the structure was *released* from the reorder buffer, which a busy recorder may
//!   have done later than valid time + delay; such a structure is now a delay
//!   violation, and is counted as one.
//! - **Real clock** (no simulated clock, e.g. a running system): every add happens
//!   now, long after the recorded valid times, so the recorded maximum delay would
//!   drop everything. The delay constraint is relaxed to "any", and a duration
//!   starting at creation (`from = 0`) to the first recorded valid time; both are
//!   reported in [`LoadedTrajectory::relaxed`].
//!
//! # Nothing silent
//! The report gives per trajectory what was offered, added, dropped by the policy (by
//! cause, from the trajectory's own statistics) and evicted. A trajectory keeps its
//! recorded cache bound: if the recording holds more structures than the cache keeps,
//! the oldest are evicted as they were in the recorded system, and the report says how
//! many.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::clock::SimClock;
use esgm_core::esgm::{CreateError, TrajectorySpec};
use esgm_core::policy::{DelayConstraint, DurationConstraint, FluentStreamPolicy};
use esgm_core::store::{AddError, AddOutcome};
use esgm_core::time::Time;
use esgm_core::{EntityStructureType, EntityTrajectoryStructure, Esgm, TypeRegistryError};

use crate::reader::{ReadError, RecordedSample, Recording};
use crate::type_diff::{TypeDifference, schema_types, type_difference};

/// How a recording is loaded. `Default`: every trajectory, no replacing, a real
/// clock, 10 s for writers in other processes to start and to account for adds.
#[derive(Debug, Clone)]
pub struct LoadOptions {
    /// Load only these trajectories (empty: all).
    pub only: Vec<String>,
    /// Re-create trajectories whose names exist (E5 re-pointing) instead of refusing.
    pub replace: bool,
    /// The simulated clock the ESGM runs on, if it does (see the module docs).
    pub sim_clock: Option<Arc<SimClock>>,
    /// How long to wait for a trajectory written by another process: for its writer
    /// to start serving adds (until the first add succeeds), and for its statistics
    /// to account for every add at the end.
    pub settle: Duration,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self { only: Vec::new(), replace: false, sim_clock: None, settle: Duration::from_secs(10) }
    }
}

impl LoadOptions {
    /// The defaults.
    pub fn new() -> Self {
        Self::default()
    }
    /// Loads only these trajectories.
    #[must_use]
    pub fn only<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.only = names.into_iter().map(Into::into).collect();
        self
    }
    /// Replaces existing trajectories of the same names.
    #[must_use]
    pub fn replace(mut self, on: bool) -> Self {
        self.replace = on;
        self
    }
    /// The ESGM runs on this simulated clock: recorded add times are replayed on it.
    #[must_use]
    pub fn sim_clock(mut self, clock: Arc<SimClock>) -> Self {
        self.sim_clock = Some(clock);
        self
    }
    /// Sets the wait for writers in other processes.
    #[must_use]
    pub fn settle(mut self, d: Duration) -> Self {
        self.settle = d;
        self
    }
}

/// Loading failed. The checks ([`LoadError::NoSuchTrajectory`],
/// [`LoadError::InconsistentRecording`], [`LoadError::TypeConflict`],
/// [`LoadError::TrajectoryExists`]) fail before anything is created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// The system could not list what it holds (across processes: the coordinator did
    /// not answer).
    #[error(transparent)]
    System(#[from] esgm_core::SystemError),
    /// The recording cannot be read (the error names the file and the position).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// `only` names a trajectory the recording does not have; check `esgm info`.
    #[error("{}: no recorded trajectory `{name}`", path.display())]
    NoSuchTrajectory {
        /// The recording.
        path: PathBuf,
        /// The name asked for.
        name: String,
    },
    /// Two recorded trajectories declare one type name differently; load them
    /// separately (`only`) into different systems.
    #[error("{}: the recording's trajectories disagree on {difference}", path.display())]
    InconsistentRecording {
        /// The recording.
        path: PathBuf,
        /// The first difference.
        difference: Box<TypeDifference>,
    },
    /// The ESGM has a type of a recorded name that differs; nothing was created.
    /// Load into a system without it, or register the recorded type there.
    #[error("{}: {difference}", path.display())]
    TypeConflict {
        /// The recording.
        path: PathBuf,
        /// The type and its first differing attribute.
        difference: Box<TypeDifference>,
    },
    /// A trajectory of a recorded name exists; nothing was created. Destroy it, load
    /// with `replace`, or load the others with `only`.
    #[error("trajectory `{name}` exists already (replace it, or leave it out)")]
    TrajectoryExists {
        /// The name.
        name: String,
    },
    /// The ESGM refused or could not answer a type operation.
    #[error("type `{type_name}`: {source}")]
    Type {
        /// The type.
        type_name: String,
        /// Why.
        source: Box<TypeRegistryError>,
    },
    /// The ESGM refused to create a trajectory (types and trajectories registered
    /// before it stay).
    #[error("cannot create trajectory `{trajectory}`: {source}")]
    Create {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: Box<CreateError>,
    },
    /// A structure could not be added (the trajectory was destroyed meanwhile, or its
    /// writer in another process is gone); what was added before stays.
    #[error("cannot add to `{trajectory}`: {source}")]
    Add {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: Box<AddError>,
    },
    /// A trajectory's statistics did not account for every structure sent to its
    /// writer in another process within [`LoadOptions::settle`].
    #[error("`{trajectory}`: {accounted} of {offered} structures accounted for after {waited:?}")]
    NotSettled {
        /// The trajectory.
        trajectory: String,
        /// Structures offered.
        offered: u64,
        /// Structures added or dropped so far.
        accounted: u64,
        /// How long it waited.
        waited: Duration,
    },
}

/// A part of the recorded policy loaded relaxed, and why.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Relaxation {
    /// The maximum delay, relaxed to any: with a real clock every add is "now".
    Delay {
        /// The recorded constraint.
        recorded: DelayConstraint,
    },
    /// A duration starting at creation (`from = 0`), which would be now.
    DurationStart {
        /// The start it was loaded with (the first recorded valid time), or `None`
        /// when the duration was loaded unbounded.
        loaded_from: Option<Time>,
    },
}

impl std::fmt::Display for Relaxation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Relaxation::Delay { recorded } => {
                write!(
                    f,
                    "delay {recorded:?} relaxed to any (added now, long after their valid times)"
                )
            }
            Relaxation::DurationStart { loaded_from: Some(t) } => {
                write!(
                    f,
                    "duration from creation relaxed to from {t} (the first recorded valid time)"
                )
            }
            Relaxation::DurationStart { loaded_from: None } => {
                f.write_str("duration from creation relaxed to unbounded")
            }
        }
    }
}

/// What happened to one loaded trajectory.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoadedTrajectory {
    /// The trajectory.
    pub name: String,
    /// Its type.
    pub type_name: String,
    /// The policy it was created with (the recorded one, but for `relaxed`).
    pub policy: FluentStreamPolicy,
    /// What of the recorded policy was relaxed.
    pub relaxed: Vec<Relaxation>,
    /// True if an existing trajectory of this name was replaced.
    pub replaced: bool,
    /// Structures offered (every readable recorded one).
    pub offered: u64,
    /// Structures that entered the trajectory (its statistics' `added`).
    pub added: u64,
    /// Structures its policy dropped, by cause (from its statistics).
    pub dropped: BTreeMap<String, u64>,
    /// Structures evicted by its recorded cache bound.
    pub evicted: u64,
    /// Structures stored now: what queries answer from.
    pub stored: usize,
    /// Structures still held for reordering.
    pub held: usize,
    /// Adds made later than recorded, because the simulated clock was already past
    /// the recorded add time.
    pub late_adds: u64,
}

/// What [`load`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoadReport {
    /// The recording.
    pub path: PathBuf,
    /// True if recorded add times were replayed on a simulated clock.
    pub simulated_clock: bool,
    /// Types registered (those the ESGM had already are not listed).
    pub types_registered: Vec<String>,
    /// Per trajectory, in recorded order.
    pub trajectories: Vec<LoadedTrajectory>,
}

/// Loads `rec` into `esgm` (see the [module docs](self)), creating each trajectory
/// with [`Esgm::create_trajectory`].
pub fn load<E: Esgm>(
    esgm: &E,
    rec: &Recording,
    options: &LoadOptions,
) -> Result<LoadReport, LoadError> {
    load_with(esgm, rec, options, |e, spec| e.create_trajectory(spec))
}

/// [`load`], creating each trajectory with `create`: a runtime where the creating
/// process should not be the writer (the command line, which exits after loading)
/// places it elsewhere and returns a handle on it.
pub fn load_with<E, F>(
    esgm: &E,
    rec: &Recording,
    options: &LoadOptions,
    mut create: F,
) -> Result<LoadReport, LoadError>
where
    E: Esgm,
    F: FnMut(&E, TrajectorySpec) -> Result<E::Trajectory, CreateError>,
{
    // 1. What to load.
    for name in &options.only {
        if rec.trajectory(name).is_none() {
            return Err(LoadError::NoSuchTrajectory { path: rec.path.clone(), name: name.clone() });
        }
    }
    let selected: Vec<usize> = (0..rec.trajectories.len())
        .filter(|&i| {
            options.only.is_empty() || options.only.contains(&rec.trajectories[i].info.name)
        })
        .collect();

    // 2. Types: consistent in the file, and equal to the ESGM's where it has them.
    let mut needed: BTreeMap<&str, &EntityStructureType> = BTreeMap::new();
    for &i in &selected {
        let t = &rec.trajectories[i];
        for (name, ty) in schema_types(&t.info.type_name, &t.types) {
            match needed.get(name) {
                Some(known) => {
                    if let Some(difference) =
                        type_difference(name, known, ty, ("in one trajectory", "in another"))
                    {
                        return Err(LoadError::InconsistentRecording {
                            path: rec.path.clone(),
                            difference: Box::new(difference),
                        });
                    }
                }
                None => {
                    needed.insert(name, ty);
                }
            }
        }
    }
    let mut missing: Vec<&str> = Vec::new();
    for (&name, &recorded) in &needed {
        match esgm.get_entity_structure_type(name) {
            Ok(theirs) => {
                if let Some(difference) =
                    type_difference(name, recorded, &theirs, ("recorded", "in the ESGM"))
                {
                    return Err(LoadError::TypeConflict {
                        path: rec.path.clone(),
                        difference: Box::new(difference),
                    });
                }
            }
            Err(TypeRegistryError::NoSuchEntityStructureType { .. }) => missing.push(name),
            Err(source) => {
                return Err(LoadError::Type {
                    type_name: name.to_owned(),
                    source: Box::new(source),
                });
            }
        }
    }

    // 3. Names.
    let existing: BTreeSet<String> = esgm.trajectories()?.into_iter().map(|t| t.name).collect();
    for &i in &selected {
        let name = &rec.trajectories[i].info.name;
        if existing.contains(name) && !options.replace {
            return Err(LoadError::TrajectoryExists { name: name.clone() });
        }
    }

    // The structures, in recorded add order across trajectories (read before anything
    // is created, so a damaged file changes nothing either).
    let mut samples: Vec<RecordedSample> = Vec::new();
    for s in rec.samples()? {
        let s = s?;
        if selected.contains(&s.trajectory) {
            samples.push(s);
        }
    }
    samples.sort_by_key(|s| (s.header.add_time, s.header.sequence));

    // 4. Types, nested ones first.
    let mut types_registered = Vec::new();
    for name in registration_order(&missing, &needed) {
        esgm.create_entity_structure_type(name, needed[name].clone()).map_err(|source| {
            LoadError::Type { type_name: name.to_owned(), source: Box::new(source) }
        })?;
        types_registered.push(name.to_owned());
    }

    // 5. Trajectories.
    if let Some(clock) = &options.sim_clock {
        if let Some(first) =
            samples.iter().map(|s| s.header.add_time.min(s.structure.valid_time)).min()
        {
            clock.set(first);
        }
    }
    let mut loaded: Vec<(E::Trajectory, LoadedTrajectory)> = Vec::new();
    for &i in &selected {
        let t = &rec.trajectories[i];
        let (policy, relaxed) = match options.sim_clock {
            Some(_) => (t.info.policy.clone(), Vec::new()),
            None => relax(&t.info.policy, t.valid_range.map(|r| r.0)),
        };
        let replaced = existing.contains(&t.info.name);
        let mut spec =
            TrajectorySpec::primitive(&t.info.name, &t.info.type_name).policy(policy.clone());
        if replaced {
            spec = spec.replace();
        }
        let handle = create(esgm, spec).map_err(|source| LoadError::Create {
            trajectory: t.info.name.clone(),
            source: Box::new(source),
        })?;
        loaded.push((
            handle,
            LoadedTrajectory {
                name: t.info.name.clone(),
                type_name: t.info.type_name.clone(),
                policy,
                relaxed,
                replaced,
                offered: 0,
                added: 0,
                dropped: BTreeMap::new(),
                evicted: 0,
                stored: 0,
                held: 0,
                late_adds: 0,
            },
        ));
    }

    // 6. Structures.
    let slot_of: BTreeMap<usize, usize> =
        selected.iter().enumerate().map(|(slot, &i)| (i, slot)).collect();
    let mut serving = vec![false; loaded.len()];
    let mut last_release: Option<Time> = None;
    for s in samples {
        let slot = slot_of[&s.trajectory];
        let (handle, report) = &mut loaded[slot];
        if let Some(clock) = &options.sim_clock {
            if clock.set(s.header.add_time) > s.header.add_time {
                report.late_adds += 1;
            }
        }
        report.offered += 1;
        let started = Instant::now();
        loop {
            // Blocking: the outcome is the writer's own, wherever it runs.
            match handle.add_blocking(s.structure.clone()) {
                Ok(AddOutcome::Held { release_at }) => {
                    last_release = Some(last_release.map_or(release_at, |r| r.max(release_at)));
                }
                Ok(_) | Err(AddError::PolicyViolation(_) | AddError::InvalidType { .. }) => {}
                // A writer placed in another process starts serving shortly after it
                // is created: until its first answer, wait for it.
                Err(AddError::Unavailable { .. })
                    if !serving[slot] && started.elapsed() < options.settle =>
                {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                Err(source) => {
                    return Err(LoadError::Add {
                        trajectory: report.name.clone(),
                        source: Box::new(source),
                    });
                }
            }
            serving[slot] = true;
            break;
        }
    }

    // 7. Held structures enter when their delay window passes.
    if let (Some(clock), Some(t)) = (&options.sim_clock, last_release) {
        clock.set(t);
    }
    for (handle, report) in &mut loaded {
        let started = Instant::now();
        loop {
            let stats = handle.stats().map_err(|e| LoadError::Add {
                trajectory: report.name.clone(),
                source: Box::new(query_to_add(&report.name, e)),
            })?;
            let accounted = stats.added + stats.dropped_total;
            let settled =
                accounted >= report.offered && (options.sim_clock.is_none() || stats.held == 0);
            if settled || started.elapsed() >= options.settle {
                if !settled && accounted < report.offered {
                    return Err(LoadError::NotSettled {
                        trajectory: report.name.clone(),
                        offered: report.offered,
                        accounted,
                        waited: started.elapsed(),
                    });
                }
                report.added = stats.added;
                report.dropped = stats.dropped.iter().map(|(c, n)| (c.to_string(), *n)).collect();
                report.evicted = stats.evicted;
                report.stored = stats.stored;
                report.held = stats.held;
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    Ok(LoadReport {
        path: rec.path.clone(),
        simulated_clock: options.sim_clock.is_some(),
        types_registered,
        trajectories: loaded.into_iter().map(|(_, r)| r).collect(),
    })
}

/// A query error on a loaded trajectory, as the add error it stands for.
fn query_to_add(trajectory: &str, e: esgm_core::QueryError) -> AddError {
    match e {
        esgm_core::QueryError::NoSuchEntityStructure { trajectory } => {
            AddError::NoSuchEntityStructure { trajectory }
        }
        esgm_core::QueryError::Unavailable { reason, .. } => {
            AddError::Unavailable { trajectory: trajectory.to_owned(), reason }
        }
        other => AddError::Unavailable {
            trajectory: trajectory.to_owned(),
            reason: esgm_core::esgm::Unreachable::refused(esgm_core::esgm::Peer::Writer, other),
        },
    }
}

/// The recorded policy for a real clock (see the module docs).
fn relax(
    policy: &FluentStreamPolicy,
    first_valid: Option<Time>,
) -> (FluentStreamPolicy, Vec<Relaxation>) {
    let mut p = policy.clone();
    let mut relaxed = Vec::new();
    if let DelayConstraint::Max(_) = p.delay {
        relaxed.push(Relaxation::Delay { recorded: p.delay });
        p.delay = DelayConstraint::Any;
    }
    if let DurationConstraint::Between { from: 0, to } = p.duration {
        // `from` must be positive to mean a time (0 is "at creation").
        match first_valid.filter(|t| *t > 0 && (to == 0 || *t <= to)) {
            Some(t) => {
                p.duration = DurationConstraint::Between { from: t, to };
                relaxed.push(Relaxation::DurationStart { loaded_from: Some(t) });
            }
            None if to == 0 => {
                p.duration = DurationConstraint::Unbounded;
                relaxed.push(Relaxation::DurationStart { loaded_from: None });
            }
            // A bounded end and no usable start: keep it; its drops are reported.
            None => {}
        }
    }
    (p, relaxed)
}

/// `missing` ordered so that a type comes after every type it nests.
fn registration_order<'a>(
    missing: &[&'a str],
    needed: &BTreeMap<&'a str, &EntityStructureType>,
) -> Vec<&'a str> {
    fn visit<'a>(
        name: &'a str,
        needed: &BTreeMap<&'a str, &EntityStructureType>,
        seen: &mut BTreeSet<&'a str>,
        out: &mut Vec<&'a str>,
    ) {
        if !seen.insert(name) {
            return; // done, or a cycle
        }
        if let Some(ty) = needed.get(name) {
            for element in ty.attributes.iter().filter_map(|a| a.element_type.as_deref()) {
                if let Some((&key, _)) = needed.get_key_value(element) {
                    visit(key, needed, seen, out);
                }
            }
        }
        out.push(name);
    }
    let (mut seen, mut out) = (BTreeSet::new(), Vec::new());
    for &name in missing {
        visit(name, needed, &mut seen, &mut out);
    }
    out.retain(|n| missing.contains(n));
    out
}
