//! # camera-publisher
//!
//! The camera of the seed's tutorial (chapter 8.2), as a library the publisher binary
//! and the tests call. The seed's camera returns an all-black 640×480 image; here a
//! camera produces frames worth detecting blobs in:
//!
//! - [`SyntheticScene`]: bright discs moving over a dark, noisy background, a pure
//!   function of time, with the ground truth ([`SyntheticScene::truth`]) to check a
//!   detector against;
//! - [`ImageDirectory`]: PNG or JPEG files from a directory, cycled through by time.
//!
//! Both are [`FrameSource`]s, and [`CameraSensor`] makes any of them an esgm pull
//! sensor. [`serve`] is the camera as a process: the command line, registration with
//! any runtime, and the worker that the `camera-publisher` binary and
//! `esgm worker camera` both run.
//!
//! ## Design decisions
//! - **Frames are written into a caller's buffer** ([`FrameSource::render_into`]): a
//!   shared-memory camera renders straight into the sample it is about to publish, so no
//!   frame is copied on the way out. [`FrameSource::frame`] allocates, for in-process
//!   use and tests.
//! - **Everything is deterministic.** A scene is a pure function of its settings and the
//!   time, its noise a hash of the seed and the time, so a test or a benchmark that
//!   renders time `t` twice gets the same bytes, on any process.
//! - **Times are [`esgm_core::Time`] nanoseconds.** Motion periods are integer
//!   nanoseconds and phases are taken modulo them, so a scene driven by a wall clock
//!   (around 1.7·10¹⁸ ns) moves exactly as one driven from zero.
//!
//! ```
//! use camera_publisher::{FrameSource, SyntheticScene};
//! use esgm_core::library::Image;
//!
//! let scene = SyntheticScene::builder().width(64).height(48).blobs(2).seed(7).create()?;
//! let mut pixels = vec![0u8; scene.frame_len()];
//! scene.render_into(0, &mut pixels)?;
//! let frame = scene.frame(0);
//! assert_eq!(frame.format, Image::FORMAT_RGB8);
//! assert_eq!(&frame.image_data[..], &pixels[..]);
//! assert_eq!(scene.truth(0).len(), 2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

pub mod camera_sensor;
pub mod frame_source;
pub mod image_directory;
mod noise;
pub mod ppm;
pub mod scene;
pub mod serve;

pub use camera_sensor::CameraSensor;
pub use frame_source::{FrameSource, MAX_DIMENSION, RenderError};
pub use image_directory::{ImageDirectory, ImageDirectoryError};
pub use ppm::write_ppm;
pub use scene::{SceneBuildError, SyntheticScene, SyntheticSceneBuilder};
pub use serve::{CameraArgs, CameraSource};
