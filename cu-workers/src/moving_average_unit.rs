//! [`MovingAverage`] as an esgm computational unit: a generic smoother for any
//! trajectory whose structures carry numbers (positions, blob centroids, states).
//!
//! The output has the input's type, so the unit is registered once per type it
//! smooths (`MovingAverageUnit::new(window, "Blob")` under a name of the user's
//! choosing); its window lives in the unit, so one unit serves one trajectory.

use std::num::NonZeroUsize;

use esgm_core::{CompUnit, ComputeError, EntityStructure, InputType, Sample, Time};
use parking_lot::Mutex;

use crate::moving_average::MovingAverage;
use crate::unit_input::{exactly, failed};

/// The running average over the last `window` structures of one input, stamped valid
/// when the newest input is and created at the query time.
#[derive(Debug)]
pub struct MovingAverageUnit {
    type_name: String,
    average: Mutex<MovingAverage>,
}

impl MovingAverageUnit {
    /// The built-in unit's kind, as configuration files name it.
    pub const BUILTIN: &'static str = "MovingAverage";

    /// A unit averaging structures of `type_name` over `window` samples.
    pub fn new(window: NonZeroUsize, type_name: impl Into<String>) -> Self {
        Self { type_name: type_name.into(), average: Mutex::new(MovingAverage::new(window)) }
    }

    /// The type it reads and writes.
    pub fn type_name(&self) -> &str {
        &self.type_name
    }

    /// Its input types, for `add_comp_unit`: one trajectory of its type.
    pub fn input_types(&self) -> Vec<InputType> {
        vec![InputType::Type(self.type_name.clone())]
    }
}

impl CompUnit for MovingAverageUnit {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let [input] = exactly(Self::BUILTIN, inputs).map_err(failed)?;
        // The average is made of owned values: an archived input is converted for it.
        let mut out = self.average.lock().push_structure(&input.structure.to_arc());
        out.create_time = qtime;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use esgm_core::Entity;
    use esgm_core::library::Blob;

    use super::*;
    use crate::unit_test_support::sample;

    #[test]
    fn averages_the_last_window_and_keeps_the_newest_times() {
        let unit = MovingAverageUnit::new(NonZeroUsize::new(2).unwrap(), "Blob");
        let a = unit.compute(&[sample(&Blob { x: 10, y: 0, size: 4 }, 100)], 150).unwrap();
        assert_eq!(Blob::from_structure(&a).unwrap(), Blob { x: 10, y: 0, size: 4 });
        let b = unit.compute(&[sample(&Blob { x: 20, y: 4, size: 8 }, 200)], 250).unwrap();
        assert_eq!(Blob::from_structure(&b).unwrap(), Blob { x: 15, y: 2, size: 6 });
        assert_eq!((b.valid_time, b.create_time), (200, 250));
        assert!(matches!(unit.compute(&[], 1), Err(ComputeError::Failed { .. })));
    }
}
