//! The in-process runtime: the [`Esgm`] interface on threads and crossbeam channels,
//! the embedded default for single-process robot programs and for tests (P4).
//!
//! - Each trajectory is a [`TrajectoryStore`] behind a mutex; handles are proxies for
//!   names (descriptors), so re-pointing a name moves its subscribers and its handles.
//! - A sampled trajectory has a thread that calls its sensor at every sample time; a
//!   computed, sync or merge trajectory has a thread waiting on its inputs'
//!   subscriptions; one more thread releases samples held for reordering on time.
//! - Structures are shared (`Arc`) from producer to store to subscribers to units: an
//!   image is never copied in process.
//! - Everything timed reads the runtime's clock; with a [`crate::SimClock`], tests
//!   advance time by hand and the runtime follows.

mod cell;
mod handle;
mod inputs;
mod periodic;
mod releaser;
mod why;
mod workers;

pub use handle::InProcessTrajectory;

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

use parking_lot::RwLock;

use crate::catalog::Catalog;
use crate::clock::{SharedClock, SystemClock};
use crate::esgm::{
    CompUnit, CreateError, Esgm, EsgmStats, FlushError, InputType, LogLevel, LookupError,
    MemoryStats, RegistrationError, SensorInterface, SystemError, TrajectoryInfo, TrajectoryKind,
    TrajectoryReport, TrajectorySource, TrajectorySpec,
};
use crate::sample::Sample;
use crate::store::{FanIn, TrajectoryStore};
use crate::type_registry::{TypeRegistry, TypeRegistryError};
use crate::types::EntityStructureType;
use cell::{Descriptor, TrajectoryCell};

impl std::fmt::Debug for dyn SensorInterface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SensorInterface")
    }
}

impl std::fmt::Debug for dyn CompUnit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CompUnit")
    }
}

/// A resolved input: its name's descriptor and the trajectory it denotes now.
type Input = (Arc<Descriptor>, Arc<TrajectoryCell>);

/// The host name the in-process runtime gives its sensors and units in the catalog.
const LOCAL_HOST: &str = "in-process";

#[derive(Debug)]
pub(crate) struct Inner {
    clock: SharedClock,
    /// Names and the rules on them. Lock order: catalog, then trajectories.
    catalog: RwLock<Catalog>,
    trajectories: RwLock<BTreeMap<String, Arc<Descriptor>>>,
    sensors: RwLock<BTreeMap<String, Arc<dyn SensorInterface>>>,
    units: RwLock<BTreeMap<String, Arc<dyn CompUnit>>>,
    subscriber_capacity: usize,
    log_level: AtomicU8,
    shutdown: AtomicBool,
    /// Wakes the release thread (see `releaser`).
    kick: crossbeam_channel::Sender<()>,
}

impl Inner {
    fn cells(&self) -> Vec<Arc<TrajectoryCell>> {
        self.trajectories.read().values().filter_map(|d| d.get()).collect()
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
        // Workers hold their trajectory, not the runtime: stop them explicitly, or they
        // would run on after the last handle on the runtime is gone.
        for cell in self.cells() {
            cell.worker.lock().take();
        }
        // The releaser sleeps until kicked while nothing is held; a trajectory handle
        // that outlives the runtime keeps the channel open, so it is told.
        let _kick_pending = self.kick.try_send(());
    }
}

/// Builds an [`InProcessEsgm`].
#[derive(Debug, Default)]
pub struct InProcessEsgmBuilder {
    clock: Option<SharedClock>,
    types: Option<TypeRegistry>,
    subscriber_capacity: Option<usize>,
}

impl InProcessEsgmBuilder {
    /// The clock (default: the system clock).
    #[must_use]
    pub fn clock(mut self, clock: SharedClock) -> Self {
        self.clock = Some(clock);
        self
    }

    /// The initial types (default: the predefined library).
    #[must_use]
    pub fn types(mut self, types: TypeRegistry) -> Self {
        self.types = Some(types);
        self
    }

    /// Buffer of each unit's input subscriptions (default 1024).
    #[must_use]
    pub fn subscriber_capacity(mut self, n: usize) -> Self {
        self.subscriber_capacity = Some(n.max(1));
        self
    }

    /// Starts the runtime.
    pub fn create(self) -> InProcessEsgm {
        let (kick, kicks) = crossbeam_channel::bounded(1);
        let inner = Arc::new(Inner {
            clock: self.clock.unwrap_or_else(SystemClock::shared),
            catalog: RwLock::new(Catalog::new(
                self.types.unwrap_or_else(TypeRegistry::with_library),
            )),
            trajectories: RwLock::new(BTreeMap::new()),
            sensors: RwLock::new(BTreeMap::new()),
            units: RwLock::new(BTreeMap::new()),
            subscriber_capacity: self.subscriber_capacity.unwrap_or(1024),
            log_level: AtomicU8::new(LogLevel::Info as u8),
            shutdown: AtomicBool::new(false),
            kick,
        });
        let weak = Arc::downgrade(&inner);
        if let Err(e) = std::thread::Builder::new()
            .name("esgm-releaser".into())
            .spawn(move || releaser::run(weak, kicks))
        {
            tracing::error!(error = %e, "could not start the release thread; held samples enter on the next add");
        }
        InProcessEsgm { inner }
    }
}

/// The ESGM in one process. Cheap to clone; the runtime stops when the last clone is
/// dropped (or on [`InProcessEsgm::shutdown`]).
#[derive(Debug, Clone)]
pub struct InProcessEsgm {
    inner: Arc<Inner>,
}

impl Default for InProcessEsgm {
    fn default() -> Self {
        Self::builder().create()
    }
}

impl InProcessEsgm {
    /// Starts building a runtime.
    pub fn builder() -> InProcessEsgmBuilder {
        InProcessEsgmBuilder::default()
    }

    /// The runtime's clock.
    pub fn clock(&self) -> &SharedClock {
        &self.inner.clock
    }

    /// Creates a replica of a trajectory written in another process: a local store
    /// with the writer's `info` (kind, type, policy) that takes no structures from
    /// users and runs no worker; a bridge feeds it with
    /// [`TrajectoryStore::replicate`] through [`InProcessTrajectory::with_store`].
    /// Local units, syncs and merges can read it like any trajectory. `types` are the
    /// definitions its type needs (registered here if missing).
    pub fn create_replica(
        &self,
        info: TrajectoryInfo,
        types: &[(String, EntityStructureType)],
    ) -> Result<InProcessTrajectory, CreateError> {
        let mut catalog = self.inner.catalog.write();
        for (name, t) in types {
            if catalog.types().get_entity_structure_type(name).is_err() {
                // Registration only checks the definition itself, so element types
                // may come in any order. A definition refused is the writer's side's
                // fault, and says why: not "no such type".
                if let Err(e) = catalog.types_mut().create_entity_structure_type(name, t.clone()) {
                    return Err(CreateError::InvalidTypeDefinition {
                        name: name.clone(),
                        reason: e.to_string(),
                    });
                }
            }
        }
        if self.descriptor(&info.name).is_some() {
            return Err(CreateError::EntityStructureAlreadyExists { name: info.name.clone() });
        }
        let checker = crate::TypeChecker::new(catalog.types(), &info.type_name).map_err(|_| {
            CreateError::NoSuchEntityStructureType {
                name: info.type_name.clone(),
                suggestion: crate::type_registry::closest_name(
                    &info.type_name,
                    catalog.types().names().iter().map(String::as_str),
                ),
            }
        })?;
        let store = TrajectoryStore::builder(info.name.clone(), checker)
            .policy(info.policy.clone())
            .clock(self.inner.clock.clone())
            .create()?;
        let cell = Arc::new(TrajectoryCell {
            store: parking_lot::Mutex::new(store),
            external_adds: false,
            info: info.clone(),
            worker: parking_lot::Mutex::new(None),
            counters: Arc::default(),
            kick: self.inner.kick.clone(),
        });
        let descriptor = Arc::new(Descriptor {
            name: info.name.clone(),
            current: parking_lot::RwLock::new(Some(cell)),
        });
        self.inner.trajectories.write().insert(info.name.clone(), Arc::clone(&descriptor));
        catalog.insert_trajectory(info);
        Ok(InProcessTrajectory { descriptor })
    }

    /// Creates a trajectory as [`Esgm::create_trajectory`] does, and runs `prepare` on
    /// it after it exists and before its worker starts: a transport installs its tap
    /// and image buffers there, so the first sample a sampler takes is already
    /// published, and written in place. An error of `prepare` undoes the creation.
    pub fn create_trajectory_prepared(
        &self,
        spec: TrajectorySpec,
        prepare: impl FnOnce(&InProcessTrajectory) -> Result<(), CreateError>,
    ) -> Result<InProcessTrajectory, CreateError> {
        // The catalog stays locked until the trajectory is published, so a concurrent
        // create of the same name, or removal of its sensor or unit, cannot slip in
        // between the checks and the start of its worker.
        let mut catalog = self.inner.catalog.write();
        let resolved = catalog.resolve(&spec)?;
        let inputs = self.input_cells(&spec.inputs())?;
        let name = spec.name.clone();
        let store = TrajectoryStore::builder(name.clone(), resolved.checker)
            .policy(spec.policy.clone())
            .clock(self.inner.clock.clone())
            .create()?;
        let cell = Arc::new(TrajectoryCell {
            store: parking_lot::Mutex::new(store),
            external_adds: spec.kind() == TrajectoryKind::Primitive,
            info: resolved.info.clone(),
            worker: parking_lot::Mutex::new(None),
            counters: Arc::default(),
            kick: self.inner.kick.clone(),
        });
        let mut map = self.inner.trajectories.write();
        let descriptor = match map.get(&name) {
            Some(d) => {
                // Re-pointing (the catalog refused it unless `replace` was set): the
                // old trajectory's subscribers and held samples move to the new one.
                let old = d.current.write().replace(Arc::clone(&cell));
                if let Some(old) = old {
                    old.worker.lock().take();
                    let mut old_store = old.store.lock();
                    cell.store.lock().adopt(&mut old_store);
                }
                Arc::clone(d)
            }
            None => {
                let d = Arc::new(Descriptor {
                    name: name.clone(),
                    current: parking_lot::RwLock::new(Some(Arc::clone(&cell))),
                });
                map.insert(name, Arc::clone(&d));
                d
            }
        };
        drop(map);
        if let Err(e) = prepare(&InProcessTrajectory { descriptor: Arc::clone(&descriptor) }) {
            self.inner.trajectories.write().remove(&spec.name);
            return Err(e);
        }
        // Start the feeder last: it subscribes to its inputs, which may include the
        // trajectory it replaced (now under the same name).
        let worker = match self.start_worker(&spec, &cell, &inputs) {
            Ok(w) => w,
            Err(e) => {
                // Not reachable after `resolve` succeeded; undo rather than leave a
                // trajectory without its feeder.
                self.inner.trajectories.write().remove(&spec.name);
                return Err(e);
            }
        };
        *cell.worker.lock() = worker;
        catalog.insert_trajectory(resolved.info);
        Ok(InProcessTrajectory { descriptor })
    }

    /// Waits until every structure added before the call has been processed by every
    /// unit, sync and merge worker, and what they produced by theirs in turn (a chain
    /// settles level by level), or `deadline` passes. Subscribers have every such
    /// structure in their channels on return (delivery is part of the add).
    ///
    /// How: a marker is queued behind each input-driven worker's inputs and waited for;
    /// rounds repeat until one changes no trajectory (no add, drop or call). Not waited
    /// for: samples held for reordering (they enter at their release time), sampling
    /// on a clock, callbacks' own threads, and work added after the call.
    pub fn flush(&self, deadline: std::time::Instant) -> Result<(), FlushError> {
        let mut previous = None;
        loop {
            let cells = self.inner.cells();
            let mut waiting = Vec::new();
            for cell in &cells {
                let Some(sender) = cell.counters.flush_sender.lock().clone() else { continue };
                let stopped = cell.worker.lock().is_none();
                if stopped {
                    continue;
                }
                let ticket = cell.counters.flush_asked.fetch_add(1, Ordering::AcqRel) + 1;
                let marker =
                    Sample::new(Arc::new(crate::value::frame::EntityStructure::default()), 0, 0);
                if sender.send_deadline((inputs::FLUSH_MARKER, marker), deadline).is_err() {
                    return Err(FlushError::DeadlinePassed { waiting_for: cell.info.name.clone() });
                }
                waiting.push((cell, ticket));
            }
            for (cell, ticket) in waiting {
                while cell.counters.flush_done.load(Ordering::Acquire) < ticket {
                    if std::time::Instant::now() >= deadline {
                        return Err(FlushError::DeadlinePassed {
                            waiting_for: cell.info.name.clone(),
                        });
                    }
                    std::thread::sleep(std::time::Duration::from_micros(100));
                }
            }
            let progress: u64 = cells
                .iter()
                .map(|c| {
                    let s = c.store.lock().stats();
                    s.added + s.dropped_total + c.counters.calls.load(Ordering::Relaxed)
                })
                .sum();
            if previous == Some(progress) {
                return Ok(());
            }
            previous = Some(progress);
        }
    }

    /// Stops every worker; trajectories stay queryable.
    pub fn shutdown(&self) {
        self.inner.shutdown.store(true, Ordering::Relaxed);
        // Wake the releaser to see it (a full channel is a kick already waiting).
        let _kick_pending = self.inner.kick.try_send(());
        for cell in self.inner.cells() {
            cell.worker.lock().take();
        }
    }

    fn descriptor(&self, name: &str) -> Option<Arc<Descriptor>> {
        self.inner.trajectories.read().get(name).cloned()
    }

    /// The inputs' descriptors and current trajectories (the catalog checked they exist;
    /// one destroyed since is reported like an unknown name).
    fn input_cells(&self, names: &[String]) -> Result<Vec<Input>, CreateError> {
        names
            .iter()
            .map(|n| {
                self.descriptor(n).and_then(|d| d.get().map(|c| (d, c))).ok_or_else(|| {
                    CreateError::NoSuchEntityStructure { name: n.clone(), suggestion: None }
                })
            })
            .collect()
    }

    /// Subscribes a worker's fan-in to every input and reads each input's latest sample
    /// in the same step (under its lock), so no update falls between the two.
    fn subscribe_inputs(&self, inputs: &[Input]) -> (FanIn<Sample>, Vec<workers::InputState>) {
        let mut fan_in = FanIn::new(self.inner.subscriber_capacity);
        // Every input fed from another process: the worker waits for their writers
        // itself (one input's waiter, or all inputs' joined into one).
        let waiters: Option<Vec<_>> =
            inputs.iter().map(|(_, cell)| cell.store.lock().feed_waiter()).collect();
        let mut waiters = waiters.unwrap_or_default().into_iter();
        if let Some(first) = waiters.next() {
            let rest: Vec<_> = waiters.collect();
            let waiter = if rest.is_empty() { Some(first) } else { first.join(rest) };
            if let Some(waiter) = waiter {
                fan_in.set_waiter(waiter);
            }
        }
        let states = inputs
            .iter()
            .enumerate()
            .map(|(i, (d, cell))| {
                let mut store = cell.store.lock();
                store.subscribe_tagged(&fan_in, i);
                // An empty input has no latest sample, the only error here.
                workers::InputState::new(store.get_latest().ok(), &store, &d.name)
            })
            .collect();
        (fan_in, states)
    }

    /// A sampling schedule with the seed's zero rules: from = 0 is now, to = 0 forever.
    fn schedule(&self, from: i64, to: i64, period: i64) -> periodic::Schedule {
        let from = if from == 0 { self.inner.clock.now() } else { from };
        periodic::Schedule { from, to: (to != 0).then_some(to), period }
    }

    /// Starts the worker that feeds `cell` from `spec`'s source.
    fn start_worker(
        &self,
        spec: &TrajectorySpec,
        cell: &Arc<TrajectoryCell>,
        inputs: &[Input],
    ) -> Result<Option<cell::Worker>, CreateError> {
        let clock = self.inner.clock.clone();
        Ok(match &spec.source {
            TrajectorySource::Primitive { .. } => None,
            TrajectorySource::Sampled { sensor, from, to, sample_period } => {
                let iface = self.inner.sensors.read().get(sensor).cloned();
                let schedule = self.schedule(*from, *to, *sample_period);
                iface.map(|iface| workers::sampler(cell, clock, iface, schedule))
            }
            TrajectorySource::Computed { unit, .. } => {
                let cu = self.inner.units.read().get(unit).cloned();
                cu.map(|cu| {
                    let (fan_in, latest) = self.subscribe_inputs(inputs);
                    *cell.counters.flush_sender.lock() = Some(fan_in.sender());
                    workers::unit(cell, clock, cu, fan_in, latest)
                })
            }
            TrajectorySource::Sync { policy, .. } => {
                // Validated here so the worker can re-create it after a reset.
                policy.create::<Sample>(inputs.len())?;
                *cell.counters.sync.lock() = Some(policy.clone());
                let (fan_in, states) = self.subscribe_inputs(inputs);
                *cell.counters.flush_sender.lock() = Some(fan_in.sender());
                let names = inputs.iter().map(|(d, _)| d.name.clone()).collect();
                Some(workers::sync(cell, clock, policy.clone(), names, fan_in, states))
            }
            TrajectorySource::Merge { .. } => {
                let (fan_in, states) = self.subscribe_inputs(inputs);
                *cell.counters.flush_sender.lock() = Some(fan_in.sender());
                Some(workers::merge(cell, fan_in, states))
            }
            TrajectorySource::SampledGenerators {
                inputs: gens,
                unit,
                from,
                to,
                sample_period,
                lag,
            } => {
                let schedule = self.schedule(*from, *to, *sample_period);
                let cu = unit.as_ref().and_then(|u| self.inner.units.read().get(u).cloned());
                let with_policies = inputs
                    .iter()
                    .zip(gens)
                    .map(|((d, _), (_, g))| (Arc::clone(d), g.clone()))
                    .collect();
                Some(workers::sampled_generators(cell, clock, with_policies, cu, schedule, *lag))
            }
        })
    }
}

impl Esgm for InProcessEsgm {
    type Trajectory = InProcessTrajectory;

    fn create_entity_structure_type(
        &self,
        type_name: &str,
        entity_type: EntityStructureType,
    ) -> Result<(), TypeRegistryError> {
        self.inner.catalog.write().types_mut().create_entity_structure_type(type_name, entity_type)
    }

    fn destroy_entity_structure_type(&self, type_name: &str) -> Result<(), TypeRegistryError> {
        self.inner.catalog.write().types_mut().destroy_entity_structure_type(type_name).map(|_| ())
    }

    fn get_entity_structure_type(
        &self,
        type_name: &str,
    ) -> Result<EntityStructureType, TypeRegistryError> {
        self.inner
            .catalog
            .read()
            .types()
            .get_entity_structure_type(type_name)
            .map(|t| t.as_ref().clone())
    }

    fn entity_structure_type_names(&self) -> Result<Vec<String>, SystemError> {
        Ok(self.inner.catalog.read().types().names())
    }

    fn create_trajectory(&self, spec: TrajectorySpec) -> Result<InProcessTrajectory, CreateError> {
        self.create_trajectory_prepared(spec, |_| Ok(()))
    }

    fn get_entity_trajectory_structure(
        &self,
        name: &str,
    ) -> Result<InProcessTrajectory, LookupError> {
        match self.descriptor(name) {
            Some(descriptor) => Ok(InProcessTrajectory { descriptor }),
            None => Err(self.inner.catalog.read().no_such_trajectory(name)),
        }
    }

    fn get_entity_trajectory_structure_type(
        &self,
        name: &str,
    ) -> Result<EntityStructureType, LookupError> {
        match self.descriptor(name).and_then(|d| d.get()) {
            Some(c) => Ok(c.store.lock().entity_type().as_ref().clone()),
            None => Err(self.inner.catalog.read().no_such_trajectory(name)),
        }
    }

    fn destroy_entity_trajectory_structure(&self, name: &str) -> Result<(), LookupError> {
        let mut catalog = self.inner.catalog.write();
        catalog.remove_trajectory(name)?;
        let removed = self.inner.trajectories.write().remove(name);
        drop(catalog);
        if let Some(cell) = removed.and_then(|d| d.current.write().take()) {
            cell.worker.lock().take();
        }
        Ok(())
    }

    fn trajectories(&self) -> Result<Vec<TrajectoryInfo>, SystemError> {
        Ok(self.inner.catalog.read().trajectories().cloned().collect())
    }

    fn why(
        &self,
        trajectory: &str,
        since: crate::time::Time,
    ) -> Result<crate::esgm::Why, LookupError> {
        let mut why = self.why_evidence(trajectory, since)?;
        why.explain();
        Ok(why)
    }

    fn add_sensor_interface(
        &self,
        sensor: &str,
        type_name: &str,
        iface: Arc<dyn SensorInterface>,
    ) -> Result<(), RegistrationError> {
        let mut catalog = self.inner.catalog.write();
        catalog.add_sensor(sensor, type_name, LOCAL_HOST)?;
        self.inner.sensors.write().insert(sensor.to_owned(), iface);
        Ok(())
    }

    fn remove_sensor_interface(&self, sensor: &str) -> Result<(), RegistrationError> {
        let mut catalog = self.inner.catalog.write();
        catalog.remove_sensor(sensor)?;
        self.inner.sensors.write().remove(sensor);
        Ok(())
    }

    fn add_comp_unit(
        &self,
        name: &str,
        type_name: &str,
        input_types: Vec<InputType>,
        cu: Arc<dyn CompUnit>,
    ) -> Result<(), RegistrationError> {
        let mut catalog = self.inner.catalog.write();
        catalog.add_unit(name, type_name, input_types, LOCAL_HOST)?;
        self.inner.units.write().insert(name.to_owned(), cu);
        Ok(())
    }

    fn remove_comp_unit(&self, name: &str) -> Result<(), RegistrationError> {
        let mut catalog = self.inner.catalog.write();
        catalog.remove_unit(name)?;
        self.inner.units.write().remove(name);
        Ok(())
    }

    fn sensors(&self) -> Result<Vec<(String, String)>, SystemError> {
        Ok(self.sensors_here())
    }

    fn comp_units(&self) -> Result<Vec<(String, String, Vec<InputType>)>, SystemError> {
        Ok(self.units_here())
    }

    fn flush(&self, deadline: std::time::Instant) -> Result<(), FlushError> {
        InProcessEsgm::flush(self, deadline)
    }

    fn ping(&self) -> bool {
        !self.inner.shutdown.load(Ordering::Relaxed)
    }

    fn reset(&self) -> Result<(), SystemError> {
        self.reset_here();
        Ok(())
    }

    fn stats(&self) -> Result<EsgmStats, SystemError> {
        Ok(self.stats_here())
    }

    fn memory_stats(&self) -> Result<MemoryStats, SystemError> {
        Ok(self.memory_here())
    }

    fn log_level(&self) -> LogLevel {
        match self.inner.log_level.load(Ordering::Relaxed) {
            0 => LogLevel::Error,
            1 => LogLevel::Warn,
            2 => LogLevel::Info,
            3 => LogLevel::Debug,
            _ => LogLevel::Trace,
        }
    }

    fn set_log_level(&self, level: LogLevel) -> Result<(), SystemError> {
        self.set_log_level_here(level);
        Ok(())
    }
}

/// This runtime's own answers to E7, which cannot fail: what its [`Esgm`] calls return,
/// and what a connected process answers about itself when another process asks.
impl InProcessEsgm {
    /// Registered sensors as (name, type).
    pub fn sensors_here(&self) -> Vec<(String, String)> {
        self.inner.catalog.read().sensors().map(|s| (s.name.clone(), s.type_name.clone())).collect()
    }

    /// Registered units as (name, output type, input types).
    pub fn units_here(&self) -> Vec<(String, String, Vec<InputType>)> {
        self.inner
            .catalog
            .read()
            .units()
            .map(|u| (u.name.clone(), u.type_name.clone(), u.input_types.clone()))
            .collect()
    }

    /// Empties every trajectory of this runtime.
    pub fn reset_here(&self) {
        for cell in self.inner.cells() {
            cell.store.lock().reset();
        }
    }

    /// Sets this runtime's log level.
    pub fn set_log_level_here(&self, level: LogLevel) {
        self.inner.log_level.store(level as u8, Ordering::Relaxed);
    }

    /// Statistics of every trajectory of this runtime and its worker.
    pub fn stats_here(&self) -> EsgmStats {
        EsgmStats {
            trajectories: self
                .inner
                .cells()
                .iter()
                .map(|c| {
                    let report = TrajectoryReport {
                        info: c.info.clone(),
                        stats: c.store.lock().stats(),
                        worker: c.counters.snapshot(),
                    };
                    (c.info.name.clone(), report)
                })
                .collect(),
        }
    }

    /// [`InProcessEsgm::stats_here`] without the listings: each trajectory's name,
    /// store statistics and worker counters, for a caller that has the listing
    /// elsewhere (a process answering `esgm stats` for 1,000 trajectories, whose
    /// asker gets the listing from the coordinator).
    pub fn figures_here(&self) -> Vec<(String, crate::TrajectoryStats, crate::esgm::WorkerStats)> {
        self.inner
            .cells()
            .iter()
            .map(|c| (c.info.name.clone(), c.store.lock().stats(), c.counters.snapshot()))
            .collect()
    }

    /// Memory this runtime's trajectories use.
    pub fn memory_here(&self) -> MemoryStats {
        let mut seen = HashSet::new();
        let mut m = MemoryStats::default();
        for c in self.inner.cells() {
            let store = c.store.lock();
            let st = store.stats();
            m.trajectories += 1;
            m.stored_samples += st.stored;
            m.held_samples += st.held;
            m.approx_bytes += store.approx_bytes(&mut seen);
        }
        m
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;
    use crate::esgm::TrajectoryKind;
    use crate::{EntityStructureType, ValueSort};

    #[test]
    fn a_replica_whose_type_definition_is_invalid_says_why() {
        let esgm = InProcessEsgm::default();
        // As a hostile or broken writer could send it: one attribute twice.
        let broken =
            EntityStructureType::new("Odd").attr("x", ValueSort::Double).attr("x", ValueSort::Long);
        let info = TrajectoryInfo {
            name: "odd".into(),
            kind: TrajectoryKind::Primitive,
            type_name: "Odd".into(),
            source: None,
            inputs: Vec::new(),
            policy: crate::policy::FluentStreamPolicy::default(),
        };
        match esgm.create_replica(info, &[("Odd".into(), broken)]) {
            Err(CreateError::InvalidTypeDefinition { name, reason }) => {
                assert_eq!(name, "Odd");
                assert!(reason.contains('x'), "{reason}");
            }
            other => panic!("expected InvalidTypeDefinition, got {other:?}"),
        }
        // Nothing was made, and the type was not registered.
        assert!(esgm.get_entity_structure_type("Odd").is_err());
    }
}
