//! The location thread: the control plane of a connection, as the seed's "location"
//! is the process-side end of the ESGM. API calls that change which trajectories this
//! process writes or mirrors reach it as [`Command`]s and run here, one at a time, so a
//! create asked by a user and the same trajectory assigned by the coordinator can
//! never be built twice. It also polls for assignments and hands late readers their
//! history.
//!
//! No sample goes through this thread: writers publish inline ([`super::export`]) and
//! the receiver thread feeds replicas ([`super::receiver`]).

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender};
use esgm_core::esgm::{
    CreateError, Esgm, LookupError, Peer, TrajectoryKind, TrajectorySpec, Unreachable,
};
use esgm_core::{AddError, EntityStructureType, InProcessEsgm, InProcessTrajectory};

use super::export::{Export, ExportStart};
use super::import::{Import, ImportSite};
use super::mirrors::SharedMirrors;
use super::receiver::Receiver as SampleReceiver;
use super::shared_node::SharedNode;
use super::takeover::TakeOverAsk;
use crate::client::holdings::{HoldingStats, Holdings};
use crate::control::protocol::{Assignment, ControlError, Request, Response, TrajectoryRecord};
use crate::control::{ControlClient, ControlClientError};
use crate::data_plane::service::OpenError;

/// How often the location thread looks after what it holds, in one wake-up: it
/// hands readers that connected without ringing (a bridge's or a recorder's own
/// subscriber) their history, drops what the registry no longer names as it was
/// built (when the registry's version changed), and reports its image counters. Each
/// wake-up of this thread costs about 65 µs on this machine: four a second in each of
/// a robot's 100 processes would be 2.6 % of a core, over the whole domain's idle
/// budget of 1 %.
pub(crate) const TICK: Duration = Duration::from_secs(2);

/// How soon a connection asks again who writes a trajectory it began to read before
/// the writer had named its port (the step doubles from there, up to [`TICK`]).
const FIRST_NAMING_ASK: Duration = Duration::from_millis(5);

/// How often a process tells the coordinator its image counters (if they changed).
pub(crate) const HOLDINGS_REPORT_PERIOD: Duration = Duration::from_secs(1);

/// How often a process that serves sensors or units asks the coordinator for the
/// trajectories it must write (creations it asks for itself are built at once), when
/// the registry's version changed. Every serving process looks, so this bounds the
/// coordinator's load.
pub(crate) const ASSIGNMENT_PERIOD: Duration = Duration::from_millis(500);

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
    /// Test support: the location thread panics.
    #[cfg(feature = "test-seams")]
    Panic,
}

/// Sends the answer to a `what` command. The caller stops waiting at its deadline and
/// says so itself; an answer later than that has nobody to go to, which is logged.
fn answer<T>(reply: &Sender<T>, what: &str, value: T) {
    if reply.send(value).is_err() {
        tracing::debug!(command = what, "the caller stopped waiting; its answer is dropped");
    }
}

/// The seed's lookup error if the coordinator gave one, else `Unavailable`.
pub(crate) fn lookup_error(e: ControlClientError) -> LookupError {
    match e {
        ControlClientError::Remote(ControlError::Lookup(e)) => e,
        e => LookupError::Unavailable { reason: e.into() },
    }
}

/// The record a `GetEntityTrajectoryStructure` call answered, or the seed's error.
pub(crate) fn trajectory_record(
    answer: Result<Response, ControlClientError>,
) -> Result<TrajectoryRecord, LookupError> {
    match answer.map_err(lookup_error)? {
        Response::Trajectory(r) => Ok(*r),
        other => Err(LookupError::Unavailable {
            reason: Unreachable::malformed(Peer::Coordinator, format!("{other:?}")),
        }),
    }
}

/// What the location thread last looked at ([`Location::looked`]).
#[derive(Debug, Default)]
pub(crate) struct Looked {
    audit: Option<(u64, u64)>,
    assignments: Option<u64>,
    /// The registry's versions as the coordinator announces them in shared memory
    /// (`None`: not subscribed; the coordinator is asked instead), and the last one.
    pub versions: Option<iceoryx2::port::subscriber::Subscriber<crate::ShmService, u64, ()>>,
    announced: Option<u64>,
    /// True while [`Location::poll_assignments`] builds: an assignment's input that is
    /// itself assigned here is built by the same poll, never by a nested one.
    building_assignments: bool,
}

impl Looked {
    /// What `node` subscribes to for the versions of `domain`'s registry (`None`, and
    /// a debug line, where it cannot: the coordinator is then asked).
    pub fn subscribe(node: &crate::ShmNode, domain: &str) -> Self {
        let limits = crate::data_plane::capacity::DomainLimits::default();
        let versions = crate::control::server::open_version_service(node, domain, &limits)
            .and_then(|s| s.subscriber_builder().create().map_err(|e| format!("{e:?}")))
            .map_err(|e| tracing::debug!(error = %e, "the registry's versions are asked for"))
            .ok();
        Self { versions, ..Self::default() }
    }
}

pub(crate) struct Location {
    pub domain: String,
    pub host: String,
    pub local: InProcessEsgm,
    pub node: SharedNode,
    pub control: ControlClient,
    pub mirrors: Arc<SharedMirrors>,
    pub holdings: Arc<Holdings>,
    /// Assignments that failed to build (reported once each).
    pub failed: BTreeSet<String>,
    pub serving: bool,
    /// The holdings last reported to the coordinator, and when to report next.
    pub reported: (HoldingStats, Instant),
    /// Where resets through this process's handles go (every process holding the
    /// trajectory; see `admin`): installed on every export and replica.
    pub resets: Arc<dyn esgm_core::ResetForwarder>,
    /// An import that holds samples from a port the registry has not named rings
    /// this (its sender), and the location asks the registry at once
    /// ([`Location::verify_writers`]) rather than at its next maintenance tick: the
    /// samples held meanwhile borrow shared memory.
    pub verify: (Sender<()>, Receiver<()>),
    /// When to ask again who writes the imports made before their writer named its
    /// port (a reader that came while the writer was still creating the trajectory),
    /// and the step to the next ask: soon, then less often, up to [`TICK`], until every
    /// import's writer is named. Without it their first samples would be held for a
    /// question asked only when they arrive. `None` while every writer is named.
    pub unnamed: Option<(Instant, Duration)>,
    /// Adders of replicas whose writer is gone ask here to take them over
    /// ([`super::takeover`]).
    pub takeovers: (Sender<TakeOverAsk>, Receiver<TakeOverAsk>),
    /// A short-lived tool's connection ([`crate::ShmEsgmBuilder::tool`]).
    pub tool: bool,
    /// The registry's version and this process's mirrors' generation at the last
    /// audit, and the registry's version at the last look for assignments: an idle
    /// domain costs each process one ping per period, whatever its size.
    pub looked: Looked,
    /// Stopped and joined when the location ends.
    pub _receiver: SampleReceiver,
}

impl Location {
    /// Serves commands until the API side is gone.
    pub fn run(mut self, commands: &Receiver<Command>) {
        let mut next_tick = Instant::now();
        let mut next_assignments = Instant::now();
        loop {
            let mut due = next_tick;
            if self.serving {
                due = due.min(next_assignments);
            }
            if let Some((ask, _)) = self.unnamed {
                due = due.min(ask);
            }
            let timeout = due.saturating_duration_since(Instant::now());
            let verify = self.verify.1.clone();
            let takeovers = self.takeovers.1.clone();
            crossbeam_channel::select! {
                recv(commands) -> c => match c {
                    Ok(c) => self.handle(c),
                    // Every sender is gone: the connection is closing.
                    Err(_) => {
                        // The last word on this process's images, for whoever looks later.
                        self.reported.1 = Instant::now();
                        self.report_holdings();
                        self.release_primitives();
                        return;
                    }
                },
                recv(verify) -> _ => self.verify_writers(),
                recv(takeovers) -> ask => {
                    if let Ok(ask) = ask {
                        let outcome = self.take_over(&ask.trajectory, ask.generation);
                        // The adder may have stopped waiting.
                        let _gone = ask.reply.send(outcome);
                    }
                }
                default(timeout) => {}
            }
            if self.unnamed.is_some_and(|(ask, _)| Instant::now() >= ask) {
                self.name_writers();
            }
            if self.serving && Instant::now() >= next_assignments {
                self.poll_assignments();
                next_assignments = Instant::now() + ASSIGNMENT_PERIOD;
            }
            if Instant::now() >= next_tick {
                self.maintain();
                self.audit();
                next_tick = Instant::now() + TICK;
            }
        }
    }

    /// Drops what this process mirrors of trajectories that no longer are what it
    /// built them for: destroyed by another process, created anew (another
    /// generation) or now written elsewhere. A re-pointed name keeps its replica (its
    /// readers receive a reset in the stream and move over, E5), as long as its type
    /// is the same.
    fn audit(&mut self) {
        let names: Vec<String> = {
            let mirrors = self.mirrors.lock();
            mirrors.exports.keys().chain(mirrors.imports.keys()).cloned().collect()
        };
        if names.is_empty() {
            return;
        }
        let looking = self.registry_version().map(|v| (v, self.mirrors.generation()));
        if looking.is_some() && looking == self.looked.audit {
            return;
        }
        let placements = match self.control.call(&Request::ListPlacementsOf { names }) {
            Ok(Response::Placements(p)) => p,
            Ok(other) => {
                tracing::warn!(answer = ?other, "unexpected answer to a placement listing");
                return;
            }
            // The coordinator is slow or gone: nothing is known to be stale.
            Err(e) => {
                tracing::debug!(error = %e, "cannot list placements");
                return;
            }
        };
        let now: std::collections::BTreeMap<_, _> =
            placements.iter().map(|p| (p.name.as_str(), p)).collect();
        let (stale, moved, unreported) = {
            let (mut stale, mut moved, mut unreported) = (Vec::new(), Vec::new(), Vec::new());
            for (name, e) in &self.mirrors.exports() {
                let e = e.lock();
                let current = now.get(name.as_str());
                if current.is_none_or(|p| p.generation != e.generation || p.writer != self.host) {
                    stale.push(name.clone());
                } else if current.and_then(|p| p.port).map(|w| w.publisher) != Some(e.publisher()) {
                    // A recovered coordinator that lost it, or a report that failed.
                    unreported.push((name.clone(), e.generation, e.publisher()));
                }
            }
            for (name, i) in &self.mirrors.imports() {
                let mut i = i.lock();
                match now.get(name.as_str()) {
                    Some(p) if p.generation == i.generation => {
                        i.set_writer(p.port);
                        i.set_released(p.released);
                    }
                    Some(p) if p.type_name == i.type_name && p.writer != self.host => {
                        moved.push(name.clone());
                    }
                    _ => stale.push(name.clone()),
                }
            }
            (stale, moved, unreported)
        };
        // Settled only if nothing needed doing: what this audit changes is looked at
        // again next time.
        if stale.is_empty() && moved.is_empty() && unreported.is_empty() {
            self.looked.audit = looking;
        }
        for (name, generation, publisher) in unreported {
            self.report_writer(&name, generation, publisher);
        }
        for name in &moved {
            self.reimport(name);
        }
        for name in &stale {
            tracing::info!(trajectory = %name, "destroyed or created anew elsewhere; dropped here");
            self.forget(name);
        }
        if self.serving && stale.iter().any(|n| now.contains_key(n.as_str())) {
            self.poll_assignments();
        }
    }

    /// Follows a name re-pointed elsewhere (E5): the replica stays, with its handles
    /// and subscribers; it forgets the former stream and imports the new trajectory's
    /// services (each generation has its own).
    fn reimport(&mut self, name: &str) {
        let record = match self.record(name) {
            Ok(r) => r,
            Err(e) => {
                tracing::debug!(trajectory = %name, error = %e, "cannot follow a re-pointed name");
                return;
            }
        };
        let Ok(replica) = self.local.get_entity_trajectory_structure(name) else {
            return self.forget(name);
        };
        let site = ImportSite {
            node: &self.node,
            domain: &self.domain,
            holdings: &self.holdings,
            mirrors: &self.mirrors,
            verify: &self.verify.0,
            take_over: &self.takeovers.0,
            tool: self.tool,
        };
        match Import::start(&site, replica.clone(), &record) {
            Ok(mut import) => {
                // The former stream's end: readers forget it, as the writer's did.
                let _destroyed = replica.with_store(|s| s.reset());
                import.pump();
                self.watch_unnamed(&import);
                self.mirrors.change(|m| m.insert_import(name.to_owned(), import));
                tracing::info!(trajectory = %name, generation = record.generation,
                    "following a re-pointed trajectory");
            }
            Err(e) => {
                tracing::warn!(trajectory = %name, error = %e,
                    "cannot import a re-pointed trajectory; dropped here");
                self.forget(name);
            }
        }
    }

    /// Removes every trace of `name` from this process: its export or import and its
    /// local trajectory. Values that still read its images own their samples.
    fn forget(&mut self, name: &str) {
        // What is forgotten here may be assigned here again (a name re-pointed): the
        // next look for assignments asks, whatever the registry's version.
        self.looked.assignments = None;
        let (export, import) =
            self.mirrors.change(|m| (m.exports.remove(name), m.imports.remove(name)));
        drop((export, import));
        if let Err(e) = self.local.destroy_entity_trajectory_structure(name) {
            tracing::debug!(trajectory = %name, error = %e, "no local trajectory to destroy");
        }
        self.failed.remove(name);
    }

    fn handle(&mut self, command: Command) {
        match command {
            Command::Control(request, reply) => {
                let request = *request;
                answer(&reply, "control", self.control.call(&request));
            }
            Command::Create(spec, reply) => {
                answer(&reply, "create", self.create(&spec));
            }
            Command::Get(name, reply) => {
                answer(&reply, "get", self.get(&name));
            }
            Command::Destroy(name, reply) => {
                answer(&reply, "destroy", self.destroy(&name));
            }
            #[cfg(feature = "test-seams")]
            Command::Panic => {
                #[allow(clippy::panic, reason = "test support: a panic asked for")]
                {
                    panic!("esgm-location: panic injected by a test");
                }
            }
            Command::Serving => {
                self.serving = true;
                self.poll_assignments();
            }
        }
    }

    fn maintain(&mut self) {
        for (_, e) in self.mirrors.exports() {
            e.lock().update_connections();
        }
        self.verify_writers();
        self.report_holdings();
    }

    /// Tells the coordinator this process's image counters, about once a second while
    /// they change (`esgm demo` and `esgm stats` show them).
    fn report_holdings(&mut self) {
        let now = Instant::now();
        if now < self.reported.1 {
            return;
        }
        self.reported.1 = now + HOLDINGS_REPORT_PERIOD;
        let stats = self.holdings.stats();
        if stats == self.reported.0 {
            return;
        }
        let request = Request::ReportHoldings { host: self.host.clone(), stats };
        match self.control.call(&request) {
            Ok(_) => self.reported.0 = stats,
            Err(e) => tracing::debug!(error = %e, "cannot report holdings"),
        }
    }

    fn exports(&self, name: &str) -> bool {
        self.mirrors.lock().exports.contains_key(name)
    }

    fn create(&mut self, spec: &TrajectorySpec) -> Result<InProcessTrajectory, CreateError> {
        let request = Request::CreateTrajectory { spec: spec.clone(), host: self.host.clone() };
        let record = match self.control.call(&request) {
            Ok(Response::Trajectory(r)) => *r,
            Ok(other) => return Err(unexpected(&other)),
            Err(ControlClientError::Remote(ControlError::Create(e))) => return Err(e),
            Err(e) => return Err(CreateError::Unavailable { reason: e.into() }),
        };
        if !spec.replace {
            // The registry had no such name: what this process still holds under it
            // is a former trajectory destroyed elsewhere, not yet audited away.
            self.forget(&spec.name);
        }
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
            // The registry still lists a trajectory nobody writes: say so if it stays.
            let undo = self
                .control
                .call(&Request::DestroyEntityTrajectoryStructure { name: spec.name.clone() });
            if let Err(e) = undo {
                tracing::warn!(trajectory = %spec.name, error = %e,
                    "a trajectory that could not be built stays registered; destroy it by hand");
            }
        }
        built
    }

    fn build_inner(
        &mut self,
        spec: &TrajectorySpec,
        record: &TrajectoryRecord,
    ) -> Result<InProcessTrajectory, CreateError> {
        install(&self.local, &record.types);
        // Re-pointed here from another writer: this process writes it now.
        if spec.replace {
            drop(self.mirrors.change(|m| m.imports.remove(&spec.name)));
        }
        for input in spec.inputs() {
            self.ensure_available(&input)?;
        }
        // The export is made before the trajectory's worker starts, so its first sample
        // is published, and a camera's first frame written in place.
        let (node, domain, holdings, mirrors) =
            (&self.node, &self.domain, &self.holdings, &self.mirrors);
        let resets = &self.resets;
        let control = &self.control;
        let mut export = None;
        let handle = self.local.create_trajectory_prepared(spec.clone(), |handle| {
            // Re-pointed here (E5): the export follows the new trajectory, and readers
            // elsewhere follow it to its new generation's services.
            let repointed =
                spec.replace && mirrors.change(|m| m.exports.remove(&spec.name)).is_some();
            let start = if repointed { ExportStart::Repointed } else { ExportStart::New };
            // Registered before its first sample goes out, so readers find the port.
            let mut register = |port| report_writer(control, &spec.name, record.generation, port);
            let started =
                Export::start(node, domain, handle, record, start, holdings, &mut register)
                    .map_err(|e| CreateError::Unavailable {
                        reason: Unreachable::transport(Peer::Processes, e),
                    })?;
            // A store destroyed meanwhile needs no resets.
            let _destroyed = handle.with_store(|s| s.forward_resets(Arc::clone(resets)));
            export = Some(started);
            Ok(())
        })?;
        if let Some(export) = export {
            self.mirrors.change(|m| m.insert_export(spec.name.clone(), export));
        }
        Ok(handle)
    }

    fn report_writer(&mut self, name: &str, generation: u64, publisher: u128) {
        report_writer(&self.control, name, generation, publisher);
    }

    /// Takes `name` over, its writer being gone ([`super::takeover`]): the registry
    /// places it here, the replica's store becomes the writer's with the history it
    /// holds and what the kept history has beyond it, and an export publishes it,
    /// numbered as kept: readers elsewhere skip what they hold, and see no reset. `Ok` also when the registry names a
    /// live writer elsewhere (another process took it over first): the add goes there.
    fn take_over(&mut self, name: &str, generation: u64) -> Result<(), AddError> {
        let unavailable =
            |reason: Unreachable| AddError::Unavailable { trajectory: name.to_owned(), reason };
        let request = Request::TakeOverTrajectory {
            trajectory: name.to_owned(),
            generation,
            host: self.host.clone(),
        };
        let pid = self.mirrors.import(name).map_or(0, |i| i.lock().writer_pid());
        let gone = |pid| AddError::WriterGone { trajectory: name.to_owned(), pid };
        let record = match self.control.call(&request) {
            Ok(Response::Trajectory(r)) => *r,
            Ok(other) => {
                let answer = format!("{other:?}");
                return Err(unavailable(Unreachable::malformed(Peer::Coordinator, answer)));
            }
            // Nobody may take it over (its writer is supervised, and comes back).
            Err(ControlClientError::Remote(ControlError::NotAllowed { reason })) => {
                tracing::debug!(trajectory = %name, %reason, "not taken over");
                return Err(gone(pid));
            }
            Err(e) => return Err(unavailable(e.into())),
        };
        if record.generation != generation {
            // Destroyed and created anew meanwhile: the audit follows it.
            return Err(gone(0));
        }
        if record.writer != self.host {
            let Some(import) = self.mirrors.import(name) else { return Err(gone(0)) };
            let mut import = import.lock();
            import.set_released(false);
            import.set_writer(record.port);
            return Ok(());
        }
        let replica = self.local.get_entity_trajectory_structure(name).map_err(|_| gone(pid))?;
        // What the replica entered of the kept history: the rest enters from the file.
        let known = self.mirrors.import(name).and_then(|i| i.lock().last_kept());
        drop(self.mirrors.change(|m| m.imports.remove(name)));
        replica.with_store(|s| s.adopt_adds()).map_err(|_| gone(pid))?;
        let control = &self.control;
        let mut register = |port| report_writer(control, name, record.generation, port);
        let export = Export::start(
            &self.node,
            &self.domain,
            &replica,
            &record,
            ExportStart::TakenOver { known },
            &self.holdings,
            &mut register,
        )
        .map_err(|e| {
            tracing::warn!(trajectory = %name, error = %e,
                "took over a trajectory but cannot publish it; adds here stay here");
            unavailable(Unreachable::transport(Peer::Processes, e))
        })?;
        self.mirrors.change(|m| m.insert_export(name.to_owned(), export));
        tracing::info!(trajectory = %name, generation, "took over a trajectory whose writer is gone");
        Ok(())
    }

    /// Lets the primitive trajectories this process writes go, as its connection
    /// closes without destroying them: another process may take them over at once,
    /// while this process lives on.
    fn release_primitives(&mut self) {
        for (name, export) in self.mirrors.exports() {
            let (generation, primitive) = {
                let e = export.lock();
                (e.generation, e.is_primitive())
            };
            if !primitive {
                continue;
            }
            let request = Request::ReleaseWriter { trajectory: name.clone(), generation };
            if let Err(e) = self.control.call(&request) {
                tracing::debug!(trajectory = %name, error = %e, "cannot release a trajectory");
            }
        }
    }

    /// Asks the registry whose port the samples are that readers here hold unverified
    /// (a writer that just started or restarted), and lets them enter or be rejected.
    fn verify_writers(&mut self) {
        self.ask_writers(Import::awaits_writer);
    }

    /// Asks the registry who writes the imports whose writer was not named yet, ahead
    /// of their first samples; asks again later while some are still not named
    /// ([`Location::unnamed`]).
    fn name_writers(&mut self) {
        self.ask_writers(Import::writer_unnamed);
        let unnamed = self.mirrors.imports().iter().any(|(_, i)| i.lock().writer_unnamed());
        self.unnamed = match self.unnamed {
            Some((_, step)) if unnamed => {
                let step = (step * 2).min(TICK);
                Some((Instant::now() + step, step))
            }
            _ => None,
        };
    }

    /// Asks again soon who writes the imports, if `import` was made before its writer
    /// named its port.
    fn watch_unnamed(&mut self, import: &Import) {
        if !import.writer_unnamed() {
            return;
        }
        let soon = Instant::now() + FIRST_NAMING_ASK;
        self.unnamed = match self.unnamed {
            Some((ask, step)) if ask <= soon => Some((ask, step)),
            _ => Some((soon, FIRST_NAMING_ASK)),
        };
    }

    /// Asks the registry who writes the imports `which` selects, and names their
    /// writers' ports.
    fn ask_writers(&mut self, which: fn(&Import) -> bool) {
        let waiting: Vec<String> = {
            let imports = self.mirrors.imports();
            imports.into_iter().filter(|(_, i)| which(&i.lock())).map(|(n, _)| n).collect()
        };
        for name in waiting {
            let record = match self.record(&name) {
                Ok(r) => r,
                Err(e) => {
                    tracing::debug!(trajectory = %name, error = %e, "cannot ask who writes");
                    continue;
                }
            };
            if let Some(import) = self.mirrors.import(&name) {
                let mut import = import.lock();
                if import.generation == record.generation {
                    import.set_writer(record.port);
                    import.set_released(record.released);
                }
            }
        }
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
            LookupError::Unavailable { reason } => CreateError::Unavailable { reason },
            other => {
                CreateError::Unavailable { reason: Unreachable::refused(Peer::Coordinator, other) }
            }
        })?;
        if record.writer == self.host {
            // Assigned here but not built yet (its creator asked another process).
            self.poll_assignments();
            return match self.local.get_entity_trajectory_structure(name) {
                Ok(_) => Ok(()),
                Err(_) => Err(CreateError::Unavailable {
                    reason: Unreachable::refused(
                        Peer::Connection,
                        format!("`{name}` is assigned here but could not be built yet"),
                    ),
                }),
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
        let site = ImportSite {
            node: &self.node,
            domain: &self.domain,
            holdings: &self.holdings,
            mirrors: &self.mirrors,
            verify: &self.verify.0,
            take_over: &self.takeovers.0,
            tool: self.tool,
        };
        match Import::start(&site, handle.clone(), record) {
            Ok(mut import) => {
                // A replica destroyed meanwhile needs no resets.
                let _destroyed = handle.with_store(|s| s.forward_resets(Arc::clone(&self.resets)));
                // The writer did not hand its history over (gone, or not serving yet):
                // what it acknowledged is in the kept history (SPEC D1). First, so
                // that what it sends later and the file held is skipped.
                if !import.history_received() && record.info.kind == TrajectoryKind::Primitive {
                    import.enter_kept(&self.domain);
                }
                // The history the writer already handed over, at once.
                import.pump();
                self.watch_unnamed(&import);
                self.mirrors.change(|m| m.insert_import(name.clone(), import));
                Ok(handle)
            }
            Err(e) => {
                if let Err(undo) = self.local.destroy_entity_trajectory_structure(name) {
                    tracing::warn!(trajectory = %name, error = %undo,
                        "cannot remove a replica that failed to start");
                }
                Err(match e {
                    OpenError::LimitReached(limit) => CreateError::LimitReached(limit),
                    e => {
                        CreateError::Unavailable { reason: Unreachable::transport(Peer::Writer, e) }
                    }
                })
            }
        }
    }

    /// The registry's version, as announced in shared memory, else as the coordinator
    /// answers (`None` if it did not).
    fn registry_version(&mut self) -> Option<u64> {
        if let Some(versions) = &self.looked.versions {
            while let Ok(Some(v)) = versions.receive() {
                self.looked.announced = Some(*v);
            }
            if self.looked.announced.is_some() {
                return self.looked.announced;
            }
        }
        match self.control.call(&Request::Ping) {
            Ok(Response::Pong { registry, .. }) => Some(registry),
            _ => None,
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
        self.replica(&record).map_err(|e| match e {
            CreateError::LimitReached(limit) => LookupError::LimitReached(limit),
            CreateError::Unavailable { reason } => LookupError::Unavailable { reason },
            e => LookupError::Unavailable { reason: Unreachable::refused(Peer::Connection, e) },
        })
    }

    fn destroy(&mut self, name: &str) -> Result<(), LookupError> {
        let request = Request::DestroyEntityTrajectoryStructure { name: name.to_owned() };
        self.control.call(&request).map_err(lookup_error)?;
        self.forget(name);
        Ok(())
    }

    /// Builds the trajectories the coordinator placed here that are not built yet
    /// (sampled on this process's sensors, computed by its units, created by others).
    ///
    /// One assignment may read another (a computed trajectory of a sampled one, both
    /// here): building it asks for its inputs, which does not poll again (that nested
    /// poll would build the same list again, without end); the input's own turn in
    /// this list builds it, and what waited for it is built in the next pass.
    fn poll_assignments(&mut self) {
        if self.looked.building_assignments {
            return;
        }
        let version = self.registry_version();
        if version.is_some() && version == self.looked.assignments && self.failed.is_empty() {
            return;
        }
        self.looked.assignments = version;
        let list = match self.control.call(&Request::Assignments { host: self.host.clone() }) {
            Ok(Response::Assignments(list)) => list,
            Ok(_) => return,
            Err(e) => {
                tracing::debug!(error = %e, "cannot ask for assignments");
                return;
            }
        };
        self.looked.building_assignments = true;
        let mut pending: Vec<Assignment> = list
            .into_iter()
            .filter(|a| !self.exports(&a.spec.name) && !self.failed.contains(&a.spec.name))
            .collect();
        while !pending.is_empty() {
            let before = pending.len();
            let mut waiting = Vec::new();
            for assignment in pending {
                match self.build(&assignment.spec, &assignment.record, false) {
                    Ok(_) => {
                        tracing::info!(trajectory = %assignment.spec.name, "writing trajectory")
                    }
                    // A transient failure (the coordinator slow to answer under load,
                    // an input of this list not built yet) is retried; anything else
                    // would fail again.
                    Err(CreateError::Unavailable { .. }) => waiting.push(assignment),
                    Err(e) => {
                        tracing::warn!(trajectory = %assignment.spec.name, error = %e,
                            "cannot build an assigned trajectory");
                        self.failed.insert(assignment.spec.name.clone());
                    }
                }
            }
            if waiting.len() == before {
                for assignment in &waiting {
                    tracing::info!(trajectory = %assignment.spec.name,
                        "cannot build an assigned trajectory yet; retrying");
                }
                // Asked again at the next poll, whatever the registry's version.
                self.looked.assignments = None;
                break;
            }
            pending = waiting;
        }
        self.looked.building_assignments = false;
    }
}

/// Registers `types` in the local runtime where missing (names defined elsewhere).
pub(crate) fn install(local: &InProcessEsgm, types: &[(String, EntityStructureType)]) {
    for (name, t) in types {
        if local.get_entity_structure_type(name).is_err() {
            // Another thread may have registered it meanwhile (the same definition, from
            // the same registry); anything else leaves the type unknown here, and the
            // operation that needs it fails naming it.
            if let Err(e) = local.create_entity_structure_type(name, t.clone()) {
                tracing::debug!(type_name = %name, error = %e, "a type from the registry not installed");
            }
        }
    }
}

fn unexpected(r: &Response) -> CreateError {
    CreateError::Unavailable { reason: Unreachable::malformed(Peer::Coordinator, format!("{r:?}")) }
}

/// Names this process's publisher port as the writer's of `name`, so that readers
/// accept its samples ([`super::import`]). A failure is logged; the next audit reports
/// again.
fn report_writer(control: &ControlClient, name: &str, generation: u64, publisher: u128) {
    let request = Request::ReportWriter { trajectory: name.to_owned(), generation, publisher };
    if let Err(e) = control.call(&request) {
        tracing::warn!(trajectory = %name, error = %e,
            "cannot register as the writer; readers hold its samples until it can");
    }
}
