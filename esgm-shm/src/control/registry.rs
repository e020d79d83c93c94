//! The coordinator's registry: the catalog of names plus where each trajectory is
//! written. Pure state, no transport, so every rule is tested without shared memory.

use std::collections::BTreeMap;

use esgm_core::catalog::Catalog;
use esgm_core::esgm::{
    CreateError, HowWriterChanged, TrajectoryInfo, TrajectoryKind, TrajectorySource,
    TrajectorySpec, WriterChange,
};
use esgm_core::policy::PolicyError;
use esgm_core::{Clock, EntityStructureType, SystemClock, TypeChecker, TypeRegistry};

use super::processes::ProcessTable;
use super::protocol::{
    Assignment, ControlError, PlacementRecord, Request, Response, TrajectoryRecord, WriterPort,
};
use super::refusal::Refusal;
use super::state::{SNAPSHOT_VERSION, SavedTrajectory, Snapshot};
use crate::control::holding_stats::HoldingStats;
use crate::data_plane::capacity::{DomainLimits, Readers};

#[derive(Debug, Clone)]
struct Placement {
    writer: String,
    generation: u64,
    spec: TrajectorySpec,
    /// The writer's publisher port, once reported ([`Request::ReportWriter`]).
    port: Option<WriterPort>,
    /// The writer stopped serving it without destroying it ([`Request::ReleaseWriter`]):
    /// another process may take it over. Not saved: after a coordinator restart, a
    /// writer whose process lives is taken to serve.
    released: bool,
    /// The last time another process became the writer (`esgm why` names it). Not
    /// saved: a coordinator restarted starts a new account.
    changed: Option<WriterChange>,
    /// The pid of the last process that reported the writer's port, kept when the
    /// port is let go, so that the next one's report can say whom it replaced.
    last_pid: Option<u32>,
}

/// Names, types, sensors, units and trajectories of one esgm system.
#[derive(Debug, Default)]
pub struct Registry {
    catalog: Catalog,
    /// Per trajectory: its writer process, generation and the spec it was made from
    /// (which the writer needs to build it).
    placement: BTreeMap<String, Placement>,
    /// The processes the system keeps running.
    processes: ProcessTable,
    /// The next trajectory generation: unique across the registry, so that a name
    /// destroyed and created again is never mistaken for its former self.
    next_generation: u64,
    /// Each connected process's last report of its images in shared memory.
    holdings: BTreeMap<String, HoldingStats>,
    /// The domain's limits: a trajectory's readers default to them, and may not
    /// exceed its processes.
    limits: DomainLimits,
    /// Bumped by every change ([`Response::Pong`]'s `registry`).
    version: u64,
}

impl Registry {
    /// A registry with `types` (the library types, usually).
    pub fn new(types: TypeRegistry) -> Self {
        Self {
            catalog: Catalog::new(types),
            placement: BTreeMap::new(),
            processes: ProcessTable::default(),
            next_generation: 0,
            holdings: BTreeMap::new(),
            limits: DomainLimits::default(),
            version: start_version(),
        }
    }

    /// The same registry with the domain's `limits` (`esgm up --max-processes`,
    /// `--readers`); [`DomainLimits::default`] until set.
    #[must_use]
    pub fn with_limits(mut self, limits: DomainLimits) -> Self {
        self.limits = limits;
        self
    }

    /// The domain's limits.
    pub fn limits(&self) -> DomainLimits {
        self.limits
    }

    /// The catalog, read-only.
    pub fn catalog(&self) -> &Catalog {
        &self.catalog
    }

    /// Carries out one request from the coordinator's own process (trusted: the
    /// supervisor reports from there).
    pub fn handle(&mut self, request: Request) -> Response {
        self.handle_from(request, Origin::Coordinator)
    }

    /// Carries out one request from `origin`: its names are checked first
    /// (`super::limits`), and a process report is accepted only from the
    /// coordinator's own process (the supervisor) or from the reported process itself.
    pub fn handle_from(&mut self, request: Request, origin: Origin) -> Response {
        let changes = changes_registry(&request);
        let checked = super::limits::check_request(&request)
            .and_then(|()| check_origin(&request, origin))
            .and_then(|()| self.apply(request, origin));
        match checked {
            Ok(r) => {
                if changes {
                    self.version += 1;
                }
                r
            }
            Err(e) => Response::Error(e),
        }
    }

    /// Returns to `saved` (what was last saved, restored on `types`): what a change
    /// that could not be saved undoes. The holdings reports and limits stay; the next
    /// generation is never lowered (a generation is never given twice) and the version
    /// is bumped, so every process looks again.
    pub fn roll_back(&mut self, types: TypeRegistry, saved: Snapshot) -> Result<(), ControlError> {
        let mut restored = Self::restore(types, saved)?;
        restored.next_generation = restored.next_generation.max(self.next_generation);
        restored.holdings = std::mem::take(&mut self.holdings);
        restored.limits = self.limits;
        restored.version = self.version + 1;
        *self = restored;
        Ok(())
    }

    /// The registry's version, bumped by every change.
    pub fn version(&self) -> u64 {
        self.version
    }

    fn placement_record(&self, name: &str, p: &Placement) -> PlacementRecord {
        PlacementRecord {
            name: name.to_owned(),
            writer: p.writer.clone(),
            generation: p.generation,
            port: p.port,
            released: p.released,
            type_name: self
                .catalog
                .trajectory(name)
                // Placed and catalogued together, removed together: the lookup finds it.
                .map(|t| t.type_name.clone())
                .unwrap_or_default(),
        }
    }

    /// Everything a new coordinator needs to answer as this one does
    /// ([`crate::control::StateDir`]).
    pub fn snapshot(&self) -> Snapshot {
        let types = self
            .catalog
            .types()
            .names()
            .into_iter()
            .filter_map(|n| match self.catalog.types().get_entity_structure_type(&n) {
                Ok(t) => Some((n, t.as_ref().clone())),
                Err(e) => {
                    tracing::error!(type_name = %n, error = %e, "a listed type is missing; not saved");
                    None
                }
            })
            .collect();
        let mut trajectories: Vec<SavedTrajectory> = self
            .placement
            .iter()
            .filter_map(|(name, p)| {
                let info = match self.catalog.trajectory(name) {
                    Ok(info) => info.clone(),
                    Err(e) => {
                        tracing::error!(trajectory = %name, error = %e,
                            "a placed trajectory is not in the catalog; not saved");
                        return None;
                    }
                };
                Some(SavedTrajectory {
                    info,
                    spec: p.spec.clone(),
                    writer: p.writer.clone(),
                    generation: p.generation,
                    port: p.port,
                })
            })
            .collect();
        trajectories.sort_by_key(|t| t.generation);
        Snapshot {
            version: SNAPSHOT_VERSION,
            types,
            sensors: self.catalog.sensors().cloned().collect(),
            units: self.catalog.units().cloned().collect(),
            trajectories,
            next_generation: self.next_generation,
            processes: self.processes.list(),
        }
    }

    /// A registry with `types` (the library types, usually) and everything `snapshot`
    /// holds. What cannot be restored (a type naming a type that is missing, say) is
    /// an error naming it: a registry silently missing part of its system would make
    /// running processes drop what they serve.
    pub fn restore(types: TypeRegistry, snapshot: Snapshot) -> Result<Self, ControlError> {
        let mut r = Self::new(types);
        // The saved types are every type the registry had: a library type it had
        // destroyed stays destroyed, and one it had defined anew comes back as it was.
        let saved: std::collections::BTreeSet<&str> =
            snapshot.types.iter().map(|(n, _)| n.as_str()).collect();
        for name in r.catalog.types().names() {
            let redefined = snapshot.types.iter().any(|(n, t)| {
                *n == name && r.catalog.types().get_entity_structure_type(n).is_ok_and(|k| *k != *t)
            });
            let destroyed = !saved.is_empty() && !saved.contains(name.as_str());
            if destroyed || redefined {
                r.catalog.types_mut().destroy_entity_structure_type(&name)?;
            }
        }
        // Types may name each other: define in passes until none is left.
        let mut pending: Vec<(String, EntityStructureType)> = snapshot
            .types
            .into_iter()
            .filter(|(n, _)| r.catalog.types().get_entity_structure_type(n).is_err())
            .collect();
        while !pending.is_empty() {
            let before = pending.len();
            let mut last_error = None;
            pending.retain(|(n, t)| {
                match r.catalog.types_mut().create_entity_structure_type(n.clone(), t.clone()) {
                    Ok(()) => false,
                    Err(e) => {
                        last_error = Some(e);
                        true
                    }
                }
            });
            if pending.len() == before {
                if let Some(e) = last_error {
                    return Err(e.into());
                }
            }
        }
        // As they were, even one whose type was destroyed since (allowed: what was
        // made with a type keeps its copy).
        for s in snapshot.sensors {
            r.catalog.restore_sensor(s);
        }
        for u in snapshot.units {
            r.catalog.restore_unit(u);
        }
        for t in snapshot.trajectories {
            let name = t.info.name.clone();
            r.catalog.insert_trajectory(t.info);
            r.placement.insert(
                name,
                Placement {
                    writer: t.writer,
                    generation: t.generation,
                    spec: t.spec,
                    port: t.port,
                    released: false,
                    changed: None,
                    last_pid: t.port.map(|p| p.pid),
                },
            );
        }
        r.next_generation = snapshot.next_generation;
        for p in snapshot.processes {
            let name = p.spec.name.clone();
            r.processes.declare(p.spec)?;
            r.processes.report(&name, p.status)?;
        }
        Ok(r)
    }

    /// The generation of trajectory `name`, if it exists.
    pub fn generation_of(&self, name: &str) -> Option<u64> {
        self.placement.get(name).map(|p| p.generation)
    }

    fn record(&self, name: &str) -> Result<TrajectoryRecord, ControlError> {
        let info = self.catalog.trajectory(name)?.clone();
        let checker = TypeChecker::new(self.catalog.types(), &info.type_name);
        let types = match checker {
            Ok(c) => c.definitions(),
            // A synthesized state type (sync) is not in the registry: one frame per
            // input, named after it, of the input's type — what a reader in another
            // process needs to check the states it receives.
            Err(_) => self.state_definitions(&info),
        };
        let (writer, generation, port, asked, released, volatile, writer_changed) = self
            .placement
            .get(name)
            .map(|p| {
                let spec = &p.spec;
                let changed = p.changed.clone();
                let (readers, volatile) = (spec.readers, spec.volatile);
                (p.writer.clone(), p.generation, p.port, readers, p.released, volatile, changed)
            })
            .unwrap_or_default();
        // Checked when it was created; a saved spec whose readers exceed a domain
        // restarted with fewer processes is served with the most it may have.
        let readers = self.limits.readers_of(asked).unwrap_or(Readers(
            asked.unwrap_or(self.limits.readers).min(self.limits.max_processes),
        ));
        Ok(TrajectoryRecord {
            info,
            types,
            writer,
            generation,
            port,
            readers,
            released,
            volatile,
            writer_changed,
        })
    }

    /// The pid a process reported for `name`, if any.
    pub fn process_pid(&self, name: &str) -> Option<u32> {
        self.processes.list().into_iter().find(|p| p.spec.name == name).and_then(|p| p.status.pid)
    }

    fn apply(&mut self, request: Request, origin: Origin) -> Result<Response, ControlError> {
        Ok(match request {
            Request::Ping => Response::Pong {
                version: env!("CARGO_PKG_VERSION").to_owned(),
                pid: std::process::id(),
                registry: self.version,
                // The coordinator, which saves, fills it in.
                saves: super::persistence::SaveHealth::default(),
            },
            Request::CreateEntityStructureType { type_name, entity_type } => {
                self.catalog.types_mut().create_entity_structure_type(type_name, entity_type)?;
                Response::Done
            }
            Request::DestroyEntityStructureType { type_name } => {
                self.catalog.types_mut().destroy_entity_structure_type(&type_name)?;
                Response::Done
            }
            Request::GetEntityStructureType { type_name } => Response::Type(
                self.catalog.types().get_entity_structure_type(&type_name)?.as_ref().clone(),
            ),
            Request::ListEntityStructureTypes => Response::Names(self.catalog.types().names()),
            Request::GetTypeDefinitions { type_name } => Response::Definitions(
                TypeChecker::new(self.catalog.types(), &type_name)?.definitions(),
            ),
            Request::AddSensorInterface { sensor, type_name, host } => {
                // The same process registering the same sensor again (a restarted
                // worker under its stable name) takes its place back.
                let again = self
                    .catalog
                    .sensor(&sensor)
                    .is_some_and(|s| s.host == host && s.type_name == type_name);
                if !again {
                    self.catalog.add_sensor(&sensor, &type_name, &host)?;
                }
                Response::Done
            }
            Request::RemoveSensorInterface { sensor } => {
                self.catalog.remove_sensor(&sensor)?;
                Response::Done
            }
            Request::AddCompUnit { name, type_name, input_types, host } => {
                let again = self.catalog.unit(&name).is_some_and(|u| {
                    u.host == host && u.type_name == type_name && u.input_types == input_types
                });
                if !again {
                    self.catalog.add_unit(&name, &type_name, input_types, &host)?;
                }
                Response::Done
            }
            // Answered by the coordinator, which then stops.
            Request::Shutdown => Response::Done,
            Request::RemoveCompUnit { name } => {
                self.catalog.remove_unit(&name)?;
                Response::Done
            }
            Request::CreateTrajectory { spec, host } => {
                let resolved = self.catalog.resolve(&spec)?;
                if let Err(e) = self.limits.readers_of(spec.readers) {
                    return Err(ControlError::Create(CreateError::IllegalPolicy(
                        PolicyError::IllegalPolicy {
                            field: "readers".into(),
                            value: e.value.to_string(),
                            rule: format!(
                                "between 1 and the domain's max-processes ({}); raise that with `esgm up --max-processes N`",
                                e.max
                            ),
                        },
                    )));
                }
                let writer = match &spec.source {
                    TrajectorySource::Sampled { sensor, .. } => {
                        self.catalog.sensor(sensor).map(|s| s.host.clone()).unwrap_or(host)
                    }
                    // A temporal function runs where its unit is, as a unit's compute.
                    TrajectorySource::Computed { unit, .. }
                    | TrajectorySource::SampledGenerators { unit: Some(unit), .. } => {
                        self.catalog.unit(unit).map(|u| u.host.clone()).unwrap_or(host)
                    }
                    _ => host,
                };
                let name = spec.name.clone();
                let generation = self.next_generation;
                self.next_generation += 1;
                self.catalog.insert_trajectory(resolved.info);
                self.placement.insert(
                    name.clone(),
                    Placement {
                        writer,
                        generation,
                        spec,
                        port: None,
                        released: false,
                        changed: None,
                        last_pid: None,
                    },
                );
                Response::Trajectory(Box::new(self.record(&name)?))
            }
            Request::GetEntityTrajectoryStructure { name } => {
                Response::Trajectory(Box::new(self.record(&name)?))
            }
            Request::DestroyEntityTrajectoryStructure { name } => {
                self.catalog.remove_trajectory(&name)?;
                self.placement.remove(&name);
                Response::Done
            }
            Request::ListTrajectories => {
                Response::Trajectories(self.catalog.trajectories().cloned().collect())
            }
            Request::ReportHoldings { host, stats } => {
                self.holdings.insert(host, stats);
                Response::Done
            }
            Request::ListHoldings => {
                Response::Holdings(self.holdings.iter().map(|(h, s)| (h.clone(), *s)).collect())
            }
            Request::ListPlacements => Response::Placements(
                self.placement.iter().map(|(name, p)| self.placement_record(name, p)).collect(),
            ),
            Request::ListPlacementsOf { names } => Response::Placements(
                names
                    .iter()
                    .filter_map(|name| {
                        self.placement.get(name).map(|p| self.placement_record(name, p))
                    })
                    .collect(),
            ),
            Request::ListSensors => Response::Sensors(self.catalog.sensors().cloned().collect()),
            Request::ListCompUnits => Response::CompUnits(self.catalog.units().cloned().collect()),
            Request::Assignments { host } => {
                let mut out = Vec::new();
                for (name, p) in &self.placement {
                    if p.writer == host {
                        out.push(Assignment { spec: p.spec.clone(), record: self.record(name)? });
                    }
                }
                Response::Assignments(out)
            }
            Request::DeclareProcess { spec } => {
                self.processes.declare(spec)?;
                Response::Done
            }
            Request::RemoveProcess { name } => {
                self.processes.remove(&name)?;
                Response::Done
            }
            Request::ListProcesses => Response::Processes(self.processes.list()),
            Request::ReportProcess { name, status } => {
                self.processes.report(&name, status)?;
                Response::Done
            }
            Request::ReportWriter { trajectory, generation, publisher } => {
                self.report_writer(&trajectory, generation, publisher, origin)?;
                Response::Done
            }
            Request::ReleaseWriter { trajectory, generation } => {
                self.release_writer(&trajectory, generation, origin)?;
                Response::Done
            }
            Request::TakeOverTrajectory { trajectory, generation, host } => {
                self.take_over(&trajectory, generation, host)?;
                Response::Trajectory(Box::new(self.record(&trajectory)?))
            }
        })
    }

    /// Marks `trajectory` as served by nobody, at its writer's word (`origin` must hold
    /// the writer's port): another process may take it over.
    fn release_writer(
        &mut self,
        trajectory: &str,
        generation: u64,
        origin: Origin,
    ) -> Result<(), ControlError> {
        self.catalog.trajectory(trajectory)?;
        let placement = self.placement.get_mut(trajectory);
        let Some(placement) = placement.filter(|p| p.generation == generation) else {
            return Err(not_allowed(Refusal::NotPlaced {
                trajectory: trajectory.to_owned(),
                generation,
            }));
        };
        let holder = placement.port.map(|p| p.pid);
        let allowed = match origin {
            Origin::Coordinator => true,
            Origin::Process(pid) => holder == Some(pid),
            Origin::Unknown => false,
        };
        if !allowed {
            return Err(not_allowed(Refusal::NotTheWriter { trajectory: trajectory.to_owned() }));
        }
        placement.port = None;
        placement.released = true;
        Ok(())
    }

    /// Places `trajectory` at `host` if its writer is gone: its process exited (its
    /// reported port's pid is not alive) or it released the trajectory. A trajectory
    /// still served, or a request about a former generation, is left as it is (the
    /// record answered says who writes it).
    fn take_over(
        &mut self,
        trajectory: &str,
        generation: u64,
        host: String,
    ) -> Result<(), ControlError> {
        let info = self.catalog.trajectory(trajectory)?;
        if info.kind != TrajectoryKind::Primitive {
            return Err(not_allowed(Refusal::CannotMove {
                trajectory: trajectory.to_owned(),
                kind: info.kind,
            }));
        }
        let supervised = |writer: &str| self.processes.list().iter().any(|p| p.spec.name == writer);
        let Some(placement) = self.placement.get(trajectory) else { return Ok(()) };
        if placement.generation != generation {
            return Ok(());
        }
        if supervised(&placement.writer) {
            return Err(not_allowed(Refusal::Supervised {
                trajectory: trajectory.to_owned(),
                writer: placement.writer.clone(),
            }));
        }
        let gone = placement.released
            || placement.port.is_some_and(|p| !crate::process::process_alive(p.pid));
        if gone {
            if let Some(p) = self.placement.get_mut(trajectory) {
                tracing::info!(%trajectory, from = %p.writer, to = %host, "writer taken over");
                p.changed = Some(WriterChange {
                    how: HowWriterChanged::TakenOver,
                    from: std::mem::replace(&mut p.writer, host.clone()),
                    from_pid: p.last_pid,
                    to: host.clone(),
                    to_pid: None,
                    at: SystemClock.now(),
                });
                p.port = None;
                p.released = false;
            }
        }
        Ok(())
    }

    /// Records the publisher port `origin` writes `trajectory` with. Refused for a
    /// former generation, from a process the coordinator cannot identify, and while
    /// another live process holds the record: a process that comes second cannot make
    /// readers take its samples for the writer's. A writer that died (a crash, a
    /// restart) leaves its record to the next.
    fn report_writer(
        &mut self,
        trajectory: &str,
        generation: u64,
        publisher: u128,
        origin: Origin,
    ) -> Result<(), ControlError> {
        let pid = match origin {
            Origin::Coordinator => std::process::id(),
            Origin::Process(pid) => pid,
            Origin::Unknown => {
                return Err(not_allowed(Refusal::UnknownOrigin {
                    action: format!("name the writer of `{trajectory}`"),
                }));
            }
        };
        self.catalog.trajectory(trajectory)?;
        let Some(placement) = self.placement.get_mut(trajectory) else {
            return Err(not_allowed(Refusal::NotPlaced {
                trajectory: trajectory.to_owned(),
                generation,
            }));
        };
        if placement.generation != generation {
            return Err(not_allowed(Refusal::FormerGeneration {
                trajectory: trajectory.to_owned(),
                current: placement.generation,
                asked: generation,
            }));
        }
        if let Some(held) = placement.port {
            if held.pid != pid && crate::process::process_alive(held.pid) {
                return Err(not_allowed(Refusal::WriterLives {
                    trajectory: trajectory.to_owned(),
                    holder: held.pid,
                    pid,
                }));
            }
        }
        placement.port = Some(WriterPort { publisher, pid });
        let replaced = placement.last_pid.replace(pid).filter(|&former| former != pid);
        match &mut placement.changed {
            // The process that took it over reports its port: the change is complete.
            Some(c) if c.how == HowWriterChanged::TakenOver && c.to_pid.is_none() => {
                c.to_pid = Some(pid);
            }
            _ => {
                if let Some(former) = replaced {
                    placement.changed = Some(WriterChange {
                        how: HowWriterChanged::Restarted,
                        from: placement.writer.clone(),
                        from_pid: Some(former),
                        to: placement.writer.clone(),
                        to_pid: Some(pid),
                        at: SystemClock.now(),
                    });
                }
            }
        }
        Ok(())
    }

    fn state_definitions(&self, info: &TrajectoryInfo) -> Vec<(String, EntityStructureType)> {
        let mut state = EntityStructureType::new(info.type_name.clone());
        let mut out = Vec::new();
        for input in &info.inputs {
            let Ok(t) = self.catalog.trajectory(input) else { continue };
            state = state.frame(input.clone(), t.type_name.clone());
            if let Ok(c) = TypeChecker::new(self.catalog.types(), &t.type_name) {
                for d in c.definitions() {
                    if !out.iter().any(|(n, _)| *n == d.0) {
                        out.push(d);
                    }
                }
            }
        }
        if info.kind == TrajectoryKind::Sync {
            state = esgm_core::operators::sync::with_member_times(state);
        }
        out.insert(0, (info.type_name.clone(), state));
        out
    }

    /// The trajectories a process writes (what it must serve), e.g. after a restart.
    pub fn written_by(&self, host: &str) -> Vec<String> {
        self.placement.iter().filter(|(_, p)| p.writer == host).map(|(n, _)| n.clone()).collect()
    }

    /// True if `name` is a primitive trajectory (writable by any process that holds it).
    pub fn is_primitive(&self, name: &str) -> bool {
        self.catalog.trajectory(name).is_ok_and(|t| t.kind == TrajectoryKind::Primitive)
    }
}

/// Who asked: what the coordinator knows of the process behind a request (from
/// iceoryx2's record of the client port's node, which the asking process cannot forge).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// The coordinator's own process (the supervisor in `esgm up`).
    Coordinator,
    /// Another process, by pid.
    Process(u32),
    /// A process the coordinator could not identify.
    Unknown,
}

/// True if the request changes the registry (and the state file must follow).
pub fn changes_registry(request: &Request) -> bool {
    !matches!(
        request,
        Request::Ping
            | Request::Shutdown
            | Request::GetEntityStructureType { .. }
            | Request::ListEntityStructureTypes
            | Request::GetTypeDefinitions { .. }
            | Request::GetEntityTrajectoryStructure { .. }
            | Request::ListTrajectories
            | Request::ReportHoldings { .. }
            | Request::ListHoldings
            | Request::ListPlacements
            | Request::ListPlacementsOf { .. }
            | Request::ListSensors
            | Request::ListCompUnits
            | Request::Assignments { .. }
            | Request::ListProcesses
    )
}

/// A registry's first version: the time it was made, in nanoseconds, so that a
/// coordinator restored after a crash never repeats a version its predecessor gave
/// (a process that saw it would take the new registry for one it has looked at).
fn start_version() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX / 2))
}

/// A process report comes from the supervisor, or from the process itself about its
/// own pid: nobody else may rewrite a process's record (a pid of 1 there made
/// `esgm down` wait for init).
fn check_origin(request: &Request, origin: Origin) -> Result<(), ControlError> {
    let Request::ReportProcess { name, status } = request else { return Ok(()) };
    match origin {
        Origin::Coordinator => Ok(()),
        Origin::Process(pid) if status.pid == Some(pid) => Ok(()),
        Origin::Process(pid) => Err(not_allowed(Refusal::NotItsRecord {
            pid,
            process: name.clone(),
            reported: status.pid,
        })),
        Origin::Unknown => {
            Err(not_allowed(Refusal::UnknownOrigin { action: format!("report on `{name}`") }))
        }
    }
}

fn not_allowed(reason: Refusal) -> ControlError {
    ControlError::NotAllowed { reason }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::esgm::{CreateError, RegistrationError, TrajectorySpec};
    use esgm_core::{EntityStructureType, TypeRegistryError, ValueSort};

    fn registry() -> Registry {
        Registry::new(TypeRegistry::with_library())
    }

    fn err(r: Response) -> ControlError {
        match r {
            Response::Error(e) => e,
            other => panic!("expected an error, got {other:?}"),
        }
    }

    #[test]
    fn writers_are_placed_where_the_data_is_made() {
        let mut r = registry();
        let ok = |r: &mut Registry, q| assert!(!matches!(r.handle(q), Response::Error(_)));
        ok(
            &mut r,
            Request::AddSensorInterface {
                sensor: "camera".into(),
                type_name: "Image".into(),
                host: "cam".into(),
            },
        );
        ok(
            &mut r,
            Request::AddCompUnit {
                name: "BlobDetection".into(),
                type_name: "BlobSeq".into(),
                input_types: vec!["Image".into()],
                host: "cu1".into(),
            },
        );
        let images = TrajectorySpec::sampled("images", "camera", 1_000_000_000).unwrap();
        match r.handle(Request::CreateTrajectory { spec: images, host: "app".into() }) {
            Response::Trajectory(t) => {
                assert_eq!((t.writer.as_str(), t.generation), ("cam", 0));
                assert_eq!(t.types.len(), 1, "Image has no element types");
            }
            other => panic!("{other:?}"),
        }
        let blobs = TrajectorySpec::computed("blobs", "BlobDetection", ["images"]);
        match r.handle(Request::CreateTrajectory { spec: blobs, host: "app".into() }) {
            Response::Trajectory(t) => {
                assert_eq!(t.writer, "cu1");
                let names: Vec<_> = t.types.iter().map(|(n, _)| n.as_str()).collect();
                assert!(names.contains(&"BlobSeq") && names.contains(&"Blob"), "{names:?}");
            }
            other => panic!("{other:?}"),
        }
        ok(
            &mut r,
            Request::CreateTrajectory {
                spec: TrajectorySpec::primitive("robot_state", "RobotState"),
                host: "robot".into(),
            },
        );
        assert_eq!(r.written_by("robot"), vec!["robot_state".to_owned()]);
        assert!(r.is_primitive("robot_state") && !r.is_primitive("images"));
        // Re-pointing, and destroying and creating again, give a new generation.
        let generation = |r: &mut Registry| match r.handle(Request::ListPlacements) {
            Response::Placements(p) => {
                p.into_iter().find(|p| p.name == "robot_state").map(|p| p.generation)
            }
            other => panic!("{other:?}"),
        };
        let first = generation(&mut r);
        let again = TrajectorySpec::primitive("robot_state", "RobotState").replace();
        match r.handle(Request::CreateTrajectory { spec: again, host: "robot2".into() }) {
            Response::Trajectory(t) => {
                assert_eq!(t.writer.as_str(), "robot2");
                assert_ne!(Some(t.generation), first);
            }
            other => panic!("{other:?}"),
        }
        let repointed = generation(&mut r);
        let destroy = Request::DestroyEntityTrajectoryStructure { name: "robot_state".into() };
        ok(&mut r, destroy);
        assert_eq!(generation(&mut r), None, "gone");
        let create = TrajectorySpec::primitive("robot_state", "RobotState");
        ok(&mut r, Request::CreateTrajectory { spec: create, host: "robot2".into() });
        let recreated = generation(&mut r);
        assert!(recreated.is_some() && recreated != repointed && recreated != first);
    }

    #[test]
    fn seed_errors_come_back_typed() {
        let mut r = registry();
        let e = err(r.handle(Request::GetEntityTrajectoryStructure { name: "nope".into() }));
        assert_eq!(e.to_string(), "no entity trajectory structure `nope`");
        let e = err(r.handle(Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("x", "Imag"),
            host: "a".into(),
        }));
        assert!(matches!(e, ControlError::Create(CreateError::NoSuchEntityStructureType { .. })));
        assert_eq!(e.to_string(), "no entity structure type `Imag`; did you mean `Image`?");
        let e = err(r.handle(Request::RemoveSensorInterface { sensor: "cam".into() }));
        assert!(matches!(e, ControlError::Registration(RegistrationError::NoSuchSensor { .. })));
        let t = EntityStructureType::new("T").attr("x", ValueSort::Long);
        assert!(matches!(
            r.handle(Request::CreateEntityStructureType {
                type_name: "T".into(),
                entity_type: t.clone()
            }),
            Response::Done
        ));
        let e =
            err(r.handle(Request::CreateEntityStructureType {
                type_name: "T".into(),
                entity_type: t,
            }));
        assert!(matches!(
            e,
            ControlError::Type(TypeRegistryError::EntityStructureTypeAlreadyExists { .. })
        ));
    }

    #[test]
    fn messages_survive_the_wire() {
        let q = Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("r", "RobotState").policy(
                esgm_core::FluentStreamPolicy::reasonable(5, 10).unwrap().filter("x > 0.0"),
            ),
            host: "h".into(),
        };
        let bytes = super::super::protocol::encode(&q).unwrap();
        let back: Request = super::super::protocol::decode(&bytes).unwrap();
        let mut r = registry();
        assert!(matches!(r.handle(back), Response::Trajectory(_)));
        assert!(super::super::protocol::decode::<Request>(b"{not json").is_err());
    }

    #[test]
    fn names_are_bounded_before_any_lookup() {
        let mut r = registry();
        for bad in [String::new(), "a/b".to_owned(), "x".repeat(300)] {
            let e = err(r.handle(Request::GetEntityTrajectoryStructure { name: bad.clone() }));
            assert!(matches!(e, ControlError::IllegalName { .. }), "{bad:?}: {e:?}");
            let e = err(r.handle(Request::CreateTrajectory {
                spec: TrajectorySpec::primitive(bad.clone(), "RobotState"),
                host: "h".into(),
            }));
            assert!(matches!(e, ControlError::IllegalName { .. }), "{bad:?}: {e:?}");
        }
        // The issue's probe: a 4 MiB unknown name is refused before the "did you mean"
        // search, so its cost does not depend on the name's length.
        let huge = "q".repeat(4 << 20);
        let e = err(r.handle(Request::GetEntityStructureType { type_name: huge }));
        assert!(matches!(e, ControlError::IllegalName { .. }), "{e:?}");
        assert!(r.catalog().trajectories().next().is_none());
    }

    /// The pid of a process that has exited (a child reaped here): a writer gone.
    fn dead_pid() -> u32 {
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        pid
    }

    fn writer_of(r: &mut Registry, name: &str) -> (String, u64, Option<WriterPort>) {
        match r.handle(Request::GetEntityTrajectoryStructure { name: name.into() }) {
            Response::Trajectory(t) => (t.writer, t.generation, t.port),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_trajectory_is_taken_over_only_once_its_writer_is_gone() {
        use super::super::processes::ProcessSpec;
        let mut r = registry();
        let create = |name: &str, host: &str| Request::CreateTrajectory {
            spec: TrajectorySpec::primitive(name, "RobotState"),
            host: host.into(),
        };
        assert!(matches!(r.handle(create("live", "a")), Response::Trajectory(_)));
        assert!(matches!(r.handle(create("dead", "b")), Response::Trajectory(_)));
        assert!(matches!(r.handle(create("freed", "c")), Response::Trajectory(_)));
        assert!(matches!(r.handle(create("kept", "cam")), Response::Trajectory(_)));
        let report = |name: &str, generation, pid| {
            (Request::ReportWriter { trajectory: name.into(), generation, publisher: 9 }, pid)
        };
        let me = std::process::id();
        let dead = dead_pid();
        for (name, pid) in [("live", me), ("dead", dead), ("freed", me), ("kept", dead)] {
            let (_, generation, _) = writer_of(&mut r, name);
            let (q, pid) = report(name, generation, pid);
            assert!(matches!(r.handle_from(q, Origin::Process(pid)), Response::Done));
        }
        let take = |r: &mut Registry, name: &str| {
            let (_, generation, _) = writer_of(r, name);
            r.handle(Request::TakeOverTrajectory {
                trajectory: name.into(),
                generation,
                host: "taker".into(),
            })
        };
        // A live writer keeps it: the answer names it.
        let Response::Trajectory(t) = take(&mut r, "live") else { panic!() };
        assert_eq!((t.writer.as_str(), t.port.map(|p| p.pid)), ("a", Some(me)));
        // A writer whose process exited gives it up; the new writer reports its port.
        let Response::Trajectory(t) = take(&mut r, "dead") else { panic!() };
        assert_eq!((t.writer.as_str(), t.port), ("taker", None));
        // A writer that released it gives it up while its process lives; only the
        // port's holder may release it, and only its generation.
        let (_, generation, _) = writer_of(&mut r, "freed");
        let release =
            |generation| Request::ReleaseWriter { trajectory: "freed".into(), generation };
        let e = err(r.handle_from(release(generation), Origin::Process(dead)));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        let e = err(r.handle_from(release(generation + 1), Origin::Process(me)));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        assert!(matches!(r.handle_from(release(generation), Origin::Process(me)), Response::Done));
        let Response::Trajectory(t) = take(&mut r, "freed") else { panic!() };
        assert_eq!(t.writer, "taker");
        // A supervised writer comes back and takes its trajectory back: refused.
        let spec =
            ProcessSpec { name: "cam".into(), program: "x".into(), args: vec![], env: vec![] };
        assert!(matches!(r.handle(Request::DeclareProcess { spec }), Response::Done));
        let e = err(take(&mut r, "kept"));
        assert!(
            matches!(&e, ControlError::NotAllowed { reason: Refusal::Supervised { .. } }),
            "{e:?}"
        );
        // A sampled trajectory lives where its sensor is.
        assert!(matches!(
            r.handle(Request::AddSensorInterface {
                sensor: "odo".into(),
                type_name: "RobotState".into(),
                host: "b".into(),
            }),
            Response::Done
        ));
        let sampled = TrajectorySpec::sampled("odom", "odo", 10).unwrap();
        assert!(matches!(
            r.handle(Request::CreateTrajectory { spec: sampled, host: "b".into() }),
            Response::Trajectory(_)
        ));
        let e = err(take(&mut r, "odom"));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        // A former generation is answered with the current record, unchanged.
        let stale = r.handle(Request::TakeOverTrajectory {
            trajectory: "live".into(),
            generation: 999,
            host: "taker".into(),
        });
        let Response::Trajectory(t) = stale else { panic!("{stale:?}") };
        assert_eq!(t.writer, "a");
    }

    #[test]
    fn a_process_cannot_rewrite_another_ones_record() {
        use super::super::processes::{ProcessSpec, ProcessStatus};
        let mut r = registry();
        let spec =
            ProcessSpec { name: "cam".into(), program: "esgm".into(), args: vec![], env: vec![] };
        assert!(matches!(r.handle(Request::DeclareProcess { spec }), Response::Done));
        let report = |pid| Request::ReportProcess {
            name: "cam".into(),
            status: ProcessStatus { pid: Some(pid), restarts: 0, last_exit: None },
        };
        // The supervisor (the coordinator's own process) may.
        assert!(matches!(r.handle(report(4242)), Response::Done));
        // Another process may not set someone's pid (to 1, say)...
        let e = err(r.handle_from(report(1), Origin::Process(777)));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        let e = err(r.handle_from(report(1), Origin::Unknown));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        assert_eq!(r.process_pid("cam"), Some(4242));
        // ...but a process may report itself.
        assert!(matches!(r.handle_from(report(777), Origin::Process(777)), Response::Done));
        assert_eq!(r.process_pid("cam"), Some(777));
    }

    #[test]
    fn the_writer_port_is_named_by_its_live_holder_alone() {
        let mut r = registry();
        let created = r.handle(Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("robot", "RobotState"),
            host: "robot".into(),
        });
        let Response::Trajectory(t) = created else { panic!("{created:?}") };
        assert_eq!(t.port, None, "nobody has reported yet");
        let report = |generation, publisher| Request::ReportWriter {
            trajectory: "robot".into(),
            generation,
            publisher,
        };
        let me = std::process::id();
        let port = |r: &mut Registry| match r
            .handle(Request::GetEntityTrajectoryStructure { name: "robot".into() })
        {
            Response::Trajectory(t) => t.port,
            other => panic!("{other:?}"),
        };
        // iceoryx2's ids use all 128 bits, and cross the wire whole.
        let wire = super::super::protocol::encode(&report(3, u128::MAX)).unwrap();
        let back: Request = super::super::protocol::decode(&wire).unwrap();
        assert!(matches!(back, Request::ReportWriter { publisher: u128::MAX, .. }), "{back:?}");
        // Nobody the coordinator cannot identify, and no former generation.
        let e = err(r.handle_from(report(t.generation, 7), Origin::Unknown));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        let e = err(r.handle_from(report(t.generation + 1, 7), Origin::Process(me)));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        assert!(matches!(
            r.handle_from(report(t.generation, 7), Origin::Process(me)),
            Response::Done
        ));
        assert_eq!(port(&mut r), Some(WriterPort { publisher: 7, pid: me }));
        // The holder (this process, alive) may name another port; another process may
        // not take it over while the holder lives...
        assert!(matches!(
            r.handle_from(report(t.generation, 8), Origin::Process(me)),
            Response::Done
        ));
        let e = err(r.handle_from(report(t.generation, 9), Origin::Process(1)));
        assert!(matches!(e, ControlError::NotAllowed { .. }), "{e:?}");
        assert_eq!(port(&mut r), Some(WriterPort { publisher: 8, pid: me }));
        // ...but once the holder is gone (a crash, a restart), the next one may.
        let dead = u32::MAX - 1;
        let mut r2 = registry();
        r2.handle(Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("robot", "RobotState"),
            host: "robot".into(),
        });
        assert!(matches!(r2.handle_from(report(0, 5), Origin::Process(dead)), Response::Done));
        assert!(matches!(r2.handle_from(report(0, 6), Origin::Process(me)), Response::Done));
        assert_eq!(port(&mut r2), Some(WriterPort { publisher: 6, pid: me }));
        // A recovered coordinator still knows it.
        let restored = Registry::restore(TypeRegistry::with_library(), r2.snapshot());
        assert_eq!(port(&mut restored.unwrap()), Some(WriterPort { publisher: 6, pid: me }));
    }

    /// Found by esgm-fuzz: states the registry allows must come back from its saved
    /// state, or a coordinator restarted after a crash would not start.
    #[test]
    fn redefined_and_destroyed_types_and_their_users_are_restored_as_they_were() {
        let mut r = registry();
        let twist = EntityStructureType::new("Twist").attr("spin", ValueSort::Long);
        let t = EntityStructureType::new("T").attr("x", ValueSort::Long);
        let ok = |resp: Response| assert!(matches!(resp, Response::Done), "{resp:?}");
        // A library type destroyed and defined anew; another destroyed for good.
        ok(r.handle(Request::DestroyEntityStructureType { type_name: "Twist".into() }));
        ok(r.handle(Request::CreateEntityStructureType {
            type_name: "Twist".into(),
            entity_type: twist.clone(),
        }));
        ok(r.handle(Request::DestroyEntityStructureType { type_name: "Blob".into() }));
        // A unit and a sensor whose type is destroyed after they were registered.
        ok(r.handle(Request::CreateEntityStructureType { type_name: "T".into(), entity_type: t }));
        ok(r.handle(Request::AddCompUnit {
            name: "u".into(),
            type_name: "T".into(),
            input_types: vec![],
            host: "h".into(),
        }));
        ok(r.handle(Request::AddSensorInterface {
            sensor: "s".into(),
            type_name: "T".into(),
            host: "h".into(),
        }));
        ok(r.handle(Request::DestroyEntityStructureType { type_name: "T".into() }));

        let json = serde_json::to_vec(&r.snapshot()).unwrap();
        let back = serde_json::from_slice(&json).unwrap();
        let restored = Registry::restore(TypeRegistry::with_library(), back).unwrap();
        let types = restored.catalog().types();
        assert_eq!(*types.get_entity_structure_type("Twist").unwrap(), twist);
        assert!(types.get_entity_structure_type("Blob").is_err(), "stays destroyed");
        assert!(types.get_entity_structure_type("T").is_err());
        assert!(restored.catalog().unit("u").is_some());
        assert!(restored.catalog().sensor("s").is_some());
        assert_eq!(restored.snapshot().types, r.snapshot().types);
    }

    #[test]
    fn a_restored_registry_answers_as_the_saved_one() {
        let mut r = registry();
        let t = EntityStructureType::new("Pose2").attr("x", ValueSort::Double);
        let outer = EntityStructureType::new("Tracked").frame("pose", "Pose2");
        for (n, t) in [("Pose2", t), ("Tracked", outer)] {
            assert!(matches!(
                r.handle(Request::CreateEntityStructureType {
                    type_name: n.into(),
                    entity_type: t
                }),
                Response::Done
            ));
        }
        r.handle(Request::AddSensorInterface {
            sensor: "cam".into(),
            type_name: "Image".into(),
            host: "camera".into(),
        });
        let created = r.handle(Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("poses", "Pose2"),
            host: "robot".into(),
        });
        let Response::Trajectory(before) = created else { panic!("{created:?}") };
        let snapshot = r.snapshot();
        let json = serde_json::to_vec(&snapshot).unwrap();
        let back = serde_json::from_slice(&json).unwrap();
        let mut restored = Registry::restore(TypeRegistry::with_library(), back).unwrap();
        let Response::Trajectory(after) =
            restored.handle(Request::GetEntityTrajectoryStructure { name: "poses".into() })
        else {
            panic!("no trajectory after restore")
        };
        assert_eq!(before, after);
        assert!(restored.catalog().sensor("cam").is_some());
        assert!(restored.catalog().types().get_entity_structure_type("Tracked").is_ok());
        // The next generation continues, never reusing one.
        let Response::Trajectory(next) = restored.handle(Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("more", "Pose2"),
            host: "robot".into(),
        }) else {
            panic!("cannot create after restore")
        };
        assert!(next.generation > before.generation);
    }
}
