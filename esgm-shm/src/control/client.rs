//! The client side of the control plane: asks the coordinator, with a deadline.

use crate::data_plane::service::ShmService;
use iceoryx2::port::notifier::Notifier;
use std::time::{Duration, Instant};

use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::client::{Client, RequestSendError};
use iceoryx2::port::{LoanError, ReceiveError};
use iceoryx2::prelude::{AllocationStrategy, NodeBuilder};
use iceoryx2::service::builder::request_response::RequestResponseOpenError;
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::request_response::PortFactory;

use super::protocol::{ControlError, Request, Response, decode, encode};
use crate::data_plane::capacity::DomainLimits;
use crate::data_plane::service::ShmNode;
use crate::data_plane::service_name::{NameError, control_service};
use esgm_core::esgm::{LimitReached, Peer, Unreachable};
use iceoryx2::service::port_factory::PortFactory as _;

/// A control call failed before an answer arrived.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ControlClientError {
    /// The domain cannot be part of a service name.
    #[error(transparent)]
    InvalidDomain(#[from] NameError),
    /// The iceoryx2 node could not be created.
    #[error("cannot create a node: {0}")]
    Node(#[source] NodeCreationFailure),
    /// No coordinator serves this domain; start one with `esgm up`.
    #[error("no coordinator is running for domain `{domain}` (start one with `esgm up`)")]
    NoCoordinator {
        /// The domain.
        domain: String,
    },
    /// The domain's control service is there but cannot be opened: made by another
    /// version of esgm, or left damaged by a crash. `esgm down` and `esgm up` make it
    /// anew.
    #[error(
        "the control service of domain `{domain}` cannot be opened (another esgm version made it, or a crash damaged it; restart the domain with `esgm down` and `esgm up`): {source}"
    )]
    ControlServiceUnusable {
        /// The domain.
        domain: String,
        /// iceoryx2's reason.
        source: RequestResponseOpenError,
    },
    /// iceoryx2's directory for nodes belongs to another user who did not open it:
    /// no process of this user can take part in any domain on this host until that
    /// user (or root) opens it, e.g. with `esgm up --allow-others` or `chmod 1777`.
    #[error(
        "cannot create a node: iceoryx2's directory {} is another user's and not open to you", dir.display()
    )]
    SharedDirClosed {
        /// The directory.
        dir: std::path::PathBuf,
    },
    /// The domain's coordinator runs as another user who did not open the domain to
    /// this one; ask for `esgm up --allow-group` or `--allow-others` (see
    /// [`crate::process::access`]).
    #[error(
        "the domain `{domain}` is another user's and not open to you (its coordinator can allow it: esgm up --allow-group or --allow-others)"
    )]
    NotAllowed {
        /// The domain.
        domain: String,
    },
    /// The domain's control service has as many clients as it admits (one per
    /// process; see [`crate::DomainLimits`]).
    #[error(transparent)]
    LimitReached(LimitReached),
    /// The client port could not be created.
    #[error("cannot create the control client: {0}")]
    Client(#[source] ClientCreateError),
    /// Loaning memory for a request failed.
    #[error("cannot loan a request: {0}")]
    Loan(#[source] LoanError),
    /// Sending the request failed.
    #[error("cannot send the request: {0}")]
    Send(#[source] RequestSendError),
    /// Receiving the answer failed.
    #[error("cannot receive the answer: {0}")]
    Receive(#[source] ReceiveError),
    /// No answer within the deadline: the coordinator is gone or stuck.
    #[error("the coordinator of domain `{domain}` did not answer within {timeout:?}")]
    Timeout {
        /// The domain.
        domain: String,
        /// The deadline.
        timeout: Duration,
    },
    /// No coordinator serves the domain any more (it stopped; its service lingers
    /// only while clients hold it). Known at once, without waiting for a deadline.
    #[error("no coordinator is serving domain `{domain}`")]
    NotServing {
        /// The domain.
        domain: String,
    },
    /// The request could not be encoded.
    #[error("malformed control message: {0}")]
    Malformed(#[source] serde_json::Error),
    /// The coordinator answered in a form this esgm cannot read: it is another esgm
    /// version. Use the same esgm for the coordinator and its clients.
    #[error(
        "protocol mismatch: the coordinator of domain `{domain}` answered in a form this esgm ({version}) cannot read; use the same esgm version for the coordinator and its clients ({source})"
    )]
    ProtocolMismatch {
        /// The domain.
        domain: String,
        /// This client's esgm version.
        version: &'static str,
        /// What could not be read.
        source: serde_json::Error,
    },
    /// This process's location thread, which makes the calls, has stopped or is stuck.
    #[error("the location thread is unavailable: {reason}")]
    LocationUnavailable {
        /// What happened.
        reason: Unreachable,
    },
    /// The coordinator answered with the seed's error.
    #[error(transparent)]
    Remote(#[from] ControlError),
}

impl From<ControlClientError> for Unreachable {
    /// The cause of an `Unavailable` error of the seed's operations: a call to the
    /// coordinator that failed, by what the caller can do about it.
    fn from(e: ControlClientError) -> Self {
        match e {
            ControlClientError::NoCoordinator { domain }
            | ControlClientError::NotServing { domain } => Unreachable::NoCoordinator { domain },
            ControlClientError::Timeout { timeout, .. } => {
                Unreachable::no_answer(Peer::Coordinator, timeout)
            }
            ControlClientError::LocationUnavailable { reason } => reason,
            ControlClientError::Remote(e) => Unreachable::refused(Peer::Coordinator, e),
            e
            @ (ControlClientError::ProtocolMismatch { .. } | ControlClientError::Malformed(_)) => {
                Unreachable::malformed(Peer::Coordinator, e)
            }
            e => Unreachable::transport(Peer::Coordinator, e),
        }
    }
}

/// Asks one domain's coordinator. Like every iceoryx2 port it stays on the thread that
/// made it.
#[derive(Debug)]
pub struct ControlClient {
    domain: String,
    client: Client<ShmService, [u8], (), [u8], ()>,
    service: PortFactory<ShmService, [u8], (), [u8], ()>,
    _node: ShmNode,
    /// Wakes the coordinator after each request (`None`: it polls for them).
    ring: Option<Notifier<ShmService>>,
    timeout: Duration,
}

impl ControlClientError {
    /// The error of a node that could not be created: [`Self::SharedDirClosed`] when
    /// iceoryx2's node directory is another user's and closed to this one (iceoryx2
    /// says only "internal error" then), else [`Self::Node`].
    pub fn node(e: NodeCreationFailure) -> Self {
        let [_, dir, _] = crate::process::access::shared_dirs();
        match crate::process::access::usable(&dir) {
            Ok(false) => Self::SharedDirClosed { dir },
            // Usable, or unknown: iceoryx2's own reason is all there is.
            _ => Self::Node(e),
        }
    }
}

impl ControlClient {
    /// Connects to the coordinator of `domain`; calls wait up to `timeout` for answers.
    pub fn connect(domain: &str, timeout: Duration) -> Result<Self, ControlClientError> {
        let name = control_service(domain)?;
        let node = NodeBuilder::new()
            .config(&crate::data_plane::service::node_config(
                crate::data_plane::service::Cleanup::None,
            ))
            .name(&crate::data_plane::service_name::node_name(domain, "control-client"))
            .create::<ShmService>()
            .map_err(ControlClientError::node)?;
        let service = node
            .service_builder(&name)
            .request_response::<[u8], [u8]>()
            .max_active_requests_per_client(4)
            .open()
            .map_err(|source| match source {
                RequestResponseOpenError::InsufficientPermissions => {
                    ControlClientError::NotAllowed { domain: domain.to_owned() }
                }
                RequestResponseOpenError::DoesNotExist => {
                    ControlClientError::NoCoordinator { domain: domain.to_owned() }
                }
                source => {
                    ControlClientError::ControlServiceUnusable { domain: domain.to_owned(), source }
                }
            })?;
        // A crashed process's client holds its room until someone cleans up after it.
        let lacks_room =
            |e: &ClientCreateError| *e == ClientCreateError::ExceedsMaxSupportedClients;
        let client = crate::data_plane::service::with_room(lacks_room, || {
            service
                .client_builder()
                .initial_max_slice_len(4096)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .create()
        })
        .map_err(|e| match e {
            ClientCreateError::ExceedsMaxSupportedClients => {
                ControlClientError::LimitReached(LimitReached::processes(
                    domain,
                    service
                        .static_config()
                        .max_clients()
                        .saturating_sub(16 + crate::data_plane::capacity::TOOL_RESERVE),
                ))
            }
            e => ControlClientError::Client(e),
        })?;
        let ring = super::server::open_control_wake(&node, domain, &DomainLimits::default())
            .and_then(|w| w.notifier_builder().create().map_err(|e| format!("{e:?}")))
            .map_err(|e| tracing::warn!(error = %e, "cannot ring the coordinator; it polls"))
            .ok();
        Ok(Self { domain: domain.to_owned(), client, service, _node: node, ring, timeout })
    }

    /// Sends `request` and waits for the answer (polling, often for its first 50 ms:
    /// iceoryx2 has no wake-up for a response); the seed's errors come back as
    /// [`ControlClientError::Remote`].
    pub fn call(&self, request: &Request) -> Result<Response, ControlClientError> {
        let bytes = encode(request).map_err(ControlClientError::Malformed)?;
        let loan = self.client.loan_slice_uninit(bytes.len()).map_err(ControlClientError::Loan)?;
        let pending = loan.write_from_slice(&bytes).send().map_err(ControlClientError::Send)?;
        if pending.number_of_server_connections() == 0 {
            return Err(ControlClientError::NotServing { domain: self.domain.clone() });
        }
        if let Some(ring) = &self.ring {
            if let Err(e) = ring.notify() {
                tracing::debug!(error = ?e, "cannot ring the coordinator; it looks soon anyway");
            }
        }
        let started = Instant::now();
        let deadline = started + self.timeout;
        let mut pause = Duration::from_micros(20);
        loop {
            if let Some(answer) = pending.receive().map_err(ControlClientError::Receive)? {
                let answer = decode::<Response>(answer.payload()).map_err(|source| {
                    ControlClientError::ProtocolMismatch {
                        domain: self.domain.clone(),
                        version: env!("CARGO_PKG_VERSION"),
                        source,
                    }
                })?;
                return match answer {
                    Response::Error(e) => Err(ControlClientError::Remote(e)),
                    ok => Ok(ok),
                };
            }
            if Instant::now() >= deadline {
                // A coordinator that crashed still counts as the server until someone
                // cleans up after it (nobody scans for dead nodes at connect): if
                // cleaning up leaves no server, nobody serves, which is not slowness.
                crate::control::server::log_cleanup(
                    crate::data_plane::service::cleanup_dead_nodes(),
                    crate::data_plane::service::CleanupReporter::Bystander,
                );
                if self.service.dynamic_config().number_of_servers() == 0 {
                    return Err(ControlClientError::NotServing { domain: self.domain.clone() });
                }
                return Err(ControlClientError::Timeout {
                    domain: self.domain.clone(),
                    timeout: self.timeout,
                });
            }
            std::thread::sleep(pause);
            pause = (pause * 2).min(answer_poll_cap(started.elapsed(), Duration::from_millis(2)));
        }
    }
}

/// The longest pause between two looks for an answer, `waited` into a call: the
/// coordinator's to a control call, or the processes' to an admin question (iceoryx2
/// has no wake-up for either). An answer usually comes within a few milliseconds (a
/// list of 1,000 trajectories takes about 3 ms to encode), and a pause of `slow` would
/// add up to `slow` to it: so pauses stay short for the first [`FAST_ANSWER`], and only
/// a slow answer is looked for every `slow`.
pub(crate) fn answer_poll_cap(waited: Duration, slow: Duration) -> Duration {
    if waited < FAST_ANSWER { Duration::from_micros(100) } else { slow }
}

/// How long a call looks for its answer often ([`answer_poll_cap`]).
const FAST_ANSWER: Duration = Duration::from_millis(50);
