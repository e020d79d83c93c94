//! # esgm-core
//!
//! The transport-free heart of esgm, a re-implementation of the Entity Structure
//! Generation Module (ESGM) and the DyKnow stream semantics under it.
//!
//! ## What lives here
//! - The data model (M1–M3): [`Time`], [`Clock`], [`Value`] and its [`ValueSort`],
//!   [`EntityFrame`], [`EntityStructure`], [`Sample`].
//! - Types (M4–M6, E1): [`EntityStructureType`], the [`TypeRegistry`], the
//!   [`TypeChecker`], `#[derive(Entity)]` and the predefined [`library`] types.
//! - The [`codec`]: the one entry point to the archived (rkyv) form that shared memory
//!   carries and readers use in place.
//!
//! ## Design decisions
//! - **No transport here.** Nothing in this crate depends on iceoryx2, clap or OS IPC;
//!   `esgm-shm` implements the same traits over shared memory. That keeps the semantics
//!   testable in one process, with a simulated clock, and reusable by both runtimes.
//! - **Time is read from a [`Clock`] that is handed in**, never from the OS directly, so
//!   every timing rule (delays, periods, time caches) is deterministic under test.
//! - **Structures are shared, not copied.** Stored structures sit behind `Arc`, and
//!   octet sequences (images) are reference counted ([`Octets`]), so a cached image
//!   exists once however many subscribers, queries and units hold it.
//! - **Names follow the seed's IDL** (`create_entity_structure_type`,
//!   `NoSuchEntityStructureType`, …) so users of the original find their way; idiomatic
//!   conveniences (builders, typed structs) sit on top.
#![deny(missing_docs)]

// Lets `#[derive(Entity)]`'s generated `::esgm_core::…` paths resolve inside this crate.
extern crate self as esgm_core;

pub mod approximation;
pub mod catalog;
pub mod clock;
pub mod codec;
pub mod entity;
pub mod entity_view;
pub mod esgm;
mod failures;
pub mod filter;
pub mod generator;
pub mod generator_entry;
pub mod library;
pub mod lineage;
mod nesting;
pub mod octets;
pub mod operators;
pub mod pixel_buffer;
pub mod policy;
pub mod prelude;
pub mod probe;
pub mod runtime;
pub mod sample;
pub mod store;
mod structure;
pub mod time;
pub mod type_check;
pub mod type_registry;
pub mod types;
pub mod value;

pub use approximation::{MergeRule, ValueApproximation};
pub use clock::{Clock, SharedClock, SimClock, SystemClock};
pub use entity::{AttributeField, Entity, FromEntityError};
pub use entity_view::{ViewError, ViewField, ViewSource, view_field};
pub use esgm::{
    CompUnit, ComputeError, CreateError, EntityTrajectoryStructure, Esgm, FlushError, InputType,
    LookupError, RegistrationError, SensorError, SensorInterface, SystemError, TrajectorySpec,
};
pub use filter::{Filter, FilterError};
pub use generator::{FluentGenerator, GeneratorPolicy};
pub use lineage::{InputRef, Lineage};
pub use pixel_buffer::{HeapAllocator, OctetsAllocator, PixelBuffer, PixelStorage};
pub use policy::{
    CacheConstraint, ChangeConstraint, Constraint, DelayConstraint, DurationConstraint,
    FluentStreamPolicy, OrderConstraint, PolicyError,
};
pub use runtime::{InProcessEsgm, InProcessTrajectory};
pub use sample::Sample;
pub use store::{
    AddError, AddForwarder, AddOutcome, BridgeLoss, CallbackError, CallbackHandle, DropCause,
    FeedWaiter, PolicyViolation, QueryError, RecvError, Rejection, ReplicaFeed, ResetForwarder,
    StoreEvent, StoreTap, SubscribeOptions, Subscription, SubscriptionId, TapId, TrajectoryStats,
    TrajectoryStore,
};
pub use structure::{Attributes, FrameRef, FramesRef, SharedStructure, StructureForm, ValueRef};
pub use time::{TIMEUNITS_PER_MILLI_SECOND, TIMEUNITS_PER_SECOND, Time, micros, millis, secs};
pub use type_check::{InvalidType, TypeChecker};
pub use type_registry::{TypeRegistry, TypeRegistryError};
pub use types::{Attr, EntityStructureType, TypeDefinitionError};
pub use value::frame::{AttributeList, AttributeValuePair, EntityFrame, EntityStructure};
pub use value::{
    Octets, Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort,
    Vec3,
};
