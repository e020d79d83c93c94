//! The coordinator: serves the [`Registry`] on `esgm/<domain>/control`, and cleans up
//! after processes that died.

use crate::service::ShmService;
use iceoryx2::port::listener::Listener;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::node::{NodeCreationFailure, NodeState};
use iceoryx2::port::server::Server;
use iceoryx2::port::{LoanError, ReceiveError, SendError};
use iceoryx2::prelude::{AllocationStrategy, NodeBuilder};
use iceoryx2::service::builder::request_response::RequestResponseCreateError;
use iceoryx2::service::port_factory::request_response::PortFactory;
use iceoryx2::service::port_factory::server::ServerCreateError;

use super::protocol::{ControlError, Request, Response, decode, encode};
use super::registry::Registry;
use crate::service::ShmNode;
use crate::service_name::{NameError, control_service};

/// Room for this many clients (processes and their threads) in one system.
pub const MAX_CLIENTS: usize = 128;

/// The coordinator could not start or serve.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CoordinatorError {
    /// The domain cannot be part of a service name.
    #[error(transparent)]
    InvalidDomain(#[from] NameError),
    /// The iceoryx2 node could not be created (shared memory unavailable?).
    #[error("cannot create the coordinator's node: {0}")]
    Node(#[source] NodeCreationFailure),
    /// The control service exists: another coordinator serves this domain.
    #[error("a coordinator already serves domain `{domain}` (or its service is stale): {source}")]
    AlreadyRunning {
        /// The domain.
        domain: String,
        /// iceoryx2's reason.
        source: RequestResponseCreateError,
    },
    /// The server port could not be created.
    #[error("cannot create the control server: {0}")]
    Server(#[source] ServerCreateError),
    /// Receiving a request failed.
    #[error("cannot receive a request: {0}")]
    Receive(#[source] ReceiveError),
    /// Loaning memory for a response failed.
    #[error("cannot loan a response: {0}")]
    Loan(#[source] LoanError),
    /// Sending a response failed.
    #[error("cannot send a response: {0}")]
    Send(#[source] SendError),
    /// The coordinator's thread could not be started.
    #[error("cannot start the coordinator thread: {0}")]
    Spawn(#[source] std::io::Error),
    /// The coordinator's thread ended before it was serving.
    #[error("the coordinator thread stopped while starting")]
    Stopped,
}

/// The longest an idle coordinator sleeps before it looks at its stop flag.
const IDLE_WAIT: Duration = Duration::from_millis(100);

/// Opens the control wake-up of `domain`, sized for every client.
pub(crate) fn open_control_wake(
    node: &ShmNode,
    domain: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ShmService>, String> {
    let name = crate::service_name::control_wake_service(domain).map_err(|e| e.to_string())?;
    node.service_builder(&name)
        .event()
        .max_notifiers(MAX_CLIENTS + 16)
        .max_listeners(4)
        .max_nodes(MAX_CLIENTS + 16)
        .open_or_create()
        .map_err(|e| format!("{e:?}"))
}

/// Serves one domain's registry.
#[derive(Debug)]
pub struct Coordinator {
    domain: String,
    registry: Registry,
    server: Server<ShmService, [u8], (), [u8], ()>,
    _service: PortFactory<ShmService, [u8], (), [u8], ()>,
    node: ShmNode,
    /// Rung by clients after each request (`None`: polled, if it could not be made).
    wake: Option<Listener<ShmService>>,
    served: u64,
    failures: u64,
    shutdown_requested: bool,
}

impl Coordinator {
    /// Starts a coordinator for `domain` with `registry`. Dead nodes left by crashed
    /// processes are cleaned first.
    pub fn create(domain: &str, registry: Registry) -> Result<Self, CoordinatorError> {
        let name = control_service(domain)?;
        let node = NodeBuilder::new()
            .name(&crate::service_name::node_name(domain, "coordinator"))
            .create::<ShmService>()
            .map_err(CoordinatorError::Node)?;
        cleanup_dead_nodes();
        let service = node
            .service_builder(&name)
            .request_response::<[u8], [u8]>()
            .max_clients(MAX_CLIENTS)
            .max_active_requests_per_client(4)
            .create()
            .map_err(|source| CoordinatorError::AlreadyRunning {
                domain: domain.to_owned(),
                source,
            })?;
        let server = service
            .server_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(CoordinatorError::Server)?;
        let wake = open_control_wake(&node, domain)
            .and_then(|w| w.listener_builder().create().map_err(|e| format!("{e:?}")))
            .map_err(|e| tracing::warn!(error = %e, "no control wake-up; the coordinator polls"))
            .ok();
        tracing::info!(domain, "coordinator serving");
        Ok(Self {
            wake,
            domain: domain.to_owned(),
            registry,
            server,
            _service: service,
            node,
            served: 0,
            failures: 0,
            shutdown_requested: false,
        })
    }

    /// The domain served.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// The registry, read-only.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// Requests answered so far.
    pub fn served(&self) -> u64 {
        self.served
    }

    /// The coordinator's iceoryx2 node.
    pub fn node(&self) -> &ShmNode {
        &self.node
    }

    /// Answers every request waiting now; returns how many were answered.
    ///
    /// One bad request or one failed answer (a client that vanished, no memory for a
    /// large response) is logged and counted in [`Coordinator::failures`], never fatal:
    /// the coordinator keeps serving everyone else and keeps cleaning up.
    pub fn serve_pending(&mut self) -> Result<usize, CoordinatorError> {
        let mut n = 0;
        loop {
            let active = match self.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => return Ok(n),
                Err(e) => {
                    self.fail(CoordinatorError::Receive(e));
                    return Ok(n);
                }
            };
            let response = match decode::<Request>(active.payload()) {
                Ok(Request::Shutdown) => {
                    tracing::info!(domain = %self.domain, "shutdown requested");
                    self.shutdown_requested = true;
                    Response::Done
                }
                Ok(request) => self.registry.handle(request),
                Err(e) => {
                    tracing::warn!(error = %e, "malformed control request");
                    Response::Error(ControlError::BadRequest { reason: e.to_string() })
                }
            };
            let bytes = match encode(&response) {
                Ok(b) => b,
                Err(e) => {
                    let fallback =
                        Response::Error(ControlError::BadRequest { reason: e.to_string() });
                    encode(&fallback).unwrap_or_default()
                }
            };
            let sent = match active.loan_slice_uninit(bytes.len()) {
                Ok(loan) => loan.write_from_slice(&bytes).send().map_err(CoordinatorError::Send),
                Err(e) => Err(CoordinatorError::Loan(e)),
            };
            match sent {
                Ok(()) => {
                    n += 1;
                    self.served += 1;
                }
                Err(e) => self.fail(e),
            }
        }
    }

    /// True once a client asked the coordinator to stop ([`Request::Shutdown`]).
    pub fn shutdown_requested(&self) -> bool {
        self.shutdown_requested
    }

    /// Requests that could not be answered (logged where they failed).
    pub fn failures(&self) -> u64 {
        self.failures
    }

    fn fail(&mut self, e: CoordinatorError) {
        self.failures += 1;
        tracing::warn!(error = %e, failures = self.failures, "control request not answered");
    }

    /// Starts a coordinator for `domain` on a thread of its own (iceoryx2 ports stay on
    /// the thread that made them); it serves until the returned handle is dropped.
    pub fn spawn(domain: &str, registry: Registry) -> Result<CoordinatorThread, CoordinatorError> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready, started) = std::sync::mpsc::sync_channel(1);
        let (d, s) = (domain.to_owned(), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name(format!("esgm-coordinator-{domain}"))
            .spawn(move || {
                let mut coordinator = match Coordinator::create(&d, registry) {
                    Ok(c) => c,
                    Err(e) => {
                        let _ = ready.send(Err(e));
                        return;
                    }
                };
                let _ = ready.send(Ok(()));
                if let Err(e) = coordinator.run(&s, Duration::from_secs(1)) {
                    tracing::error!(error = %e, "coordinator stopped");
                }
            })
            .map_err(CoordinatorError::Spawn)?;
        match started.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => return Err(CoordinatorError::Stopped),
        }
        Ok(CoordinatorThread { domain: domain.to_owned(), stop, thread: Some(thread) })
    }

    /// Sleeps up to `timeout` on the control wake-up (or, without it, polls).
    fn sleep(&self, timeout: Duration) {
        let Some(wake) = &self.wake else {
            return std::thread::sleep(timeout.min(Duration::from_millis(1)));
        };
        if let Err(e) = crate::wait::timed_wait(wake, timeout) {
            tracing::warn!(error = ?e, "cannot wait for requests; polling");
            std::thread::sleep(timeout.min(Duration::from_millis(1)));
        }
    }

    /// Serves until `stop` is set — asleep while nobody asks: clients ring the
    /// coordinator's wake-up after each request — and cleans up dead processes'
    /// resources every `cleanup_every`.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        cleanup_every: Duration,
    ) -> Result<(), CoordinatorError> {
        let mut next_cleanup = Instant::now() + cleanup_every;
        let mut leaving: Option<Instant> = None;
        while !stop.load(Ordering::Relaxed) {
            // After a shutdown request, answer for a moment longer: the answer lives in
            // this server's memory until the client has taken it.
            if self.shutdown_requested {
                let since = *leaving.get_or_insert_with(Instant::now);
                if since.elapsed() > Duration::from_millis(300) {
                    break;
                }
            }
            if self.serve_pending()? == 0 {
                // Asleep until a client rings (after sending), the next cleanup, or a
                // look at `stop`.
                let until_cleanup = next_cleanup.saturating_duration_since(Instant::now());
                self.sleep(until_cleanup.min(IDLE_WAIT));
            }
            if Instant::now() >= next_cleanup {
                let removed = cleanup_dead_nodes();
                if removed > 0 {
                    tracing::info!(removed, "cleaned up resources of dead processes");
                }
                next_cleanup = Instant::now() + cleanup_every;
            }
        }
        Ok(())
    }
}

/// A coordinator serving on its own thread ([`Coordinator::spawn`]); dropping it stops
/// and joins the thread.
#[derive(Debug)]
pub struct CoordinatorThread {
    domain: String,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl CoordinatorThread {
    /// The domain served.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// True once the coordinator has stopped serving (after [`Request::Shutdown`], or
    /// an error it logged): the process hosting it can wind down.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(std::thread::JoinHandle::is_finished)
    }
}

impl Drop for CoordinatorThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Removes what crashed processes left in shared memory (iceoryx2's dead-node cleanup);
/// returns how many dead nodes were cleaned.
pub fn cleanup_dead_nodes() -> usize {
    let mut removed = 0;
    let result = iceoryx2::node::Node::<ShmService>::list(
        iceoryx2::config::Config::global_config(),
        |state| {
            if let NodeState::Dead(view) = state {
                if view.try_remove_stale_resources().is_ok() {
                    removed += 1;
                }
            }
            iceoryx2::prelude::CallbackProgression::Continue
        },
    );
    if let Err(e) = result {
        tracing::warn!(error = %e, "cannot list nodes for cleanup");
    }
    removed
}
