//! The interfaces users implement: pull sensors (`SensorInterface`) and
//! computational units (`CompUnit`), with closures accepted as either.

use crate::frame::EntityStructure;
use crate::pixel_buffer::OctetsAllocator;
use crate::sample::Sample;
use crate::time::Time;

/// A sensor failed to produce a value; the sampler counts it and carries on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SensorError {
    /// No value can be read now (the seed's `ValueNotAvailable`).
    #[error("value not available")]
    ValueNotAvailable,
    /// The sensor failed; the reason is logged and counted.
    #[error("sensor failed: {reason}")]
    Failed {
        /// What went wrong.
        reason: String,
    },
}

/// A pull source (seed 2.2): esgm calls it at each sample time of every sampled
/// trajectory created from it.
///
/// It must answer at any time, since it does not choose when it is asked. `qtime` is
/// the scheduled sample time (an exact multiple of the period after the start); a
/// sensor that reads "now" should stamp its structure's valid time with it. A sensor
/// that stamps its own acquisition time instead must keep consecutive valid times at
/// least a period apart, or the sampled trajectory's "sample every period" constraint
/// drops the early ones (counted as change violations).
pub trait SensorInterface: Send + Sync {
    /// The current value, as asked at `qtime`.
    fn get_current_value(&self, qtime: Time) -> Result<EntityStructure, SensorError>;

    /// The current value, with the trajectory's own image buffers at hand: a camera
    /// renders its frame into `images.image(..)` (shared memory on the shared-memory
    /// runtime), so the frame is written once, where every reader reads it. The
    /// default ignores them and calls [`SensorInterface::get_current_value`].
    fn get_current_value_with(
        &self,
        qtime: Time,
        images: &dyn OctetsAllocator,
    ) -> Result<EntityStructure, SensorError> {
        let _heap_is_fine = images;
        self.get_current_value(qtime)
    }
}

impl<F> SensorInterface for F
where
    F: Fn(Time) -> Result<EntityStructure, SensorError> + Send + Sync,
{
    fn get_current_value(&self, qtime: Time) -> Result<EntityStructure, SensorError> {
        self(qtime)
    }
}

/// A computational unit produced no output.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ComputeError {
    /// Nothing to output for these inputs (the seed's `ValueNotAvailable`): not an
    /// error, just no output this time.
    #[error("value not available")]
    ValueNotAvailable,
    /// The unit does not support this operation (e.g. `compute_at`).
    #[error("operation not supported")]
    OperationNotSupported,
    /// The unit failed; the reason is logged and counted.
    #[error("computation failed: {reason}")]
    Failed {
        /// What went wrong.
        reason: String,
    },
}

/// A computation on entity structures (seed 2.3, 3.3.2): esgm calls it with the
/// latest sample of each input, in input order, whenever an input is updated.
pub trait CompUnit: Send + Sync {
    /// Computes an output from `inputs` (one per input trajectory), asked at `qtime`.
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError>;

    /// Computes the output valid at `t` (a temporal function). Optional.
    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        let _ = (inputs, t);
        Err(ComputeError::OperationNotSupported)
    }
}

impl<F> CompUnit for F
where
    F: Fn(&[Sample], Time) -> Result<EntityStructure, ComputeError> + Send + Sync,
{
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        self(inputs, qtime)
    }
}
