//! The reference system on esgm, in esgm's own terms (README, "The Autoware reference
//! system"):
//! - a **sensor** is a sampled trajectory of a sensor interface, its sample times on
//!   multiples of its period (the seed's `from`), so every process's timers tick in
//!   phase and at START, as upstream's, made together in one process, do; it produces
//!   from START to UNTIL;
//! - a **transform** is a computed trajectory: its unit runs on every input;
//! - a **fusion** is a computed trajectory with two inputs, whose unit makes an output
//!   once both inputs have a structure it has not used (esgm calls a unit with the
//!   latest of each input on every update; the unit tells the new ones by their
//!   sequence numbers);
//! - the **behavior planner** is a sampled trajectory every 100 ms whose sensor reads the
//!   latest of its six inputs (queries, answered from this process's copy of them);
//! - the **intersection** node is two computed trajectories, one per connection;
//! - a **command** sink is a subscription;
//! - "history depth 1" is a cache of one structure on every trajectory, and a
//!   subscription queue of one.
//!
//! Every message is a `Message4kb` structure, its 4,096 bytes an octet sequence. The
//! same code builds the system in one process (`refsys-esgm`) and one node per process
//! through `connect` (`refsys-esgm-procs`).

use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context as _, bail};
use esgm_shm::prelude::*;
use parking_lot::Mutex;

use super::message::Message;
use super::node::{Command, Cyclic, Fusion, Sensor, Transform};
use super::report::NodeReport;
use super::topology::{Kind, Node};

/// The type of every trajectory.
pub const MESSAGE_TYPE: &str = "Message4kb";
/// Its one attribute.
const ATTRIBUTE: &str = "message";
/// How long after UNTIL messages in flight are let through before reporting.
pub const DRAIN: Duration = Duration::from_millis(500);
/// How long a node waits for its inputs to be declared (by other processes).
const INPUTS_PATIENCE: Duration = Duration::from_secs(60);

/// The Message4kb type.
pub fn message_type() -> EntityStructureType {
    EntityStructureType::new(MESSAGE_TYPE).attr(ATTRIBUTE, ValueSort::OctetSeq)
}

fn structure(m: &Message, valid: Time) -> EntityStructure {
    EntityStructure::new(MESSAGE_TYPE, valid, valid)
        .with(ATTRIBUTE, Octets::from(&m.as_bytes()[..]))
}

fn message_of(s: &Sample) -> Option<Message> {
    match s.structure.get(ATTRIBUTE) {
        Some(Value::OctetSeq(o)) => Message::from_bytes(o).ok(),
        _ => None,
    }
}

fn now() -> Time {
    SystemClock.now()
}

/// A sampled trajectory of the sensor `name` every `period`, its sample times on
/// multiples of the period since the epoch: so timers in different processes tick
/// together, and at START (a multiple of every period), as upstream's timers, made
/// together in one process, do.
fn in_phase(name: &str, period: Duration) -> anyhow::Result<TrajectorySpec> {
    let period = Time::try_from(period.as_nanos()).unwrap_or(Time::MAX);
    let first = (now() / period + 1).saturating_mul(period);
    Ok(TrajectorySpec::sampled(name, name, period)?.between(first, 0))
}

/// A cache of one: the reference system keeps only the latest message of every topic.
fn depth_one() -> FluentStreamPolicy {
    FluentStreamPolicy::default().cache(CacheConstraint::Elements(1))
}

/// What a node keeps to report at the end.
enum Logic {
    Sensor(Arc<Mutex<Sensor>>),
    Transform(Vec<Arc<Mutex<Transform>>>),
    Fusion(Arc<Mutex<Fusion>>),
    Cyclic(Arc<Mutex<Cyclic>>),
    Command(Arc<Mutex<Command>>, std::thread::JoinHandle<()>),
}

/// Nodes built in one ESGM, ready to run.
pub struct Built {
    nodes: Vec<(&'static str, Logic)>,
    /// Handles that keep the trajectories (and their workers) this process made.
    _trajectories: Vec<InProcessTrajectory>,
}

impl std::fmt::Debug for Built {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.nodes.iter().map(|(n, _)| n)).finish()
    }
}

/// When the topology runs: sensors and the planner's timer produce only inside it,
/// sinks listen until DRAIN after it. Set once every process is ready (`go`).
#[derive(Debug, Default)]
pub struct Window {
    start: std::sync::atomic::AtomicI64,
    until: std::sync::atomic::AtomicI64,
}

impl Window {
    /// Opens the window from `start` to `until` (ns on the system clock).
    pub fn set(&self, start: Time, until: Time) {
        use std::sync::atomic::Ordering::SeqCst;
        self.until.store(until, SeqCst);
        self.start.store(start, SeqCst);
    }

    /// Whether `t` is inside it.
    fn open(&self, t: Time) -> bool {
        use std::sync::atomic::Ordering::SeqCst;
        let start = self.start.load(SeqCst);
        start > 0 && t >= start && t < self.until.load(SeqCst)
    }

    /// Whether the run and its drain are over at `t`.
    fn over(&self, t: Time) -> bool {
        use std::sync::atomic::Ordering::SeqCst;
        let until = self.until.load(SeqCst);
        until > 0 && t >= until.saturating_add(Time::try_from(DRAIN.as_nanos()).unwrap_or(0))
    }
}

/// Waits until every trajectory of `names` exists (declared by another process).
fn wait_for_inputs<E: Esgm<Trajectory = InProcessTrajectory>>(
    esgm: &E,
    names: &[&str],
) -> anyhow::Result<Vec<InProcessTrajectory>> {
    let deadline = std::time::Instant::now() + INPUTS_PATIENCE;
    names
        .iter()
        .map(|name| {
            loop {
                match esgm.get_entity_trajectory_structure(name) {
                    Ok(t) => return Ok(t),
                    Err(LookupError::NoSuchEntityStructure { .. })
                        if std::time::Instant::now() < deadline =>
                    {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    Err(e) => bail!("input `{name}` of the reference system: {e}"),
                }
            }
        })
        .collect()
}

/// Declares `nodes` in `esgm`: their sensors, units and trajectories, with `crunch` of
/// work per message; sensors and the planner produce only inside `window`. Inputs
/// declared by other processes are waited for.
pub fn build<E: Esgm<Trajectory = InProcessTrajectory>>(
    esgm: &E,
    nodes: &[&'static Node],
    crunch: u64,
    window: &Arc<Window>,
) -> anyhow::Result<Built> {
    match esgm.create_type(message_type()) {
        Ok(()) | Err(TypeRegistryError::EntityStructureTypeAlreadyExists { .. }) => {}
        Err(e) => bail!("cannot declare {MESSAGE_TYPE}: {e}"),
    }
    let mut built = Built { nodes: Vec::new(), _trajectories: Vec::new() };
    let input_type = || vec![InputType::Type(MESSAGE_TYPE.to_owned())];
    for node in nodes {
        let name = node.name;
        let logic = match node.kind {
            Kind::Sensor { period } => {
                let sensor = Arc::new(Mutex::new(Sensor::new(name)));
                let s = Arc::clone(&sensor);
                let w = Arc::clone(window);
                let iface = move |qtime: Time| -> Result<EntityStructure, SensorError> {
                    if !w.open(qtime) {
                        return Err(SensorError::ValueNotAvailable);
                    }
                    Ok(structure(&s.lock().fire(), qtime))
                };
                esgm.add_sensor_interface(name, MESSAGE_TYPE, Arc::new(iface))?;
                let spec = in_phase(name, period)?;
                let policy = spec.policy.clone().cache(CacheConstraint::Elements(1));
                built._trajectories.push(esgm.create_trajectory(spec.policy(policy))?);
                Logic::Sensor(sensor)
            }
            Kind::Transform { input } => {
                let t = transform(esgm, name, input, name, crunch, &mut built._trajectories)?;
                Logic::Transform(vec![t])
            }
            Kind::Intersection { connections } => {
                let mut both = Vec::new();
                for (input, output) in connections {
                    both.push(transform(
                        esgm,
                        name,
                        input,
                        output,
                        crunch,
                        &mut built._trajectories,
                    )?);
                }
                Logic::Transform(both)
            }
            Kind::Fusion { inputs } => {
                wait_for_inputs(esgm, &inputs)?;
                let fusion = Arc::new(Mutex::new(Fusion::new(name, inputs, crunch)));
                let f = Arc::clone(&fusion);
                let offered: Mutex<[Option<u32>; 2]> = Mutex::new([None, None]);
                let unit = move |samples: &[Sample],
                                 _q: Time|
                      -> Result<EntityStructure, ComputeError> {
                    let mut offered = offered.lock();
                    let mut fusion = f.lock();
                    let mut out = None;
                    for (i, s) in samples.iter().enumerate().take(2) {
                        let Some(m) = message_of(s) else {
                            return Err(ComputeError::Failed { reason: "not a Message4kb".into() });
                        };
                        // Only what this input brought since the last call is new.
                        if offered[i] == Some(m.sequence()) {
                            continue;
                        }
                        offered[i] = Some(m.sequence());
                        if let Some(o) = fusion.on_input(i, m) {
                            out = Some(o);
                        }
                    }
                    out.map(|o| structure(&o, now())).ok_or(ComputeError::ValueNotAvailable)
                };
                esgm.add_comp_unit(
                    name,
                    MESSAGE_TYPE,
                    vec![input_type()[0].clone(); 2],
                    Arc::new(unit),
                )?;
                let spec = TrajectorySpec::computed(name, name, inputs).policy(depth_one());
                built._trajectories.push(esgm.create_trajectory(spec)?);
                Logic::Fusion(fusion)
            }
            Kind::Cyclic { inputs, period } => {
                let handles = wait_for_inputs(esgm, &inputs)?;
                let cyclic = Arc::new(Mutex::new(Cyclic::new(name, &inputs, crunch)));
                let c = Arc::clone(&cyclic);
                let offered: Mutex<Vec<Option<u32>>> = Mutex::new(vec![None; inputs.len()]);
                let w = Arc::clone(window);
                let iface = move |qtime: Time| -> Result<EntityStructure, SensorError> {
                    if !w.open(qtime) {
                        return Err(SensorError::ValueNotAvailable);
                    }
                    let mut cyclic = c.lock();
                    let mut offered = offered.lock();
                    for (i, h) in handles.iter().enumerate() {
                        // The latest of each input, from this process's copy of it.
                        let Ok(s) = h.get_latest() else { continue };
                        let Some(m) = message_of(&s) else { continue };
                        if offered[i] != Some(m.sequence()) {
                            offered[i] = Some(m.sequence());
                            cyclic.on_input(i, m);
                        }
                    }
                    Ok(structure(&cyclic.on_timer(), qtime))
                };
                esgm.add_sensor_interface(name, MESSAGE_TYPE, Arc::new(iface))?;
                let spec = in_phase(name, period)?;
                let policy = spec.policy.clone().cache(CacheConstraint::Elements(1));
                built._trajectories.push(esgm.create_trajectory(spec.policy(policy))?);
                Logic::Cyclic(cyclic)
            }
            Kind::Command { input } => {
                let [handle] =
                    <[InProcessTrajectory; 1]>::try_from(wait_for_inputs(esgm, &[input])?)
                        .map_err(|_| anyhow::anyhow!("one input"))?;
                let sub = handle.subscribe(SubscribeOptions::default().capacity(1))?;
                let command = Arc::new(Mutex::new(Command::new(name, input)));
                let c = Arc::clone(&command);
                let w = Arc::clone(window);
                let thread = std::thread::Builder::new()
                    .name(format!("refsys-{name}"))
                    .spawn(move || {
                        while !w.over(now()) {
                            if let Ok(s) = sub.recv_timeout(Duration::from_millis(50)) {
                                if let Some(m) = message_of(&s) {
                                    c.lock().on_input(&m);
                                }
                            }
                        }
                    })
                    .context("cannot start a command sink's thread")?;
                built._trajectories.push(handle);
                Logic::Command(command, thread)
            }
        };
        built.nodes.push((name, logic));
    }
    Ok(built)
}

/// A transform (or an intersection's connection): `node` making `output` from `input`.
fn transform<E: Esgm<Trajectory = InProcessTrajectory>>(
    esgm: &E,
    node: &'static str,
    input: &'static str,
    output: &'static str,
    crunch: u64,
    trajectories: &mut Vec<InProcessTrajectory>,
) -> anyhow::Result<Arc<Mutex<Transform>>> {
    wait_for_inputs(esgm, &[input])?;
    let logic = Arc::new(Mutex::new(Transform::new(node, input, output, crunch)));
    let l = Arc::clone(&logic);
    let unit = move |samples: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        let m = samples
            .first()
            .and_then(message_of)
            .ok_or_else(|| ComputeError::Failed { reason: "not a Message4kb".into() })?;
        Ok(structure(&l.lock().on_input(&m), now()))
    };
    esgm.add_comp_unit(
        output,
        MESSAGE_TYPE,
        vec![InputType::Type(MESSAGE_TYPE.to_owned())],
        Arc::new(unit),
    )?;
    let spec = TrajectorySpec::computed(output, output, [input]).policy(depth_one());
    trajectories.push(esgm.create_trajectory(spec)?);
    Ok(logic)
}

impl Built {
    /// The nodes' reports, once the run is over (command sinks stop DRAIN after UNTIL).
    pub fn reports(self) -> Vec<NodeReport> {
        let mut out = Vec::new();
        for (_, logic) in self.nodes {
            out.push(match logic {
                Logic::Sensor(s) => s.lock().report(),
                Logic::Transform(ts) => {
                    let mut reports = ts.iter().map(|t| t.lock().report());
                    let mut first = reports.next().unwrap_or_default();
                    reports.for_each(|r| first.merge(r));
                    first
                }
                Logic::Fusion(f) => f.lock().report(),
                Logic::Cyclic(c) => c.lock().report(),
                Logic::Command(c, thread) => {
                    let _ended = thread.join();
                    c.lock().report()
                }
            });
        }
        out
    }
}

/// The peer argument of the in-process system's process.
const INPROC: &str = "esgm-inproc";
/// The peer argument of a node process.
const NODE: &str = "esgm-node";
/// The peer argument of the coordinator's process.
const COORDINATOR: &str = "esgm-coordinator";

/// `refsys-esgm`: every node in one process, on the in-process runtime (as upstream
/// requires: "all nodes must run on a single process").
#[derive(Debug, Clone, Copy)]
pub struct EsgmInProcess;

/// `refsys-esgm-procs`: one process per node through `connect`, and a coordinator (a
/// documented deviation from upstream's single process: esgm's own deployment).
#[derive(Debug, Clone, Copy)]
pub struct EsgmProcesses;

fn peer_command(domain: &str, arg: String) -> anyhow::Result<std::process::Command> {
    let role = crate::peer_role::PeerRole {
        scenario: crate::scenarios::refsys::NAME.to_owned(),
        wait: crate::wait_mode::WaitMode::Block,
        domain: domain.to_owned(),
        core: None,
        arg: Some(arg),
    };
    let exe = std::env::current_exe().context("cannot find the esgm-bench executable")?;
    let mut c = std::process::Command::new(exe);
    c.args(role.to_args());
    Ok(c)
}

impl super::system::System for EsgmInProcess {
    fn name(&self) -> &'static str {
        "esgm"
    }

    fn summary(&self) -> &'static str {
        "esgm's in-process runtime, every node in one process"
    }

    fn run(&self, s: &super::system::RunSettings) -> anyhow::Result<super::system::SystemRun> {
        let domain = esgm_shm::unique_domain("refsys-inproc");
        let arg = format!("{INPROC}|all|{}|{}", s.crunch, s.dir.display());
        let (reports, usage, notes) =
            super::processes::run(vec![("esgm".into(), peer_command(&domain, arg)?)], &[], s)?;
        Ok(super::system::SystemRun { reports, usage, processes: 1, notes })
    }
}

impl super::system::System for EsgmProcesses {
    fn name(&self) -> &'static str {
        "esgm-procs"
    }

    fn summary(&self) -> &'static str {
        "esgm through connect, one process per node and a coordinator"
    }

    fn run(&self, s: &super::system::RunSettings) -> anyhow::Result<super::system::SystemRun> {
        let domain = esgm_shm::unique_domain("refsys");
        let _end = crate::domain_end::DomainEnd::new(&domain);
        let mut processes = vec![(
            "coordinator".to_owned(),
            peer_command(&domain, format!("{COORDINATOR}|-|{}|{}", s.crunch, s.dir.display()))?,
        )];
        for n in super::topology::build_order() {
            let arg = format!("{NODE}|{}|{}|{}", n.name, s.crunch, s.dir.display());
            processes.push((n.name.to_owned(), peer_command(&domain, arg)?));
        }
        let count = processes.len();
        let (reports, usage, notes) = super::processes::run(processes, &[], s)?;
        Ok(super::system::SystemRun { reports, usage, processes: count, notes })
    }
}

/// Runs this process as one of the esgm systems' processes (`arg`:
/// `KIND|NODE|CRUNCH|DIR`), in `domain`. `None` if `arg` is not one of theirs.
pub fn peer_main(domain: &str, arg: &str) -> Option<anyhow::Result<()>> {
    let mut parts = arg.splitn(4, '|');
    let (Some(kind), Some(node), Some(crunch), Some(dir)) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return None;
    };
    if ![INPROC, NODE, COORDINATOR].contains(&kind) {
        return None;
    }
    let dir = std::path::PathBuf::from(dir);
    Some((|| -> anyhow::Result<()> {
        let crunch: u64 = crunch.parse().context("the crunch limit")?;
        let window = Arc::new(Window::default());
        match kind {
            COORDINATOR => {
                let registry =
                    esgm_shm::control::Registry::new(esgm_core::TypeRegistry::with_library());
                let _coordinator = esgm_shm::control::Coordinator::spawn(domain, registry)?;
                let (side, _start, until) = super::processes::NodeSide::ready()?;
                super::processes::sleep_until(until.saturating_add(drain_ns()));
                side.done(&[], &dir)
            }
            INPROC => {
                let esgm = InProcessEsgm::default();
                let nodes = super::topology::build_order();
                let built = build(&esgm, &nodes, crunch, &window)?;
                run_built(built, &window, &dir)
            }
            _ => {
                let node =
                    super::topology::node(node).with_context(|| format!("no node {node}"))?;
                // The coordinator's process starts with the nodes': wait for it.
                let deadline = std::time::Instant::now() + INPUTS_PATIENCE;
                let esgm = loop {
                    match ShmEsgm::builder()
                        .domain(domain)
                        .host(format!("refsys-{}", node.name))
                        .connect()
                    {
                        Ok(e) => break e,
                        Err(ConnectError::Control(_)) if std::time::Instant::now() < deadline => {
                            std::thread::sleep(Duration::from_millis(50));
                        }
                        Err(e) => return Err(e.into()),
                    }
                };
                let built = build(&esgm, &[node], crunch, &window)?;
                run_built(built, &window, &dir)
            }
        }
    })())
}

fn drain_ns() -> u64 {
    u64::try_from(DRAIN.as_nanos()).unwrap_or(0)
}

/// Says ready, runs the window it is given, reports.
fn run_built(built: Built, window: &Window, dir: &std::path::Path) -> anyhow::Result<()> {
    let (side, start, until) = super::processes::NodeSide::ready()?;
    let as_time = |ns: u64| Time::try_from(ns).unwrap_or(Time::MAX);
    window.set(as_time(start), as_time(until));
    super::processes::sleep_until(until.saturating_add(drain_ns()));
    let reports = built.reports();
    side.done(&reports, dir)
}
