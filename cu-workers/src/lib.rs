//! # cu-workers
//!
//! The computational units of the seed's tutorial (chapter 9), with the computations
//! the seed leaves as `// Do stuff with image`, plus generic units:
//!
//! | computation | esgm unit (registered name) | input → output |
//! | --- | --- | --- |
//! | [`BlobDetector`] | [`BlobDetectionUnit`] (`BlobDetection`, the seed's BlobDetector) | `Image` → `BlobSeq` |
//! | [`select_blob`] | [`BlobSelectionUnit`] (`BlobSelection`, the seed's ObjectSelector) | `BlobSeq` → `Blob` or no value |
//! | [`ComputeDirection`] | [`DrivingDirectionUnit`] (`DrivingDirection`, the seed's ComputeDirection) | `RobotState`, `Blob` → `DrivingDirection` |
//! | [`MovingAverage`] | [`MovingAverageUnit`] (`MovingAverage`, one per smoothed type) | any structure → the same structure, averaged |
//!
//! [`register_tutorial_units`] registers the three tutorial units on any runtime;
//! `examples/tutorial.rs` runs the seed's whole tutorial (chapters 8–10) in process.
//!
//! ## Design decisions
//! - **Pure computations, typed units.** Each computation is a plain function or a
//!   struct with a `&mut self` method over the typed library structs, tested here
//!   without a runtime. Each `…Unit` (in a sibling `*_unit.rs`) is a
//!   [`esgm_core::esgm::TypedUnit`]: it declares its inputs and output as library
//!   structs and receives them decoded, with their times; registered through
//!   [`esgm_core::esgm::TypedUnitAdapter`], esgm-core reads the input samples, checks
//!   their count and types, and stamps the output. The units name only esgm-core's
//!   traits, so the same units run in process and in a worker process. The moving
//!   average, over any type, stays an untyped [`esgm_core::CompUnit`].
//! - **"No value" is `None`.** Where the seed throws `ValueNotAvailable` (no blob to
//!   select, inputs not yet synchronized) a unit returns `Option`; the adapter turns it
//!   into [`esgm_core::ComputeError::ValueNotAvailable`].
//! - **Malformed input is an error, never a panic.** Images come from other processes;
//!   the detector checks sizes and formats and reports a typed [`DetectionError`];
//!   structures of the wrong type or number fail the call, naming the input
//!   ([`UnitInputError`] for the moving average); the runtime gets either as
//!   [`esgm_core::ComputeError::Failed`] with the error's message.
//! - **Scratch space is reused.** The detector keeps its label and union-find buffers
//!   between frames, so a steady stream of frames allocates only the output.
//!
//! ```
//! use cu_workers::{BlobDetector, ComputeDirection, DrivingDirectionConfig, select_blob};
//! use esgm_core::library::{Image, RobotState};
//!
//! // A 4×2 grey image with one bright 2×2 square on the right.
//! let image = Image {
//!     width: 4,
//!     height: 2,
//!     format: Image::FORMAT_MONO8,
//!     image_data: vec![0, 0, 255, 255, 0, 0, 255, 255].into(),
//! };
//! let mut detector = BlobDetector::default();
//! detector.config_mut().min_size = 1;
//! let blobs = detector.detect(&image)?;
//! let blob = select_blob(&blobs).expect("one blob");
//! assert_eq!((blob.x, blob.y, blob.size), (3, 1, 4)); // centroid (2.5, 0.5) rounds up
//!
//! // A 4-pixel-wide camera with a 60° lens: column 3 is 22.5° right of the axis.
//! let unit = ComputeDirection::new(DrivingDirectionConfig {
//!     image_width: 4,
//!     ..Default::default()
//! })?;
//! let robot = RobotState { x: 0.0, y: 0.0, dir: 90.0 };
//! let drive = unit.compute(&robot, &blob);
//! assert_eq!(drive.dir, 67.5); // right of centre: the heading decreases (turn right)
//! assert!(drive.speed < unit.config().max_speed);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

pub mod blob_detection;
pub mod blob_detection_unit;
pub mod blob_selection;
pub mod blob_selection_unit;
pub mod driving_direction;
pub mod driving_direction_unit;
pub mod moving_average;
pub mod moving_average_unit;
pub mod tutorial;
pub mod unit_input;

pub use blob_detection::{BlobDetectionConfig, BlobDetector, Connectivity, DetectionError};
pub use blob_detection_unit::BlobDetectionUnit;
pub use blob_selection::select_blob;
pub use blob_selection_unit::BlobSelectionUnit;
pub use driving_direction::{
    ComputeDirection, DrivingDirectionConfig, DrivingDirectionConfigError, inputs_synchronized,
};
pub use driving_direction_unit::DrivingDirectionUnit;
pub use moving_average::MovingAverage;
pub use moving_average_unit::MovingAverageUnit;
pub use tutorial::register_tutorial_units;
pub use unit_input::UnitInputError;

/// Builds input samples for the adapters' tests.
#[cfg(test)]
mod unit_test_support {
    use std::sync::Arc;

    use esgm_core::{Entity, Sample, Time};

    /// `value` as a sample valid (and created and added) at `valid_time`.
    pub(crate) fn sample<T: Entity>(value: &T, valid_time: Time) -> Sample {
        Sample::new(
            Arc::new(value.to_structure("input", valid_time, valid_time)),
            valid_time,
            valid_time,
        )
    }
}
