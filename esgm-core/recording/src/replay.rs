//! Replaying a recording into a running ESGM (`esgm replay FILE`).
//!
//! The recorded primitive and sampled trajectories are published again, in recorded
//! add order, paced by their recorded add times (`rate` × real time, or as fast as
//! possible). Computed trajectories are left to the domain's own units by default:
//! a recorded computed trajectory the domain lacks is declared with its recorded unit
//! and inputs if that unit is registered, so the domain recomputes it from the
//! replayed inputs. With [`ComputedMode::AsRecorded`] they are published as recorded
//! instead.
//!
//! Everything is checked before the first structure is published: every recorded type
//! against the domain's type of that name (a difference is refused naming the type
//! and the attribute), and every replayed trajectory against the domain's trajectory
//! of that name (it must have the recorded type and accept adds).
//!
//! An image is written into the trajectory's own pixel buffer
//! ([`InProcessTrajectory::image_buffer`]): into a shared-memory loan when the
//! replaying process writes the trajectory, as a live camera's frames are.

use std::collections::{BTreeMap, BinaryHeap};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::Image;
use esgm_core::time::Time;
use esgm_core::{
    AddOutcome, EntityStructure, EntityStructureType, EntityTrajectoryStructure, Esgm,
    InProcessTrajectory, TrajectorySpec, Value,
};

use crate::layout::PIXELS_ATTRIBUTE;
use crate::reader::{ReadError, RecordedSample, Recording, Samples};
use crate::type_diff::type_difference;

/// The longest pause a replay's pace computes: a crafted file's add times cannot make
/// it wait past the clock's range (stopping still ends it at once).
const LONGEST_PAUSE: Duration = Duration::from_secs(86_400);

/// How fast a replay publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// As recorded, times this factor (2.0: twice as fast).
    Rate(f64),
    /// As fast as the domain takes them.
    Max,
}

/// What happens to the recorded times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeMode {
    /// Valid and create times are shifted so the first replayed structure is valid
    /// now: delays and the robot's clock line up with the domain's. The default.
    #[default]
    ShiftToNow,
    /// Times are kept as recorded. A trajectory's delay constraint would drop every
    /// structure (they are old), so replayed trajectories the replay creates get no
    /// delay constraint; existing ones keep theirs and count the drops.
    Keep,
}

/// What happens to recorded computed trajectories.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ComputedMode {
    /// The domain's units recompute them from the replayed inputs. The default.
    #[default]
    Recompute,
    /// They are published as recorded, like primitive ones.
    AsRecorded,
}

/// A replay's settings; `Default` replays everything once, at recorded speed, shifted
/// to now, recomputing computed trajectories.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// Pacing.
    pub pace: Pace,
    /// Start again from the beginning at the end, until stopped.
    pub looped: bool,
    /// Replay only these trajectories (their names as recorded).
    pub only: Option<Vec<String>>,
    /// Skip structures valid before this time.
    pub start: Option<Time>,
    /// Skip structures valid after this time.
    pub end: Option<Time>,
    /// Times shifted or kept.
    pub times: TimeMode,
    /// Computed trajectories recomputed or replayed.
    pub computed: ComputedMode,
    /// The least look-ahead (in recorded time) used to put structures of different
    /// trajectories back in add order; the recording's own
    /// [`max_lateness`](Recording::max_lateness) is used when longer.
    pub reorder_window: Duration,
    /// Where the replay is, updated after every structure, for a progress display.
    pub position: Option<Arc<ReplayPosition>>,
}

/// Where a running replay is: shared with a progress display, which reads it while
/// [`replay`] runs on another thread.
#[derive(Debug)]
pub struct ReplayPosition {
    valid_time: AtomicI64,
    published: AtomicU64,
    passes: AtomicU64,
}

impl Default for ReplayPosition {
    fn default() -> Self {
        Self {
            valid_time: AtomicI64::new(Time::MIN),
            published: AtomicU64::new(0),
            passes: AtomicU64::new(0),
        }
    }
}

impl ReplayPosition {
    /// The recorded valid time of the structure published last (`None` before the
    /// first).
    pub fn valid_time(&self) -> Option<Time> {
        Some(self.valid_time.load(Ordering::Relaxed)).filter(|t| *t != Time::MIN)
    }

    /// Structures published so far, over all passes.
    pub fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }

    /// Passes started (1 for a replay without `looped`).
    pub fn passes(&self) -> u64 {
        self.passes.load(Ordering::Relaxed)
    }
}

impl Default for ReplayOptions {
    fn default() -> Self {
        Self {
            pace: Pace::Rate(1.0),
            looped: false,
            only: None,
            start: None,
            end: None,
            times: TimeMode::default(),
            computed: ComputedMode::default(),
            reorder_window: Duration::from_secs(2),
            position: None,
        }
    }
}

/// Why a replay was refused or stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReplayError {
    /// The system could not list what it holds (across processes: the coordinator did
    /// not answer).
    #[error(transparent)]
    System(#[from] esgm_core::SystemError),
    /// The recording cannot be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// A recorded type differs from the domain's type of that name.
    #[error("the domain's {detail}; nothing was published")]
    TypeMismatch {
        /// The type.
        type_name: String,
        /// The attribute and how it differs.
        detail: String,
    },
    /// A replayed trajectory cannot be written in this domain.
    #[error("cannot replay into `{trajectory}`: {reason}; nothing was published")]
    Trajectory {
        /// The trajectory.
        trajectory: String,
        /// Why.
        reason: String,
    },
    /// `only` names a trajectory the recording lacks.
    #[error("the recording has no trajectory `{0}`")]
    NotRecorded(String),
    /// The domain refused something while setting up or publishing.
    #[error("`{trajectory}`: {reason}")]
    Domain {
        /// The trajectory.
        trajectory: String,
        /// What the domain said.
        reason: String,
    },
}

/// What a replay did, per trajectory.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ReplayReport {
    /// Structures published and how the domain took them, per trajectory.
    pub published: BTreeMap<String, PublishCounts>,
    /// Trajectories the replay created (primitive ones for inputs, computed ones from
    /// the recorded declaration).
    pub created: Vec<String>,
    /// Recorded computed trajectories the domain will not recompute, with the reason.
    pub not_recomputed: BTreeMap<String, String>,
    /// Passes over the recording (more than one with `looped`).
    pub passes: u64,
}

/// How the domain took one trajectory's replayed structures.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct PublishCounts {
    /// Added.
    pub added: u64,
    /// Held for reordering.
    pub held: u64,
    /// Dropped by the trajectory's policy.
    pub dropped: u64,
    /// Drops by the constraint that dropped them.
    pub dropped_by: BTreeMap<String, u64>,
    /// Images written into the trajectory's own (shared) memory.
    pub images_in_place: u64,
}

/// True for the kinds a replay publishes by default.
fn is_input(kind: TrajectoryKind) -> bool {
    matches!(kind, TrajectoryKind::Primitive | TrajectoryKind::Sampled)
}

/// Registers the recording's types in `esgm`, refusing (before registering anything)
/// if one differs from the domain's type of the same name.
pub fn check_and_register_types<E: Esgm>(
    esgm: &E,
    rec: &Recording,
    names: &[&str],
) -> Result<(), ReplayError> {
    let mut needed: BTreeMap<String, EntityStructureType> = BTreeMap::new();
    for t in rec.trajectories.iter().filter(|t| names.contains(&t.info.name.as_str())) {
        needed.insert(t.info.type_name.clone(), t.types.root.clone());
        needed.extend(t.types.nested.iter().map(|(k, v)| (k.clone(), v.clone())));
    }
    let mut missing = Vec::new();
    for (name, recorded) in &needed {
        match esgm.get_entity_structure_type(name) {
            Ok(domain) => {
                if let Some(d) =
                    type_difference(name, recorded, &domain, ("in the recording", "in the domain"))
                {
                    return Err(ReplayError::TypeMismatch {
                        type_name: name.clone(),
                        detail: d.to_string(),
                    });
                }
            }
            // Not in the domain (or unreadable): creating it below reports any real failure.
            Err(_) => missing.push((name, recorded)),
        }
    }
    for (name, t) in missing {
        esgm.create_entity_structure_type(name, t.clone())
            .map_err(|e| ReplayError::Domain { trajectory: name.clone(), reason: e.to_string() })?;
    }
    Ok(())
}

/// Replays `rec` into `esgm` until done or `stop` is set: see the [module docs](self).
pub fn replay<E>(
    esgm: &E,
    rec: &Recording,
    options: &ReplayOptions,
    stop: &AtomicBool,
) -> Result<ReplayReport, ReplayError>
where
    E: Esgm<Trajectory = InProcessTrajectory>,
{
    if let Some(only) = &options.only {
        if let Some(missing) = only.iter().find(|n| rec.trajectory(n).is_none()) {
            return Err(ReplayError::NotRecorded(missing.clone()));
        }
    }
    let wanted = |t: &TrajectoryInfo| options.only.as_ref().is_none_or(|o| o.contains(&t.name));
    let published: Vec<&TrajectoryInfo> = rec
        .trajectories
        .iter()
        .map(|t| &t.info)
        .filter(|t| wanted(t) && (is_input(t.kind) || options.computed == ComputedMode::AsRecorded))
        .collect();
    let recomputed: Vec<&TrajectoryInfo> = rec
        .trajectories
        .iter()
        .map(|t| &t.info)
        .filter(|t| wanted(t) && !is_input(t.kind) && options.computed == ComputedMode::Recompute)
        .collect();

    // Check everything before publishing anything.
    let names: Vec<&str> = published.iter().chain(&recomputed).map(|t| t.name.as_str()).collect();
    check_and_register_types(esgm, rec, &names)?;
    let existing: BTreeMap<String, TrajectoryInfo> =
        esgm.trajectories()?.into_iter().map(|t| (t.name.clone(), t)).collect();
    for t in &published {
        if let Some(d) = existing.get(&t.name) {
            if d.type_name != t.type_name {
                return Err(ReplayError::Trajectory {
                    trajectory: t.name.clone(),
                    reason: format!(
                        "it holds {} in the domain, {} in the recording",
                        d.type_name, t.type_name
                    ),
                });
            }
            if d.kind != TrajectoryKind::Primitive {
                return Err(ReplayError::Trajectory {
                    trajectory: t.name.clone(),
                    reason: format!(
                        "it is {} in the domain{}, so it takes no adds (replay into a domain without it)",
                        d.kind.name(),
                        d.source.as_ref().map(|s| format!(" (fed by `{s}`)")).unwrap_or_default()
                    ),
                });
            }
        }
    }

    let mut report = ReplayReport::default();
    let mut handles: BTreeMap<String, InProcessTrajectory> = BTreeMap::new();
    for t in &published {
        if !existing.contains_key(&t.name) {
            let mut policy = t.policy.clone();
            if options.times == TimeMode::Keep {
                // Recorded times are old: a delay bound would drop every structure,
                // and a duration starting "when created" (from = 0) would too.
                policy.delay = esgm_core::DelayConstraint::Any;
                if let esgm_core::DurationConstraint::Between { from: 0, to } = policy.duration {
                    let first = rec
                        .trajectory(&t.name)
                        .and_then(|r| r.valid_range)
                        .map_or(1, |r| r.0.max(1));
                    policy.duration = esgm_core::DurationConstraint::Between { from: first, to };
                }
            }
            esgm.create_trajectory(TrajectorySpec::primitive(&t.name, &t.type_name).policy(policy))
                .map_err(|e| ReplayError::Domain {
                    trajectory: t.name.clone(),
                    reason: e.to_string(),
                })?;
            report.created.push(t.name.clone());
        }
        let h = esgm.get_entity_trajectory_structure(&t.name).map_err(|e| ReplayError::Domain {
            trajectory: t.name.clone(),
            reason: e.to_string(),
        })?;
        handles.insert(t.name.clone(), h);
        report.published.insert(t.name.clone(), PublishCounts::default());
    }
    let units: Vec<String> = esgm.comp_units()?.into_iter().map(|u| u.0).collect();
    for t in &recomputed {
        if existing.contains_key(&t.name) {
            continue; // the domain computes it already
        }
        let reason = match (&t.kind, &t.source) {
            (TrajectoryKind::Computed, Some(unit)) if units.contains(unit) => {
                let spec = TrajectorySpec::computed(&t.name, unit, t.inputs.clone())
                    .policy(t.policy.clone());
                match esgm.create_trajectory(spec) {
                    Ok(_) => {
                        report.created.push(t.name.clone());
                        continue;
                    }
                    Err(e) => e.to_string(),
                }
            }
            (TrajectoryKind::Computed, Some(unit)) => {
                format!("unit `{unit}` is not registered in the domain")
            }
            (kind, _) => format!("{} trajectories are not re-declared by a replay", kind.name()),
        };
        report.not_recomputed.insert(t.name.clone(), reason);
    }

    // Publish.
    let index_of: BTreeMap<usize, &str> = rec
        .trajectories
        .iter()
        .enumerate()
        .filter(|(_, t)| handles.contains_key(&t.info.name))
        .map(|(i, t)| (i, t.info.name.as_str()))
        .collect();
    let mut shift: Option<Time> = None;
    let mut pass_offset: Time = 0;
    loop {
        report.passes += 1;
        if let Some(p) = &options.position {
            p.passes.fetch_add(1, Ordering::Relaxed);
        }
        let started = Instant::now();
        let mut first_add: Option<Time> = None;
        let mut last_valid = Time::MIN;
        let mut first_valid = Time::MAX;
        for sample in AddOrder::of(rec, options.reorder_window)? {
            if stop.load(Ordering::Acquire) {
                return Ok(report);
            }
            let sample = sample?;
            let Some(name) = index_of.get(&sample.trajectory).copied() else { continue };
            let v = sample.structure.valid_time;
            if options.start.is_some_and(|s| v < s) || options.end.is_some_and(|e| v > e) {
                continue;
            }
            let base = *first_add.get_or_insert(sample.header.add_time);
            if let Pace::Rate(r) = options.pace {
                if r > 0.0 {
                    // Add times come from the file: the pause saturates, never wraps.
                    let wait = Duration::from_nanos(
                        (sample.header.add_time.saturating_sub(base).max(0) as f64 / r) as u64,
                    )
                    .min(LONGEST_PAUSE);
                    let due = started + wait;
                    while Instant::now() < due {
                        if stop.load(Ordering::Acquire) {
                            return Ok(report);
                        }
                        std::thread::sleep((due - Instant::now()).min(Duration::from_millis(50)));
                    }
                }
            }
            first_valid = first_valid.min(v);
            last_valid = last_valid.max(v);
            let mut es = sample.structure;
            if options.times == TimeMode::ShiftToNow {
                let offset = *shift.get_or_insert_with(|| {
                    esgm_core::clock::Clock::now(&esgm_core::SystemClock).saturating_sub(v)
                });
                let moved = offset.saturating_add(pass_offset);
                es.valid_time = es.valid_time.saturating_add(moved);
                es.create_time = es.create_time.saturating_add(moved);
            }
            let Some(handle) = handles.get(name) else { continue };
            let counts = report.published.entry(name.to_owned()).or_default();
            if into_own_buffer(handle, &mut es) {
                counts.images_in_place += 1;
            }
            let added = handle.add(es);
            if let Some(p) = &options.position {
                p.valid_time.store(v, Ordering::Relaxed);
                p.published.fetch_add(1, Ordering::Relaxed);
            }
            match added {
                Ok(AddOutcome::Added) => counts.added += 1,
                Ok(AddOutcome::Held { .. }) => counts.held += 1,
                Ok(AddOutcome::Dropped(v)) => {
                    counts.dropped += 1;
                    *counts.dropped_by.entry(v.constraint.to_string()).or_default() += 1;
                }
                Ok(other) => {
                    tracing::debug!("`{name}`: replayed structure {other:?}");
                    counts.added += 1;
                }
                Err(e) => {
                    return Err(ReplayError::Domain {
                        trajectory: name.to_owned(),
                        reason: e.to_string(),
                    });
                }
            }
        }
        if !options.looped || first_valid > last_valid {
            return Ok(report);
        }
        // The next pass continues the valid time where this one ended.
        pass_offset =
            pass_offset.saturating_add(last_valid.saturating_sub(first_valid)).saturating_add(1);
    }
}

/// Moves an image's pixels into the trajectory's own buffer (a shared-memory loan
/// where the trajectory is published), as a camera renders into one. False when the
/// structure is not an image or the trajectory has no such buffer.
fn into_own_buffer(t: &InProcessTrajectory, es: &mut EntityStructure) -> bool {
    let long = |es: &EntityStructure, a: &str| es.get(a).and_then(Value::as_long);
    let (Some(w), Some(h), Some(f)) = (long(es, "width"), long(es, "height"), long(es, "format"))
    else {
        return false;
    };
    let Some(pixels) = es.get(PIXELS_ATTRIBUTE).and_then(Value::as_octets) else { return false };
    if Image::bytes_per_pixel(f).is_none() {
        return false;
    }
    let Some(mut buffer) = t.image_buffer(w, h, f) else { return false };
    if buffer.pixels_mut().len() != pixels.len() {
        return false;
    }
    buffer.pixels_mut().copy_from_slice(pixels);
    let octets = buffer.into_octets();
    // Heap pixels are plain octets; a loan's are held by their shared-memory sample.
    let in_place = octets.is_held();
    es.set(PIXELS_ATTRIBUTE, octets);
    in_place
}

/// A recording's samples in add order: the recorder writes them as they arrive, which
/// is add order within a trajectory but may interleave trajectories a little
/// differently; samples are held until nothing recorded later can be added earlier
/// (recorded time − add time stays below the window).
#[derive(Debug)]
pub struct AddOrder {
    samples: Samples,
    heap: BinaryHeap<Pending>,
    window: Time,
    latest_recorded: Time,
    next: u64,
    done: bool,
}

/// A sample waiting in [`AddOrder`], ordered by add time then arrival.
#[derive(Debug)]
struct Pending(Time, u64, Box<RecordedSample>);

impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        (self.0, self.1) == (o.0, o.1)
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Pending {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        // A min-heap on (add time, arrival).
        (o.0, o.1).cmp(&(self.0, self.1))
    }
}

impl AddOrder {
    /// `rec`'s samples in add order, looking ahead at least `window` and as far as the
    /// recording's latest structure was late ([`Recording::max_lateness`]), plus a
    /// second for recorder threads that read the clock in a different order than
    /// they wrote: exact for every structure recorded no later than that.
    pub fn of(rec: &Recording, window: Duration) -> Result<Self, ReadError> {
        let lateness = Duration::from_nanos(u64::try_from(rec.max_lateness).unwrap_or(0));
        Ok(Self::new(rec.samples()?, window.max(lateness + Duration::from_secs(1))))
    }

    /// Orders `samples` by add time within `window`.
    pub fn new(samples: Samples, window: Duration) -> Self {
        Self {
            samples,
            heap: BinaryHeap::new(),
            window: Time::try_from(window.as_nanos()).unwrap_or(Time::MAX),
            latest_recorded: Time::MIN,
            next: 0,
            done: false,
        }
    }
}

impl Iterator for AddOrder {
    type Item = Result<RecordedSample, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(top) = self.heap.peek() {
                if self.done || top.0 < self.latest_recorded.saturating_sub(self.window) {
                    return self.heap.pop().map(|p| Ok(*p.2));
                }
            } else if self.done {
                return None;
            }
            match self.samples.next() {
                Some(Ok(s)) => {
                    self.latest_recorded = self.latest_recorded.max(s.header.recorded_time);
                    self.heap.push(Pending(s.header.add_time, self.next, Box::new(s)));
                    self.next += 1;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(e));
                }
                None => self.done = true,
            }
        }
    }
}
