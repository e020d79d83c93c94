//! `apply`: bring a running system to what a [`Plan`] declares.
//!
//! Order matters and is fixed: check everything first (names the file uses against
//! the file and the system, existing things against their declarations), then types,
//! then primitive trajectories (so a pusher finds its trajectory placed on it), then
//! the processes (declared to the coordinator; `esgm up` starts and supervises them),
//! then — once every declared sensor and unit has registered — the sampled, computed
//! and operator trajectories in dependency order. What already exists as declared is
//! left alone, so applying a file twice changes nothing.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use esgm_core::catalog::{SensorRecord, UnitRecord};
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind, TrajectorySource};
use esgm_core::type_registry::closest_name;
use esgm_core::{Clock as _, EntityStructureType, SystemClock};
use esgm_shm::control::{ControlClient, ProcessRecord, Request, Response};

use super::{Item, Plan, PlannedTrajectory, Serves};

/// The process in `esgm up` that writes the primitive, sync and merge trajectories
/// created from the command line or a file (the command line itself does not stay).
pub const SYSTEM_HOST: &str = "esgm-system";

/// How long `apply` waits for declared sensors and units to register.
const REGISTER_WITHIN: Duration = Duration::from_secs(45);

/// One thing `apply` did or found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Outcome {
    /// `type`, `process`, `sensor`, `unit`, `trajectory`.
    pub kind: &'static str,
    /// Its name.
    pub name: String,
    /// `created`, `unchanged`, `declared`, `registered`, `replaced`.
    pub change: &'static str,
    /// The line of its declaration.
    pub line: usize,
}

/// The coordinator, as `apply` asks it.
struct System {
    control: ControlClient,
}

/// Picks the expected answer out of a response.
macro_rules! answer {
    ($variant:path) => {
        |r| match r {
            $variant(x) => Some(x),
            _ => None,
        }
    };
}

impl System {
    fn call(&self, request: &Request) -> anyhow::Result<Response> {
        Ok(self.control.call(request)?)
    }

    /// `request`'s answer of the expected kind.
    fn ask<T>(&self, request: &Request, pick: fn(Response) -> Option<T>) -> anyhow::Result<T> {
        pick(self.call(request)?)
            .with_context(|| format!("unexpected answer from the coordinator to {request:?}"))
    }

    fn types(&self) -> anyhow::Result<Vec<String>> {
        self.ask(&Request::ListEntityStructureTypes, answer!(Response::Names))
    }

    fn get_type(&self, name: &str) -> anyhow::Result<EntityStructureType> {
        let request = Request::GetEntityStructureType { type_name: name.to_owned() };
        self.ask(&request, answer!(Response::Type))
    }

    fn sensors(&self) -> anyhow::Result<Vec<SensorRecord>> {
        self.ask(&Request::ListSensors, answer!(Response::Sensors))
    }

    fn units(&self) -> anyhow::Result<Vec<UnitRecord>> {
        self.ask(&Request::ListCompUnits, answer!(Response::CompUnits))
    }

    fn trajectories(&self) -> anyhow::Result<Vec<TrajectoryInfo>> {
        self.ask(&Request::ListTrajectories, answer!(Response::Trajectories))
    }

    fn processes(&self) -> anyhow::Result<Vec<ProcessRecord>> {
        self.ask(&Request::ListProcesses, answer!(Response::Processes))
    }
}

/// Applies `plan` to the system of `domain`, reporting each outcome as it happens.
pub fn apply(domain: &str, plan: &Plan, report: &mut dyn FnMut(Outcome)) -> anyhow::Result<()> {
    let control = ControlClient::connect(domain, Duration::from_secs(5))
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    let system = System { control };
    let order = check(&system, plan)?;
    let existing: BTreeMap<String, TrajectoryInfo> =
        system.trajectories()?.into_iter().map(|t| (t.name.clone(), t)).collect();
    let outcome =
        |kind, name: &str, change, line| Outcome { kind, name: name.to_owned(), change, line };

    for Item { line, what: (name, t) } in &plan.types {
        if system.types()?.contains(name) {
            report(outcome("type", name, "unchanged", *line));
            continue;
        }
        system
            .call(&Request::CreateEntityStructureType {
                type_name: name.clone(),
                entity_type: t.clone(),
            })
            .map_err(|e| plan.error(*line, format!("type `{name}`: {e:#}")))?;
        report(outcome("type", name, "created", *line));
    }

    let (primitive, rest): (Vec<_>, Vec<_>) = order
        .into_iter()
        .partition(|i| plan.trajectories[*i].what.spec.kind() == TrajectoryKind::Primitive);
    let create = |i: usize, report: &mut dyn FnMut(Outcome)| -> anyhow::Result<()> {
        let Item { line, what } = &plan.trajectories[i];
        let name = &what.spec.name;
        if existing.contains_key(name) && !what.spec.replace {
            report(outcome("trajectory", name, "unchanged", *line));
            return Ok(());
        }
        let host = what.writer.clone().unwrap_or_else(|| SYSTEM_HOST.to_owned());
        // An aligned trajectory's first sample time is resolved now, as it is created.
        let spec = what.spec_at(SystemClock.now());
        system
            .call(&Request::CreateTrajectory { spec, host })
            .map_err(|e| plan.error(*line, format!("trajectory `{name}`: {e:#}")))?;
        let change = if existing.contains_key(name) { "replaced" } else { "created" };
        report(outcome("trajectory", name, change, *line));
        Ok(())
    };
    for i in primitive {
        create(i, report)?;
    }

    for Item { line, what } in &plan.workers {
        system
            .call(&Request::DeclareProcess { spec: what.spec.clone() })
            .map_err(|e| plan.error(*line, format!("process `{}`: {e:#}", what.spec.name)))?;
        report(outcome("process", &what.spec.name, "declared", *line));
    }
    wait_for_registrations(&system, plan, report)?;

    for i in rest {
        create(i, report)?;
    }
    Ok(())
}

/// Waits until every declared sensor and unit is registered; an error names the one
/// missing, its line, and what its process last did.
fn wait_for_registrations(
    system: &System,
    plan: &Plan,
    report: &mut dyn FnMut(Outcome),
) -> anyhow::Result<()> {
    let deadline = Instant::now() + REGISTER_WITHIN;
    let mut pending: Vec<&Item<super::Worker>> = plan
        .workers
        .iter()
        .filter(|w| !matches!(w.what.serves, Serves::Pushes(_) | Serves::Bridge(_)))
        .collect();
    while !pending.is_empty() {
        let sensors = system.sensors()?;
        let units = system.units()?;
        pending.retain(|w| {
            let (kind, name, done) = match &w.what.serves {
                Serves::Sensor(n) => ("sensor", n, sensors.iter().any(|s| s.name == *n)),
                Serves::Unit(n) => ("unit", n, units.iter().any(|u| u.name == *n)),
                Serves::Pushes(_) | Serves::Bridge(_) => return false,
            };
            if done {
                report(Outcome { kind, name: name.clone(), change: "registered", line: w.line });
            }
            !done
        });
        if pending.is_empty() {
            break;
        }
        if Instant::now() > deadline {
            let w = pending[0];
            let status = system
                .processes()?
                .into_iter()
                .find(|p| p.spec.name == w.what.spec.name)
                .map(|p| p.status)
                .unwrap_or_default();
            let last = status.last_exit.map(|e| format!("; last exit: {e}")).unwrap_or_default();
            return Err(plan
                .error(
                    w.line,
                    format!(
                        "process `{}` did not register what it serves within {REGISTER_WITHIN:?} \
                         ({} restarts{last}); is `esgm up` running for this domain?",
                        w.what.spec.name, status.restarts
                    ),
                )
                .into());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}

/// Checks every name the plan uses and every existing thing against its declaration;
/// returns the order to create trajectories in (inputs first).
fn check(system: &System, plan: &Plan) -> anyhow::Result<Vec<usize>> {
    let mut types: BTreeSet<String> = system.types()?.into_iter().collect();
    for Item { line, what: (name, t) } in &plan.types {
        if types.contains(name) {
            let current = system.get_type(name)?;
            if current.attributes != t.attributes {
                bail!(plan.error(
                    *line,
                    format!("type `{name}` exists with other attributes; remove it first (esgm type rm {name})")
                ));
            }
        }
        types.insert(name.clone());
        for a in &t.attributes {
            if let Some(e) = &a.element_type {
                known(plan, *line, "type", e, &types)?;
            }
        }
    }
    let mut sensors: BTreeSet<String> = system.sensors()?.into_iter().map(|s| s.name).collect();
    let mut units: BTreeSet<String> = system.units()?.into_iter().map(|u| u.name).collect();
    for w in &plan.workers {
        match &w.what.serves {
            Serves::Sensor(n) => sensors.insert(n.clone()),
            Serves::Unit(n) => units.insert(n.clone()),
            Serves::Pushes(_) | Serves::Bridge(_) => false,
        };
    }
    let existing: BTreeMap<String, TrajectoryInfo> =
        system.trajectories()?.into_iter().map(|t| (t.name.clone(), t)).collect();
    let all: BTreeSet<String> = existing
        .keys()
        .cloned()
        .chain(plan.trajectories.iter().map(|t| t.what.spec.name.clone()))
        .collect();

    for Item { line, what } in &plan.trajectories {
        match &what.spec.source {
            TrajectorySource::Primitive { type_name } => {
                known(plan, *line, "type", type_name, &types)?
            }
            TrajectorySource::Sampled { sensor, .. } => {
                known(plan, *line, "sensor", sensor, &sensors)?
            }
            TrajectorySource::Computed { unit, .. }
            | TrajectorySource::SampledGenerators { unit: Some(unit), .. } => {
                known(plan, *line, "unit", unit, &units)?
            }
            _ => {}
        }
        for input in &what.inputs {
            known(plan, *line, "trajectory", input, &all)?;
        }
        if let Some(current) = existing.get(&what.spec.name) {
            if !what.spec.replace && !same(current, what) {
                bail!(plan.error(
                    *line,
                    format!(
                        "trajectory `{}` exists with another definition; set replace = true to re-point it",
                        what.spec.name
                    )
                ));
            }
        }
    }

    // Inputs declared in the file are created before the trajectories reading them.
    Ok(plan.creation_order()?)
}

fn known(
    plan: &Plan,
    line: usize,
    what: &str,
    name: &str,
    names: &BTreeSet<String>,
) -> anyhow::Result<()> {
    if names.contains(name) {
        return Ok(());
    }
    let hint = closest_name(name, names.iter().map(String::as_str))
        .map(|s| format!("; did you mean `{s}`?"))
        .unwrap_or_default();
    bail!(plan.error(line, format!("unknown {what} `{name}`{hint}")))
}

/// An existing trajectory is what the file declares.
fn same(current: &TrajectoryInfo, planned: &PlannedTrajectory) -> bool {
    let spec = &planned.spec;
    let source = match &spec.source {
        TrajectorySource::Sampled { sensor, .. } => Some(sensor.clone()),
        TrajectorySource::Computed { unit, .. } => Some(unit.clone()),
        _ => current.source.clone(),
    };
    let type_ok = match &spec.source {
        TrajectorySource::Primitive { type_name } => *type_name == current.type_name,
        _ => true,
    };
    current.kind == spec.kind()
        && type_ok
        && current.source == source
        && current.inputs == planned.inputs
        && current.policy == spec.policy
}
