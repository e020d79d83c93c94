//! Blocking adds across processes (T4): `add_blocking` on a replica of a primitive
//! trajectory returns the writer's own outcome — `Added`, `Held`, or the
//! `PolicyViolation` with its constraint — as it would in the writer's process.
//!
//! A non-blocking add only needs to reach the writer's inbox. A blocking one needs an
//! answer, so it is an iceoryx2 request (`esgm/<domain>:add/traj/<name>`): the
//! structure's codec bytes go to the writer's [`AddServer`], which the writer's
//! receiver thread serves — the client rings the inbox's wake-up service after
//! sending, so the writer wakes at once — and the answer is the gate's outcome,
//! serialized with the control protocol's encoding. The client polls for it with a
//! short backoff, up to [`BLOCKING_ADD_TIMEOUT`]: a blocking add is a rare,
//! synchronous call, not the data path. Its structure is copied into the request
//! (images included): use the non-blocking forms for streams.

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::codec;
use esgm_core::esgm::{Limit, Peer, Unreachable};
use esgm_core::{
    AddError, AddOutcome, EntityStructure, EntityTrajectoryStructure, InProcessTrajectory,
};
use iceoryx2::port::client::Client;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::{AllocationStrategy, ServiceName};
use iceoryx2::service::builder::request_response::{
    RequestResponseOpenError, RequestResponseOpenOrCreateError,
};
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::request_response::PortFactory;

use crate::control::protocol::{decode, encode};
use crate::data_plane::capacity::Readers;
use crate::data_plane::service::{EventSpec, OpenError, ShmNode, ShmService, with_room};
use crate::data_plane::service_name::{NameError, TrajectoryServiceNames};

/// The longest a blocking add waits for the writer's answer. The writer answers in
/// microseconds; waiting longer means it is gone or stuck, and the replica's lock is
/// held meanwhile.
pub(crate) const BLOCKING_ADD_TIMEOUT: Duration = Duration::from_secs(1);

/// Blocking adds one process may have in flight to one trajectory.
const MAX_ACTIVE_REQUESTS: usize = 4;

/// The largest answer (a gate's outcome: a policy violation names its constraint and
/// values): answers are loaned from a fixed-size pool, which costs the writer no
/// private memory per possible segment.
const MAX_ANSWER: usize = 16 * 1024;

type AddService = PortFactory<ShmService, [u8], (), [u8], ()>;

/// The blocking-add service of `trajectory` in `domain`.
fn add_service_name(domain: &str, trajectory: &str) -> Result<ServiceName, NameError> {
    Ok(*TrajectoryServiceNames::new(&format!("{domain}:add"), trajectory)?.data())
}

/// Every process using the trajectory may add blocking ([`Readers::ports`]).
fn open_service(
    node: &ShmNode,
    domain: &str,
    trajectory: &str,
    readers: Readers,
) -> Result<AddService, BlockingAddError> {
    let name = add_service_name(domain, trajectory).map_err(OpenError::from)?;
    let denied = |e: &RequestResponseOpenOrCreateError| {
        matches!(
            e,
            RequestResponseOpenOrCreateError::RequestResponseOpenError(
                RequestResponseOpenError::InsufficientPermissions
            )
        )
    };
    // In a domain shared with other users, a service just made by another user's
    // process is closed until its owner widens it.
    crate::data_plane::service::with_access(denied, || {
        node.service_builder(&name)
            .request_response::<[u8], [u8]>()
            .max_clients(readers.ports())
            .max_nodes(readers.nodes())
            .max_active_requests_per_client(MAX_ACTIVE_REQUESTS)
            .open_or_create()
    })
    .map_err(|e| match e {
        RequestResponseOpenOrCreateError::RequestResponseOpenError(
            RequestResponseOpenError::ExceedsMaxNumberOfNodes,
        ) => BlockingAddError::Open(OpenError::LimitReached(
            readers.reached(Limit::Adders, trajectory),
        )),
        e => BlockingAddError::Service(format!("{e:?}")),
    })
}

/// A blocking-add port could not be opened.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BlockingAddError {
    /// A service name or event service failed.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// The request-response service could not be opened.
    #[error("cannot open the blocking-add service: {0}")]
    Service(String),
    /// The client or server port could not be created.
    #[error("cannot create the blocking-add port: {0}")]
    Port(String),
}

/// The writer's end: answers blocking adds with its gate's outcome.
#[derive(Debug)]
pub(crate) struct AddServer {
    server: Server<ShmService, [u8], (), [u8], ()>,
    _service: AddService,
}

impl AddServer {
    /// Serves blocking adds to `trajectory`.
    pub fn open(
        node: &ShmNode,
        domain: &str,
        trajectory: &str,
        readers: Readers,
    ) -> Result<Self, BlockingAddError> {
        let service = open_service(node, domain, trajectory, readers)?;
        let server = service
            .server_builder()
            .initial_max_slice_len(MAX_ANSWER)
            .allocation_strategy(AllocationStrategy::Static)
            .create()
            .map_err(|e| BlockingAddError::Port(format!("{e:?}")))?;
        Ok(Self { server, _service: service })
    }

    /// Adds every waiting request's structure through `handle` (the writer's gate)
    /// and answers each with the outcome; returns how many there were.
    pub fn serve(&self, handle: &InProcessTrajectory) -> usize {
        let mut n = 0;
        loop {
            let request = match self.server.receive() {
                Ok(Some(r)) => r,
                Ok(None) => return n,
                Err(e) => {
                    tracing::warn!(trajectory = %handle.name(), error = ?e,
                        "cannot receive blocking adds");
                    return n;
                }
            };
            n += 1;
            let answer = match serve_request(handle, request.payload()) {
                Ok(bytes) => bytes,
                Err(e) => {
                    tracing::error!(error = %e, "cannot encode a blocking add's outcome");
                    continue;
                }
            };
            let sent =
                request.loan_slice_uninit(answer.len()).map_err(|e| format!("{e:?}")).and_then(
                    |loan| loan.write_from_slice(&answer).send().map_err(|e| format!("{e:?}")),
                );
            if let Err(e) = sent {
                tracing::warn!(trajectory = %handle.name(), error = %e,
                    "cannot answer a blocking add (the caller times out)");
            }
        }
    }
}

/// The writer's answer to one blocking add's bytes: the structure added through
/// `handle` (the writer's gate), the outcome encoded for the replica; bytes that are
/// not a structure are answered with why, and nothing is added. `Err`: the outcome
/// did not encode (no answer is sent; the caller times out).
///
/// Public and hidden for esgm-fuzz: the bytes are another process's, so the fuzzer
/// runs this, the code the writer runs, on hostile ones.
#[doc(hidden)]
pub fn serve_request(
    handle: &InProcessTrajectory,
    payload: &[u8],
) -> Result<Vec<u8>, serde_json::Error> {
    let outcome = match codec::decode_bytes(payload) {
        Ok(es) => handle.add_blocking(es),
        Err(e) => Err(AddError::Unavailable {
            trajectory: handle.name().to_owned(),
            reason: Unreachable::malformed(
                Peer::Writer,
                format!("a structure it cannot read: {e}"),
            ),
        }),
    };
    encode(&outcome)
}

/// The writer's answer to a blocking add of `trajectory`, as the replica reads it:
/// the gate's outcome, or [`AddError::Unavailable`] when the bytes are not an answer.
///
/// Public and hidden for esgm-fuzz: the bytes are the writer process's, so the
/// fuzzer runs this, the code the replica runs, on hostile ones.
#[doc(hidden)]
pub fn read_answer(trajectory: &str, answer: &[u8]) -> Result<AddOutcome, AddError> {
    decode::<Result<AddOutcome, AddError>>(answer).map_err(|e| AddError::Unavailable {
        trajectory: trajectory.to_owned(),
        reason: Unreachable::malformed(Peer::Writer, e),
    })?
}

/// The replica's end: sends a blocking add and waits for the writer's outcome.
#[derive(Debug)]
pub(crate) struct AddClient {
    client: Client<ShmService, [u8], (), [u8], ()>,
    /// Wakes the writer's receiver thread (it listens to the inbox's wake-up).
    ring: Notifier<ShmService>,
    service: AddService,
    trajectory: String,
}

impl AddClient {
    /// Opens the client of `trajectory`'s blocking adds; `wake` is the writer's inbox
    /// wake-up service.
    pub fn open(
        node: &ShmNode,
        domain: &str,
        trajectory: &str,
        readers: Readers,
        wake: &EventSpec,
    ) -> Result<Self, BlockingAddError> {
        // A crashed adder's ports hold their room until someone cleans up after it.
        let lacks_room =
            |e: &BlockingAddError| matches!(e, BlockingAddError::Open(e) if e.lacks_room());
        with_room(lacks_room, || {
            let service = open_service(node, domain, trajectory, readers)?;
            let client = service
                .client_builder()
                .initial_max_slice_len(4096)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .create()
                .map_err(|e| match e {
                    ClientCreateError::ExceedsMaxSupportedClients => BlockingAddError::Open(
                        OpenError::LimitReached(readers.reached(Limit::Adders, trajectory)),
                    ),
                    e => BlockingAddError::Port(format!("{e:?}")),
                })?;
            let ring = wake
                .open(node)?
                .notifier_builder()
                .create()
                .map_err(|e| OpenError::Notifier(e).as_limit(trajectory, readers))?;
            Ok(Self { client, ring, service, trajectory: trajectory.to_owned() })
        })
    }

    /// Adds `es` through the writer's gate and returns its outcome.
    pub fn add(&self, es: &Arc<EntityStructure>) -> Result<AddOutcome, AddError> {
        let unavailable = |reason: Unreachable| AddError::Unavailable {
            trajectory: self.trajectory.clone(),
            reason,
        };
        let transport = |detail: String| unavailable(Unreachable::transport(Peer::Writer, detail));
        let bytes = codec::encode(es).map_err(|e| transport(e.to_string()))?;
        // The writer opens its server when an adder first rings (see `Export`).
        let serving = || {
            iceoryx2::prelude::PortFactory::dynamic_config(&self.service).number_of_servers() > 0
        };
        if !super::import::writer_listens(serving, || self.ring.notify().map(|_| ())) {
            return Err(unavailable(Unreachable::no_answer(
                Peer::Writer,
                super::import::WRITER_OPENS,
            )));
        }
        let pending = self
            .client
            .loan_slice_uninit(bytes.len())
            .map_err(|e| transport(format!("cannot loan a request: {e:?}")))?
            .write_from_slice(&bytes)
            .send()
            .map_err(|e| transport(format!("cannot send: {e:?}")))?;
        if pending.number_of_server_connections() == 0 {
            return Err(transport("it stopped serving blocking adds".into()));
        }
        if let Err(e) = self.ring.notify() {
            tracing::debug!(error = ?e, "cannot wake the writer; it polls");
        }
        let deadline = Instant::now() + BLOCKING_ADD_TIMEOUT;
        let mut pause = Duration::from_micros(2);
        loop {
            match pending.receive() {
                Ok(Some(answer)) => return read_answer(&self.trajectory, answer.payload()),
                Ok(None) => {}
                Err(e) => return Err(transport(format!("cannot receive its answer: {e:?}"))),
            }
            if Instant::now() >= deadline {
                return Err(unavailable(Unreachable::no_answer(
                    Peer::Writer,
                    BLOCKING_ADD_TIMEOUT,
                )));
            }
            if pause < Duration::from_micros(50) {
                std::thread::yield_now();
            } else {
                std::thread::sleep(pause);
            }
            pause = (pause * 2).min(Duration::from_micros(500));
        }
    }
}
