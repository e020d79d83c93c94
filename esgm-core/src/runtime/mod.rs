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
mod workers;

pub use handle::InProcessTrajectory;

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

use parking_lot::RwLock;

use crate::clock::{SharedClock, SystemClock};
use crate::esgm::{
    CompUnit, CreateError, Esgm, EsgmStats, InputType, LogLevel, LookupError, MemoryStats,
    RegistrationError, SensorInterface, TrajectoryInfo, TrajectoryKind, TrajectorySource,
    TrajectorySpec,
};
use crate::sample::Sample;
use crate::store::{SubscribeOptions, Subscription, TrajectoryStore};
use crate::type_check::TypeChecker;
use crate::type_registry::{TypeRegistry, TypeRegistryError, closest_name};
use crate::types::EntityStructureType;
use cell::{Descriptor, TrajectoryCell};

#[derive(Debug)]
struct SensorEntry {
    type_name: String,
    iface: Arc<dyn SensorInterface>,
}

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

#[derive(Debug)]
struct UnitEntry {
    type_name: String,
    input_types: Vec<InputType>,
    cu: Arc<dyn CompUnit>,
}

/// A resolved input: its name's descriptor and the trajectory it denotes now.
type Input = (Arc<Descriptor>, Arc<TrajectoryCell>);

#[derive(Debug)]
pub(crate) struct Inner {
    clock: SharedClock,
    types: RwLock<TypeRegistry>,
    trajectories: RwLock<BTreeMap<String, Arc<Descriptor>>>,
    sensors: RwLock<BTreeMap<String, SensorEntry>>,
    units: RwLock<BTreeMap<String, UnitEntry>>,
    subscriber_capacity: usize,
    log_level: AtomicU8,
    shutdown: AtomicBool,
}

impl Inner {
    fn cells(&self) -> Vec<Arc<TrajectoryCell>> {
        self.trajectories.read().values().filter_map(|d| d.get()).collect()
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
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
        let inner = Arc::new(Inner {
            clock: self.clock.unwrap_or_else(SystemClock::shared),
            types: RwLock::new(self.types.unwrap_or_else(TypeRegistry::with_library)),
            trajectories: RwLock::new(BTreeMap::new()),
            sensors: RwLock::new(BTreeMap::new()),
            units: RwLock::new(BTreeMap::new()),
            subscriber_capacity: self.subscriber_capacity.unwrap_or(1024),
            log_level: AtomicU8::new(LogLevel::Info as u8),
            shutdown: AtomicBool::new(false),
        });
        let weak = Arc::downgrade(&inner);
        if let Err(e) = std::thread::Builder::new()
            .name("esgm-releaser".into())
            .spawn(move || releaser::run(weak))
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

    /// Stops every worker; trajectories stay queryable.
    pub fn shutdown(&self) {
        self.inner.shutdown.store(true, Ordering::Relaxed);
        for cell in self.inner.cells() {
            cell.worker.lock().take();
        }
    }

    fn no_such_trajectory(&self, name: &str) -> LookupError {
        let map = self.inner.trajectories.read();
        LookupError::NoSuchEntityStructure {
            name: name.to_owned(),
            suggestion: closest_name(name, map.keys().map(String::as_str)),
        }
    }

    fn descriptor(&self, name: &str) -> Option<Arc<Descriptor>> {
        self.inner.trajectories.read().get(name).cloned()
    }

    fn input_cells(&self, names: &[String]) -> Result<Vec<Input>, CreateError> {
        names
            .iter()
            .map(|n| {
                self.descriptor(n).and_then(|d| d.get().map(|c| (d, c))).ok_or_else(|| {
                    match self.no_such_trajectory(n) {
                        LookupError::NoSuchEntityStructure { name, suggestion } => {
                            CreateError::NoSuchEntityStructure { name, suggestion }
                        }
                    }
                })
            })
            .collect()
    }

    /// Subscribes to an input and reads its latest sample in one step, so no update
    /// falls between the two.
    fn subscribe_input(&self, cell: &TrajectoryCell) -> (Subscription<Sample>, Option<Sample>) {
        let mut store = cell.store.lock();
        let latest = store.get_latest().ok();
        let sub =
            store.subscribe(SubscribeOptions::default().capacity(self.inner.subscriber_capacity));
        (sub, latest)
    }

    fn checker(&self, type_name: &str) -> Result<TypeChecker, CreateError> {
        TypeChecker::new(&self.inner.types.read(), type_name).map_err(type_error)
    }

    /// A checker for an operator's own state type (one frame per input), built on a
    /// copy of the registry so the synthesized type does not appear in it.
    fn state_checker(&self, name: &str, inputs: &[Input]) -> Result<TypeChecker, CreateError> {
        let mut ty = EntityStructureType::new(format!("{name}:state"));
        for (d, c) in inputs {
            ty = ty.frame(d.name.clone(), c.info.type_name.clone());
        }
        let mut registry = self.inner.types.read().clone();
        let key = ty.name.clone();
        let _ = registry.destroy_entity_structure_type(&key);
        registry.create_entity_structure_type(key.clone(), ty).map_err(type_error)?;
        TypeChecker::new(&registry, &key).map_err(type_error)
    }

    /// A sampling schedule with the seed's zero rules: from = 0 is now, to = 0 forever.
    fn schedule(&self, from: i64, to: i64, period: i64) -> periodic::Schedule {
        let from = if from == 0 { self.inner.clock.now() } else { from };
        periodic::Schedule { from, to: (to != 0).then_some(to), period }
    }
}

fn type_error(e: TypeRegistryError) -> CreateError {
    match e {
        TypeRegistryError::NoSuchEntityStructureType { name, suggestion } => {
            CreateError::NoSuchEntityStructureType { name, suggestion }
        }
        // Only lookups happen here; a definition error means a synthesized type broke
        // a rule, reported as the type that could not be resolved.
        other => {
            CreateError::NoSuchEntityStructureType { name: other.to_string(), suggestion: None }
        }
    }
}

impl Esgm for InProcessEsgm {
    type Trajectory = InProcessTrajectory;

    fn create_entity_structure_type(
        &self,
        type_name: &str,
        entity_type: EntityStructureType,
    ) -> Result<(), TypeRegistryError> {
        self.inner.types.write().create_entity_structure_type(type_name, entity_type)
    }

    fn destroy_entity_structure_type(&self, type_name: &str) -> Result<(), TypeRegistryError> {
        self.inner.types.write().destroy_entity_structure_type(type_name).map(|_| ())
    }

    fn get_entity_structure_type(
        &self,
        type_name: &str,
    ) -> Result<EntityStructureType, TypeRegistryError> {
        self.inner.types.read().get_entity_structure_type(type_name).map(|t| t.as_ref().clone())
    }

    fn entity_structure_type_names(&self) -> Vec<String> {
        self.inner.types.read().names()
    }

    fn create_trajectory(&self, spec: TrajectorySpec) -> Result<InProcessTrajectory, CreateError> {
        let name = spec.name.clone();
        let existing = self.descriptor(&name);
        if existing.is_some() && !spec.replace {
            return Err(CreateError::EntityStructureAlreadyExists { name });
        }
        let clock = self.inner.clock.clone();
        let input_names = spec.inputs();
        let inputs = self.input_cells(&input_names)?;
        if matches!(
            spec.source,
            TrajectorySource::Sync { .. }
                | TrajectorySource::Merge { .. }
                | TrajectorySource::SampledGenerators { .. }
        ) && inputs.is_empty()
        {
            return Err(CreateError::NoInputs { name });
        }

        // The type of the new trajectory, and what feeds it.
        let (checker, source_name) = match &spec.source {
            TrajectorySource::Primitive { type_name } => (self.checker(type_name)?, None),
            TrajectorySource::Sampled { sensor, .. } => {
                let sensors = self.inner.sensors.read();
                let entry = sensors.get(sensor).ok_or_else(|| CreateError::NoSuchSensor {
                    name: sensor.clone(),
                    suggestion: closest_name(sensor, sensors.keys().map(String::as_str)),
                })?;
                (self.checker(&entry.type_name)?, Some(sensor.clone()))
            }
            TrajectorySource::Computed { unit, .. } => {
                let units = self.inner.units.read();
                let entry = units.get(unit).ok_or_else(|| CreateError::NoSuchCompUnit {
                    name: unit.clone(),
                    suggestion: closest_name(unit, units.keys().map(String::as_str)),
                })?;
                if entry.input_types.len() != inputs.len() {
                    return Err(CreateError::WrongInputCount {
                        unit: unit.clone(),
                        expected: entry.input_types.len(),
                        found: inputs.len(),
                    });
                }
                for (position, (declared, (d, c))) in
                    entry.input_types.iter().zip(&inputs).enumerate()
                {
                    if !declared.accepts(&c.info.type_name) {
                        return Err(CreateError::InvalidInput {
                            unit: unit.clone(),
                            input: d.name.clone(),
                            position,
                            expected: declared.to_string(),
                            actual: c.info.type_name.clone(),
                        });
                    }
                }
                (self.checker(&entry.type_name)?, Some(unit.clone()))
            }
            TrajectorySource::Merge { .. } => {
                let first = inputs[0].1.info.type_name.clone();
                for (position, (d, c)) in inputs.iter().enumerate() {
                    if c.info.type_name != first {
                        return Err(CreateError::InvalidInput {
                            unit: "merge".into(),
                            input: d.name.clone(),
                            position,
                            expected: format!(
                                "type `{first}` (all inputs of a merge share one type)"
                            ),
                            actual: c.info.type_name.clone(),
                        });
                    }
                }
                (self.checker(&first)?, Some("merge".into()))
            }
            TrajectorySource::Sync { .. } => {
                (self.state_checker(&name, &inputs)?, Some("sync".into()))
            }
            TrajectorySource::SampledGenerators { .. } if inputs.len() == 1 => {
                (self.checker(&inputs[0].1.info.type_name)?, Some("generator".into()))
            }
            TrajectorySource::SampledGenerators { .. } => {
                (self.state_checker(&name, &inputs)?, Some("state".into()))
            }
        };

        let store = TrajectoryStore::builder(name.clone(), checker)
            .policy(spec.policy.clone())
            .clock(clock.clone())
            .create()?;
        let info = TrajectoryInfo {
            name: name.clone(),
            kind: spec.kind(),
            type_name: store.type_name().to_owned(),
            source: source_name,
            inputs: input_names,
            policy: spec.policy.clone(),
        };
        let cell = Arc::new(TrajectoryCell {
            store: parking_lot::Mutex::new(store),
            external_adds: spec.kind() == TrajectoryKind::Primitive,
            info,
            worker: parking_lot::Mutex::new(None),
            counters: Arc::default(),
        });

        // Start what feeds it.
        let worker = match &spec.source {
            TrajectorySource::Primitive { .. } => None,
            TrajectorySource::Sampled { sensor, from, to, sample_period } => {
                let iface = self.inner.sensors.read().get(sensor).map(|e| Arc::clone(&e.iface));
                let schedule = self.schedule(*from, *to, *sample_period);
                iface.map(|iface| workers::sampler(&cell, clock.clone(), iface, schedule))
            }
            TrajectorySource::Computed { unit, .. } => {
                let cu = self.inner.units.read().get(unit).map(|e| Arc::clone(&e.cu));
                let (subs, latest): (Vec<_>, Vec<_>) =
                    inputs.iter().map(|(_, c)| self.subscribe_input(c)).unzip();
                cu.map(|cu| workers::unit(&cell, clock.clone(), cu, subs, latest))
            }
            TrajectorySource::Sync { policy, .. } => {
                let synchronizer = policy.create::<Sample>(inputs.len())?;
                let subs = inputs.iter().map(|(_, c)| self.subscribe_input(c).0).collect();
                let names = inputs.iter().map(|(d, _)| d.name.clone()).collect();
                Some(workers::sync(&cell, clock.clone(), synchronizer, names, subs))
            }
            TrajectorySource::Merge { .. } => {
                let subs = inputs.iter().map(|(_, c)| self.subscribe_input(c).0).collect();
                Some(workers::merge(&cell, subs))
            }
            TrajectorySource::SampledGenerators { inputs: gens, from, to, sample_period } => {
                if *sample_period <= 0 {
                    return Err(CreateError::IllegalPolicy(crate::policy::PolicyError::illegal(
                        "sample_period",
                        sample_period,
                        "must be positive",
                    )));
                }
                let schedule = self.schedule(*from, *to, *sample_period);
                let with_policies = inputs
                    .iter()
                    .zip(gens)
                    .map(|((d, _), (_, g))| (Arc::clone(d), g.clone()))
                    .collect();
                Some(workers::sampled_generators(&cell, clock.clone(), with_policies, schedule))
            }
        };
        *cell.worker.lock() = worker;

        // Publish it under its name (re-pointing keeps subscribers and handles).
        let mut map = self.inner.trajectories.write();
        let descriptor = match map.get(&name) {
            Some(d) if spec.replace => {
                let old = d.current.write().replace(Arc::clone(&cell));
                if let Some(old) = old {
                    old.worker.lock().take();
                    let mut old_store = old.store.lock();
                    cell.store.lock().adopt_subscribers(&mut old_store);
                }
                Arc::clone(d)
            }
            Some(_) => return Err(CreateError::EntityStructureAlreadyExists { name }),
            None => {
                let d = Arc::new(Descriptor {
                    name: name.clone(),
                    current: parking_lot::RwLock::new(Some(cell)),
                });
                map.insert(name, Arc::clone(&d));
                d
            }
        };
        Ok(InProcessTrajectory { descriptor })
    }

    fn get_entity_trajectory_structure(
        &self,
        name: &str,
    ) -> Result<InProcessTrajectory, LookupError> {
        self.descriptor(name)
            .map(|descriptor| InProcessTrajectory { descriptor })
            .ok_or_else(|| self.no_such_trajectory(name))
    }

    fn get_entity_trajectory_structure_type(
        &self,
        name: &str,
    ) -> Result<EntityStructureType, LookupError> {
        self.descriptor(name)
            .and_then(|d| d.get())
            .map(|c| c.store.lock().entity_type().as_ref().clone())
            .ok_or_else(|| self.no_such_trajectory(name))
    }

    fn destroy_entity_trajectory_structure(&self, name: &str) -> Result<(), LookupError> {
        let removed = self.inner.trajectories.write().remove(name);
        let d = removed.ok_or_else(|| self.no_such_trajectory(name))?;
        if let Some(cell) = d.current.write().take() {
            cell.worker.lock().take();
        }
        Ok(())
    }

    fn trajectories(&self) -> Vec<TrajectoryInfo> {
        self.inner.cells().iter().map(|c| c.info.clone()).collect()
    }

    fn add_sensor_interface(
        &self,
        sensor: &str,
        type_name: &str,
        iface: Arc<dyn SensorInterface>,
    ) -> Result<(), RegistrationError> {
        if let Err(TypeRegistryError::NoSuchEntityStructureType { name, suggestion }) =
            self.inner.types.read().get_entity_structure_type(type_name)
        {
            return Err(RegistrationError::NoSuchEntityStructureType { name, suggestion });
        }
        let mut sensors = self.inner.sensors.write();
        if sensors.contains_key(sensor) {
            return Err(RegistrationError::SensorAlreadyExists { name: sensor.to_owned() });
        }
        sensors.insert(sensor.to_owned(), SensorEntry { type_name: type_name.to_owned(), iface });
        Ok(())
    }

    fn remove_sensor_interface(&self, sensor: &str) -> Result<(), RegistrationError> {
        let users = users_of(self, TrajectoryKind::Sampled, sensor);
        let mut sensors = self.inner.sensors.write();
        if !sensors.contains_key(sensor) {
            return Err(RegistrationError::NoSuchSensor {
                name: sensor.to_owned(),
                suggestion: closest_name(sensor, sensors.keys().map(String::as_str)),
            });
        }
        if !users.is_empty() {
            return Err(RegistrationError::InUse { name: sensor.to_owned(), users });
        }
        sensors.remove(sensor);
        Ok(())
    }

    fn add_comp_unit(
        &self,
        name: &str,
        type_name: &str,
        input_types: Vec<InputType>,
        cu: Arc<dyn CompUnit>,
    ) -> Result<(), RegistrationError> {
        {
            let types = self.inner.types.read();
            let all =
                std::iter::once(type_name.to_owned()).chain(input_types.iter().filter_map(|t| {
                    match t {
                        InputType::Type(t) => Some(t.clone()),
                        InputType::Sort(_) => None,
                    }
                }));
            for t in all {
                if let Err(TypeRegistryError::NoSuchEntityStructureType { name, suggestion }) =
                    types.get_entity_structure_type(&t)
                {
                    return Err(RegistrationError::NoSuchEntityStructureType { name, suggestion });
                }
            }
        }
        let mut units = self.inner.units.write();
        if units.contains_key(name) {
            return Err(RegistrationError::CompUnitAlreadyExists { name: name.to_owned() });
        }
        units.insert(
            name.to_owned(),
            UnitEntry { type_name: type_name.to_owned(), input_types, cu },
        );
        Ok(())
    }

    fn remove_comp_unit(&self, name: &str) -> Result<(), RegistrationError> {
        let users = users_of(self, TrajectoryKind::Computed, name);
        let mut units = self.inner.units.write();
        if !units.contains_key(name) {
            return Err(RegistrationError::NoSuchCompUnit {
                name: name.to_owned(),
                suggestion: closest_name(name, units.keys().map(String::as_str)),
            });
        }
        if !users.is_empty() {
            return Err(RegistrationError::InUse { name: name.to_owned(), users });
        }
        units.remove(name);
        Ok(())
    }

    fn sensors(&self) -> Vec<(String, String)> {
        self.inner.sensors.read().iter().map(|(n, e)| (n.clone(), e.type_name.clone())).collect()
    }

    fn comp_units(&self) -> Vec<(String, String, Vec<InputType>)> {
        self.inner
            .units
            .read()
            .iter()
            .map(|(n, e)| (n.clone(), e.type_name.clone(), e.input_types.clone()))
            .collect()
    }

    fn ping(&self) -> bool {
        !self.inner.shutdown.load(Ordering::Relaxed)
    }

    fn reset(&self) {
        for cell in self.inner.cells() {
            cell.store.lock().reset();
        }
    }

    fn stats(&self) -> EsgmStats {
        EsgmStats {
            trajectories: self
                .inner
                .cells()
                .iter()
                .map(|c| (c.info.clone(), c.store.lock().stats(), c.counters.snapshot()))
                .collect(),
        }
    }

    fn memory_stats(&self) -> MemoryStats {
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

    fn log_level(&self) -> LogLevel {
        match self.inner.log_level.load(Ordering::Relaxed) {
            0 => LogLevel::Error,
            1 => LogLevel::Warn,
            2 => LogLevel::Info,
            3 => LogLevel::Debug,
            _ => LogLevel::Trace,
        }
    }

    fn set_log_level(&self, level: LogLevel) {
        self.inner.log_level.store(level as u8, Ordering::Relaxed);
    }
}

fn users_of(esgm: &InProcessEsgm, kind: TrajectoryKind, source: &str) -> Vec<String> {
    esgm.inner
        .cells()
        .iter()
        .filter(|c| c.info.kind == kind && c.info.source.as_deref() == Some(source))
        .map(|c| c.info.name.clone())
        .collect()
}
