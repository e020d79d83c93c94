//! The control protocol: requests as the coordinator decodes and carries them out,
//! and answers as a client decodes them ([`esgm_shm::control::protocol`]).
//!
//! A decoded request goes to a real [`Registry`] (the coordinator's state and rules,
//! transport-free), kept for [`crate::target::RESET_EVERY`] cases so requests meet
//! the state earlier ones built. Promises checked beyond "no panic": what decodes
//! encodes and decodes again (a client's request reaches the coordinator), and every
//! answer the registry gives encodes and decodes as a [`Response`] (the client can
//! read it); every seed decodes.

use std::path::Path;
use std::sync::{Mutex, PoisonError};

use esgm_cli::config;
use esgm_core::TypeRegistry;
use esgm_core::esgm::InputType;
use esgm_core::library::predefined_types;
use esgm_shm::HoldingStats;
use esgm_shm::control::limits::MAX_REQUEST_BYTES;
use esgm_shm::control::protocol::{decode, encode};
use esgm_shm::control::{ControlError, Origin, ProcessStatus, Registry, Request, Response};

use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};
use crate::targets::configuration::seed_files;
use crate::text::mutate_text;

/// JSON's punctuation and words, and the protocol's variant names.
const JSON_TOKENS: [&str; 30] = [
    "{",
    "}",
    "[",
    "]",
    "\"",
    ":",
    ",",
    "null",
    "true",
    "false",
    "\"\\u0000\"",
    "\"\\ud800\"",
    "\\",
    "\"\\uDBFF\\uDFFF\"",
    "{\"Ping\":null}",
    "\"Ping\"",
    "\"Shutdown\"",
    "\"CreateTrajectory\"",
    "\"DestroyEntityTrajectoryStructure\"",
    "\"ReportProcess\"",
    "\"DeclareProcess\"",
    "\"AddCompUnit\"",
    "\"GetTypeDefinitions\"",
    "\"Sort\"",
    "\"Type\"",
    "\"pid\":1",
    "\"name\":\"\"",
    "\"name\":\"a/b\"",
    "1e999",
    "-0.0",
];

/// Valid requests: every kind, with the library's types and the configuration seeds'
/// types, processes and trajectories, in an order that builds a registry up.
fn requests() -> Result<Vec<Request>, Broken> {
    let mut out = vec![Request::Ping, Request::ListEntityStructureTypes];
    for t in predefined_types() {
        out.push(Request::GetEntityStructureType { type_name: t.name.clone() });
        out.push(Request::GetTypeDefinitions { type_name: t.name.clone() });
        out.push(Request::CreateEntityStructureType { type_name: t.name.clone(), entity_type: t });
    }
    for (file, text) in seed_files() {
        let plan = config::parse(file, text, Path::new("."))
            .map_err(|e| Broken::new("a configuration seed parses", e))?;
        for item in plan.types {
            let (type_name, entity_type) = item.what;
            out.push(Request::CreateEntityStructureType { type_name, entity_type });
        }
        for item in plan.workers {
            out.push(Request::DeclareProcess { spec: item.what.spec });
        }
        for item in plan.trajectories {
            let host = item.what.writer.unwrap_or_else(|| "esgm-fuzz".to_owned());
            out.push(Request::CreateTrajectory { spec: item.what.spec, host });
        }
    }
    let host = || "camera-camera".to_owned();
    out.extend([
        Request::AddSensorInterface {
            sensor: "camera".into(),
            type_name: "Image".into(),
            host: host(),
        },
        Request::AddCompUnit {
            name: "BlobDetection".into(),
            type_name: "BlobSeq".into(),
            input_types: vec![InputType::Type("Image".into())],
            host: host(),
        },
        Request::GetEntityTrajectoryStructure { name: "robot_state".into() },
        Request::ListTrajectories,
        Request::ListSensors,
        Request::ListCompUnits,
        Request::ListPlacements,
        Request::Assignments { host: host() },
        Request::ReportHoldings { host: host(), stats: HoldingStats::default() },
        Request::ListHoldings,
        Request::ListProcesses,
        Request::ReportProcess {
            name: "camera-camera".into(),
            status: ProcessStatus {
                pid: Some(4242),
                restarts: 1,
                last_exit: Some("signal: 9 (SIGKILL)".into()),
            },
        },
        Request::RemoveProcess { name: "unit-detector".into() },
        Request::DestroyEntityTrajectoryStructure { name: "blobs".into() },
        Request::RemoveCompUnit { name: "BlobDetection".into() },
        Request::RemoveSensorInterface { sensor: "camera".into() },
        Request::DestroyEntityStructureType { type_name: "Detection".into() },
        Request::Shutdown,
    ]);
    Ok(out)
}

fn request_bytes(request: &Request) -> Result<Vec<u8>, Broken> {
    encode(request).map_err(|e| Broken::new("a decoded request encodes again", e))
}

fn response_bytes(response: &Response) -> Result<Vec<u8>, Broken> {
    encode(response).map_err(|e| Broken::new("every answer encodes", e))
}

/// A protocol input: a seed mutated as text or as bytes, or random bytes; never more
/// than the coordinator decodes (it refuses larger requests unread).
fn control_input(rng: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    let mut data = if rng.chance(5) {
        let n = rng.len(4096);
        rng.bytes(n)
    } else {
        let mut data = rng.pick(seeds).clone();
        if rng.chance(75) {
            mutate_text(rng, &mut data, seeds, &JSON_TOKENS);
        } else {
            mutate(rng, &mut data, seeds);
        }
        data
    };
    data.truncate(MAX_REQUEST_BYTES);
    data
}

fn answer_is_readable(response: &Response) -> Result<(), Broken> {
    let bytes = response_bytes(response)?;
    decode::<Response>(&bytes).map_err(|e| Broken::new("every answer decodes as a Response", e))?;
    Ok(())
}

/// The request target: what the coordinator does with a request's bytes.
#[derive(Debug)]
pub struct Requests {
    seeds: Vec<Vec<u8>>,
    registry: Mutex<Registry>,
}

fn new_registry() -> Registry {
    Registry::new(TypeRegistry::with_library())
}

impl Requests {
    /// The seed requests, encoded.
    pub fn new() -> Result<Self, Broken> {
        let seeds = requests()?.iter().map(request_bytes).collect::<Result<_, _>>()?;
        Ok(Self { seeds, registry: Mutex::new(new_registry()) })
    }
}

impl Target for Requests {
    fn name(&self) -> &'static str {
        "request"
    }

    fn about(&self) -> &'static str {
        "control protocol decode::<Request>, then the coordinator's Registry::handle_from"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        control_input(rng, &self.seeds)
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        let Ok(request) = decode::<Request>(input) else { return Ok(()) };
        let wire = request_bytes(&request)?;
        decode::<Request>(&wire).map_err(|e| Broken::new("a re-encoded request decodes", e))?;
        // Now and then as the coordinator's own supervisor, which may report processes.
        let origin = if input.len() % 4 == 0 { Origin::Coordinator } else { Origin::Unknown };
        // A panic in an earlier case poisons the lock; the runner resets the registry.
        let response = self
            .registry
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .handle_from(request, origin);
        answer_is_readable(&response)
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        decode::<Request>(seed).map_err(|e| Broken::new("a valid request decodes", e))?;
        self.run(seed)
    }

    fn reset(&self) {
        *self.registry.lock().unwrap_or_else(PoisonError::into_inner) = new_registry();
    }
}

/// The response target: what a client does with an answer's bytes.
#[derive(Debug)]
pub struct Responses {
    seeds: Vec<Vec<u8>>,
}

impl Responses {
    /// The registry's answers to the seed requests, and a few made by hand.
    pub fn new() -> Result<Self, Broken> {
        let mut registry = new_registry();
        let mut answers: Vec<Response> =
            requests()?.into_iter().map(|r| registry.handle_from(r, Origin::Coordinator)).collect();
        answers.push(Response::Pong { version: "0.1.0".into(), pid: u32::MAX });
        answers.push(Response::Error(ControlError::TooLarge { bytes: usize::MAX, max: 1 }));
        answers.push(Response::Error(ControlError::BadRequest { reason: "ü".into() }));
        let seeds = answers.iter().map(response_bytes).collect::<Result<_, _>>()?;
        Ok(Self { seeds })
    }
}

impl Target for Responses {
    fn name(&self) -> &'static str {
        "response"
    }

    fn about(&self) -> &'static str {
        "control protocol decode::<Response>, as a client reads an answer"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        control_input(rng, &self.seeds)
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        match decode::<Response>(input) {
            Ok(response) => answer_is_readable(&response),
            Err(_) => Ok(()),
        }
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        decode::<Response>(seed).map_err(|e| Broken::new("a valid answer decodes", e))?;
        self.run(seed)
    }
}
