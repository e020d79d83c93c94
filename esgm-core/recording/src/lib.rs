//! Recordings: esgm trajectories in MCAP files (SPEC S1, U1, M1).
//!
//! `esgm record` writes a running system's trajectories into one MCAP file, the
//! container `ros2 bag` and Foxglove use. A recording keeps what esgm knows and those
//! tools do not: each structure's four times (valid, create, add, recorded), its type,
//! its trajectory's declaration (kind, source, inputs, policy), and the violations and
//! losses seen while recording. Each structure is kept as the codec's canonical archive,
//! so what is read back is bit-identical to what was added. Beside the lossless
//! channels, views in Foxglove's encodings (`foxglove.RawImage`, JSON with a JSON
//! Schema) make the file open and plot in Foxglove; images are stored once.
//!
//! # Layers
//! - [`layout`]: the file's contract (channels, schemas, headers, metadata);
//! - [`view`]: the Foxglove encodings;
//! - [`writer`]: [`RecordingWriter`], the MCAP writer (chunks, compression, splits,
//!   flushes);
//! - [`reader`]: [`Recording`], the reader that survives damage;
//! - [`recorder`]: [`Recorder`], subscriptions to a running system into a writer,
//!   never blocking the system's writers;
//! - [`replay`]: publishing a recording into a running ESGM again, in add order;
//! - [`rerun()`]: a configuration's units run on recorded inputs in one process,
//!   deterministically, under the simulated clock.
//! - [`compare()`]: two recordings aligned by valid time, trajectory by trajectory
//!   ([`value_diff`] names the attribute that differs, [`type_diff`] the type);
//! - [`load()`]: recorded trajectories made queryable in an ESGM, with their policies.
#![deny(missing_docs)]

pub mod compare;
pub mod info;
pub mod layout;
pub mod load;
pub mod reader;
pub mod recorder;
pub mod replay;
pub mod rerun;
pub mod ros2_bag;
pub mod rosbag2;
pub mod type_diff;
pub mod value_diff;
pub mod view;
pub mod writer;

pub use compare::{
    Alignment, CompareError, CompareOptions, CompareReport, Presence, TrajectoryComparison, compare,
};
pub use info::{RecordingInfo, TrajectoryInfoLine};
pub use layout::{EventKind, RecordHeader, RecordedEvent, TypeSchema};
pub use load::{LoadError, LoadOptions, LoadReport, LoadedTrajectory, Relaxation, load, load_with};
pub use reader::{Damage, ReadError, RecordedSample, RecordedTrajectory, Recording, Samples};
pub use recorder::{Recorder, RecorderError, RecorderStats};
pub use replay::{
    ComputedMode, Pace, ReplayError, ReplayOptions, ReplayPosition, ReplayReport, TimeMode,
};
pub use rerun::{RerunError, RerunPlan, RerunReport, RerunUnit, rerun};
pub use type_diff::TypeDifference;
pub use writer::{
    Compression, RecordError, RecordOptions, RecordingWriter, TrajectoryId, WriteSummary,
};
