//! The control plane: one coordinator process owns the registry (types, sensors,
//! units, trajectories and where each is written); every other process asks it over an
//! iceoryx2 request-response service, `esgm/<domain>/control`.
//!
//! - `protocol`: the requests and answers, JSON on the wire.
//! - [`Registry`]: the coordinator's state and rules, transport-free.
//! - [`Coordinator`]: serves the registry.
//! - `processes`: the workers a system keeps running, declared to the coordinator.
//! - [`ControlClient`]: asks it, with a deadline on every call.
//! - `limits`: what the coordinator accepts (bounded names and requests).
//! - `state`: the registry on disk, so a crashed coordinator comes back whole (and
//!   why a state file rather than processes re-registering).

pub(crate) mod admin_services;
pub(crate) mod client;
pub(crate) mod holding_stats;
pub(crate) mod limits;
mod listing_wire;
pub(crate) mod persistence;
pub(crate) mod processes;
pub(crate) mod protocol;
pub(crate) mod refusal;
pub(crate) mod registry;
pub(crate) mod server;
pub(crate) mod state;

pub use client::{ControlClient, ControlClientError};
pub use limits::{MAX_NAME_LEN, MAX_REQUEST_BYTES, NameRule, check_name, name_problem};
pub use persistence::SaveHealth;
pub use processes::ProcessTable;
pub use processes::{ProcessError, ProcessRecord, ProcessSpec, ProcessStatus};
pub use protocol::{
    Assignment, ControlError, PlacementRecord, Request, Response, TrajectoryRecord, WriterPort,
    decode, encode,
};
pub use refusal::Refusal;
pub use registry::{Origin, Registry};
pub use server::{
    Coordinator, CoordinatorError, CoordinatorThread, MAX_RESPONSE_BYTES, log_cleanup,
};
pub use state::{STATE_DIR_ENV, StateDir, StateError};
