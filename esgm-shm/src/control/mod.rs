//! The control plane: one coordinator process owns the registry (types, sensors,
//! units, trajectories and where each is written); every other process asks it over an
//! iceoryx2 request-response service, `esgm/<domain>/control`.
//!
//! - [`protocol`]: the requests and answers, JSON on the wire.
//! - [`Registry`]: the coordinator's state and rules, transport-free.
//! - [`Coordinator`]: serves the registry.
//! - [`processes`]: the workers a system keeps running, declared to the coordinator.
//! - [`ControlClient`]: asks it, with a deadline on every call.
//! - [`limits`]: what the coordinator accepts (bounded names and requests).
//! - [`state`]: the registry on disk, so a crashed coordinator comes back whole (and
//!   why a state file rather than processes re-registering).

pub(crate) mod admin_services;
pub mod client;
pub(crate) mod holding_stats;
pub mod limits;
mod listing_wire;
pub mod persistence;
pub mod processes;
pub mod protocol;
pub mod refusal;
pub mod registry;
pub mod server;
pub mod state;

pub use client::{ControlClient, ControlClientError};
pub use persistence::SaveHealth;
pub use processes::{ProcessError, ProcessRecord, ProcessSpec, ProcessStatus};
pub use protocol::{Assignment, ControlError, Request, Response, TrajectoryRecord, WriterPort};
pub use refusal::Refusal;
pub use registry::{Origin, Registry};
pub use server::{Coordinator, CoordinatorError, CoordinatorThread};
pub use state::{StateDir, StateError};
