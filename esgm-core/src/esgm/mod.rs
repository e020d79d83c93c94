//! The ESGM interface (E1–E7, T1–T5): every operation of the seed's `esgm.idl` and
//! `entity_trajectory_structure.idl`, with the same names, as two traits that both
//! runtimes implement — the in-process one in [`crate::runtime`] and the
//! shared-memory one in `esgm-shm` — so application code runs unchanged on either.
//!
//! Designed for a second, out-of-process implementation:
//! - nothing borrowed escapes a call: answers are owned [`Sample`]s (sharing the
//!   structure in process) and owned types;
//! - a trajectory handle is a cheap, cloneable proxy for a *name* (the seed's
//!   descriptor), valid across re-pointing, that can stand for a remote trajectory;
//! - subscriptions are channels ([`Subscription`]), which a remote implementation
//!   feeds from its transport; callbacks are layered on top
//!   ([`Subscription::spawn_callback`]);
//! - every error is a typed enum that can cross a process boundary.

mod errors;
mod interfaces;
mod report;
mod spec;
mod trace;
mod typed_unit;
mod why;

pub use crate::failures::{Limit, LimitReached, Peer, Unreachable};
pub use errors::{CreateError, FlushError, InputType, LookupError, RegistrationError, SystemError};
pub use interfaces::{CompUnit, ComputeError, SensorError, SensorInterface};
pub use report::{EsgmStats, LogLevel, MemoryStats, TrajectoryInfo, TrajectoryReport, WorkerStats};
pub use spec::{TrajectoryKind, TrajectorySource, TrajectorySpec};
pub use trace::{Found, MAX_TRACE_DEPTH, MAX_TRACE_NODES, TraceNode, trace, trace_with};
pub use typed_unit::{Stamped, TypedUnit, TypedUnitAdapter, UnitInputs};
pub use why::{
    CallOutcome, CallRecord, DropSummary, HowWriterChanged, InputHealth, MissCause, MissedPoints,
    RECENT_CALLS, SyncInputDrops, SyncWait, Why, WriterChange,
};

use std::sync::Arc;

use crate::approximation::ValueApproximation;
use crate::policy::FluentStreamPolicy;
use crate::sample::Sample;
use crate::store::{
    AddError, AddOutcome, PolicyViolation, QueryError, SubscribeOptions, Subscription,
    SubscriptionId, TrajectoryStats,
};
use crate::time::Time;
use crate::type_registry::TypeRegistryError;
use crate::types::EntityStructureType;
use crate::value::frame::{AttributeList, EntityStructure};

/// A handle on a named trajectory (the seed's `EntityTrajectoryStructure` interface).
///
/// A handle follows its name: if the name is re-pointed to a new trajectory, the
/// handle reaches the new one. After the trajectory is destroyed every operation
/// fails with `NoSuchEntityStructure`.
pub trait EntityTrajectoryStructure: Clone + Send + Sync + std::fmt::Debug {
    /// The trajectory's name (`name`).
    fn name(&self) -> &str;
    /// Its type (`type`).
    fn entity_type(&self) -> Result<EntityStructureType, QueryError>;
    /// Its policy (`pol`).
    fn policy(&self) -> Result<FluentStreamPolicy, QueryError>;
    /// The earliest valid time stored (`start_time`).
    fn start_time(&self) -> Result<Time, QueryError>;
    /// The latest valid time stored (`end_time`).
    fn end_time(&self) -> Result<Time, QueryError>;

    /// T1: the latest sample added.
    fn get_latest(&self) -> Result<Sample, QueryError>;
    /// T1: the most current value (the seed's `get_latest_vtime`): the sample with the
    /// latest *valid* time, which is not the last one added when structures arrive
    /// out of order (then [`EntityTrajectoryStructure::get_latest`] differs). Of
    /// several samples valid at that time, the one added last.
    fn get_latest_vtime(&self) -> Result<Sample, QueryError> {
        self.get_closest_at_or_before(Time::MAX)
    }
    /// T1: the `n`-th latest sample (0 = latest).
    fn get_nth_latest(&self, n: usize) -> Result<Sample, QueryError>;
    /// T1: samples with valid time in `[from, to]`, by valid time.
    fn get_between(&self, from: Time, to: Time) -> Result<Vec<Sample>, QueryError>;
    /// T1: the sample with the largest valid time not after `t`.
    fn get_closest_at_or_before(&self, t: Time) -> Result<Sample, QueryError>;
    /// T1: the sample valid exactly at `t`.
    fn get_at(&self, t: Time) -> Result<Sample, QueryError>;
    /// T2: the value at `t`, approximated by `aprx`.
    fn get_at_approximating(
        &self,
        t: Time,
        aprx: &ValueApproximation,
    ) -> Result<Sample, QueryError>;

    /// T3: every structure added from now on, after the last `options.last`.
    fn subscribe(&self, options: SubscribeOptions) -> Result<Subscription<Sample>, QueryError>;
    /// T3: ends a subscription.
    fn unsubscribe(&self, id: SubscriptionId) -> Result<(), QueryError>;
    /// C7: every policy violation of this trajectory from now on.
    fn subscribe_violations(
        &self,
        capacity: usize,
    ) -> Result<Subscription<PolicyViolation>, QueryError>;

    /// T4: adds a structure; a violation drops and counts it.
    fn add(&self, es: EntityStructure) -> Result<AddOutcome, AddError>;
    /// T4: adds a structure; a violation is returned.
    fn add_blocking(&self, es: EntityStructure) -> Result<AddOutcome, AddError>;
    /// T4: creates a structure valid at `valid_time` and adds it.
    fn create_at(
        &self,
        name: &str,
        valid_time: Time,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError>;
    /// T4: `create_at`, returning violations.
    fn create_at_blocking(
        &self,
        name: &str,
        valid_time: Time,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError>;
    /// T4: creates a structure valid now and adds it.
    fn create_at_now(&self, name: &str, attributes: AttributeList) -> Result<AddOutcome, AddError>;
    /// T4: `create_at_now`, returning violations.
    fn create_at_now_blocking(
        &self,
        name: &str,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError>;

    /// T5: empties the trajectory (asynchronously where the runtime is remote).
    fn reset(&self) -> Result<(), QueryError>;
    /// T5: empties the trajectory and returns when done.
    fn reset_blocking(&self) -> Result<(), QueryError>;

    /// E7: this trajectory's statistics.
    fn stats(&self) -> Result<TrajectoryStats, QueryError>;
}

/// The ESGM (the seed's `Esgm` interface): types, trajectories, sensors, units.
pub trait Esgm: Send + Sync {
    /// This runtime's trajectory handle.
    type Trajectory: EntityTrajectoryStructure;

    /// E1: registers a type.
    fn create_entity_structure_type(
        &self,
        type_name: &str,
        entity_type: EntityStructureType,
    ) -> Result<(), TypeRegistryError>;
    /// E1 without repeating the name: registers `entity_type` under its own name
    /// ([`EntityStructureType::name`]). The IDL form,
    /// [`Esgm::create_entity_structure_type`], stays for a registered name that
    /// differs from the type's.
    fn create_type(&self, entity_type: EntityStructureType) -> Result<(), TypeRegistryError> {
        let name = entity_type.name.clone();
        self.create_entity_structure_type(&name, entity_type)
    }
    /// E1: registers the type a `#[derive(Entity)]` struct declares, under its name.
    fn create_type_of<T: crate::entity::Entity>(&self) -> Result<(), TypeRegistryError>
    where
        Self: Sized,
    {
        self.create_entity_structure_type(T::TYPE_NAME, T::entity_structure_type())
    }
    /// E1: removes a type (existing trajectories keep theirs).
    fn destroy_entity_structure_type(&self, type_name: &str) -> Result<(), TypeRegistryError>;
    /// E1: a registered type.
    fn get_entity_structure_type(
        &self,
        type_name: &str,
    ) -> Result<EntityStructureType, TypeRegistryError>;
    /// The registered type names.
    fn entity_structure_type_names(&self) -> Result<Vec<String>, SystemError>;

    /// E2: a trajectory fed by pushes.
    fn create_primitive_entity_trajectory_structure(
        &self,
        name: &str,
        type_name: &str,
    ) -> Result<Self::Trajectory, CreateError> {
        self.create_trajectory(TrajectorySpec::primitive(name, type_name))
    }

    /// E3: a trajectory sampled from `sensor` every `sample_period` (from = 0: now;
    /// to = 0: forever; delay = 0: any; cache_size = 0: all).
    #[allow(clippy::too_many_arguments)] // the seed's signature
    fn create_entity_trajectory_structure(
        &self,
        name: &str,
        sensor: &str,
        from: Time,
        to: Time,
        sample_period: Time,
        delay: Time,
        cache_size: i64,
    ) -> Result<Self::Trajectory, CreateError> {
        let policy = FluentStreamPolicy::sampled(from, to, sample_period, delay, cache_size)?;
        let spec = TrajectorySpec {
            name: name.to_owned(),
            source: TrajectorySource::Sampled {
                sensor: sensor.to_owned(),
                from,
                to,
                sample_period,
            },
            policy,
            replace: false,
            readers: None,
            volatile: false,
        };
        self.create_trajectory(spec)
    }

    /// E4: a trajectory computed by `cu` from `inputs`.
    fn create_computed_entity_trajectory_structure(
        &self,
        name: &str,
        cu: &str,
        inputs: &[&str],
    ) -> Result<Self::Trajectory, CreateError> {
        self.create_trajectory(TrajectorySpec::computed(name, cu, inputs.iter().copied()))
    }

    /// Any trajectory, with a full policy (the richer constructor).
    fn create_trajectory(&self, spec: TrajectorySpec) -> Result<Self::Trajectory, CreateError>;

    /// E5: a handle on the trajectory called `name`.
    fn get_entity_trajectory_structure(&self, name: &str) -> Result<Self::Trajectory, LookupError>;
    /// E5: the type of the trajectory called `name`.
    fn get_entity_trajectory_structure_type(
        &self,
        name: &str,
    ) -> Result<EntityStructureType, LookupError>;
    /// E5: destroys a trajectory; its name can be reused.
    fn destroy_entity_trajectory_structure(&self, name: &str) -> Result<(), LookupError>;
    /// Every trajectory, for listings and graphs.
    fn trajectories(&self) -> Result<Vec<TrajectoryInfo>, SystemError>;

    /// Why `trajectory` has not produced since `since` (SPEC X2): its producer's last
    /// calls and what came of them, each input's latest structure and age, what a
    /// sync waits for, each constraint's drops with the last structure dropped, and
    /// whether the writer is alive, with the reasons in words ([`Why::reasons`]).
    /// Answered by the process that writes it. An esgm extension; not in the seed.
    fn why(&self, trajectory: &str, since: Time) -> Result<Why, LookupError>;

    /// E6: registers a pull sensor producing structures of `type_name`.
    fn add_sensor_interface(
        &self,
        sensor: &str,
        type_name: &str,
        iface: Arc<dyn SensorInterface>,
    ) -> Result<(), RegistrationError>;
    /// E6: removes a sensor no trajectory samples.
    fn remove_sensor_interface(&self, sensor: &str) -> Result<(), RegistrationError>;
    /// E6: registers a computational unit producing `type_name` from inputs of
    /// `input_types`.
    fn add_comp_unit(
        &self,
        name: &str,
        type_name: &str,
        input_types: Vec<InputType>,
        cu: Arc<dyn CompUnit>,
    ) -> Result<(), RegistrationError>;
    /// E6: removes a unit no trajectory uses.
    fn remove_comp_unit(&self, name: &str) -> Result<(), RegistrationError>;
    /// Registered sensors as (name, type).
    fn sensors(&self) -> Result<Vec<(String, String)>, SystemError>;
    /// Registered units as (name, output type, input types).
    fn comp_units(&self) -> Result<Vec<(String, String, Vec<InputType>)>, SystemError>;

    /// Waits for the runtime: returns once every structure added before the call has
    /// been processed by every unit, sync and merge (and what they produced by theirs),
    /// delivered to every subscriber and, across processes, entered into every other
    /// process's replica — or fails when `deadline` passes. Held samples (reordering)
    /// and clock-driven sampling are not waited for.
    fn flush(&self, deadline: std::time::Instant) -> Result<(), FlushError>;

    /// E7: true if the ESGM answers.
    fn ping(&self) -> bool;
    /// E7: empties every trajectory (across processes: in every process, or an error).
    fn reset(&self) -> Result<(), SystemError>;
    /// E7: statistics of every trajectory and its worker.
    fn stats(&self) -> Result<EsgmStats, SystemError>;
    /// E7: memory in use.
    fn memory_stats(&self) -> Result<MemoryStats, SystemError>;
    /// E7: the log level.
    fn log_level(&self) -> LogLevel;
    /// E7: sets the log level. esgm logs through `tracing`; the level is applied by the
    /// process's subscriber (the `esgm` binaries install one that follows it). A
    /// library embedding the in-process runtime with its own subscriber reads it here.
    fn set_log_level(&self, level: LogLevel) -> Result<(), SystemError>;
}
