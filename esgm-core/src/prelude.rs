//! One import for application code: `use esgm_core::prelude::*;` brings the two
//! interface traits (so a runtime's and a trajectory handle's methods are in scope),
//! the in-process runtime, and the data model's everyday types and time helpers.
//!
//! ```
//! use esgm_core::prelude::*;
//!
//! let esgm = InProcessEsgm::default();
//! esgm.create_type(EntityStructureType::new("Reading").attr("x", ValueSort::Double)).unwrap();
//! let t = esgm.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
//! t.add(EntityStructure::named("r").at(secs(1)).with("x", 1.0)).unwrap();
//! t.add(EntityStructure::named("r").at(secs(3)).with("x", 3.0)).unwrap();
//! t.add(EntityStructure::named("r").at(secs(2)).with("x", 2.0)).unwrap();
//! assert_eq!(t.get_latest().unwrap().valid_time(), secs(2)); // the last added
//! assert_eq!(t.get_latest_vtime().unwrap().valid_time(), secs(3)); // the most current
//! ```

pub use crate::approximation::{MergeRule, ValueApproximation};
pub use crate::entity::Entity;
pub use crate::esgm::{
    CompUnit, ComputeError, EntityTrajectoryStructure, Esgm, InputType, SensorError,
    SensorInterface, TrajectorySpec,
};
pub use crate::policy::FluentStreamPolicy;
pub use crate::runtime::{InProcessEsgm, InProcessTrajectory};
pub use crate::sample::Sample;
pub use crate::store::{AddOutcome, SubscribeOptions};
pub use crate::structure::{SharedStructure, ValueRef};
pub use crate::time::{Time, micros, millis, secs};
pub use crate::types::EntityStructureType;
pub use crate::value::frame::{EntityFrame, EntityStructure};
pub use crate::value::{Value, ValueSort};
