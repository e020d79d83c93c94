//! The receiver thread: the one thread of a connection that wakes when another
//! process publishes something this process reads, and that handles it itself.
//!
//! It listens to the wake-up services of every mirrored trajectory ([`Mirrors`]: each
//! import's samples and violations, each primitive export's inbox) in one iceoryx2
//! `WaitSet`. When one fires, it takes what arrived and enters it where it belongs —
//! samples into their replica, whose subscribers and units are told from this
//! thread; other processes' adds through the writer's gate, whose tap publishes them
//! — without waking any other thread of esgm on the way. With the writer publishing
//! inline (see [`super::export`]), a structure crosses a process boundary with one
//! wake-up: this one.
//!
//! It rebuilds its listeners when the set of mirrors changes (a generation the
//! location bumps and then rings the receiver's *doorbell*, an event service of its
//! own), and pumps once then and at every [`RECHECK`] anyway, which bounds the delay
//! of a notify it could not hear (a service whose listener could not be made).

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::{
    CallbackProgression, NodeBuilder, NodeName, ServiceName, SignalHandlingMode, WaitSetBuilder,
};

use super::mirrors::SharedMirrors;
use super::shared_node::SharedNode;
use crate::service::{ShmNode, ShmService, open_event_service};

/// The longest the receiver sleeps before it pumps anyway and looks for a new set of
/// services (and for its stop).
pub(crate) const RECHECK: Duration = Duration::from_millis(250);

/// The receiver thread could not be started.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReceiverError {
    /// Its doorbell service could not be opened.
    #[error("cannot open the receiver's doorbell: {0}")]
    Doorbell(String),
    /// The thread could not be spawned.
    #[error("cannot start the receiver thread: {0}")]
    Spawn(#[source] std::io::Error),
}

/// The connection's handle on its receiver thread: stops and joins it when dropped.
#[derive(Debug)]
pub(crate) struct Receiver {
    mirrors: Arc<SharedMirrors>,
    thread: Option<JoinHandle<()>>,
}

impl Receiver {
    /// Starts the receiver thread on a node of its own named `node_name`; its doorbell
    /// is the event service `doorbell`, rung through `node`.
    pub fn start(
        node: &SharedNode,
        node_name: NodeName,
        doorbell: ServiceName,
        mirrors: Arc<SharedMirrors>,
    ) -> Result<Self, ReceiverError> {
        let notifier = node.with(|node| {
            open_event_service(node, &doorbell)
                .map_err(|e| ReceiverError::Doorbell(e.to_string()))?
                .notifier_builder()
                .create()
                .map_err(|e| ReceiverError::Doorbell(format!("{e:?}")))
        })?;
        mirrors.set_doorbell(notifier);
        let shared = Arc::clone(&mirrors);
        let thread = std::thread::Builder::new()
            .name("esgm-receiver".to_owned())
            .spawn(move || run(&node_name, &doorbell, &shared))
            .map_err(ReceiverError::Spawn)?;
        Ok(Self { mirrors, thread: Some(thread) })
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.mirrors.stop();
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                tracing::error!("the receiver thread panicked");
            }
        }
    }
}

fn run(node_name: &NodeName, doorbell: &ServiceName, mirrors: &SharedMirrors) {
    let node = match NodeBuilder::new()
        .name(node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ShmService>()
    {
        Ok(node) => node,
        Err(e) => {
            tracing::error!(error = ?e,
                "the receiver has no node; samples from other processes are polled every {RECHECK:?}");
            return poll(mirrors);
        }
    };
    while !mirrors.stopped() {
        let generation = mirrors.generation();
        let mut services = mirrors.lock().wake_services();
        services.push(*doorbell);
        let listeners = listen(&node, &services);
        // What arrived before these listeners existed would not wake them.
        let mut locked = mirrors.lock();
        locked.welcome(None);
        locked.pump();
        drop(locked);
        wait_while_unchanged(mirrors, generation, &listeners);
    }
}

/// Without a node: pump at every [`RECHECK`] until stopped.
fn poll(mirrors: &SharedMirrors) {
    while !mirrors.stopped() {
        std::thread::sleep(RECHECK);
        mirrors.lock().pump();
        if mirrors.panic_requested() {
            #[allow(clippy::panic, reason = "test support: a panic asked for")]
            {
                panic!("esgm-receiver: panic injected by a test");
            }
        }
    }
}

/// One listener per service; a service that cannot be listened to is pumped at every
/// [`RECHECK`] only (logged once per list).
fn listen(node: &ShmNode, services: &[ServiceName]) -> Vec<(ServiceName, Listener<ShmService>)> {
    let mut listeners = Vec::with_capacity(services.len());
    for service in services {
        let listener = open_event_service(node, service)
            .map_err(|e| e.to_string())
            .and_then(|s| s.listener_builder().create().map_err(|e| format!("{e:?}")));
        match listener {
            Ok(l) => listeners.push((*service, l)),
            Err(e) => tracing::warn!(service = service.as_str(), error = %e,
                "cannot listen to a service; what it carries is polled every {RECHECK:?}"),
        }
    }
    listeners
}

/// Sleeps on every listener and pumps on each wake-up (and at least every [`RECHECK`])
/// until the set of mirrors changes or the receiver is stopped.
fn wait_while_unchanged(
    mirrors: &SharedMirrors,
    generation: u64,
    listeners: &[(ServiceName, Listener<ShmService>)],
) {
    let waitset = match WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ShmService>()
    {
        Ok(w) => w,
        Err(e) => {
            tracing::warn!(error = ?e, "cannot create a WaitSet; polling");
            while !mirrors.stopped() && mirrors.generation() == generation {
                std::thread::sleep(RECHECK);
                mirrors.lock().pump();
            }
            return;
        }
    };
    let guards: Vec<_> = listeners
        .iter()
        .enumerate()
        .filter_map(|(i, l)| {
            waitset
                .attach_notification(&l.1)
                .map(|g| (i, g))
                .map_err(|e| tracing::warn!(error = ?e, "cannot attach a listener; polling it"))
                .ok()
        })
        .collect();
    let mut fired = Vec::with_capacity(listeners.len());
    let mut rung = Vec::with_capacity(listeners.len());
    while !mirrors.stopped() && mirrors.generation() == generation {
        fired.clear();
        let waited = waitset.wait_and_process_once_with_timeout(
            |id| {
                fired.extend(guards.iter().filter(|(_, g)| id.has_event_from(g)).map(|(i, _)| *i));
                CallbackProgression::Continue
            },
            RECHECK,
        );
        if let Err(e) = waited {
            tracing::warn!(error = ?e, "the WaitSet failed; polling");
            std::thread::sleep(RECHECK);
        }
        // Consume the notifications, so that the next notify wakes again.
        rung.clear();
        for &i in &fired {
            if let Some((service, l)) = listeners.get(i) {
                rung.push(*service);
                if let Err(e) = l.try_wait(|_| {}) {
                    tracing::debug!(error = ?e, "cannot consume a notification");
                }
            }
        }
        let mut locked = mirrors.lock();
        if !rung.is_empty() {
            locked.welcome(Some(&rung));
        }
        locked.pump();
        drop(locked);
        if mirrors.panic_requested() {
            #[allow(clippy::panic, reason = "test support: a panic asked for")]
            {
                panic!("esgm-receiver: panic injected by a test");
            }
        }
    }
}
