//! The declarations a configuration file (and the command line) is made of: one struct
//! per kind of thing, read from TOML tables and, where the command line creates the
//! same thing (`esgm type add`, `esgm traj create`), from flags — one declaration, two
//! faces.

use std::collections::BTreeMap;

use anyhow::{Context, bail};
use esgm_core::esgm::{TrajectorySource, TrajectorySpec};
use esgm_core::operators::sync::SyncPolicy;
use esgm_core::value::ValueSort;
use esgm_core::{Attr, EntityStructureType, Time};
use serde::Deserialize;

use crate::policy_args::{PolicyArgs, duration};
use crate::time_arg::TimeArg;
use esgm_core::generator_entry::parse_generator;

/// `[[type]]` / `esgm type add`: an entity structure type.
#[derive(Debug, Clone, clap::Args, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TypeDecl {
    /// The type's name.
    pub name: String,
    /// Attributes as `name:Sort`, e.g. `x:Double`, `blobs:EntityFrameSeq<Blob>`.
    #[arg(required = true)]
    pub attributes: Vec<String>,
}

impl TypeDecl {
    /// The type, or an error naming the attribute that is wrong.
    pub fn to_type(&self) -> anyhow::Result<EntityStructureType> {
        let mut t = EntityStructureType::new(&self.name);
        for a in &self.attributes {
            t.attributes.push(attr(a)?);
        }
        t.validate()?;
        Ok(t)
    }
}

/// `name:Sort` or `name:Sort<ElementType>` (spaces allowed).
fn attr(spec: &str) -> anyhow::Result<Attr> {
    let (name, sort) = spec
        .split_once(':')
        .with_context(|| format!("attribute `{spec}` must be written name:Sort, e.g. x:Double"))?;
    let (sort, element) = match sort.trim().split_once('<') {
        Some((s, rest)) => {
            let element = rest
                .strip_suffix('>')
                .with_context(|| format!("attribute `{spec}`: missing `>`"))?;
            (s.trim(), Some(element.trim().to_owned()))
        }
        None => (sort.trim(), None),
    };
    let sort = ValueSort::parse(sort).with_context(|| {
        format!("attribute `{spec}`: unknown sort `{sort}` (e.g. Long, Double, String, Pos2, OctetSeq, EntityFrameSeq)")
    })?;
    Ok(Attr { name: name.trim().to_owned(), sort, element_type: element })
}

/// `[[sensor]]`: a pull sensor served by a process the system keeps running — a
/// built-in camera, your own program, or a class written in Python.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorDecl {
    /// The sensor's name.
    pub name: String,
    /// `"synthetic"` (moving bright blobs), or a directory of PNG/JPEG frames.
    pub camera: Option<String>,
    /// Your own program serving the sensor (it registers it under `name`): a bare
    /// name found on `PATH`, or a path relative to this file.
    pub program: Option<String>,
    /// The older name of `program`.
    pub exec: Option<String>,
    /// A class written in Python serving the sensor, `"FILE.py:CLASS"` (relative to
    /// this file): run as a worker by `python -m esgm.worker`.
    pub python: Option<String>,
    /// The interpreter of `python` (default: `ESGM_PYTHON`, else `python3`); the
    /// `esgm` package must be installed in it.
    pub interpreter: Option<String>,
    /// Its arguments.
    #[serde(default)]
    pub args: Vec<String>,
    /// Extra environment for it.
    #[serde(default)]
    pub env: BTreeMap<String, String>,
    /// Synthetic scene: seed (same seed, same scene).
    pub seed: Option<u64>,
    /// Synthetic scene: number of blobs.
    pub blobs: Option<usize>,
    /// Synthetic scene: width in pixels.
    pub width: Option<u32>,
    /// Synthetic scene: height in pixels.
    pub height: Option<u32>,
    /// Directory camera: time each frame is shown (e.g. `100ms`).
    pub frame_period: Option<String>,
}

/// `[[unit]]`: a computational unit served by a process the system keeps running —
/// built in (BlobDetection, BlobSelection, DrivingDirection, MovingAverage), your
/// own program, or a class written in Python.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitDecl {
    /// The unit's registered name.
    pub name: String,
    /// Which built-in unit (default: the one called `name`).
    pub builtin: Option<String>,
    /// Your own program serving the unit (it registers it under `name`): a bare name
    /// found on `PATH`, or a path relative to this file.
    pub program: Option<String>,
    /// The older name of `program`.
    pub exec: Option<String>,
    /// A class written in Python serving the unit, `"FILE.py:CLASS"` (relative to
    /// this file): run as a worker by `python -m esgm.worker`.
    pub python: Option<String>,
    /// The interpreter of `python` (default: `ESGM_PYTHON`, else `python3`); the
    /// `esgm` package must be installed in it.
    pub interpreter: Option<String>,
    /// Its arguments.
    #[serde(default)]
    pub args: Vec<String>,
    /// Extra environment for it.
    #[serde(default)]
    pub env: BTreeMap<String, String>,
    /// MovingAverage: the type it averages (input and output).
    #[serde(rename = "type")]
    pub type_name: Option<String>,
    /// MovingAverage: samples in the window.
    pub window: Option<usize>,
}

impl UnitDecl {
    /// Whether a program of the user's serves it (`program`, or its older name
    /// `exec`), not one of esgm's.
    pub fn has_program(&self) -> bool {
        self.program.is_some() || self.exec.is_some()
    }
}

/// The built-in units a worker can serve.
pub const BUILTIN_UNITS: [&str; 4] =
    ["BlobDetection", "BlobSelection", "DrivingDirection", "MovingAverage"];

/// `[[robot]]`: the tutorial's robot, pushing its state and steering by a direction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDecl {
    /// The primitive trajectory it pushes `RobotState`s into.
    #[serde(default = "robot_state")]
    pub trajectory: String,
    /// The `DrivingDirection` trajectory it follows.
    #[serde(default = "driving_direction")]
    pub follow: String,
    /// Time between states (default `100ms`: 10 Hz).
    pub period: Option<String>,
}

fn robot_state() -> String {
    "robot_state".into()
}

fn driving_direction() -> String {
    "driving_direction".into()
}

/// `[[trajectory]]` / `esgm traj create`: a trajectory, its source and its policy.
/// Exactly one source: `primitive`, `sampled`, `computed`, `sync`, `merge` or
/// `generate`.
#[derive(Debug, Clone, Default, clap::Args, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryDecl {
    /// The trajectory's name.
    pub name: String,
    /// Pushed structures of this type.
    #[arg(long, value_name = "TYPE")]
    pub primitive: Option<String>,
    /// Sampled from this sensor every `period`.
    #[arg(long, value_name = "SENSOR")]
    pub sampled: Option<String>,
    /// Computed by this unit from `inputs`.
    #[arg(long, value_name = "UNIT")]
    pub computed: Option<String>,
    /// States of these trajectories with the same valid time.
    #[arg(long, value_delimiter = ',', value_name = "TRAJ,TRAJ")]
    pub sync: Option<Vec<String>>,
    /// Every sample of these trajectories (one type), as they come.
    #[arg(long, value_delimiter = ',', value_name = "TRAJ,TRAJ")]
    pub merge: Option<Vec<String>>,
    /// Sampled every `period` from fluent generators over these trajectories, each
    /// `TRAJ[:APPROXIMATION[:MERGE]]` (approximation: none, closest, most-recent,
    /// linear; merge: keep-first, keep-last, average, median). Several give their state.
    #[arg(long, value_delimiter = ',', value_name = "TRAJ[:APPROX[:MERGE]],…")]
    pub generate: Option<Vec<String>>,
    /// Generate: sample this unit's temporal function (`compute_at`) of the generators'
    /// values instead of the values themselves.
    #[arg(long, value_name = "UNIT")]
    pub function: Option<String>,
    /// Generate: read the generators this long before each sample time, which becomes
    /// the valid time (`100ms`): a `linear` generator needs a sample after the time it
    /// is read at, which a live stream has only later.
    #[arg(long)]
    pub lag: Option<String>,
    /// Inputs of a computed trajectory, in the unit's order.
    #[arg(long, value_delimiter = ',', value_name = "TRAJ,TRAJ")]
    pub inputs: Option<Vec<String>>,
    /// Sampled or generate: time between samples (`100ms`).
    #[arg(long)]
    pub period: Option<String>,
    /// Sampled or generate: first sample time (ns or RFC 3339; 0 = now).
    #[arg(long = "start", value_name = "TIME")]
    #[serde(rename = "start")]
    pub start: Option<String>,
    /// Sampled or generate: last sample time (ns or RFC 3339; 0 = forever).
    #[arg(long = "stop", value_name = "TIME")]
    #[serde(rename = "stop")]
    pub stop: Option<String>,
    /// Sampled or generate: sample times on multiples of the period since the epoch,
    /// the first the next one after the trajectory is created (instead of `start`).
    /// Trajectories sampled in different processes then tick together, as timers made
    /// together in one process do, and so do periods that divide one another.
    #[arg(long)]
    #[serde(default)]
    pub align: bool,
    /// Sync: match items within this tolerance (ROS ApproximateTime) instead of exactly.
    #[arg(long)]
    pub tolerance: Option<String>,
    /// Sync with a tolerance: `approximate` (the default; ROS ApproximateTime, the best
    /// sets) or `epsilon` (ROS ApproximateEpsilonTime: a set as soon as every input
    /// has an item within the tolerance of the oldest).
    #[arg(long, value_name = "POLICY")]
    pub sync_policy: Option<String>,
    /// Sync: items held per input (default 10).
    #[arg(long)]
    pub queue: Option<usize>,
    /// Primitive: the process that writes it, whose policy gate admits every add
    /// (default: the coordinator's own process; other processes' adds are forwarded
    /// there). Name the main pusher, e.g. `robot-robot_state`, to save it a hop.
    #[arg(long)]
    pub writer: Option<String>,
    /// If the name exists, re-point it to the new trajectory (subscribers move over).
    #[arg(long)]
    #[serde(default)]
    pub replace: bool,
    /// Reader processes it admits at once (default: the domain's `esgm up --readers`;
    /// at most its --max-processes). Raise it for a stream every process reads (a
    /// `tf`-like one); each reader costs its writer about 3 KiB of private memory.
    #[arg(long, value_name = "N")]
    pub readers: Option<usize>,
    /// Keep its history only in its writer and readers, as ROS 2's volatile
    /// durability (a camera's frames): a primitive trajectory's acknowledged
    /// structures otherwise outlive every process while the domain runs.
    #[arg(long)]
    #[serde(default)]
    pub volatile: bool,
    /// The policy (C1–C6).
    #[command(flatten)]
    #[serde(default)]
    pub policy: PolicyArgs,
}

impl TrajectoryDecl {
    /// The names of the trajectories it reads.
    pub fn inputs(&self) -> Vec<String> {
        let mut out = Vec::new();
        for list in [&self.sync, &self.merge, &self.inputs].into_iter().flatten() {
            out.extend(list.iter().cloned());
        }
        for entry in self.generate.iter().flatten() {
            // A malformed entry is reported by `to_spec`; its name part is still read.
            out.push(entry.split(':').next().unwrap_or_default().trim().to_owned());
        }
        out
    }

    /// The spec to create, or an error naming what is missing or wrong.
    pub fn to_spec(&self) -> anyhow::Result<TrajectorySpec> {
        let sources = [
            self.primitive.is_some(),
            self.sampled.is_some(),
            self.computed.is_some(),
            self.sync.is_some(),
            self.merge.is_some(),
            self.generate.is_some(),
        ];
        match sources.iter().filter(|s| **s).count() {
            1 => {}
            0 => bail!(
                "trajectory `{}` needs a source: primitive, sampled, computed, sync, merge or \
                 generate",
                self.name
            ),
            _ => bail!(
                "trajectory `{}` has more than one source (primitive, sampled, computed, sync, \
                 merge, generate)",
                self.name
            ),
        }
        let only_for = |set: bool, what: &str, source: &str| -> anyhow::Result<()> {
            if set {
                bail!("trajectory `{}`: `{what}` is only for {source} trajectories", self.name);
            }
            Ok(())
        };
        let periodic = self.sampled.is_some() || self.generate.is_some();
        let sampled_or_generate = "sampled and generate";
        only_for(!periodic && self.period.is_some(), "period", sampled_or_generate)?;
        only_for(!periodic && self.start.is_some(), "start", sampled_or_generate)?;
        only_for(!periodic && self.stop.is_some(), "stop", sampled_or_generate)?;
        only_for(!periodic && self.align, "align", sampled_or_generate)?;
        if self.align && self.start.is_some() {
            bail!(
                "trajectory `{}`: give start or align (the next multiple of the period), not both",
                self.name
            );
        }
        only_for(self.generate.is_none() && self.function.is_some(), "function", "generate")?;
        only_for(self.generate.is_none() && self.lag.is_some(), "lag", "generate")?;
        only_for(self.computed.is_none() && self.inputs.is_some(), "inputs", "computed")?;
        only_for(self.sync.is_none() && self.tolerance.is_some(), "tolerance", "sync")?;
        only_for(self.sync.is_none() && self.sync_policy.is_some(), "sync_policy", "sync")?;
        only_for(self.sync.is_none() && self.queue.is_some(), "queue", "sync")?;
        only_for(self.primitive.is_none() && self.writer.is_some(), "writer", "primitive")?;

        let period = || -> anyhow::Result<Time> {
            let period = self.period.as_deref().with_context(|| {
                format!("sampled trajectory `{}` needs a period, e.g. 100ms", self.name)
            })?;
            duration(period).context("period")
        };
        let start = self.start.as_deref().map_or(Ok(0), |s| absolute("start", s))?;
        let stop = self.stop.as_deref().map_or(Ok(0), |s| absolute("stop", s))?;
        let mut spec = if let Some(t) = &self.primitive {
            TrajectorySpec::primitive(&self.name, t)
        } else if let Some(sensor) = &self.sampled {
            TrajectorySpec::sampled(&self.name, sensor, period()?)?.between(start, stop)
        } else if let Some(entries) = &self.generate {
            if entries.is_empty() {
                bail!("trajectory `{}`: `generate` needs at least one trajectory", self.name);
            }
            let generators = entries
                .iter()
                .map(|e| parse_generator(e))
                .collect::<Result<Vec<_>, _>>()
                .with_context(|| format!("trajectory `{}`", self.name))?;
            let spec = match &self.function {
                Some(unit) => {
                    TrajectorySpec::sampled_function(&self.name, unit, generators, period()?)
                }
                None => TrajectorySpec::sampled_generators(&self.name, generators, period()?),
            };
            let lag = self.lag.as_deref().map_or(Ok(0), duration).context("lag")?;
            spec.between(start, stop).lag(lag)
        } else if let Some(unit) = &self.computed {
            let inputs = self.inputs.clone().unwrap_or_default();
            if inputs.is_empty() {
                bail!("computed trajectory `{}` needs inputs", self.name);
            }
            TrajectorySpec::computed(&self.name, unit, inputs)
        } else if let Some(inputs) = &self.sync {
            let queue = self.queue.unwrap_or(10);
            let tolerance =
                self.tolerance.as_deref().map(duration).transpose().context("tolerance")?;
            let policy = SyncPolicy::from_words(self.sync_policy.as_deref(), tolerance, queue)
                .with_context(|| format!("trajectory `{}`", self.name))?;
            TrajectorySpec::sync(&self.name, inputs.clone(), policy)
        } else {
            TrajectorySpec::merge(&self.name, self.merge.clone().unwrap_or_default())
        };
        spec.policy = self.policy.apply_to(spec.policy)?;
        if self.replace {
            spec = spec.replace();
        }
        if let Some(readers) = self.readers {
            if readers == 0 {
                bail!(
                    "trajectory `{}`: readers = 0: at least one process must be able to read it",
                    self.name
                );
            }
            spec = spec.readers(readers);
        }
        if self.volatile {
            spec = spec.volatile();
        }
        Ok(spec)
    }
}

/// `spec` with its first sample time on the next multiple of its sample period after
/// `now` (`align = true`); a source that is not sampled is returned as it is. It is
/// resolved when the trajectory is created, not when the file is read: a first sample
/// time already past would count the sample times in between as missed.
pub fn aligned(mut spec: TrajectorySpec, now: Time) -> TrajectorySpec {
    match &mut spec.source {
        TrajectorySource::Sampled { from, sample_period, .. }
        | TrajectorySource::SampledGenerators { from, sample_period, .. }
            if *sample_period > 0 =>
        {
            *from = (now.max(0) / *sample_period + 1).saturating_mul(*sample_period);
        }
        _ => {}
    }
    spec
}

fn absolute(field: &str, s: &str) -> anyhow::Result<Time> {
    match s.parse::<TimeArg>() {
        Ok(TimeArg::Absolute(t)) => Ok(t),
        _ => bail!("{field} = `{s}`: expected nanoseconds or an RFC 3339 time (0 = default)"),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use esgm_core::esgm::TrajectoryKind;

    use super::*;

    #[test]
    fn attributes_with_sorts_and_element_types() {
        let t = TypeDecl {
            name: "Scan".into(),
            attributes: vec!["range: Double".into(), "hits: EntityFrameSeq<Blob>".into()],
        }
        .to_type()
        .unwrap();
        assert_eq!(t.attributes[0].sort, ValueSort::Double);
        assert_eq!(t.attributes[1].element_type.as_deref(), Some("Blob"));
        for bad in ["range", "range: Meters", "hits: frames<Blob"] {
            let decl = TypeDecl { name: "Scan".into(), attributes: vec![bad.into()] };
            assert!(decl.to_type().is_err(), "{bad}");
        }
    }

    /// One name for the tolerance, and the sync policy by name.
    #[test]
    fn sync_policies_by_name_with_one_tolerance() {
        let sync = |tolerance: Option<&str>, policy: Option<&str>| {
            TrajectoryDecl {
                name: "pair".into(),
                sync: Some(vec!["a".into(), "b".into()]),
                tolerance: tolerance.map(Into::into),
                sync_policy: policy.map(Into::into),
                ..Default::default()
            }
            .to_spec()
        };
        let policy = |spec: TrajectorySpec| match spec.source {
            esgm_core::esgm::TrajectorySource::Sync { policy, .. } => policy,
            other => panic!("not a sync: {other:?}"),
        };
        let ms20 = 20_000_000;
        assert!(matches!(policy(sync(None, None).unwrap()), SyncPolicy::Exact(_)));
        assert!(matches!(
            policy(sync(Some("20ms"), None).unwrap()),
            SyncPolicy::Approximate(c) if c.tolerance == Some(ms20)
        ));
        assert!(matches!(
            policy(sync(Some("20ms"), Some("epsilon")).unwrap()),
            SyncPolicy::Epsilon(c) if c.tolerance == ms20
        ));
        assert!(sync(None, Some("epsilon")).is_err(), "epsilon needs a tolerance");
        assert!(sync(Some("20ms"), Some("closest")).is_err());
    }

    #[test]
    fn exactly_one_source_and_options_only_where_they_mean_something() {
        let sampled = TrajectoryDecl {
            name: "images".into(),
            sampled: Some("camera".into()),
            period: Some("100ms".into()),
            ..Default::default()
        };
        assert_eq!(sampled.to_spec().unwrap().kind(), TrajectoryKind::Sampled);
        let none = TrajectoryDecl { name: "x".into(), ..Default::default() };
        assert!(format!("{:#}", none.to_spec().unwrap_err()).contains("needs a source"));
        let two = TrajectoryDecl { primitive: Some("Blob".into()), ..sampled.clone() };
        assert!(format!("{:#}", two.to_spec().unwrap_err()).contains("more than one source"));
        let stray = TrajectoryDecl {
            name: "b".into(),
            primitive: Some("Blob".into()),
            period: Some("1s".into()),
            ..Default::default()
        };
        assert!(format!("{:#}", stray.to_spec().unwrap_err()).contains("only for sampled"));
        let no_period = TrajectoryDecl { period: None, ..sampled };
        assert!(format!("{:#}", no_period.to_spec().unwrap_err()).contains("period"));
        let function = TrajectoryDecl {
            name: "b".into(),
            merge: Some(vec!["a".into()]),
            function: Some("Steer".into()),
            ..Default::default()
        };
        let e = format!("{:#}", function.to_spec().unwrap_err());
        assert!(e.contains("`function` is only for generate"), "{e}");
    }

    /// `align = true`: the first sample time is the next multiple of the period after
    /// the creation time, so every later one is a multiple too.
    #[test]
    fn aligned_trajectories_sample_on_multiples_of_their_period() {
        use esgm_core::esgm::TrajectorySource;
        let ms = 1_000_000;
        let decl = TrajectoryDecl {
            name: "lidar".into(),
            sampled: Some("lidar".into()),
            period: Some("25ms".into()),
            align: true,
            ..Default::default()
        };
        let spec = decl.to_spec().unwrap();
        let from = |spec: &TrajectorySpec| match &spec.source {
            TrajectorySource::Sampled { from, .. }
            | TrajectorySource::SampledGenerators { from, .. } => *from,
            other => panic!("not sampled: {other:?}"),
        };
        assert_eq!(from(&spec), 0, "resolved when created, not when read");
        assert_eq!(from(&aligned(spec.clone(), 1_000 * ms + 1)), 1_025 * ms);
        assert_eq!(from(&aligned(spec.clone(), 1_000 * ms)), 1_025 * ms, "strictly after");
        assert_eq!(from(&aligned(spec, 1_024 * ms)), 1_025 * ms);
        let generate = TrajectoryDecl {
            name: "plan".into(),
            generate: Some(vec!["lidar:closest".into()]),
            period: Some("100ms".into()),
            align: true,
            ..Default::default()
        };
        assert_eq!(from(&aligned(generate.to_spec().unwrap(), 1_050 * ms)), 1_100 * ms);

        let with_start = TrajectoryDecl { start: Some("5".into()), ..decl.clone() };
        let e = format!("{:#}", with_start.to_spec().unwrap_err());
        assert!(e.contains("start or align"), "{e}");
        let computed = TrajectoryDecl {
            name: "c".into(),
            computed: Some("Unit".into()),
            inputs: Some(vec!["lidar".into()]),
            align: true,
            ..Default::default()
        };
        let e = format!("{:#}", computed.to_spec().unwrap_err());
        assert!(e.contains("`align` is only for sampled and generate"), "{e}");
        let spec = TrajectorySpec::computed("c", "Unit", ["lidar"]);
        assert!(matches!(aligned(spec, 7).source, TrajectorySource::Computed { .. }));
    }

    #[test]
    fn generators_give_their_values_their_state_or_a_temporal_function() {
        use esgm_core::approximation::{MergeRule, ValueApproximation};
        use esgm_core::esgm::TrajectorySource;
        let decl = TrajectoryDecl {
            name: "pose".into(),
            generate: Some(vec!["robot_state:linear".into(), "alt:closest:median".into()]),
            function: Some("Fuse".into()),
            period: Some("100ms".into()),
            start: Some("5".into()),
            lag: Some("50ms".into()),
            ..Default::default()
        };
        assert_eq!(decl.inputs(), ["robot_state", "alt"]);
        let spec = decl.to_spec().unwrap();
        let TrajectorySource::SampledGenerators { inputs, unit, from, sample_period, lag, .. } =
            &spec.source
        else {
            panic!("{spec:?}")
        };
        assert_eq!(unit.as_deref(), Some("Fuse"));
        assert_eq!(*lag, 50_000_000);
        assert_eq!((*from, *sample_period), (5, 100_000_000));
        assert_eq!(inputs[0].1.approximation, ValueApproximation::Linear);
        assert_eq!(inputs[1].1.merge, MergeRule::Median);
        let empty = TrajectoryDecl { generate: Some(vec![]), function: None, ..decl.clone() };
        assert!(format!("{:#}", empty.to_spec().unwrap_err()).contains("at least one"));
        let no_period = TrajectoryDecl { period: None, ..decl };
        assert!(format!("{:#}", no_period.to_spec().unwrap_err()).contains("period"));
    }
}
