//! The location thread: the one thread of a process that owns its iceoryx2 ports (the
//! control client, and every export and import), as the seed's "location" is the
//! process-side end of the ESGM. API calls reach it as [`Command`]s.
//!
//! Everything that changes which trajectories this process writes or mirrors runs
//! here, one command at a time, so a create asked by a user and the same trajectory
//! assigned by the coordinator can never be built twice.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Select, Sender, TryRecvError};
use esgm_core::esgm::{CreateError, Esgm, LookupError, TrajectoryKind, TrajectorySpec};
use esgm_core::{EntityStructureType, InProcessEsgm, InProcessTrajectory};

use super::bridge::{Export, Import};
use super::waker::Waker;
use crate::control::protocol::{Assignment, ControlError, Request, Response, TrajectoryRecord};
use crate::control::{ControlClient, ControlClientError};
use crate::holdings::{HoldingStats, Holdings};
use crate::service::ShmNode;

/// How often publishers hand late readers their history.
pub(crate) const MAINTENANCE_PERIOD: Duration = Duration::from_millis(20);

/// How often a process that serves sensors or units asks the coordinator for the
/// trajectories it must write (creations it asks for itself are built at once). Every
/// serving process polls, so this bounds the coordinator's load.
pub(crate) const ASSIGNMENT_PERIOD: Duration = Duration::from_millis(200);

/// The longest the thread sleeps when nothing happens. Everything that needs it wakes
/// it at once — API commands, local store events, outboxes, released images, and
/// samples from other processes through the waker — so this only bounds the delay of
/// what cannot (a service the waker could not listen to, a notify sent before the
/// waker listened). It was 1 ms while imports were polled: an idle connected process
/// then woke a thousand times a second.
const MAX_IDLE: Duration = MAINTENANCE_PERIOD;

/// What the API asks the location thread.
pub(crate) enum Command {
    /// One control request, answered as is.
    Control(Box<Request>, Sender<Result<Response, ControlClientError>>),
    /// Create (or re-point) a trajectory and build it here or mirror it.
    Create(Box<TrajectorySpec>, Sender<Result<InProcessTrajectory, CreateError>>),
    /// A handle on a trajectory, mirrored here if another process writes it.
    Get(String, Sender<Result<InProcessTrajectory, LookupError>>),
    /// Destroy a trajectory everywhere.
    Destroy(String, Sender<Result<(), LookupError>>),
    /// This process now serves sensors or units: poll for assignments.
    Serving,
    /// What this process holds in shared memory for its values.
    Holdings(Sender<Option<HoldingStats>>),
}

/// The seed's lookup error if the coordinator gave one, else `Unavailable`.
pub(crate) fn lookup_error(e: ControlClientError) -> LookupError {
    match e {
        ControlClientError::Remote(ControlError::Lookup(e)) => e,
        e => LookupError::Unavailable { reason: e.to_string() },
    }
}

/// The record a `GetEntityTrajectoryStructure` call answered, or the seed's error.
pub(crate) fn trajectory_record(
    answer: Result<Response, ControlClientError>,
) -> Result<TrajectoryRecord, LookupError> {
    match answer.map_err(lookup_error)? {
        Response::Trajectory(r) => Ok(r),
        other => Err(LookupError::Unavailable { reason: format!("{other:?}") }),
    }
}

pub(crate) struct Location {
    pub domain: String,
    pub host: String,
    pub local: InProcessEsgm,
    pub node: ShmNode,
    pub control: ControlClient,
    pub exports: BTreeMap<String, Export>,
    pub imports: BTreeMap<String, Import>,
    /// Received samples whose images values in this process still read in place.
    pub holdings: Holdings,
    /// Assignments that failed to build (reported once each).
    pub failed: BTreeSet<String>,
    pub serving: bool,
    /// Pokes this thread when a service it reads from another process is notified.
    pub waker: Waker,
}

impl Location {
    /// Serves commands and pumps bridges until the API side is gone.
    pub fn run(mut self, commands: &Receiver<Command>) {
        let mut idle = Duration::from_micros(20);
        let mut next_maintenance = Instant::now();
        let mut next_assignments = Instant::now();
        loop {
            let mut work = 0;
            // A poke only ends a sleep: the imports are read below whatever it said.
            while self.waker.pokes.try_recv().is_ok() {}
            loop {
                match commands.try_recv() {
                    Ok(c) => {
                        self.handle(c);
                        work += 1;
                    }
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => return self.close(),
                }
            }
            for e in self.exports.values_mut() {
                work += e.pump();
            }
            work += self.holdings.collect();
            for i in self.imports.values_mut() {
                work += i.pump(&self.node, &mut self.holdings);
            }
            if Instant::now() >= next_maintenance {
                self.maintain();
                next_maintenance = Instant::now() + MAINTENANCE_PERIOD;
            }
            if self.serving && Instant::now() >= next_assignments {
                self.poll_assignments();
                next_assignments = Instant::now() + ASSIGNMENT_PERIOD;
            }
            if work > 0 {
                idle = Duration::from_micros(20);
                continue;
            }
            // Wake at once for a command, a local event, a released image or a poke from
            // the waker (a service read from another process was notified); polling
            // with the idle backoff remains the fallback.
            let mut sel = Select::new();
            sel.recv(commands);
            sel.recv(&self.waker.pokes);
            for e in self.exports.values() {
                sel.recv(&e.events);
            }
            for outbox in self.imports.values().filter_map(|i| i.outbox.as_ref()) {
                sel.recv(outbox);
            }
            sel.recv(self.holdings.releases());
            // Not past the next periodic duty.
            let mut due = next_maintenance;
            if self.serving {
                due = due.min(next_assignments);
            }
            let _ = sel.ready_timeout(idle.min(due.saturating_duration_since(Instant::now())));
            idle = (idle * 2).min(MAX_IDLE);
        }
    }

    /// Shuts the location down when its API side is gone.
    ///
    /// Values may still read images in samples this location received (a user kept one
    /// past the connection). Those samples must stay borrowed: iceoryx2 gives a
    /// publisher back every chunk a subscriber held as soon as the subscriber's port,
    /// or its node, is gone, and the publisher would then write new images over bytes
    /// the values read. So then the subscribers and the node are kept, not dropped,
    /// until the process exits (the coordinator's dead-node cleanup reclaims them
    /// after that). Their queues cost nothing meanwhile: readers overwrite, they never
    /// hold a writer back.
    fn close(self) {
        let Location { node, imports, mut holdings, .. } = self;
        holdings.collect();
        let held = holdings.stats().held_now;
        if held > 0 {
            tracing::debug!(held, "values still read received images; their subscribers stay");
            std::mem::forget(imports);
            std::mem::forget(node);
        }
    }

    /// Tells the waker every service this location reads from other processes: each
    /// import's samples and violations, each primitive export's inbox.
    fn rewatch(&self) {
        let names = self
            .imports
            .values()
            .flat_map(Import::wake_services)
            .chain(self.exports.values().flat_map(Export::wake_services))
            .collect();
        self.waker.watch(names);
    }

    fn handle(&mut self, command: Command) {
        match command {
            Command::Control(request, reply) => {
                let request = *request;
                let _ = reply.send(self.control.call(&request));
            }
            Command::Create(spec, reply) => {
                let _ = reply.send(self.create(&spec));
            }
            Command::Get(name, reply) => {
                let _ = reply.send(self.get(&name));
            }
            Command::Destroy(name, reply) => {
                let _ = reply.send(self.destroy(&name));
            }
            Command::Serving => {
                self.serving = true;
                self.poll_assignments();
            }
            Command::Holdings(reply) => {
                self.holdings.collect();
                let _ = reply.send(Some(self.holdings.stats()));
            }
        }
    }

    fn maintain(&mut self) {
        for e in self.exports.values() {
            // Readers that connected since the last send receive the history now,
            // not only at the next sample.
            let _ = e.publisher.update_connections();
        }
    }

    fn create(&mut self, spec: &TrajectorySpec) -> Result<InProcessTrajectory, CreateError> {
        let request = Request::CreateTrajectory { spec: spec.clone(), host: self.host.clone() };
        let record = match self.control.call(&request) {
            Ok(Response::Trajectory(r)) => r,
            Ok(other) => return Err(unexpected(&other)),
            Err(ControlClientError::Remote(ControlError::Create(e))) => return Err(e),
            Err(e) => return Err(CreateError::Unavailable { reason: e.to_string() }),
        };
        if record.writer == self.host {
            self.build(spec, &record, true)
        } else {
            self.replica(&record)
        }
    }

    /// Builds a trajectory this process writes: its inputs available here, the local
    /// runtime runs its policy and worker, an export publishes it.
    fn build(
        &mut self,
        spec: &TrajectorySpec,
        record: &TrajectoryRecord,
        undo_on_failure: bool,
    ) -> Result<InProcessTrajectory, CreateError> {
        let built = self.build_inner(spec, record);
        if built.is_err() && undo_on_failure && !spec.replace {
            let _ = self
                .control
                .call(&Request::DestroyEntityTrajectoryStructure { name: spec.name.clone() });
        }
        built
    }

    fn build_inner(
        &mut self,
        spec: &TrajectorySpec,
        record: &TrajectoryRecord,
    ) -> Result<InProcessTrajectory, CreateError> {
        install(&self.local, &record.types);
        for input in spec.inputs() {
            self.ensure_available(&input)?;
        }
        let handle = self.local.create_trajectory(spec.clone())?;
        // Re-pointed here (E5): the export follows the new trajectory, and readers
        // elsewhere forget the old stream (a reset marker) before the new one's history.
        let repointed = spec.replace && self.exports.remove(&spec.name).is_some();
        if !self.exports.contains_key(&spec.name) {
            let export = Export::start(
                &self.node,
                &self.domain,
                &handle,
                &record.info.type_name,
                &record.info.policy,
                record.info.kind == TrajectoryKind::Primitive,
                repointed,
            )
            .map_err(|e| CreateError::Unavailable { reason: e.to_string() })?;
            self.exports.insert(spec.name.clone(), export);
            self.rewatch();
        }
        Ok(handle)
    }

    /// Makes `name` readable here: local already, or mirrored from its writer.
    fn ensure_available(&mut self, name: &str) -> Result<(), CreateError> {
        if self.local.get_entity_trajectory_structure(name).is_ok() {
            return Ok(());
        }
        let record = self.record(name).map_err(|e| match e {
            LookupError::NoSuchEntityStructure { name, suggestion } => {
                CreateError::NoSuchEntityStructure { name, suggestion }
            }
            other => CreateError::Unavailable { reason: other.to_string() },
        })?;
        if record.writer == self.host {
            // Assigned here but not built yet (its creator asked another process).
            self.poll_assignments();
            return match self.local.get_entity_trajectory_structure(name) {
                Ok(_) => Ok(()),
                Err(e) => Err(CreateError::Unavailable { reason: e.to_string() }),
            };
        }
        self.replica(&record).map(|_| ())
    }

    /// Mirrors a trajectory another process writes.
    fn replica(&mut self, record: &TrajectoryRecord) -> Result<InProcessTrajectory, CreateError> {
        let name = &record.info.name;
        if let Ok(h) = self.local.get_entity_trajectory_structure(name) {
            return Ok(h);
        }
        let handle = self.local.create_replica(record.info.clone(), &record.types)?;
        match Import::start(
            &self.node,
            &self.domain,
            handle.clone(),
            &record.info.type_name,
            &record.info.policy,
            record.info.kind == TrajectoryKind::Primitive,
            &mut self.holdings,
        ) {
            Ok(import) => {
                self.imports.insert(name.clone(), import);
                self.rewatch();
                Ok(handle)
            }
            Err(e) => {
                let _ = self.local.destroy_entity_trajectory_structure(name);
                Err(CreateError::Unavailable { reason: e.to_string() })
            }
        }
    }

    fn record(&mut self, name: &str) -> Result<TrajectoryRecord, LookupError> {
        trajectory_record(
            self.control.call(&Request::GetEntityTrajectoryStructure { name: name.to_owned() }),
        )
    }

    fn get(&mut self, name: &str) -> Result<InProcessTrajectory, LookupError> {
        if let Ok(h) = self.local.get_entity_trajectory_structure(name) {
            return Ok(h);
        }
        let record = self.record(name)?;
        if record.writer == self.host {
            self.poll_assignments();
            return self.local.get_entity_trajectory_structure(name);
        }
        self.replica(&record).map_err(|e| LookupError::Unavailable { reason: e.to_string() })
    }

    fn destroy(&mut self, name: &str) -> Result<(), LookupError> {
        let request = Request::DestroyEntityTrajectoryStructure { name: name.to_owned() };
        self.control.call(&request).map_err(lookup_error)?;
        self.exports.remove(name);
        self.imports.remove(name);
        self.rewatch();
        let _ = self.local.destroy_entity_trajectory_structure(name);
        self.failed.remove(name);
        Ok(())
    }

    /// Builds the trajectories the coordinator placed here that are not built yet
    /// (sampled on this process's sensors, computed by its units, created by others).
    fn poll_assignments(&mut self) {
        let list = match self.control.call(&Request::Assignments { host: self.host.clone() }) {
            Ok(Response::Assignments(list)) => list,
            Ok(_) => return,
            Err(e) => {
                tracing::debug!(error = %e, "cannot ask for assignments");
                return;
            }
        };
        for Assignment { spec, record } in list {
            if self.exports.contains_key(&spec.name) || self.failed.contains(&spec.name) {
                continue;
            }
            match self.build(&spec, &record, false) {
                Ok(_) => tracing::info!(trajectory = %spec.name, "writing trajectory"),
                // A transient failure (the coordinator slow to answer under load) is
                // retried at the next poll; anything else would fail again.
                Err(e @ CreateError::Unavailable { .. }) => {
                    tracing::info!(trajectory = %spec.name, error = %e,
                        "cannot build an assigned trajectory yet; retrying");
                }
                Err(e) => {
                    tracing::warn!(trajectory = %spec.name, error = %e,
                        "cannot build an assigned trajectory");
                    self.failed.insert(spec.name.clone());
                }
            }
        }
    }
}

/// Registers `types` in the local runtime where missing (names defined elsewhere).
pub(crate) fn install(local: &InProcessEsgm, types: &[(String, EntityStructureType)]) {
    for (name, t) in types {
        if local.get_entity_structure_type(name).is_err() {
            let _ = local.create_entity_structure_type(name, t.clone());
        }
    }
}

fn unexpected(r: &Response) -> CreateError {
    CreateError::Unavailable { reason: format!("unexpected answer from the coordinator: {r:?}") }
}
