//! The coordinator's registry: the catalog of names plus where each trajectory is
//! written. Pure state, no transport, so every rule is tested without shared memory.

use std::collections::BTreeMap;

use esgm_core::catalog::Catalog;
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind, TrajectorySource, TrajectorySpec};
use esgm_core::{EntityStructureType, TypeChecker, TypeRegistry};

use super::processes::ProcessTable;
use super::protocol::{
    Assignment, ControlError, PlacementRecord, Request, Response, TrajectoryRecord,
};
use crate::holdings::HoldingStats;

#[derive(Debug, Clone)]
struct Placement {
    writer: String,
    generation: u64,
    spec: TrajectorySpec,
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
        }
    }

    /// The catalog, read-only.
    pub fn catalog(&self) -> &Catalog {
        &self.catalog
    }

    /// Carries out one request.
    pub fn handle(&mut self, request: Request) -> Response {
        match self.apply(request) {
            Ok(r) => r,
            Err(e) => Response::Error(e),
        }
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
        let (writer, generation) =
            self.placement.get(name).map(|p| (p.writer.clone(), p.generation)).unwrap_or_default();
        Ok(TrajectoryRecord { info, types, writer, generation })
    }

    fn apply(&mut self, request: Request) -> Result<Response, ControlError> {
        Ok(match request {
            Request::Ping => Response::Pong {
                version: env!("CARGO_PKG_VERSION").to_owned(),
                pid: std::process::id(),
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
                let writer = match &spec.source {
                    TrajectorySource::Sampled { sensor, .. } => {
                        self.catalog.sensor(sensor).map(|s| s.host.clone()).unwrap_or(host)
                    }
                    TrajectorySource::Computed { unit, .. } => {
                        self.catalog.unit(unit).map(|u| u.host.clone()).unwrap_or(host)
                    }
                    _ => host,
                };
                let name = spec.name.clone();
                let generation = self.next_generation;
                self.next_generation += 1;
                self.catalog.insert_trajectory(resolved.info);
                self.placement.insert(name.clone(), Placement { writer, generation, spec });
                Response::Trajectory(self.record(&name)?)
            }
            Request::GetEntityTrajectoryStructure { name } => {
                Response::Trajectory(self.record(&name)?)
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
                self.placement
                    .iter()
                    .map(|(name, p)| PlacementRecord {
                        name: name.clone(),
                        writer: p.writer.clone(),
                        generation: p.generation,
                        type_name: self
                            .catalog
                            .trajectory(name)
                            .map(|t| t.type_name.clone())
                            .unwrap_or_default(),
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
        })
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
}
