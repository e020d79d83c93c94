//! [`select_blob`] as an esgm computational unit: `BlobSeq` → `Blob` (the seed's
//! `BlobSelectionCU`).

use esgm_core::esgm::{Stamped, TypedUnit};
use esgm_core::library::{Blob, BlobSeq};
use esgm_core::{ComputeError, Entity, InputType, Time};

use crate::blob_selection::select_blob;

/// The `BlobSelection` unit: the current object of interest in each new blob sequence.
///
/// An empty sequence yields no value ([`ComputeError::ValueNotAvailable`]), so the
/// `current_blob` trajectory keeps its last blob. The output is valid when the blobs
/// are (the image they were found in) and created at the query time.
#[derive(Debug, Clone, Copy, Default)]
pub struct BlobSelectionUnit;

impl BlobSelectionUnit {
    /// The name the tutorial registers it under.
    pub const NAME: &'static str = "BlobSelection";
    /// The type of its output.
    pub const OUTPUT_TYPE: &'static str = Blob::TYPE_NAME;
    /// The name of every structure it produces.
    pub const STRUCTURE_NAME: &'static str = "blob";

    /// Its input types, for `add_comp_unit`: one `BlobSeq` ([`TypedUnit::Inputs`]).
    pub fn input_types() -> Vec<InputType> {
        <Self as TypedUnit>::input_types()
    }
}

impl TypedUnit for BlobSelectionUnit {
    const NAME: &'static str = "BlobSelection";
    type Inputs = (Stamped<BlobSeq>,);
    type Output = Blob;

    fn compute(&self, (blobs,): Self::Inputs, qtime: Time) -> Result<Stamped<Blob>, ComputeError> {
        let blob = select_blob(&blobs.value).ok_or(ComputeError::ValueNotAvailable)?;
        Ok(Stamped::new(Self::STRUCTURE_NAME, blobs.valid_time, qtime, blob))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unit_test_support::sample;
    use esgm_core::library::RobotState;

    #[test]
    fn selects_the_largest_blob_valid_when_the_blobs_are() {
        let blobs =
            BlobSeq { items: vec![Blob { x: 1, y: 1, size: 5 }, Blob { x: 9, y: 4, size: 50 }] };
        let es = BlobSelectionUnit.compute_samples(&[sample(&blobs, 300)], 420).unwrap();
        assert_eq!((es.name.as_str(), es.valid_time, es.create_time), ("blob", 300, 420));
        assert_eq!(Blob::from_structure(&es).unwrap(), Blob { x: 9, y: 4, size: 50 });
    }

    #[test]
    fn no_blobs_is_no_value() {
        let empty = BlobSeq { items: Vec::new() };
        assert_eq!(
            BlobSelectionUnit.compute_samples(&[sample(&empty, 1)], 2),
            Err(ComputeError::ValueNotAvailable)
        );
    }

    #[test]
    fn malformed_inputs_fail() {
        let robot = sample(&RobotState { x: 0.0, y: 0.0, dir: 0.0 }, 1);
        assert!(matches!(
            BlobSelectionUnit.compute_samples(std::slice::from_ref(&robot), 2),
            Err(ComputeError::Failed { .. })
        ));
        assert!(matches!(
            BlobSelectionUnit.compute_samples(&[robot.clone(), robot], 2),
            Err(ComputeError::Failed { .. })
        ));
    }
}
