//! The one entry point of a Rust program (SPEC A1): `use esgm_shm::prelude::*;`
//! brings everything a program of a robot needs, on either runtime, and each item the
//! same way whichever runtime it uses:
//! - joining a system: [`connect`], [`ShmEsgm`] and its builder, the worker's
//!   environment; and the in-process runtime, [`InProcessEsgm`];
//! - the interface: the [`Esgm`] and [`EntityTrajectoryStructure`] traits, with the
//!   seed's operation names;
//! - the data model: types ([`EntityStructureType`], [`ValueSort`]), structures,
//!   frames, values, samples, time, clocks, and [`Entity`] with its derive
//!   (`#[derive(Entity)]`), plus the [`library`] of predefined types; and how a sample
//!   is read in place ([`SharedStructure`], [`ValueRef`], [`FrameRef`]);
//! - trajectories: [`TrajectorySpec`] for every kind, [`FluentStreamPolicy`] and its
//!   six constraints, sync and generator settings, queries' approximations,
//!   subscriptions, the add outcomes and violations;
//! - image loans ([`PixelBuffer`], [`OctetsAllocator`]): pixels written once, where
//!   every reader reads them;
//! - units and sensors ([`CompUnit`], [`SensorInterface`]);
//! - one error enum per operation, and the reports (stats, memory, log level).
//!
//! Bindings (the C ABI in `esgm-shm/c`, Python in `esgm-shm/python`) bind this and
//! nothing under it.
//!
//! ```
//! use esgm_shm::prelude::*;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let lab = esgm_shm::unique_domain("prelude");
//! # let registry = esgm_shm::control::Registry::new(esgm_core::TypeRegistry::with_library());
//! # let _coordinator = esgm_shm::control::Coordinator::spawn(&lab, registry)?;
//! // A system's coordinator runs (`esgm up --domain lab`).
//! let esgm = connect(&lab)?; // or InProcessEsgm::default(), with the same code below
//! let odometry = esgm.create_primitive_entity_trajectory_structure("odo", "RobotState")?;
//! odometry.create_at_now("robot1", [("x", 1.0.into()), ("y", 2.0.into()), ("dir", 0.0.into())].into())?;
//! let latest = odometry.get_latest()?;
//! assert_eq!(latest.get("x").and_then(|x| x.as_double()), Some(1.0));
//! # Ok(())
//! # }
//! ```

pub use super::{ConnectError, DOMAIN_ENV, ShmEsgm, ShmEsgmBuilder, WORKER_ENV, connect};
pub use crate::process::{init_logging, share_domain};
pub use esgm_core::prelude::*;

pub use esgm_core::esgm::{
    CreateError, EsgmStats, FlushError, LimitReached, LogLevel, LookupError, MemoryStats,
    RegistrationError, SystemError, TrajectoryInfo, TrajectoryKind, TrajectorySource,
};
pub use esgm_core::generator_entry::parse_generator;
pub use esgm_core::library;
pub use esgm_core::operators::sync::SyncPolicy;
pub use esgm_core::{
    AddError, Attr, AttributeList, AttributeValuePair, Attributes, CacheConstraint,
    ChangeConstraint, Clock, Constraint, DelayConstraint, DropCause, DurationConstraint, FrameRef,
    FramesRef, GeneratorPolicy, HeapAllocator, InvalidType, MergeRule, Octets, OctetsAllocator,
    OrderConstraint, PixelBuffer, PolicyError, PolicyViolation, Pos2, Position, PositionAltitude,
    PositionAltitudeRotation, QueryError, RecvError, Rotation, SharedClock, SimClock,
    StructureForm, Subscription, SubscriptionId, SystemClock, TrajectoryStats, TypeRegistryError,
    Vec3,
};
