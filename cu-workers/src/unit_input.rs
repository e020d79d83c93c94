//! Reading a computational unit's inputs: the one place the runtime adapters turn
//! [`Sample`]s into the typed library structs, and their failures into a typed error.

use esgm_core::{ComputeError, Entity, FromEntityError, Sample};

/// A unit's inputs cannot be read. The runtime counts the call as failed and logs this
/// message; the trajectory keeps running.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum UnitInputError {
    /// The unit got the wrong number of inputs. A runtime checks the count against the
    /// registered input types when the trajectory is created, so this only happens when
    /// a unit is called directly: pass one sample per declared input.
    #[error("{unit} takes {expected} input(s), got {found}")]
    WrongInputCount {
        /// The unit's registered name.
        unit: &'static str,
        /// Inputs it declares.
        expected: usize,
        /// Inputs given.
        found: usize,
    },
    /// An input is not a structure of the type the unit declares: connect a trajectory
    /// of that type (registering the unit with typed inputs makes the runtime refuse
    /// others up front), or fix the producer.
    #[error("input {position} of {unit} is not a readable `{type_name}`: {source}")]
    WrongType {
        /// The unit's registered name.
        unit: &'static str,
        /// The input's position (0-based, in the trajectory's input order).
        position: usize,
        /// The type the unit expects there.
        type_name: &'static str,
        /// What did not fit.
        source: FromEntityError,
    },
}

/// The inputs as an array of exactly `N`, for destructuring.
pub(crate) fn exactly<'a, const N: usize>(
    unit: &'static str,
    inputs: &'a [Sample],
) -> Result<&'a [Sample; N], UnitInputError> {
    inputs.try_into().map_err(|_| UnitInputError::WrongInputCount {
        unit,
        expected: N,
        found: inputs.len(),
    })
}

/// Input `position` as a `T`.
pub(crate) fn read<T: Entity>(
    unit: &'static str,
    position: usize,
    sample: &Sample,
) -> Result<T, UnitInputError> {
    T::from_structure(sample).map_err(|source| UnitInputError::WrongType {
        unit,
        position,
        type_name: T::TYPE_NAME,
        source,
    })
}

/// A typed error as the runtime's failure outcome, keeping its message.
pub(crate) fn failed(error: impl std::fmt::Display) -> ComputeError {
    ComputeError::Failed { reason: error.to_string() }
}
