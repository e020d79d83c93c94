//! Internals that the workspace's own tools reach for, and no program should: the
//! sample layout's block helpers, the futex wake words and their service names, the
//! image archive's fixed offsets, the publisher's notify counter and the kept-history
//! file (which the fuzzer writes corrupt), and the coordinator's state file and which
//! requests change it (which the control-plane fuzzer checks against each other), and
//! the admin channel's and the blocking add's decoders (which their fuzzers feed).
//!
//! Why it exists: the benches measure the data plane below the API (a hand-rolled
//! transport needs the block layout to compare against), the fuzzers write malformed
//! samples, and the wake-word tests check files that users never see. Making these
//! public at their modules would make every refactor of the data plane a break for
//! users; here they are one module whose name says they may change in any release,
//! and the rest of the data plane stays crate-private.

pub use crate::client::{AdminRead, AdminReader, read_blocking_add_answer, serve_blocking_add};
pub use crate::control::registry::changes_registry;
pub use crate::control::state::{SNAPSHOT_VERSION, SavedTrajectory, Snapshot};
pub use crate::data_plane::image_layout::{IMAGE_NAME_MAX, IMAGE_PIXELS_OFFSET};
pub use crate::data_plane::kept::{
    HOLDERS, KeepError, KeptEntries, KeptEntry, KeptHistory, KeptImage, KeptLocation, KeptView,
    Retention, RingLoan,
};
pub use crate::data_plane::payload::{BLOCK_LEN, as_bytes, blocks_for};
pub use crate::data_plane::publisher::notifies_spared_here;
pub use crate::data_plane::service_name::{control_service, data_service_name, wake_service_name};
pub use crate::data_plane::wait::DEFAULT_SPIN;
pub use crate::data_plane::wake_word::{FRUITLESS_RINGS, WakeWord, path_for, remove_domain};
