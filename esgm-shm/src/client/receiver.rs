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
//! wake-up: this one, or the one of a thread that waits on the writer itself.
//!
//! While a thread of this connection sleeps on an import's futex word, it feeds that
//! import itself once woken, and the writer skips the notify that would wake this
//! thread too ([`super::coverage`]): this thread's listener on the import's samples is
//! counted in the word from after it exists until before it goes.
//!
//! Cost proportional to use: a wake-up serves the one mirror its service belongs to
//! ([`Route`]), looked up by the WaitSet's attachment id, under that mirror's own lock,
//! whatever the number of mirrors. When the set changes (a generation the location bumps and then rings the
//! receiver's *doorbell*, an event service of its own), it listens to the services
//! that came and stops listening to those that went, keeping the others' listeners,
//! and serves the new ones once. Services it could not listen to are served every
//! [`RECHECK`], and everything every [`SWEEP`], which bounds the delay of a notify
//! that was lost.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::{
    CallbackProgression, NodeBuilder, NodeName, ServiceName, SignalHandlingMode,
    WaitSetAttachmentId, WaitSetBuilder,
};

use super::mirrors::{Route, SharedMirrors};
use super::shared_node::SharedNode;
use crate::data_plane::capacity::EventCapacity;
use crate::data_plane::service::{EventSpec, ShmNode, ShmService};

/// The longest the receiver sleeps before it pumps anyway and looks for a new set of
/// services (and for its stop).
/// As long as a [`SWEEP`]: one wake-up of an idle receiver (about 100 µs, a look at
/// every mirror) every five seconds.
pub(crate) const RECHECK: Duration = Duration::from_secs(5);

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
        let doorbell = EventSpec { name: doorbell, capacity: EventCapacity::own() };
        let notifier = node.with(|node| {
            doorbell
                .open(node)
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

/// Puts the calling thread (the receiver) in `SCHED_BATCH`: the same share of the CPU
/// as any thread, but its wake-ups never preempt a running thread.
///
/// A sample written in another process can wake two threads here at once: a
/// subscription or worker that waits on the writer itself (on the trajectory's futex
/// word), and this thread (on the iceoryx2 event), which feeds the replica for
/// everything that does not wait. (The writer skips the notify when every connection
/// listening has such a thread asleep, [`super::coverage`]; not, for instance, while
/// another connection reads the trajectory without waiting.) On a busy core, this thread preempting the reader that is taking the
/// sample cost every hop of `connect-small` (event) about 4 µs, a quarter of it
/// (16.5 µs → 12.4 µs in the same pinned setting, BENCHMARKS.md). A batch thread
/// still runs as soon as the core is free, and gets its fair share under load, so the
/// replica is fed as before.
fn never_preempt_on_wake_up() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: a valid sched_param for this thread's id; SCHED_BATCH needs no privilege.
    let set = unsafe { libc::sched_setscheduler(libc::gettid(), libc::SCHED_BATCH, &param) };
    if set != 0 {
        tracing::debug!(error = %std::io::Error::last_os_error(),
            "the receiver thread stays a normal thread");
    }
}

fn run(node_name: &NodeName, doorbell: &EventSpec, mirrors: &SharedMirrors) {
    never_preempt_on_wake_up();
    let node = match NodeBuilder::new()
        .config(&crate::data_plane::service::node_config(crate::data_plane::service::Cleanup::None))
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
    // Listeners live across changes of the set: a change opens the new services' and
    // drops the gone ones', never all of them again.
    let mut listening: HashMap<ServiceName, Heard> = HashMap::new();
    let bell = match listener(&node, doorbell) {
        Ok(l) => Some(l),
        Err(e) => {
            tracing::warn!(error = %e, "the receiver has no doorbell; it looks for changes every {RECHECK:?}");
            None
        }
    };
    while !mirrors.stopped() {
        let generation = mirrors.generation();
        let wanted = mirrors.wake_routes();
        let names: HashSet<ServiceName> = wanted.iter().map(|(spec, _)| spec.name).collect();
        listening.retain(|name, _| names.contains(name));
        let mut fresh = Vec::new();
        let mut unheard = Vec::new();
        for (spec, route) in &wanted {
            if listening.contains_key(&spec.name) {
                continue;
            }
            match listener(&node, spec) {
                Ok(listener) => {
                    // Counted once it listens; served once below, after the count.
                    let receiving = route.receiving(spec);
                    listening.insert(spec.name, Heard { _receiving: receiving, listener });
                    fresh.push(route.clone());
                }
                Err(e) => {
                    tracing::warn!(service = spec.name.as_str(), error = %e,
                        "cannot listen to a service; what it carries is polled every {RECHECK:?}");
                    unheard.push(route.clone());
                }
            }
        }
        let routes: HashMap<ServiceName, Route> =
            wanted.into_iter().map(|(spec, route)| (spec.name, route)).collect();
        // What arrived before the new listeners existed would not wake them.
        for route in &fresh {
            route.serve(false);
        }
        for route in &unheard {
            route.serve(true);
        }
        let set = Listening { listeners: &listening, routes: &routes, unheard: &unheard };
        wait_while_unchanged(mirrors, generation, bell.as_ref(), &set);
    }
}

/// Without a node: pump at every [`RECHECK`] until stopped.
fn poll(mirrors: &SharedMirrors) {
    while !mirrors.stopped() {
        std::thread::sleep(RECHECK);
        mirrors.pump();
        mirrors.panic_if_requested();
    }
}

/// A listener on `service`.
fn listener(node: &ShmNode, service: &EventSpec) -> Result<Listener<ShmService>, String> {
    service
        .open(node)
        .map_err(|e| e.to_string())
        .and_then(|s| s.listener_builder().create().map_err(|e| format!("{e:?}")))
}

/// A service the receiver listens to.
struct Heard {
    /// Its listener counted in the writer's word, for an import's samples (see
    /// [`super::coverage`]). Before `listener`: counted out before the listener goes.
    _receiving: Option<super::coverage::Receiving>,
    listener: Listener<ShmService>,
}

/// What the receiver waits on between two changes of the set of mirrors.
struct Listening<'a> {
    listeners: &'a HashMap<ServiceName, Heard>,
    /// Where each service's notifications go.
    routes: &'a HashMap<ServiceName, Route>,
    /// Services without a listener: served at every [`RECHECK`].
    unheard: &'a [Route],
}

/// How often everything mirrored is pumped even though nothing rang: a notify lost
/// (a writer that crashed between its send and its notify) delays a sample by at most
/// this. Pumping an idle mirror costs a look at its queue, about a microsecond.
const SWEEP: Duration = Duration::from_secs(5);

/// Sleeps on every listener and serves what each wake-up is for (and at least every
/// [`RECHECK`] what cannot be listened to) until the set of mirrors changes or the
/// receiver is stopped. A wake-up costs what its own mirror needs, whatever the
/// number of mirrors.
fn wait_while_unchanged(
    mirrors: &SharedMirrors,
    generation: u64,
    bell: Option<&Listener<ShmService>>,
    set: &Listening<'_>,
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
                mirrors.pump();
            }
            return;
        }
    };
    let mut by_id = HashMap::with_capacity(set.listeners.len() + 1);
    let mut guards = Vec::with_capacity(set.listeners.len() + 1);
    let all = set.listeners.iter().map(|(name, heard)| (Some(*name), &heard.listener));
    for (name, listener) in all.chain(bell.map(|b| (None, b))) {
        match waitset.attach_notification(listener) {
            Ok(guard) => {
                by_id.insert(WaitSetAttachmentId::from_guard(&guard), (name, listener));
                guards.push(guard);
            }
            Err(e) => {
                tracing::warn!(error = ?e, "cannot attach a listener; polling it");
            }
        }
    }
    let mut fired = Vec::new();
    let mut next_sweep = Instant::now() + SWEEP;
    while !mirrors.stopped() && mirrors.generation() == generation {
        fired.clear();
        let waited = waitset.wait_and_process_once_with_timeout(
            |id| {
                if let Some(hit) = by_id.get(&id) {
                    fired.push(*hit);
                }
                CallbackProgression::Continue
            },
            RECHECK,
        );
        if let Err(e) = waited {
            tracing::warn!(error = ?e, "the WaitSet failed; polling");
            std::thread::sleep(RECHECK);
        }
        // Consume the notifications, so that the next notify wakes again.
        for (_, listener) in &fired {
            if let Err(e) = listener.try_wait(|_| {}) {
                tracing::debug!(error = ?e, "cannot consume a notification");
            }
        }
        let sweep = Instant::now() >= next_sweep;
        if fired.is_empty() && set.unheard.is_empty() && !sweep {
            continue;
        }
        // Each route locks its own mirror: a wake-up waits for no other trajectory.
        for (name, _) in &fired {
            if let Some(route) = name.as_ref().and_then(|n| set.routes.get(n)) {
                route.serve(true);
            }
        }
        for route in set.unheard {
            route.serve(true);
        }
        if sweep {
            mirrors.pump();
            next_sweep = Instant::now() + SWEEP;
        }
        mirrors.panic_if_requested();
    }
    drop(guards);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_receiver_thread_is_a_batch_thread_and_others_are_not() {
        let policy = std::thread::spawn(|| {
            never_preempt_on_wake_up();
            // SAFETY: asks about the calling thread.
            unsafe { libc::sched_getscheduler(0) }
        })
        .join();
        assert_eq!(policy.ok(), Some(libc::SCHED_BATCH));
        // SAFETY: as above; this thread was left alone.
        assert_eq!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_OTHER);
    }
}
