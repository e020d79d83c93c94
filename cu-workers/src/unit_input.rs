//! Reading an untyped unit's inputs (the moving average, over any type a system file
//! names), and a unit's failures as the runtime's outcome. The typed units
//! ([`esgm_core::esgm::TypedUnit`]) have their inputs read by esgm-core's adapter.

use esgm_core::{ComputeError, Sample};

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

/// A typed error as the runtime's failure outcome, keeping its message.
pub(crate) fn failed(error: impl std::fmt::Display) -> ComputeError {
    ComputeError::Failed { reason: error.to_string() }
}
