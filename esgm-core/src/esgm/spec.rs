//! The richer constructor: a trajectory described in full (source + policy), so the
//! seed's "reasonable set of constraints" and every operator are one call away.

use crate::generator::GeneratorPolicy;
use crate::operators::sync::SyncPolicy;
use crate::policy::{FluentStreamPolicy, PolicyError};
use crate::time::Time;

/// Where a trajectory's structures come from (the content part of a DyKnow policy).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum TrajectorySource {
    /// Pushed by an outside source (E2).
    Primitive {
        /// The registered type of its structures.
        type_name: String,
    },
    /// Pulled from a registered sensor every `sample_period` between `from` and `to`
    /// (E3; `from = 0`: now, `to = 0`: forever).
    Sampled {
        /// The sensor.
        sensor: String,
        /// First sample time.
        from: Time,
        /// Last sample time.
        to: Time,
        /// Time between samples.
        sample_period: Time,
    },
    /// Computed by a unit on every update of any input (E4).
    Computed {
        /// The computational unit.
        unit: String,
        /// The inputs, in the order the unit receives them.
        inputs: Vec<String>,
    },
    /// States holding one sample of every input valid at the same time (G2).
    Sync {
        /// The inputs.
        inputs: Vec<String>,
        /// Exact or approximate (ROS ApproximateTime) matching.
        policy: SyncPolicy,
    },
    /// Every sample of every input, in the order they arrive (G3).
    Merge {
        /// The inputs; they must share one type.
        inputs: Vec<String>,
    },
    /// A stream sampled from fluent generators over other trajectories (G4,
    /// `fstream(l, s, c)`): with one input, the generator's values; with several, a
    /// state of all of them (`state(s1..sn)`); with a `unit`, the unit's temporal
    /// function of them (`feature(l, f(s1..sn))` sampled: `compute_at(values, t)`).
    SampledGenerators {
        /// The inputs and the generator policy (approximation + merge) for each.
        inputs: Vec<(String, GeneratorPolicy)>,
        /// A computational unit whose `compute_at` combines the inputs' values at each
        /// sample time, if any.
        unit: Option<String>,
        /// First sample time (0 = now).
        from: Time,
        /// Last sample time (0 = forever).
        to: Time,
        /// Time between samples.
        sample_period: Time,
        /// How far behind its sample time each value is taken: at sample time `t` the
        /// generators are read at `t − lag`, which is the structure's valid time. A
        /// linear approximation needs a sample after the time it is asked for, which a
        /// live stream has only some time later (as tf2 looks up transforms in the
        /// past); 0 reads at the sample time itself.
        #[serde(default)]
        lag: Time,
    },
}

/// A full description of a trajectory to create.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrajectorySpec {
    /// The trajectory's name.
    pub name: String,
    /// Where its structures come from.
    pub source: TrajectorySource,
    /// The constraints it keeps.
    pub policy: FluentStreamPolicy,
    /// If a trajectory with this name exists, re-point the name to the new one; its
    /// subscribers move over and see the new stream from then on (E5).
    pub replace: bool,
    /// How many processes may read it at once, where a runtime must size its transport
    /// up front (shared memory; see [`crate::esgm::Limit::Readers`]). `None`: the
    /// system's default (the domain's `esgm up --readers`). The in-process runtime has
    /// no such limit and ignores it.
    #[serde(default)]
    pub readers: Option<usize>,
    /// Its history lives only in the process that writes it and its readers (ROS 2's
    /// "volatile" durability): a primitive trajectory's acknowledged structures are
    /// otherwise kept where they outlive every process while the domain runs (SPEC
    /// D1), which costs one encode per add into that memory, a copy for images. For a
    /// camera's frames, whose history nobody asks for after the camera died. The
    /// in-process runtime has no process to outlive and ignores it.
    #[serde(default)]
    pub volatile: bool,
}

impl TrajectorySpec {
    fn new(name: impl Into<String>, source: TrajectorySource) -> Self {
        Self {
            name: name.into(),
            source,
            policy: FluentStreamPolicy::default(),
            replace: false,
            readers: None,
            volatile: false,
        }
    }

    /// A trajectory whose history is not kept beyond the process that writes it (see
    /// the field `volatile`).
    #[must_use]
    pub fn volatile(mut self) -> Self {
        self.volatile = true;
        self
    }

    /// Room for `readers` processes reading it at once (see the field `readers`).
    #[must_use]
    pub fn readers(mut self, readers: usize) -> Self {
        self.readers = Some(readers);
        self
    }

    /// A primitive trajectory of `type_name`, unconstrained until a policy is set.
    pub fn primitive(name: impl Into<String>, type_name: impl Into<String>) -> Self {
        Self::new(name, TrajectorySource::Primitive { type_name: type_name.into() })
    }

    /// A sampled trajectory with the seed's policy for it (period → change, from/to →
    /// duration, monotone order; delay any and keep all until set).
    pub fn sampled(
        name: impl Into<String>,
        sensor: impl Into<String>,
        sample_period: Time,
    ) -> Result<Self, PolicyError> {
        let mut s = Self::new(
            name,
            TrajectorySource::Sampled { sensor: sensor.into(), from: 0, to: 0, sample_period },
        );
        s.policy = FluentStreamPolicy::sampled(0, 0, sample_period, 0, 0)?;
        Ok(s)
    }

    /// A computed trajectory.
    pub fn computed<S: Into<String>>(
        name: impl Into<String>,
        unit: impl Into<String>,
        inputs: impl IntoIterator<Item = S>,
    ) -> Self {
        Self::new(
            name,
            TrajectorySource::Computed {
                unit: unit.into(),
                inputs: inputs.into_iter().map(Into::into).collect(),
            },
        )
    }

    /// A synchronized trajectory of states.
    pub fn sync<S: Into<String>>(
        name: impl Into<String>,
        inputs: impl IntoIterator<Item = S>,
        policy: SyncPolicy,
    ) -> Self {
        Self::new(
            name,
            TrajectorySource::Sync { inputs: inputs.into_iter().map(Into::into).collect(), policy },
        )
    }

    /// A merged trajectory.
    pub fn merge<S: Into<String>>(
        name: impl Into<String>,
        inputs: impl IntoIterator<Item = S>,
    ) -> Self {
        Self::new(
            name,
            TrajectorySource::Merge { inputs: inputs.into_iter().map(Into::into).collect() },
        )
    }

    /// A trajectory sampled every `sample_period` from generators over `inputs`.
    pub fn sampled_generators<S: Into<String>>(
        name: impl Into<String>,
        inputs: impl IntoIterator<Item = (S, GeneratorPolicy)>,
        sample_period: Time,
    ) -> Self {
        Self::new(
            name,
            TrajectorySource::SampledGenerators {
                inputs: inputs.into_iter().map(|(n, g)| (n.into(), g)).collect(),
                unit: None,
                from: 0,
                to: 0,
                sample_period,
                lag: 0,
            },
        )
    }

    /// A trajectory sampled every `sample_period` from `unit`'s temporal function
    /// (`compute_at`) of the values of generators over `inputs` at each sample time.
    pub fn sampled_function<S: Into<String>>(
        name: impl Into<String>,
        unit: impl Into<String>,
        inputs: impl IntoIterator<Item = (S, GeneratorPolicy)>,
        sample_period: Time,
    ) -> Self {
        let mut s = Self::sampled_generators(name, inputs, sample_period);
        if let TrajectorySource::SampledGenerators { unit: u, .. } = &mut s.source {
            *u = Some(unit.into());
        }
        s
    }

    /// Reads the generators `lag` behind each sample time (see
    /// [`TrajectorySource::SampledGenerators`]); other sources ignore it.
    #[must_use]
    pub fn lag(mut self, lag: Time) -> Self {
        if let TrajectorySource::SampledGenerators { lag: l, .. } = &mut self.source {
            *l = lag;
        }
        self
    }

    /// Sets the policy.
    #[must_use]
    pub fn policy(mut self, policy: FluentStreamPolicy) -> Self {
        self.policy = policy;
        self
    }

    /// Sets the start and end of a sampled source (0 rules as in E3), and, as E3 does,
    /// the policy's duration constraint to the same interval.
    #[must_use]
    pub fn between(mut self, from_time: Time, to_time: Time) -> Self {
        match &mut self.source {
            TrajectorySource::Sampled { from, to, .. }
            | TrajectorySource::SampledGenerators { from, to, .. } => {
                *from = from_time;
                *to = to_time;
                self.policy.duration =
                    crate::policy::DurationConstraint::Between { from: from_time, to: to_time };
            }
            _ => {}
        }
        self
    }

    /// Re-points the name if it exists (subscribers move to the new trajectory).
    #[must_use]
    pub fn replace(mut self) -> Self {
        self.replace = true;
        self
    }

    /// The trajectory's kind, for listings.
    pub fn kind(&self) -> TrajectoryKind {
        match self.source {
            TrajectorySource::Primitive { .. } => TrajectoryKind::Primitive,
            TrajectorySource::Sampled { .. } => TrajectoryKind::Sampled,
            TrajectorySource::Computed { .. } => TrajectoryKind::Computed,
            TrajectorySource::Sync { .. } => TrajectoryKind::Sync,
            TrajectorySource::Merge { .. } => TrajectoryKind::Merge,
            TrajectorySource::SampledGenerators { unit: Some(_), .. } => {
                TrajectoryKind::SampledFunction
            }
            TrajectorySource::SampledGenerators { .. } => TrajectoryKind::SampledGenerators,
        }
    }

    /// The names of the trajectories this one reads, in order.
    pub fn inputs(&self) -> Vec<String> {
        match &self.source {
            TrajectorySource::Computed { inputs, .. }
            | TrajectorySource::Sync { inputs, .. }
            | TrajectorySource::Merge { inputs } => inputs.clone(),
            TrajectorySource::SampledGenerators { inputs, .. } => {
                inputs.iter().map(|(n, _)| n.clone()).collect()
            }
            _ => Vec::new(),
        }
    }
}

/// The kinds of trajectory, for listings and graphs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum TrajectoryKind {
    /// Pushed from outside.
    Primitive,
    /// Pulled from a sensor.
    Sampled,
    /// Computed by a unit.
    Computed,
    /// Synchronized states.
    Sync,
    /// Merged inputs.
    Merge,
    /// Sampled from generators.
    SampledGenerators,
    /// Sampled from a unit's temporal function of generators.
    SampledFunction,
}

impl TrajectoryKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            TrajectoryKind::Primitive => "primitive",
            TrajectoryKind::Sampled => "sampled",
            TrajectoryKind::Computed => "computed",
            TrajectoryKind::Sync => "sync",
            TrajectoryKind::Merge => "merge",
            TrajectoryKind::SampledGenerators => "sampled-generators",
            TrajectoryKind::SampledFunction => "sampled-function",
        }
    }
}
