//! The control protocol: what clients ask the coordinator, and its answers.
//!
//! Messages are JSON. The control plane carries names, types and policies, a few
//! hundred bytes at human rates, so readability (a stuck system can be inspected with
//! a hex dump) and schema evolution beat speed here; structures themselves never pass
//! through it — they travel on the data plane, archived and zero-copy.

use esgm_core::catalog::{SensorRecord, UnitRecord};
use esgm_core::esgm::{
    CreateError, InputType, LookupError, RegistrationError, TrajectoryInfo, TrajectorySpec,
};
use esgm_core::{EntityStructureType, TypeRegistryError};
use serde::{Deserialize, Serialize};

use crate::control::holding_stats::HoldingStats;

use super::processes::{ProcessError, ProcessRecord, ProcessSpec, ProcessStatus};

/// A request to the coordinator. Operation names follow the seed's `esgm.idl`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Request {
    /// E7 `ping`.
    Ping,
    /// Stop the coordinator (`esgm down`); processes of the system notice it is gone
    /// and leave.
    Shutdown,
    /// E1.
    CreateEntityStructureType {
        /// Registered name.
        type_name: String,
        /// Definition.
        entity_type: EntityStructureType,
    },
    /// E1.
    DestroyEntityStructureType {
        /// Registered name.
        type_name: String,
    },
    /// E1.
    GetEntityStructureType {
        /// Registered name.
        type_name: String,
    },
    /// Every registered type name.
    ListEntityStructureTypes,
    /// A type with every element type it names, so another process can check its
    /// structures.
    GetTypeDefinitions {
        /// Registered name.
        type_name: String,
    },
    /// E6: a sensor served by the process `host`.
    AddSensorInterface {
        /// Sensor name.
        sensor: String,
        /// Type of its structures.
        type_name: String,
        /// The serving process.
        host: String,
    },
    /// E6.
    RemoveSensorInterface {
        /// Sensor name.
        sensor: String,
    },
    /// E6: a unit run by the process `host`.
    AddCompUnit {
        /// Unit name.
        name: String,
        /// Output type.
        type_name: String,
        /// Declared inputs.
        input_types: Vec<InputType>,
        /// The running process.
        host: String,
    },
    /// E6.
    RemoveCompUnit {
        /// Unit name.
        name: String,
    },
    /// E2–E5: create (or re-point) a trajectory; `host` is the asking process.
    CreateTrajectory {
        /// What to create.
        spec: TrajectorySpec,
        /// The asking process.
        host: String,
    },
    /// E5.
    GetEntityTrajectoryStructure {
        /// Trajectory name.
        name: String,
    },
    /// E5.
    DestroyEntityTrajectoryStructure {
        /// Trajectory name.
        name: String,
    },
    /// Every trajectory.
    ListTrajectories,
    /// A connected process's images in shared memory: what it reads in place, what it
    /// sent in place, and what it had to copy (sent by each process about once a
    /// second while it changes).
    ReportHoldings {
        /// The reporting process.
        host: String,
        /// Its counters.
        stats: HoldingStats,
    },
    /// The last report of every process ([`Request::ReportHoldings`]).
    ListHoldings,
    /// Where every trajectory is written, and its generation: what a process compares
    /// with the trajectories it mirrors, to drop those destroyed or re-created
    /// elsewhere.
    ListPlacements,
    /// [`Request::ListPlacements`] of the named trajectories alone (those a process
    /// mirrors): its cost is the asker's, not the domain's. A name without a
    /// trajectory is left out of the answer.
    ListPlacementsOf {
        /// The trajectories.
        names: Vec<String>,
    },
    /// Every sensor.
    ListSensors,
    /// Every unit.
    ListCompUnits,
    /// The trajectories the process `host` must write (its sampled and computed
    /// trajectories created by others, too): it polls this to serve them.
    Assignments {
        /// The asking process.
        host: String,
    },
    /// Keep a process running (see [`crate::control::ProcessSpec`]); the same declaration again
    /// changes nothing, another under the same name replaces it.
    DeclareProcess {
        /// What to run.
        spec: ProcessSpec,
    },
    /// Stop keeping a process running; its supervisor stops it.
    RemoveProcess {
        /// Its name.
        name: String,
    },
    /// Every declared process with its last reported status.
    ListProcesses,
    /// The supervisor's report on one process.
    ReportProcess {
        /// Its name.
        name: String,
        /// What the supervisor saw.
        status: ProcessStatus,
    },
    /// The writer of a trajectory names the iceoryx2 publisher port it writes with, so
    /// readers accept samples from that port alone ([`WriterPort`]). Accepted from
    /// the asking process (its pid is recorded with the port) while no other live
    /// process holds the record.
    ReportWriter {
        /// The trajectory.
        trajectory: String,
        /// Its generation ([`TrajectoryRecord::generation`]): a report on a former
        /// generation is refused.
        generation: u64,
        /// The publisher port's id (`UniquePublisherId::value`).
        publisher: u128,
    },
    /// The writer of a primitive trajectory stops serving it without destroying it
    /// (its connection closes), so that another process may take it over
    /// ([`Request::TakeOverTrajectory`]) while the writer's process lives on. Accepted
    /// from the process that holds the writer's port.
    ReleaseWriter {
        /// The trajectory.
        trajectory: String,
        /// Its generation: a release of a former generation is refused.
        generation: u64,
    },
    /// `host` asks to write a primitive trajectory whose writer is gone: the writer's
    /// process exited, or it released the trajectory. The answer is the trajectory's
    /// record, whose `writer` is `host` when granted, else whoever writes it (a live
    /// writer, or another process that took it over first). Refused
    /// ([`ControlError::NotAllowed`]) for a trajectory that is not primitive (its
    /// sensor or unit has a home) or whose writer the coordinator supervises (it is
    /// restarted, and takes its trajectory back).
    TakeOverTrajectory {
        /// The trajectory.
        trajectory: String,
        /// The generation the asking process mirrors: the former writer's.
        generation: u64,
        /// The asking process.
        host: String,
    },
}

/// The one publisher port readers of a trajectory accept samples and resets from, and
/// the process that holds it.
///
/// Why: a trajectory's data service is iceoryx2 shared memory that any process of the
/// user can open. esgm creates it with room for one publisher, but a process that
/// comes first can create it with more; so readers also check each sample's port
/// against the one the writer registered, and the writer's gate stays the only way in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct WriterPort {
    /// The publisher port's id (`UniquePublisherId::value`).
    pub publisher: u128,
    /// The pid of the process that reported it (iceoryx2's record of its client port).
    pub pid: u32,
}

/// A trajectory a process must write, and how to build it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Assignment {
    /// What to build (as the creator asked).
    pub spec: TrajectorySpec,
    /// Where it stands now.
    pub record: TrajectoryRecord,
}

/// Where a trajectory lives and what it holds: enough for any process to write or read
/// it on the data plane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryRecord {
    /// The listing (kind, type name, source, inputs, policy).
    pub info: TrajectoryInfo,
    /// The trajectory's type and every element type it names, so a process can check
    /// structures without asking again.
    pub types: Vec<(String, EntityStructureType)>,
    /// The process that writes it: the creator of a primitive or operator trajectory,
    /// the sensor's host for a sampled one, the unit's host for a computed one.
    pub writer: String,
    /// Changes each time the name is created or re-pointed (unique in the registry).
    pub generation: u64,
    /// The writer's publisher port, once it has reported it ([`Request::ReportWriter`]).
    #[serde(default)]
    pub port: Option<WriterPort>,
    /// The writer let it go ([`Request::ReleaseWriter`]): an adder may take it over.
    #[serde(default)]
    pub released: bool,
    /// How many processes may read it at once: the capacity every process opens its
    /// services with ([`crate::DomainLimits`]); the spec's `readers`, else the domain's
    /// default.
    #[serde(default)]
    pub readers: crate::data_plane::capacity::Readers,
    /// Its history is not kept beyond its writer ([`TrajectorySpec::volatile`]).
    #[serde(default)]
    pub volatile: bool,
    /// The last time another process became its writer, since the coordinator
    /// started: a restart, or a take-over ([`Request::TakeOverTrajectory`]).
    #[serde(default)]
    pub writer_changed: Option<esgm_core::esgm::WriterChange>,
}

/// Where one trajectory is written ([`Request::ListPlacements`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlacementRecord {
    /// The trajectory.
    pub name: String,
    /// The process that writes it.
    pub writer: String,
    /// Its generation ([`TrajectoryRecord::generation`]).
    pub generation: u64,
    /// Its type's name.
    pub type_name: String,
    /// The writer's publisher port, once reported ([`TrajectoryRecord::port`]).
    #[serde(default)]
    pub port: Option<WriterPort>,
    /// The writer let the trajectory go ([`Request::ReleaseWriter`]): an adder may take
    /// it over.
    #[serde(default)]
    pub released: bool,
}

/// A coordinator's answer.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Response {
    /// Done, nothing to return.
    Done,
    /// Answer to [`Request::Ping`].
    Pong {
        /// The coordinator's esgm version.
        version: String,
        /// The coordinator's process id (`esgm down` waits for it to exit).
        #[serde(default)]
        pid: u32,
        /// The registry's version: it changes with every change of the registry, so a
        /// process whose last look found the same version has nothing to look at
        /// again (its audit and its assignments).
        #[serde(default)]
        registry: u64,
        /// How the coordinator's saves of the registry went.
        #[serde(default)]
        saves: super::persistence::SaveHealth,
    },
    /// A type.
    Type(EntityStructureType),
    /// Names.
    Names(Vec<String>),
    /// Type definitions, by name.
    Definitions(Vec<(String, EntityStructureType)>),
    /// A trajectory (boxed: by far the largest answer, and a rare one).
    Trajectory(Box<TrajectoryRecord>),
    /// Trajectories (on the wire as one compact array each, the default policy left out).
    Trajectories(#[serde(with = "super::listing_wire")] Vec<TrajectoryInfo>),
    /// Sensors.
    Sensors(Vec<SensorRecord>),
    /// Units.
    CompUnits(Vec<UnitRecord>),
    /// Answer to [`Request::Assignments`].
    Assignments(Vec<Assignment>),
    /// Answer to [`Request::ListPlacements`].
    Placements(Vec<PlacementRecord>),
    /// Answer to [`Request::ListHoldings`]: per process, its last report.
    Holdings(Vec<(String, HoldingStats)>),
    /// Answer to [`Request::ListProcesses`].
    Processes(Vec<ProcessRecord>),
    /// The operation failed with the seed's error.
    Error(ControlError),
}

/// The seed's errors, as they cross the process boundary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, thiserror::Error)]
#[non_exhaustive]
pub enum ControlError {
    /// A type operation failed.
    #[error(transparent)]
    Type(#[from] TypeRegistryError),
    /// Creating a trajectory failed.
    #[error(transparent)]
    Create(#[from] CreateError),
    /// A trajectory name is unknown.
    #[error(transparent)]
    Lookup(#[from] LookupError),
    /// Registering a sensor or unit failed.
    #[error(transparent)]
    Registration(#[from] RegistrationError),
    /// A process operation failed.
    #[error(transparent)]
    Process(#[from] ProcessError),
    /// The request is not in this coordinator's protocol: the client is another esgm
    /// version. Use the same esgm for the coordinator and its clients.
    #[error(
        "protocol mismatch: the coordinator (esgm {coordinator_version}) cannot read this request; use the same esgm version for the coordinator and its clients ({reason})"
    )]
    ProtocolMismatch {
        /// The coordinator's esgm version.
        coordinator_version: String,
        /// What could not be read.
        reason: String,
    },
    /// A name is refused (empty, too long, or with `/`, spaces or control characters);
    /// rename it (see `super::limits`).
    #[error("illegal {what} name `{name}`: {reason}")]
    IllegalName {
        /// What it names (`trajectory`, `type`, `process`…).
        what: String,
        /// The name (shortened if long).
        name: String,
        /// The rule it breaks.
        reason: super::limits::NameRule,
    },
    /// The request is larger than the coordinator accepts; split it.
    #[error("request of {bytes} bytes refused; the coordinator accepts at most {max}")]
    TooLarge {
        /// Its size.
        bytes: usize,
        /// The limit ([`super::limits::MAX_REQUEST_BYTES`]).
        max: usize,
    },
    /// The asking process may not do this: the rule it broke says why (a process
    /// reports on itself only, only a writer releases its trajectory, …).
    #[error("not allowed: {reason}")]
    NotAllowed {
        /// The rule.
        reason: super::refusal::Refusal,
    },
    /// The coordinator could not save the registry to its state directory, so it undid
    /// the change rather than lose it in a crash: nothing was changed. Free the disk or
    /// fix the directory's permissions, then retry (`esgm ps` shows the failures).
    #[error("the change was not made: the coordinator cannot save its registry ({reason})")]
    NotSaved {
        /// Why the save failed.
        reason: String,
    },
}

/// Encodes a message for the wire.
pub fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, serde_json::Error> {
    serde_json::to_vec(message)
}

/// Decodes a message from the wire; malformed bytes are an error, never a panic.
pub fn decode<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, serde_json::Error> {
    serde_json::from_slice(bytes)
}
