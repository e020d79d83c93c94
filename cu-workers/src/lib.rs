//! # cu-workers
//!
//! The computational units of the seed's tutorial (chapter 9), with the computations
//! the seed leaves as `// Do stuff with image`, plus generic units:
//!
//! | unit | seed name | input → output |
//! | --- | --- | --- |
//! | [`BlobDetector`] | `BlobDetection` (BlobDetector) | `Image` → `BlobSeq` |
//! | [`select_blob`] | `BlobSelection` (ObjectSelector) | `BlobSeq` → `Blob` or no value |
//! | [`ComputeDirection`] | `DrivingDirection` (ComputeDirection) | `RobotState`, `Blob` → `DrivingDirection` |
//! | [`MovingAverage`] | — | any structure → the same structure, averaged |
//!
//! ## Design decisions
//! - **Pure computations, no runtime.** Each unit is a plain function or a struct with a
//!   `&mut self` method over the typed library structs; the runtime adapters (which read
//!   inputs from trajectories and write samples) wrap them. So every unit is tested here
//!   without a runtime, and the same code runs in process and in a worker process.
//! - **"No value" is `None`.** Where the seed throws `ValueNotAvailable` (no blob to
//!   select, inputs not yet synchronized) a unit returns `Option`; the adapter turns it
//!   into the runtime's no-value outcome.
//! - **Malformed input is an error, never a panic.** Images come from other processes;
//!   the detector checks sizes and formats and reports a typed [`DetectionError`].
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
pub mod blob_selection;
pub mod driving_direction;
pub mod moving_average;

pub use blob_detection::{BlobDetectionConfig, BlobDetector, Connectivity, DetectionError};
pub use blob_selection::select_blob;
pub use driving_direction::{
    ComputeDirection, DrivingDirectionConfig, DrivingDirectionConfigError, inputs_synchronized,
};
pub use moving_average::MovingAverage;
