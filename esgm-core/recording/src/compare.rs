//! Comparing two recordings trajectory by trajectory (`esgm compare`).
//!
//! Trajectories of the same name are aligned by valid time and their structures
//! compared attribute by attribute ([`crate::value_diff`]). What is reported per
//! trajectory: the counts in each file, the pairs matched, the structures only one
//! file has, the first difference (valid time, attribute, both values), the largest
//! numeric deviation, and whether the two recorded types differ
//! ([`crate::type_diff`]). A trajectory only one file has is reported as such.
//!
//! # Alignment
//! B's structures are put in esgm-core's own trajectory store (no policy, keep all),
//! so alignment asks B the queries a trajectory answers, with their rules:
//! - [`Alignment::Exact`]: the structures valid at the same time pair up; several at
//!   one valid time pair in create-time order, then recorded order.
//! - [`Alignment::Nearest`]: each structure of A pairs with B's structure of the
//!   closest valid time ([`ValueApproximation::Closest`]: before wins a tie) if it is
//!   within the given time. One of B's may pair with several of A's.
//!
//! # Memory
//! The two files are streamed. Trajectories without octet sequences are read in one
//! pass; each trajectory with images in a pass of its own, so at most one image
//! trajectory's structures (from both files) are in memory at a time.

mod by_lineage;

pub use by_lineage::{DifferenceOrigin, InputComparison, InputVerdict, MAX_DEPTH};

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;

use esgm_core::approximation::ValueApproximation;
use esgm_core::clock::{SharedClock, SimClock};
use esgm_core::store::{AddError, TrajectoryStore};
use esgm_core::time::Time;
use esgm_core::value::ValueSort;
use esgm_core::{EntityStructure, Lineage, PolicyError, Sample, TypeChecker, TypeRegistryError};

use crate::reader::{Damage, ReadError, RecordedTrajectory, Recording};
use crate::type_diff::{TypeDifference, schema_difference, schema_types};
use crate::value_diff::{LeafDeviation, diff_structures};

/// How structures of the two files are paired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Alignment {
    /// Same valid time (the default).
    #[default]
    Exact,
    /// B's closest valid time, if at most `within` away.
    Nearest {
        /// The largest valid-time distance of a pair, ns.
        within: Time,
    },
}

/// What to compare and how. `Default`: every trajectory, exact alignment, bitwise
/// equal values, create times compared.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareOptions {
    /// Compare only these trajectories (empty: all).
    pub only: Vec<String>,
    /// How structures are paired.
    pub alignment: Alignment,
    /// Numeric leaves within this distance are equal; `None`: bitwise equality.
    pub value_tolerance: Option<f64>,
    /// Whether create times must be equal too (off for a replay whose times were
    /// shifted to now).
    pub create_time: bool,
    /// Compare each trajectory only over the valid times both files cover: two
    /// recordings of one system started at different moments (a live recording that
    /// began with each trajectory's history, and a rerun of its inputs) then compare
    /// what they have in common.
    pub overlap: bool,
}

impl Default for CompareOptions {
    fn default() -> Self {
        Self {
            only: Vec::new(),
            alignment: Alignment::Exact,
            value_tolerance: None,
            create_time: true,
            overlap: false,
        }
    }
}

impl CompareOptions {
    /// The defaults.
    pub fn new() -> Self {
        Self::default()
    }
    /// Compares only these trajectories.
    #[must_use]
    pub fn only<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.only = names.into_iter().map(Into::into).collect();
        self
    }
    /// Sets the alignment.
    #[must_use]
    pub fn alignment(mut self, alignment: Alignment) -> Self {
        self.alignment = alignment;
        self
    }
    /// Pairs with B's closest valid time within `within` ns.
    #[must_use]
    pub fn nearest(self, within: Time) -> Self {
        self.alignment(Alignment::Nearest { within })
    }
    /// Numbers within `tolerance` of each other are equal.
    #[must_use]
    pub fn value_tolerance(mut self, tolerance: Option<f64>) -> Self {
        self.value_tolerance = tolerance;
        self
    }
    /// Compares create times (on by default).
    #[must_use]
    pub fn create_time(mut self, on: bool) -> Self {
        self.create_time = on;
        self
    }
    /// Compares only the valid times both files cover (off by default).
    #[must_use]
    pub fn overlap(mut self, on: bool) -> Self {
        self.overlap = on;
        self
    }
}

/// Comparing failed; each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CompareError {
    /// A file cannot be read (the error names it and the position).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// `--only` names a trajectory neither file has; check the spelling (`esgm info`).
    #[error("no trajectory `{name}` in {} or {}", a.display(), b.display())]
    NoSuchTrajectory {
        /// The name asked for.
        name: String,
        /// The first file.
        a: PathBuf,
        /// The second file.
        b: PathBuf,
    },
    /// A trajectory's recorded types do not form a usable definition; the file is
    /// damaged or was written by another tool.
    #[error("{}: the types of `{trajectory}` are unusable: {source}", path.display())]
    Types {
        /// The file.
        path: PathBuf,
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: Box<TypeRegistryError>,
    },
    /// A recorded structure does not fit its own recorded type; the file is damaged or
    /// was written by another tool.
    #[error("{}: a structure of `{trajectory}` does not fit its recorded type: {source}", path.display())]
    Structure {
        /// The file.
        path: PathBuf,
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: Box<AddError>,
    },
    /// The valid-time index of a trajectory cannot be built (an unconstrained policy
    /// always validates; this is a bug to report).
    #[error("{}: cannot index `{trajectory}`: {source}", path.display())]
    Index {
        /// The file.
        path: PathBuf,
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: Box<PolicyError>,
    },
}

/// Which files hold a trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Presence {
    /// Both.
    Both,
    /// Only the first.
    OnlyInA,
    /// Only the second.
    OnlyInB,
}

/// The first pair that differs.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FirstDifference {
    /// Valid time of A's structure.
    pub valid_time: Time,
    /// Valid time of B's structure (the same with exact alignment).
    pub valid_time_b: Time,
    /// The attribute path (`x`, `blobs[2].size`, `image_data[1043]`, `(create_time)`).
    pub attribute: String,
    /// A's value, as text.
    pub a: String,
    /// B's value, as text.
    pub b: String,
    /// The inputs A's structure was made from (its lineage), each compared with the
    /// one B's was made from, followed back while they differ: which recorded input
    /// the output differs by. Empty for a structure without lineage.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<InputComparison>,
    /// Where the difference comes from, as far as the lineage tells: a differing
    /// source structure, a producer given the same inputs, inputs paired otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub origins: Vec<DifferenceOrigin>,
}

/// The largest numeric deviation over every pair.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LargestDeviation {
    /// Where and how much.
    #[serde(flatten)]
    pub leaf: LeafDeviation,
    /// Valid time of A's structure.
    pub valid_time: Time,
}

/// How one trajectory compares.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TrajectoryComparison {
    /// The trajectory.
    pub name: String,
    /// Which files hold it.
    pub presence: Presence,
    /// Structures in A.
    pub count_a: u64,
    /// Structures in B.
    pub count_b: u64,
    /// Pairs aligned.
    pub matched: u64,
    /// Pairs that differ.
    pub differing: u64,
    /// A's structures with no partner in B.
    pub only_in_a: u64,
    /// B's structures with no partner in A.
    pub only_in_b: u64,
    /// Valid time of the first structure only A has.
    pub first_only_in_a: Option<Time>,
    /// Valid time of the first structure only B has.
    pub first_only_in_b: Option<Time>,
    /// The first differing pair in A's valid-time order.
    pub first_difference: Option<FirstDifference>,
    /// The largest numeric deviation over every pair (also within the tolerance).
    pub largest_deviation: Option<LargestDeviation>,
    /// How the recorded types differ, if they do.
    pub type_difference: Option<TypeDifference>,
}

impl TrajectoryComparison {
    /// True if anything differs: presence, type, values or unmatched structures.
    pub fn differs(&self) -> bool {
        self.presence != Presence::Both
            || self.type_difference.is_some()
            || self.differing > 0
            || self.only_in_a > 0
            || self.only_in_b > 0
    }

    fn one_sided(name: &str, presence: Presence, count: u64) -> Self {
        let (count_a, count_b) =
            if presence == Presence::OnlyInA { (count, 0) } else { (0, count) };
        Self {
            name: name.to_owned(),
            presence,
            count_a,
            count_b,
            matched: 0,
            differing: 0,
            only_in_a: count_a,
            only_in_b: count_b,
            first_only_in_a: None,
            first_only_in_b: None,
            first_difference: None,
            largest_deviation: None,
            type_difference: None,
        }
    }
}

/// What [`compare`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CompareReport {
    /// The first file.
    pub a: PathBuf,
    /// The second file.
    pub b: PathBuf,
    /// How structures were paired.
    pub alignment: Alignment,
    /// The numeric tolerance, if any.
    pub value_tolerance: Option<f64>,
    /// Per trajectory: A's in order, then those only B has.
    pub trajectories: Vec<TrajectoryComparison>,
    /// Where A stops being readable, if it is damaged (only what precedes is compared).
    pub damage_a: Option<Damage>,
    /// Where B stops being readable, if it is damaged.
    pub damage_b: Option<Damage>,
}

impl CompareReport {
    /// True if any trajectory differs.
    pub fn differs(&self) -> bool {
        self.trajectories.iter().any(TrajectoryComparison::differs)
    }
}

/// Compares `a` and `b` (see the [module docs](self)).
pub fn compare(
    a: &Recording,
    b: &Recording,
    options: &CompareOptions,
) -> Result<CompareReport, CompareError> {
    for name in &options.only {
        if a.trajectory(name).is_none() && b.trajectory(name).is_none() {
            return Err(CompareError::NoSuchTrajectory {
                name: name.clone(),
                a: a.path.clone(),
                b: b.path.clone(),
            });
        }
    }
    let wanted = |n: &str| options.only.is_empty() || options.only.iter().any(|o| o == n);
    let mut names: Vec<&str> =
        a.trajectories.iter().map(|t| t.info.name.as_str()).filter(|n| wanted(n)).collect();
    names.extend(
        b.trajectories
            .iter()
            .map(|t| t.info.name.as_str())
            .filter(|n| wanted(n) && a.trajectory(n).is_none()),
    );

    // Passes: every image-free trajectory in both files at once, then each one with
    // octet sequences alone.
    let both: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| a.trajectory(n).is_some() && b.trajectory(n).is_some())
        .collect();
    let (light, heavy): (Vec<&str>, Vec<&str>) = both.iter().partition(|n| {
        !a.trajectory(n).is_some_and(has_octets) && !b.trajectory(n).is_some_and(has_octets)
    });
    let mut passes: Vec<Vec<&str>> = Vec::new();
    if !light.is_empty() {
        passes.push(light);
    }
    passes.extend(heavy.into_iter().map(|n| vec![n]));

    let mut results: BTreeMap<&str, TrajectoryComparison> = BTreeMap::new();
    let mut differing: Vec<by_lineage::Differing> = Vec::new();
    for pass in passes {
        let mut from_a = read_pass(a, &pass)?;
        let mut from_b = read_pass(b, &pass)?;
        for name in pass {
            let (ta, tb) = match (a.trajectory(name), b.trajectory(name)) {
                (Some(ta), Some(tb)) => (ta, tb),
                _ => continue,
            };
            let mut sa = from_a.remove(name).unwrap_or_default();
            let mut sb = from_b.remove(name).unwrap_or_default();
            if options.overlap {
                if let (Some((a_lo, a_hi)), Some((b_lo, b_hi))) = (ta.valid_range, tb.valid_range) {
                    let (lo, hi) = (a_lo.max(b_lo), a_hi.min(b_hi));
                    sa.retain(|(s, _)| (lo..=hi).contains(&s.valid_time));
                    sb.retain(|(s, _)| (lo..=hi).contains(&s.valid_time));
                }
            }
            let (result, lineages) = compare_one(options, (b, tb), ta, tb, sa, sb)?;
            if let (Some(first), Some((lineage_a, lineage_b))) =
                (&result.first_difference, lineages)
            {
                differing.push(by_lineage::Differing {
                    trajectory: name.to_owned(),
                    valid_time: first.valid_time,
                    lineage_a,
                    lineage_b,
                });
            }
            results.insert(name, result);
        }
    }
    // Each first difference of a produced structure, followed back through its inputs.
    let explained = by_lineage::explain(a, b, options, &differing)?;
    for (out, (inputs, origins)) in differing.iter().zip(explained) {
        let first =
            results.get_mut(out.trajectory.as_str()).and_then(|r| r.first_difference.as_mut());
        if let Some(first) = first {
            first.inputs = inputs;
            first.origins = origins;
        }
    }
    let trajectories = names
        .iter()
        .map(|n| match (results.remove(n), a.trajectory(n), b.trajectory(n)) {
            (Some(r), _, _) => r,
            (None, Some(t), _) => TrajectoryComparison::one_sided(n, Presence::OnlyInA, t.count),
            (None, None, Some(t)) => TrajectoryComparison::one_sided(n, Presence::OnlyInB, t.count),
            (None, None, None) => TrajectoryComparison::one_sided(n, Presence::OnlyInA, 0),
        })
        .collect();
    Ok(CompareReport {
        a: a.path.clone(),
        b: b.path.clone(),
        alignment: options.alignment,
        value_tolerance: options.value_tolerance,
        trajectories,
        damage_a: a.damage.clone(),
        damage_b: b.damage.clone(),
    })
}

/// True if a trajectory's type (or a type it nests) has octet sequences (images).
fn has_octets(t: &RecordedTrajectory) -> bool {
    schema_types(&t.info.type_name, &t.types)
        .iter()
        .any(|(_, ty)| ty.attributes.iter().any(|a| a.sort == ValueSort::OctetSeq))
}

/// A recorded structure and the lineage recorded with it.
type Traced = (EntityStructure, Option<Arc<Lineage>>);

/// The structures of `names` in `rec`, in recorded order, with their lineage.
fn read_pass(
    rec: &Recording,
    names: &[&str],
) -> Result<BTreeMap<String, Vec<Traced>>, CompareError> {
    let indexes: HashSet<usize> = rec
        .trajectories
        .iter()
        .enumerate()
        .filter(|(_, t)| names.contains(&t.info.name.as_str()))
        .map(|(i, _)| i)
        .collect();
    let mut out: BTreeMap<String, Vec<Traced>> = BTreeMap::new();
    for sample in rec.samples()? {
        let sample = sample?;
        if indexes.contains(&sample.trajectory) {
            let name = &rec.trajectories[sample.trajectory].info.name;
            let lineage = sample.lineage.map(Arc::new);
            out.entry(name.clone()).or_default().push((sample.structure, lineage));
        }
    }
    Ok(out)
}

/// B's structures in esgm-core's store, so alignment uses its valid-time queries.
fn index(
    rec: &Recording,
    t: &RecordedTrajectory,
    structures: Vec<Traced>,
) -> Result<TrajectoryStore, CompareError> {
    let name = &t.info.name;
    let definitions = schema_types(&t.info.type_name, &t.types)
        .into_iter()
        .map(|(n, ty)| (n.to_owned(), ty.clone()))
        .collect::<Vec<_>>();
    let checker =
        TypeChecker::from_definitions(&t.info.type_name, definitions).map_err(|source| {
            CompareError::Types {
                path: rec.path.clone(),
                trajectory: name.clone(),
                source: Box::new(source),
            }
        })?;
    let clock: SharedClock = SimClock::shared(0);
    let mut store = TrajectoryStore::builder(name.clone(), checker).clock(clock).create().map_err(
        |source| CompareError::Index {
            path: rec.path.clone(),
            trajectory: name.clone(),
            source: Box::new(source),
        },
    )?;
    for (es, lineage) in structures {
        store.add_produced(Arc::new(es), lineage, false).map_err(|source| {
            CompareError::Structure {
                path: rec.path.clone(),
                trajectory: name.clone(),
                source: Box::new(source),
            }
        })?;
    }
    Ok(store)
}

fn compare_one(
    options: &CompareOptions,
    (b_rec, b_traj): (&Recording, &RecordedTrajectory),
    ta: &RecordedTrajectory,
    tb: &RecordedTrajectory,
    sa: Vec<Traced>,
    sb: Vec<Traced>,
) -> Result<(TrajectoryComparison, Option<Lineages>), CompareError> {
    let mut r = TrajectoryComparison::one_sided(&ta.info.name, Presence::Both, 0);
    r.count_a = sa.len() as u64;
    r.count_b = sb.len() as u64;
    r.only_in_a = 0;
    r.type_difference = schema_difference(
        (&ta.info.type_name, &ta.types),
        (&tb.info.type_name, &tb.types),
        ("in A", "in B"),
    );
    let store = index(b_rec, b_traj, sb)?;

    // A in valid-time order; ties by create time, then recorded order.
    let mut a_sorted: Vec<(usize, Traced)> = sa.into_iter().enumerate().collect();
    a_sorted.sort_by_key(|(i, (e, _))| (e.valid_time, e.create_time, *i));
    let mut used: HashSet<*const ()> = HashSet::new();
    let mut pairs: Vec<(Traced, Sample)> = Vec::new();
    let unmatched_a = |r: &mut TrajectoryComparison, e: &EntityStructure| {
        r.only_in_a += 1;
        r.first_only_in_a.get_or_insert(e.valid_time);
    };
    match options.alignment {
        Alignment::Exact => {
            let mut i = 0;
            while i < a_sorted.len() {
                let vt = a_sorted[i].1.0.valid_time;
                let group_end = a_sorted[i..]
                    .iter()
                    .position(|(_, (e, _))| e.valid_time != vt)
                    .map_or(a_sorted.len(), |k| i + k);
                let mut partners = store.get_between(vt, vt);
                // get_between keeps add order among ties; create time first.
                partners.sort_by_key(|s| s.structure.create_time());
                let mut partners = partners.into_iter();
                for (_, e) in &a_sorted[i..group_end] {
                    match partners.next() {
                        Some(s) => {
                            used.insert(s.structure.identity());
                            pairs.push((e.clone(), s));
                        }
                        None => unmatched_a(&mut r, &e.0),
                    }
                }
                i = group_end;
            }
        }
        Alignment::Nearest { within } => {
            for (_, e) in &a_sorted {
                let vt = e.0.valid_time;
                match store.get_at_approximating(vt, &ValueApproximation::Closest) {
                    Ok(s)
                        if (i128::from(s.structure.valid_time()) - i128::from(vt)).abs()
                            <= i128::from(within) =>
                    {
                        used.insert(s.structure.identity());
                        pairs.push((e.clone(), s));
                    }
                    _ => unmatched_a(&mut r, &e.0),
                }
            }
        }
    }
    for s in store.samples() {
        if !used.contains(&s.structure.identity()) {
            r.only_in_b += 1;
            let vt = s.structure.valid_time();
            r.first_only_in_b = Some(r.first_only_in_b.map_or(vt, |f: Time| f.min(vt)));
        }
    }
    r.matched = pairs.len() as u64;
    let mut lineages = None;
    for ((ea, lineage_a), sb) in &pairs {
        let d = diff_structures(
            ea,
            &sb.structure.to_arc(),
            options.value_tolerance,
            options.create_time,
        );
        if let Some(first) = d.first {
            r.differing += 1;
            if r.first_difference.is_none() && (lineage_a.is_some() || sb.lineage.is_some()) {
                lineages = Some((lineage_a.clone(), sb.lineage.clone()));
            }
            r.first_difference.get_or_insert(FirstDifference {
                valid_time: ea.valid_time,
                valid_time_b: sb.structure.valid_time(),
                attribute: first.attribute,
                a: first.a,
                b: first.b,
                inputs: Vec::new(),
                origins: Vec::new(),
            });
        }
        if let Some(leaf) = d.largest {
            if r.largest_deviation.as_ref().is_none_or(|l| leaf.deviation > l.leaf.deviation) {
                r.largest_deviation = Some(LargestDeviation { leaf, valid_time: ea.valid_time });
            }
        }
    }
    Ok((r, lineages))
}

/// A's and B's lineage of a structure.
type Lineages = (Option<Arc<Lineage>>, Option<Arc<Lineage>>);
