//! [`BlobDetector`] as an esgm computational unit: `Image` → `BlobSeq` (the seed's
//! `BlobDetectionCU`).

use std::sync::{Mutex, PoisonError};

use esgm_core::esgm::{Stamped, TypedUnit};
use esgm_core::library::{BlobSeq, Image};
use esgm_core::{ComputeError, Entity, InputType, Time};

use crate::blob_detection::{BlobDetectionConfig, BlobDetector};
use crate::unit_input::failed;

/// The `BlobDetection` unit: the blobs of each new image.
///
/// The output is valid when the image is (the scene it shows) and created at the query
/// time. An image the detector cannot read (corrupt header, wrong data length) fails
/// the call with the [`crate::DetectionError`]'s message; nothing panics.
///
/// The detector keeps scratch buffers between frames, so it sits behind a mutex: a
/// unit shared by several trajectories runs one detection at a time.
#[derive(Debug, Default)]
pub struct BlobDetectionUnit {
    detector: Mutex<BlobDetector>,
}

impl BlobDetectionUnit {
    /// The name the tutorial registers it under.
    pub const NAME: &'static str = "BlobDetection";
    /// The type of its output.
    pub const OUTPUT_TYPE: &'static str = BlobSeq::TYPE_NAME;
    /// The name of every structure it produces (the seed's `"blobs"`).
    pub const STRUCTURE_NAME: &'static str = "blobs";

    /// A unit detecting with `config`.
    pub fn new(config: BlobDetectionConfig) -> Self {
        Self { detector: Mutex::new(BlobDetector::new(config)) }
    }

    /// Its input types, for `add_comp_unit`: one `Image` ([`TypedUnit::Inputs`]).
    pub fn input_types() -> Vec<InputType> {
        <Self as TypedUnit>::input_types()
    }
}

impl TypedUnit for BlobDetectionUnit {
    const NAME: &'static str = "BlobDetection";
    type Inputs = (Stamped<Image>,);
    type Output = BlobSeq;

    fn compute(
        &self,
        (image,): Self::Inputs,
        qtime: Time,
    ) -> Result<Stamped<BlobSeq>, ComputeError> {
        // The detector resets its scratch buffers on every call, so a poisoned lock
        // (a panic elsewhere while holding it) leaves nothing stale behind.
        let blobs = self
            .detector
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .detect(&image.value)
            .map_err(failed)?;
        Ok(Stamped::new(Self::STRUCTURE_NAME, image.valid_time, qtime, blobs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unit_test_support::sample;
    use esgm_core::library::Blob;

    fn mono(width: i64, height: i64, data: Vec<u8>) -> Image {
        Image { width, height, format: Image::FORMAT_MONO8, image_data: data.into() }
    }

    #[test]
    fn detects_blobs_valid_when_the_image_is() {
        let unit =
            BlobDetectionUnit::new(BlobDetectionConfig { min_size: 1, ..Default::default() });
        let image = mono(4, 2, vec![0, 0, 255, 255, 0, 0, 255, 255]);
        let es = unit.compute_samples(&[sample(&image, 100)], 250).unwrap();
        assert_eq!((es.name.as_str(), es.valid_time, es.create_time), ("blobs", 100, 250));
        let blobs = BlobSeq::from_structure(&es).unwrap();
        assert_eq!(blobs.items, vec![Blob { x: 3, y: 1, size: 4 }]);
    }

    #[test]
    fn an_image_without_blobs_gives_an_empty_sequence() {
        let es =
            BlobDetectionUnit::default().compute_samples(&[sample(&mono(2, 2, vec![0; 4]), 1)], 2);
        assert_eq!(BlobSeq::from_structure(&es.unwrap()).unwrap().items, vec![]);
    }

    #[test]
    fn malformed_inputs_fail_with_the_typed_message() {
        let unit = BlobDetectionUnit::default();
        let truncated = mono(4, 2, vec![0; 5]);
        assert_eq!(
            unit.compute_samples(&[sample(&truncated, 1)], 2),
            Err(ComputeError::Failed {
                reason: "image data is 5 bytes, its size and format need 8".into()
            })
        );
        let not_an_image = sample(&Blob { x: 1, y: 1, size: 1 }, 1);
        let Err(ComputeError::Failed { reason }) = unit.compute_samples(&[not_an_image], 2) else {
            panic!("a blob was read as an image");
        };
        assert!(
            reason.starts_with("input 0 of BlobDetection is not a readable `Image`"),
            "{reason}"
        );
        assert_eq!(
            unit.compute_samples(&[], 2),
            Err(ComputeError::Failed { reason: "BlobDetection takes 1 input(s), got 0".into() })
        );
    }
}
