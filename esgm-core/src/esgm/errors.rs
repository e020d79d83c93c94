//! One error enum per kind of ESGM operation, with the seed's exception names as
//! variants. Every variant names what was wrong (and, for unknown names, the closest
//! known one).

use crate::operators::sync::SyncError;
use crate::policy::PolicyError;
use crate::type_registry::did_you_mean;
use crate::value::ValueSort;

/// Errors of the `create_…_entity_trajectory_structure` operations.
#[derive(Debug, Clone, PartialEq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum CreateError {
    /// The name is taken; destroy the trajectory first, choose another name, or
    /// re-point the name with `replace`.
    #[error("entity trajectory structure `{name}` already exists")]
    EntityStructureAlreadyExists {
        /// The name.
        name: String,
    },
    /// The type is not registered.
    #[error("no entity structure type `{name}`{}", did_you_mean(suggestion))]
    NoSuchEntityStructureType {
        /// The unknown type.
        name: String,
        /// The closest registered type.
        suggestion: Option<String>,
    },
    /// The sensor is not registered; `add_sensor_interface` it first.
    #[error("no sensor `{name}`{}", did_you_mean(suggestion))]
    NoSuchSensor {
        /// The unknown sensor.
        name: String,
        /// The closest registered sensor.
        suggestion: Option<String>,
    },
    /// The computational unit is not registered; `add_comp_unit` it first.
    #[error("no computational unit `{name}`{}", did_you_mean(suggestion))]
    NoSuchCompUnit {
        /// The unknown unit.
        name: String,
        /// The closest registered unit.
        suggestion: Option<String>,
    },
    /// An input trajectory does not exist.
    #[error("no entity trajectory structure `{name}` (an input){}", did_you_mean(suggestion))]
    NoSuchEntityStructure {
        /// The unknown input.
        name: String,
        /// The closest existing trajectory.
        suggestion: Option<String>,
    },
    /// The policy makes no sense (the seed's `IllegalPolicy`).
    #[error(transparent)]
    IllegalPolicy(#[from] PolicyError),
    /// The number of inputs differs from what the unit declared.
    #[error("computational unit `{unit}` takes {expected} inputs, {found} given")]
    WrongInputCount {
        /// The unit.
        unit: String,
        /// Declared inputs.
        expected: usize,
        /// Inputs given.
        found: usize,
    },
    /// An input trajectory's type is not what the unit (or operator) declared.
    #[error("input {position} (`{input}`) of `{unit}` has type `{actual}`, expected {expected}")]
    InvalidInput {
        /// The unit or operator.
        unit: String,
        /// The input trajectory.
        input: String,
        /// Its position (0-based).
        position: usize,
        /// What was declared.
        expected: String,
        /// The input's type.
        actual: String,
    },
    /// An operator's own settings are invalid (sync queue size, tolerance, …).
    #[error("illegal operator: {0}")]
    IllegalOperator(#[from] SyncError),
    /// Re-pointing the name would make the trajectory read itself (directly or through
    /// other trajectories), a loop with no source; read another name.
    #[error("`{name}` would read itself through {}", path.join(" → "))]
    Cycle {
        /// The trajectory.
        name: String,
        /// The chain of inputs that leads back to it.
        path: Vec<String>,
    },
    /// Re-pointing may not change a trajectory's type: trajectories reading the name
    /// were checked against the old one. Destroy and re-create instead.
    #[error("`{name}` has type `{old}`; re-pointing it to type `{new}` is refused")]
    TypeChange {
        /// The trajectory.
        name: String,
        /// Its current type.
        old: String,
        /// The type asked for.
        new: String,
    },
    /// The trajectory needs at least one input.
    #[error("`{name}` needs at least one input")]
    NoInputs {
        /// The trajectory.
        name: String,
    },
    /// A limit of the runtime was reached (shared memory: the domain's processes, or
    /// a trajectory's readers); the error names the setting that raises it. Nothing
    /// was changed, and every other process is served as before.
    #[error(transparent)]
    LimitReached(#[from] crate::esgm::LimitReached),
    /// A definition of the trajectory's types, as its writer's process or host sent
    /// it, is not valid here (malformed, or from an incompatible version): no replica
    /// was made. The writer's side has to fix or re-register the type.
    #[error("the definition of entity structure type `{name}` is invalid: {reason}")]
    InvalidTypeDefinition {
        /// The type whose definition was refused.
        name: String,
        /// Why it was refused.
        reason: String,
    },
    /// The ESGM could not be reached or did not answer (a remote runtime whose
    /// coordinator is gone, stuck or unreachable — CORBA's `COMM_FAILURE`). Nothing
    /// was changed by this call as far as the caller can tell; retry or check the
    /// coordinator.
    #[error("the ESGM is unavailable: {reason}")]
    Unavailable {
        /// Why.
        reason: crate::esgm::Unreachable,
    },
}

/// Errors of looking a trajectory up or destroying it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum LookupError {
    /// No trajectory has that name (the seed's `NoSuchEntityStructure`).
    #[error("no entity trajectory structure `{name}`{}", did_you_mean(suggestion))]
    NoSuchEntityStructure {
        /// The unknown name.
        name: String,
        /// The closest existing name.
        suggestion: Option<String>,
    },
    /// A limit of the runtime was reached (shared memory: the domain's processes, or
    /// a trajectory's readers); the error names the setting that raises it. Nothing
    /// was changed, and every other process is served as before.
    #[error(transparent)]
    LimitReached(#[from] crate::esgm::LimitReached),
    /// The ESGM could not be reached or did not answer (a remote runtime whose
    /// coordinator is gone, stuck or unreachable — CORBA's `COMM_FAILURE`). Nothing
    /// was changed by this call as far as the caller can tell; retry or check the
    /// coordinator.
    #[error("the ESGM is unavailable: {reason}")]
    Unavailable {
        /// Why.
        reason: crate::esgm::Unreachable,
    },
}

/// Errors of registering or removing sensors and computational units.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum RegistrationError {
    /// A sensor with that name is registered; remove it first.
    #[error("sensor `{name}` already exists")]
    SensorAlreadyExists {
        /// The name.
        name: String,
    },
    /// No sensor has that name.
    #[error("no sensor `{name}`{}", did_you_mean(suggestion))]
    NoSuchSensor {
        /// The unknown name.
        name: String,
        /// The closest registered sensor.
        suggestion: Option<String>,
    },
    /// A unit with that name is registered; remove it first.
    #[error("computational unit `{name}` already exists")]
    CompUnitAlreadyExists {
        /// The name.
        name: String,
    },
    /// No unit has that name.
    #[error("no computational unit `{name}`{}", did_you_mean(suggestion))]
    NoSuchCompUnit {
        /// The unknown name.
        name: String,
        /// The closest registered unit.
        suggestion: Option<String>,
    },
    /// The declared output type is not registered.
    #[error("no entity structure type `{name}`{}", did_you_mean(suggestion))]
    NoSuchEntityStructureType {
        /// The unknown type.
        name: String,
        /// The closest registered type.
        suggestion: Option<String>,
    },
    /// Trajectories still use it; destroy them first.
    #[error("`{name}` is used by {}", users.join(", "))]
    InUse {
        /// The sensor or unit.
        name: String,
        /// The trajectories that use it.
        users: Vec<String>,
    },
    /// The ESGM could not be reached or did not answer (a remote runtime whose
    /// coordinator is gone, stuck or unreachable — CORBA's `COMM_FAILURE`). Nothing
    /// was changed by this call as far as the caller can tell; retry or check the
    /// coordinator.
    #[error("the ESGM is unavailable: {reason}")]
    Unavailable {
        /// Why.
        reason: crate::esgm::Unreachable,
    },
}

/// What a computational unit declares about one input: any structure (the seed's
/// `ENTITY_FRAME_TYPE`) or structures of one registered type.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum InputType {
    /// A value sort: `EntityFrame` or `AnyValue` accept any trajectory.
    Sort(ValueSort),
    /// A registered entity structure type name.
    Type(String),
}

impl From<ValueSort> for InputType {
    fn from(s: ValueSort) -> Self {
        InputType::Sort(s)
    }
}

impl From<&str> for InputType {
    fn from(s: &str) -> Self {
        InputType::Type(s.to_owned())
    }
}

impl std::fmt::Display for InputType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InputType::Sort(s) => write!(f, "{s}"),
            InputType::Type(t) => write!(f, "type `{t}`"),
        }
    }
}

impl InputType {
    /// True if a trajectory of type `type_name` fits.
    pub fn accepts(&self, type_name: &str) -> bool {
        match self {
            InputType::Sort(ValueSort::EntityFrame | ValueSort::AnyValue) => true,
            InputType::Sort(_) => false,
            InputType::Type(t) => t == type_name,
        }
    }
}

/// [`crate::Esgm::flush`] gave up.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum FlushError {
    /// The deadline passed with work still queued (a unit slower than the deadline
    /// allows, or one that never returns); wait longer, or look at `waiting_for`.
    #[error("the deadline passed while `{waiting_for}` was still processing")]
    DeadlinePassed {
        /// A trajectory, or a process, still at work.
        waiting_for: String,
    },
    /// A process of the system could not be asked (see the reason).
    #[error("cannot flush the system: {reason}")]
    Unavailable {
        /// Why.
        reason: crate::esgm::Unreachable,
    },
}

/// A system-wide call (E7's listings, statistics, reset and log level) could not reach
/// what it concerns. Across processes, an answer built from part of the system would
/// look complete and not be, so none is given: the error says what is missing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum SystemError {
    /// The coordinator, or the domain's administration channel, could not be asked or
    /// did not answer.
    #[error("cannot {operation}: {reason}")]
    Unavailable {
        /// What was asked (`list the trajectories`, `reset the system`…).
        operation: String,
        /// Why it could not be.
        reason: crate::esgm::Unreachable,
    },
    /// Some processes of the domain did not answer in time (one is stuck or gone): the
    /// operation reached only `answered` of `expected`.
    #[error("cannot {operation}: {answered} of {expected} processes answered within {timeout:?}")]
    Incomplete {
        /// What was asked.
        operation: String,
        /// Processes that answered.
        answered: usize,
        /// Processes connected when it was asked.
        expected: usize,
        /// How long they had.
        timeout: std::time::Duration,
    },
}
