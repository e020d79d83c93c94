//! The location thread's ears: a thread that sleeps on the wake-up events of every
//! service the location reads, and pokes the location when one fires.
//!
//! The location thread waits in a crossbeam `Select` (API commands, local store events,
//! outboxes), which cannot also wait on iceoryx2 events. Without help it could only
//! poll its imports, sleeping up to a millisecond between polls when idle: a sample
//! from another process then waited up to that long before entering this process
//! (about 0.15–0.9 ms per pipeline stage, measured). The waker closes the gap. It owns
//! one iceoryx2 listener per watched wake-up service (the trajectory's, its violations',
//! a primitive's inbox), sleeps on all of them in an iceoryx2 `WaitSet`, and on any
//! event sends a poke that the location's `Select` waits on. A publish in another
//! process then reaches the location in two wake-ups instead of a poll period.
//!
//! Measured with `examples/connect_hop.rs` (two locations, a structure every 5 ms, add
//! in one until a subscriber of the other holds it; release, this 2-core VM): p50
//! 0.25–0.30 ms and p99 0.6 ms with the waker, 1.0–1.07 ms p50 without it. What remains
//! is the wake-ups of the threads on the way (the writer's location, the waker, the
//! reader's location, the subscriber), each tens of µs on this VM.
//!
//! iceoryx2 ports cannot move between threads, so the waker has its own node and
//! builds its listeners itself from the service names the location sends whenever its
//! imports or exports change. It checks for a new list at least every
//! [`RECHECK`], and stops (dropping its node) when the location drops it.

use std::collections::BTreeMap;
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TryRecvError, TrySendError};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::{
    CallbackProgression, Node, NodeBuilder, ServiceName, SignalHandlingMode, WaitSetBuilder, ipc,
};

/// The longest the waker sleeps before looking for a new list of services (and for
/// its own stop).
pub(crate) const RECHECK: Duration = Duration::from_millis(50);

/// The location's handle on its waker thread.
pub(crate) struct Waker {
    watch: Option<Sender<Vec<ServiceName>>>,
    /// A value arrives here when a watched service was notified (at most one waits).
    pub pokes: Receiver<()>,
    /// Keeps `pokes` connected whatever happens to the thread: a disconnected channel
    /// would be ready forever, and the location's `Select` would spin.
    _poke: Sender<()>,
    thread: Option<JoinHandle<()>>,
}

impl Waker {
    /// Starts the waker thread, whose node is named `node_name`. Failing to start it
    /// is not fatal: the location then polls as before (see [`Self::pokes`], which
    /// then never fires).
    pub fn start(node_name: iceoryx2::prelude::NodeName) -> Self {
        let (watch, watched) = crossbeam_channel::unbounded();
        let (poke, pokes) = crossbeam_channel::bounded(1);
        let sender = poke.clone();
        let thread = std::thread::Builder::new()
            .name("esgm-waker".to_owned())
            .spawn(move || run(&node_name, &watched, &sender))
            .map_err(|e| tracing::warn!(error = %e, "cannot start the waker; imports are polled"))
            .ok();
        Self { watch: Some(watch), _poke: poke, pokes, thread }
    }

    /// Watches exactly `services` from now on.
    pub fn watch(&self, services: Vec<ServiceName>) {
        if let Some(w) = &self.watch {
            let _ = w.send(services);
        }
    }
}

impl Drop for Waker {
    fn drop(&mut self) {
        // Closing the channel stops the thread within `RECHECK`.
        self.watch = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The waker thread: sleeps on the watched services until the location is gone.
fn run(
    node_name: &iceoryx2::prelude::NodeName,
    watched: &Receiver<Vec<ServiceName>>,
    poke: &Sender<()>,
) {
    let node = match NodeBuilder::new()
        .name(node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
    {
        Ok(node) => node,
        Err(e) => {
            tracing::warn!(error = ?e, "the waker has no node; imports are polled");
            return;
        }
    };
    let mut listeners: BTreeMap<String, Listener<ipc::Service>> = BTreeMap::new();
    loop {
        // Nothing to listen to: wait for a list. The newest list wins; a closed channel
        // is the stop.
        let mut newest = None;
        if listeners.is_empty() {
            match watched.recv_timeout(RECHECK) {
                Ok(list) => newest = Some(list),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
        loop {
            match watched.try_recv() {
                Ok(list) => newest = Some(list),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return,
            }
        }
        if let Some(list) = newest {
            listen_to(&node, &mut listeners, &list);
        }
        if listeners.is_empty() || !wait_once(&listeners) {
            continue;
        }
        match poke.try_send(()) {
            // A poke already waiting covers this one too.
            Ok(()) | Err(TrySendError::Full(())) => {}
            Err(TrySendError::Disconnected(())) => return,
        }
    }
}

/// Keeps a listener for exactly the services of `list`.
fn listen_to(
    node: &Node<ipc::Service>,
    listeners: &mut BTreeMap<String, Listener<ipc::Service>>,
    list: &[ServiceName],
) {
    listeners.retain(|name, _| list.iter().any(|s| s.as_str() == name));
    for service in list {
        if listeners.contains_key(service.as_str()) {
            continue;
        }
        let listener = node
            .service_builder(service)
            .event()
            .open_or_create()
            .map_err(|e| format!("{e:?}"))
            .and_then(|s| s.listener_builder().create().map_err(|e| format!("{e:?}")));
        match listener {
            Ok(l) => {
                listeners.insert(service.as_str().to_owned(), l);
            }
            // That service is polled, as without a waker.
            Err(e) => tracing::debug!(service = service.as_str(), error = %e,
                "the waker cannot listen to a service"),
        }
    }
}

/// Sleeps up to [`RECHECK`] on every listener; true if any was notified (its
/// notifications are consumed, so that the next notify wakes again).
fn wait_once(listeners: &BTreeMap<String, Listener<ipc::Service>>) -> bool {
    let Ok(waitset) = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
    else {
        std::thread::sleep(RECHECK);
        return false;
    };
    let guards: Vec<_> =
        listeners.values().filter_map(|l| waitset.attach_notification(l).ok()).collect();
    if guards.is_empty() {
        std::thread::sleep(RECHECK);
        return false;
    }
    let mut fired = false;
    let _ = waitset.wait_and_process_once_with_timeout(
        |_| {
            fired = true;
            CallbackProgression::Stop
        },
        RECHECK,
    );
    drop(guards);
    if fired {
        for l in listeners.values() {
            let _ = l.try_wait(|_| {});
        }
    }
    fired
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service_name::{node_name, unique_domain, wake_service_name};

    #[test]
    fn a_notify_on_a_watched_service_pokes_and_an_unwatched_one_does_not() {
        let domain = unique_domain("waker");
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let service = |t: &str| ServiceName::new(&wake_service_name(&domain, t)).unwrap();
        let notifier = |t: &str| {
            let s = node.service_builder(&service(t)).event().open_or_create().unwrap();
            s.notifier_builder().create().unwrap()
        };
        let (watched, other) = (notifier("a"), notifier("b"));
        let waker = Waker::start(node_name(&domain, "waker"));
        waker.watch(vec![service("a")]);

        // The listener is made on the waker's thread: notify until it has one.
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        let poked = loop {
            watched.notify().unwrap();
            if waker.pokes.recv_timeout(Duration::from_millis(20)).is_ok() {
                break true;
            }
            if std::time::Instant::now() > deadline {
                break false;
            }
        };
        assert!(poked, "a notify on a watched service pokes the location");
        while waker.pokes.recv_timeout(RECHECK * 2).is_ok() {}

        other.notify().unwrap();
        assert!(waker.pokes.recv_timeout(RECHECK * 3).is_err(), "b is not watched");

        // Unwatched, then stopped with its node.
        waker.watch(Vec::new());
        drop(waker);
        assert!(crate::service_name::nodes_of(&domain).is_empty(), "the waker's node is gone");
    }
}
