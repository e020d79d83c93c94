//! What the reference system's node program serves for each sensor and unit its system
//! file declares ([`super::system_file`]), on either runtime: the node kinds' logic
//! ([`super::node`]) as esgm's own sensors and units. The name a sensor or unit is
//! declared under is the trajectory it makes:
//! - a **sensor** node: a sensor interface, pulled by its sampled trajectory at each
//!   sample time, which makes a fresh message inside the run's window;
//! - a **transform**, and each of the **intersection**'s two connections: a unit with
//!   one input, which its computed trajectory calls on every input;
//! - a **fusion**: a unit with two inputs, which esgm calls with the latest of both on
//!   every update; it makes an output once both brought a message it has not used, and
//!   tells the new ones by their sequence numbers;
//! - the **behavior planner**: a unit whose temporal function (`compute_at`) its
//!   generate trajectory samples every period with the latest of its six inputs;
//! - a **command** sink: a unit with one input that makes nothing, called by its computed
//!   trajectory (which stays empty) on every input, as a subscriber's callback.
//!
//! Every message is a `Message4kb` structure, its 4,096 bytes one octet sequence.

use std::sync::Arc;

use anyhow::{Context as _, bail};
use esgm_shm::prelude::*;
use parking_lot::Mutex;

use super::message::Message;
use super::node::{Command, Cyclic, Fusion, Sensor, Transform};
use super::report::NodeReport;
use super::topology::{Kind, NODES, Node};
use super::window::Window;

/// The type of every trajectory.
pub const MESSAGE_TYPE: &str = "Message4kb";
/// Its one attribute.
pub const ATTRIBUTE: &str = "message";

/// The Message4kb type.
pub fn message_type() -> EntityStructureType {
    EntityStructureType::new(MESSAGE_TYPE).attr(ATTRIBUTE, ValueSort::OctetSeq)
}

fn structure(m: &Message, valid: Time) -> EntityStructure {
    EntityStructure::new(MESSAGE_TYPE, valid, valid)
        .with(ATTRIBUTE, Octets::from(&m.as_bytes()[..]))
}

fn message_of(s: &Sample) -> Result<Message, ComputeError> {
    match s.structure.get(ATTRIBUTE).and_then(|v| v.as_bytes()) {
        Some(o) => Message::from_bytes(o)
            .map_err(|e| ComputeError::Failed { reason: format!("not a Message4kb: {e}") }),
        _ => Err(ComputeError::Failed { reason: format!("no `{ATTRIBUTE}` octets") }),
    }
}

fn now() -> Time {
    SystemClock.now()
}

/// What a declared name is in the topology.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// A sensor node.
    Sensor(&'static Node),
    /// A node whose part is a unit making the trajectory of that name (the
    /// intersection's second connection makes `EuclideanIntersection`; a sink makes
    /// nothing, its trajectory named after it stays empty).
    Unit(&'static Node),
}

impl Part {
    /// The part declared as `name`, if the topology has it.
    pub fn of(name: &str) -> Option<Self> {
        let node = NODES.iter().find(|n| n.name == name || n.outputs().contains(&name))?;
        Some(match node.kind {
            Kind::Sensor { .. } => Part::Sensor(node),
            _ => Part::Unit(node),
        })
    }

    /// Its node.
    pub fn node(&self) -> &'static Node {
        match self {
            Part::Sensor(n) | Part::Unit(n) => n,
        }
    }
}

/// A part of a node this process serves, kept for the node's report.
#[derive(Debug, Clone)]
pub enum Served {
    /// A sensor.
    Sensor(Arc<Mutex<Sensor>>),
    /// A transform, or one of the intersection's connections.
    Transform(Arc<Mutex<Transform>>),
    /// A fusion.
    Fusion(Arc<Mutex<Fusion>>),
    /// The behavior planner.
    Cyclic(Arc<Mutex<Cyclic>>),
    /// A command sink.
    Command(Arc<Mutex<Command>>),
}

impl Served {
    /// What it did, as its node's report (an intersection's two parts: merge them).
    pub fn report(&self) -> NodeReport {
        match self {
            Served::Sensor(s) => s.lock().report(),
            Served::Transform(t) => t.lock().report(),
            Served::Fusion(f) => f.lock().report(),
            Served::Cyclic(c) => c.lock().report(),
            Served::Command(c) => c.lock().report(),
        }
    }
}

/// Registers in `esgm` the sensor or unit declared as `name`, with `crunch` of work per
/// message; sensors and the planner produce only inside `window`. The trajectories
/// that use them are the system file's, created by whoever applies it.
pub fn serve<E: Esgm>(
    esgm: &E,
    name: &str,
    crunch: u64,
    window: &Arc<Window>,
) -> anyhow::Result<Served> {
    let (served, registration) = make(name, crunch, window)?;
    let registered = || format!("cannot register `{name}`");
    match registration {
        Registration::Sensor(iface) => {
            esgm.add_sensor_interface(name, MESSAGE_TYPE, iface).with_context(registered)?
        }
        Registration::Unit(inputs, unit) => {
            esgm.add_comp_unit(name, MESSAGE_TYPE, inputs, unit).with_context(registered)?
        }
    }
    Ok(served)
}

/// What a part registers.
enum Registration {
    Sensor(Arc<dyn SensorInterface>),
    /// Its input types and the unit.
    Unit(Vec<InputType>, Arc<dyn CompUnit>),
}

/// The part declared as `name`: its logic, and the sensor or unit wrapping it.
fn make(name: &str, crunch: u64, window: &Arc<Window>) -> anyhow::Result<(Served, Registration)> {
    let part = Part::of(name)
        .with_context(|| format!("`{name}` is no sensor or unit of the reference system"))?;
    let node = part.node();
    let message = || InputType::Type(MESSAGE_TYPE.to_owned());
    Ok(match node.kind {
        Kind::Sensor { .. } => {
            let sensor = Arc::new(Mutex::new(Sensor::new(node.name)));
            let s = Arc::clone(&sensor);
            let w = Arc::clone(window);
            let iface = move |qtime: Time| -> Result<EntityStructure, SensorError> {
                if !w.open(qtime) {
                    return Err(SensorError::ValueNotAvailable);
                }
                Ok(structure(&s.lock().fire(), qtime))
            };
            (Served::Sensor(sensor), Registration::Sensor(Arc::new(iface)))
        }
        Kind::Transform { input } => transform(node, input, name, crunch)?,
        Kind::Intersection { connections } => {
            let Some((input, _)) = connections.iter().find(|(_, output)| *output == name) else {
                bail!("`{name}` is no connection of node {}", node.name);
            };
            transform(node, input, name, crunch)?
        }
        Kind::Fusion { inputs } => {
            let fusion = Arc::new(Mutex::new(Fusion::new(node.name, inputs, crunch)));
            let f = Arc::clone(&fusion);
            // The sequence number of each input's message offered last.
            let offered: Mutex<[Option<u32>; 2]> = Mutex::new([None, None]);
            let unit =
                move |samples: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
                    let mut offered = offered.lock();
                    let mut fusion = f.lock();
                    let mut out = None;
                    for (i, s) in samples.iter().enumerate().take(2) {
                        let m = message_of(s)?;
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
            (Served::Fusion(fusion), Registration::Unit(vec![message(); 2], Arc::new(unit)))
        }
        Kind::Cyclic { inputs, .. } => {
            let cyclic = Arc::new(Mutex::new(Cyclic::new(node.name, &inputs, crunch)));
            let planner = Planner {
                cyclic: Arc::clone(&cyclic),
                offered: Mutex::new(vec![None; inputs.len()]),
                window: Arc::clone(window),
            };
            let types = vec![message(); inputs.len()];
            (Served::Cyclic(cyclic), Registration::Unit(types, Arc::new(planner)))
        }
        Kind::Command { input } => {
            let command = Arc::new(Mutex::new(Command::new(node.name, input)));
            let c = Arc::clone(&command);
            let unit = move |samples: &[Sample],
                             _q: Time|
                  -> Result<EntityStructure, ComputeError> {
                let m =
                    samples.first().map(message_of).ok_or(ComputeError::ValueNotAvailable)??;
                c.lock().on_input(&m);
                // A sink: nothing comes out.
                Err(ComputeError::ValueNotAvailable)
            };
            (Served::Command(command), Registration::Unit(vec![message()], Arc::new(unit)))
        }
    })
}

/// A transform (or an intersection's connection) of `node`, making `output` from
/// `input`.
fn transform(
    node: &'static Node,
    input: &'static str,
    output: &str,
    crunch: u64,
) -> anyhow::Result<(Served, Registration)> {
    let output = node
        .outputs()
        .into_iter()
        .find(|o| *o == output)
        .with_context(|| format!("node {} does not make `{output}`", node.name))?;
    let logic = Arc::new(Mutex::new(Transform::new(node.name, input, output, crunch)));
    let l = Arc::clone(&logic);
    let unit = move |samples: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        let m = samples.first().map(message_of).ok_or(ComputeError::ValueNotAvailable)??;
        Ok(structure(&l.lock().on_input(&m), now()))
    };
    let input_types = vec![InputType::Type(MESSAGE_TYPE.to_owned())];
    Ok((Served::Transform(logic), Registration::Unit(input_types, Arc::new(unit))))
}

/// The behavior planner as a temporal function: at each sample time of its generate
/// trajectory, the latest message of each of its inputs; it fires with what is new
/// since its last tick (sequence numbers tell), as upstream's timer does.
struct Planner {
    cyclic: Arc<Mutex<Cyclic>>,
    offered: Mutex<Vec<Option<u32>>>,
    window: Arc<Window>,
}

impl CompUnit for Planner {
    fn compute(&self, _inputs: &[Sample], _qtime: Time) -> Result<EntityStructure, ComputeError> {
        // Only sampled, through `compute_at`: a computed trajectory of it is a mistake.
        Err(ComputeError::OperationNotSupported)
    }

    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        if !self.window.open(t) {
            return Err(ComputeError::ValueNotAvailable);
        }
        let mut cyclic = self.cyclic.lock();
        let mut offered = self.offered.lock();
        for (i, s) in inputs.iter().enumerate().take(offered.len()) {
            let m = message_of(s)?;
            if offered[i] != Some(m.sequence()) {
                offered[i] = Some(m.sequence());
                cyclic.on_input(i, m);
            }
        }
        Ok(structure(&cyclic.on_timer(), t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_declared_name_is_a_part_of_its_node() {
        assert!(
            matches!(Part::of("FrontLidarDriver"), Some(Part::Sensor(n)) if n.name == "FrontLidarDriver")
        );
        let intersection = |name| Part::of(name).map(|p| p.node().name);
        assert_eq!(intersection("EuclideanClusterDetector"), Some("EuclideanClusterDetector"));
        assert_eq!(intersection("EuclideanIntersection"), Some("EuclideanClusterDetector"));
        assert!(matches!(Part::of("VehicleDBWSystem"), Some(Part::Unit(_))));
        assert!(Part::of("NoSuchNode").is_none());
    }

    /// Each node kind's part: a transform on every input, a fusion once both inputs are
    /// new, a sink that makes nothing, the planner ticking through its temporal
    /// function only inside the window.
    #[test]
    fn the_parts_do_what_their_nodes_do() {
        let window = Arc::new(Window::default());
        let part = |name: &str| make(name, 0, &window).unwrap();
        let unit = |r: Registration| match r {
            Registration::Unit(_, unit) => unit,
            Registration::Sensor(_) => panic!("a sensor"),
        };
        let fire = |s: &Served| match s {
            Served::Sensor(s) => Sample::new(Arc::new(structure(&s.lock().fire(), 1)), 1, 1),
            other => panic!("not a sensor: {other:?}"),
        };
        let (front, rear) = (fire(&part("FrontLidarDriver").0), fire(&part("RearLidarDriver").0));
        let transformer = unit(part("PointsTransformerFront").1);
        assert!(transformer.compute(std::slice::from_ref(&front), 2).is_ok());
        let fusion = unit(part("PointCloudFusion").1);
        assert!(fusion.compute(&[front.clone(), rear.clone()], 2).is_ok(), "both new");
        let again = fusion.compute(&[front.clone(), rear], 3);
        assert!(matches!(again, Err(ComputeError::ValueNotAvailable)), "neither new");
        let (sink, registration) = part("VehicleDBWSystem");
        let sunk = unit(registration).compute(std::slice::from_ref(&front), 2);
        assert!(matches!(sunk, Err(ComputeError::ValueNotAvailable)));
        assert_eq!(sink.report().received[0].1, 1);
        let (planner, registration) = part("BehaviorPlanner");
        let planner_unit = unit(registration);
        let six = vec![front; 6];
        let closed = planner_unit.compute_at(&six, 5);
        assert!(matches!(closed, Err(ComputeError::ValueNotAvailable)));
        window.set(1, 10);
        assert!(planner_unit.compute_at(&six, 5).is_ok());
        assert_eq!(planner.report().planner_fired.len(), 1);
        assert!(make("NoSuchNode", 0, &window).is_err());
    }
}
