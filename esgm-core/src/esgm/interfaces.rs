//! The interfaces users implement: pull sensors (`SensorInterface`) and
//! computational units (`CompUnit`), with closures accepted as either.

use crate::pixel_buffer::OctetsAllocator;
use crate::sample::Sample;
use crate::time::Time;
use crate::value::frame::EntityStructure;

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
///
/// A closure is a sensor:
///
/// ```
/// use std::sync::Arc;
/// use esgm_core::prelude::*;
///
/// let esgm = InProcessEsgm::default();
/// esgm.create_type(EntityStructureType::new("Battery").attr("volts", ValueSort::Double)).unwrap();
/// let battery = |qtime: Time| -> Result<EntityStructure, SensorError> {
///     Ok(EntityStructure::named("battery").at(qtime).with("volts", 24.1))
/// };
/// esgm.add_sensor_interface("battery", "Battery", Arc::new(battery)).unwrap();
/// // Sampled every 10 ms from now, for ever, any delay, the last 100 kept.
/// let volts =
///     esgm.create_entity_trajectory_structure("volts", "battery", 0, 0, millis(10), 0, 100)
///         .unwrap();
/// let samples = volts.subscribe(SubscribeOptions::default()).unwrap();
/// let first = samples.recv_timeout(std::time::Duration::from_secs(5)).unwrap();
/// let next = samples.recv_timeout(std::time::Duration::from_secs(5)).unwrap();
/// assert_eq!(first.get("volts").and_then(|v| v.as_double()), Some(24.1));
/// // Stamped at their sample times, whole periods apart.
/// let apart = next.valid_time() - first.valid_time();
/// assert!(apart > 0 && apart % millis(10) == 0, "{apart} ns apart");
/// ```
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
///
/// A closure is a unit. The same code runs on a system of processes
/// (`esgm_shm::connect`), where the unit runs in the process that registered it.
///
/// ```
/// use std::sync::Arc;
/// use std::time::{Duration, Instant};
/// use esgm_core::prelude::*;
///
/// let esgm = InProcessEsgm::default();
/// esgm.create_type(EntityStructureType::new("Reading").attr("x", ValueSort::Double)).unwrap();
/// // Doubles its one input's `x`; no output while `x` is missing.
/// let double = |inputs: &[Sample], _qtime: Time| -> Result<EntityStructure, ComputeError> {
///     // Read where the input lies (in another process's memory, across processes).
///     let x = inputs[0].get("x").and_then(|x| x.as_double());
///     let x = x.ok_or(ComputeError::ValueNotAvailable)?;
///     Ok(EntityStructure::named("doubled").at(inputs[0].valid_time()).with("x", 2.0 * x))
/// };
/// let reading = vec![InputType::Type("Reading".into())];
/// esgm.add_comp_unit("double", "Reading", reading, Arc::new(double)).unwrap();
/// let raw = esgm.create_primitive_entity_trajectory_structure("raw", "Reading").unwrap();
/// let doubled =
///     esgm.create_computed_entity_trajectory_structure("doubled", "double", &["raw"]).unwrap();
/// raw.add(EntityStructure::named("r").at(secs(1)).with("x", 1.5)).unwrap();
/// esgm.flush(Instant::now() + Duration::from_secs(5)).unwrap();
/// let out = doubled.get_latest().unwrap();
/// assert_eq!((out.valid_time(), out.value("x")), (secs(1), Some(Value::Double(3.0))));
/// ```
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
