//! [`select_blob`] as an esgm computational unit: `BlobSeq` → `Blob` (the seed's
//! `BlobSelectionCU`).

use esgm_core::library::{Blob, BlobSeq};
use esgm_core::{CompUnit, ComputeError, Entity, EntityStructure, InputType, Sample, Time};

use crate::blob_selection::select_blob;
use crate::unit_input::{exactly, failed, read};

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

    /// Its input types, for `add_comp_unit`: one `BlobSeq`.
    pub fn input_types() -> Vec<InputType> {
        vec![InputType::Type(BlobSeq::TYPE_NAME.to_owned())]
    }
}

impl CompUnit for BlobSelectionUnit {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        let [blobs_sample] = exactly(Self::NAME, inputs).map_err(failed)?;
        let blobs: BlobSeq = read(Self::NAME, 0, blobs_sample).map_err(failed)?;
        let blob = select_blob(&blobs).ok_or(ComputeError::ValueNotAvailable)?;
        Ok(blob.to_structure(Self::STRUCTURE_NAME, blobs_sample.valid_time, qtime))
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
        let es = BlobSelectionUnit.compute(&[sample(&blobs, 300)], 420).unwrap();
        assert_eq!((es.name.as_str(), es.valid_time, es.create_time), ("blob", 300, 420));
        assert_eq!(Blob::from_structure(&es).unwrap(), Blob { x: 9, y: 4, size: 50 });
    }

    #[test]
    fn no_blobs_is_no_value() {
        let empty = BlobSeq { items: Vec::new() };
        assert_eq!(
            BlobSelectionUnit.compute(&[sample(&empty, 1)], 2),
            Err(ComputeError::ValueNotAvailable)
        );
    }

    #[test]
    fn malformed_inputs_fail() {
        let robot = sample(&RobotState { x: 0.0, y: 0.0, dir: 0.0 }, 1);
        assert!(matches!(
            BlobSelectionUnit.compute(std::slice::from_ref(&robot), 2),
            Err(ComputeError::Failed { .. })
        ));
        assert!(matches!(
            BlobSelectionUnit.compute(&[robot.clone(), robot], 2),
            Err(ComputeError::Failed { .. })
        ));
    }
}
