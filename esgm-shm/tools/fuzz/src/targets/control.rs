//! The control protocol: requests as the coordinator decodes and carries them out,
//! and answers as a client decodes them ([`esgm_shm::control::Request`]).
//!
//! A decoded request goes to a real [`Registry`] (the coordinator's state and rules,
//! transport-free), kept for [`crate::target::RESET_EVERY`] cases so requests meet
//! the state earlier ones built. Promises checked beyond "no panic": what decodes
//! encodes and decodes again (a client's request reaches the coordinator), and every
//! answer the registry gives encodes and decodes as a [`Response`] (the client can
//! read it); after a request that changes the registry, its saved state encodes,
//! decodes and is restored (a crashed coordinator comes back from it); every seed
//! decodes.

use std::path::Path;
use std::sync::{LazyLock, Mutex, PoisonError};

use esgm_cli::config;
use esgm_core::TypeRegistry;
use esgm_core::esgm::InputType;
use esgm_core::library::predefined_types;
use esgm_shm::HoldingStats;
use esgm_shm::control::MAX_REQUEST_BYTES;
use esgm_shm::control::{
    ControlError, Origin, ProcessStatus, Registry, Request, Response, SaveHealth,
};
use esgm_shm::control::{decode, encode};
use esgm_shm::unstable::Snapshot;
use esgm_shm::unstable::changes_registry;

use crate::json::{json_tokens, mutate_json};
use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};
use crate::targets::configuration::seed_files;
use crate::text::mutate_text;

/// JSON's tokens and the protocol's variant names and fields.
static TOKENS: LazyLock<Vec<&str>> = LazyLock::new(|| {
    json_tokens(&[
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
    ])
});

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
        Request::ListPlacementsOf { names: vec!["robot_state".into(), "x".repeat(101)] },
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
    let seed = rng.pick(seeds);
    let mut data = match rng.below(20) {
        0 => {
            let n = rng.len(4096);
            rng.bytes(n)
        }
        1..=10 => mutate_json(rng, seed, seeds).unwrap_or_else(|| seed.clone()),
        11..=16 => {
            let mut data = seed.clone();
            mutate_text(rng, &mut data, seeds, &TOKENS);
            data
        }
        _ => {
            let mut data = seed.clone();
            mutate(rng, &mut data, seeds);
            data
        }
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
        let persist = changes_registry(&request);
        // A panic in an earlier case poisons the lock; the runner resets the registry.
        let mut registry = self.registry.lock().unwrap_or_else(PoisonError::into_inner);
        let response = registry.handle_from(request, origin);
        answer_is_readable(&response)?;
        if persist && !matches!(response, Response::Error(_)) {
            // The coordinator saves its state after such a request; a coordinator that
            // crashed must come back from it.
            let saved = encode(&registry.snapshot())
                .map_err(|e| Broken::new("the registry's state encodes", e))?;
            let read = decode::<Snapshot>(&saved)
                .map_err(|e| Broken::new("the registry's saved state decodes", e))?;
            Registry::restore(TypeRegistry::with_library(), read)
                .map_err(|e| Broken::new("a saved registry is restored", e))?;
        }
        Ok(())
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
        answers.push(Response::Pong {
            version: "0.1.0".into(),
            pid: u32::MAX,
            registry: u64::MAX,
            saves: SaveHealth { failures: u64::MAX, failing: Some("disk full".into()) },
        });
        answers.push(Response::Error(ControlError::NotSaved { reason: "ü".into() }));
        answers.push(Response::Error(ControlError::TooLarge { bytes: usize::MAX, max: 1 }));
        answers.push(Response::Error(ControlError::NotAllowed {
            reason: esgm_shm::control::Refusal::WriterLives {
                trajectory: "ü".into(),
                holder: u32::MAX,
                pid: 0,
            },
        }));
        answers.push(Response::Error(ControlError::IllegalName {
            what: "trajectory".into(),
            name: "a/b".into(),
            reason: esgm_shm::control::NameRule::BadCharacter('/'),
        }));
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutated requests must still decode often enough to reach the registry.
    #[test]
    fn many_mutated_requests_reach_the_registry() {
        let target = Requests::new().unwrap_or_else(|e| panic!("{e}"));
        let decoded = (0..1_000)
            .filter(|i| decode::<Request>(&target.input(&mut Rng::for_case(4, *i))).is_ok())
            .count();
        assert!(decoded > 100, "{decoded} of 1000 decoded");
    }
}
