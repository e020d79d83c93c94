//! What a connection mirrors through shared memory — the trajectories it exports and
//! imports — shared by the location thread, which changes the set, and the receiver
//! thread, which feeds it from other processes.

use std::collections::BTreeMap;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use iceoryx2::port::notifier::Notifier;

use parking_lot::{Mutex, MutexGuard};

use super::export::Export;
use super::import::Import;
use crate::service::{EventSpec, ShmService};

/// What a wake-up service's notifications are for (the receiver thread serves that
/// one mirror alone).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Route {
    /// An import's samples or violations arrived.
    Import(String),
    /// Another process added to an export's inbox (or asks for its blocking adds).
    Inbox(String),
    /// A new reader of an export asks for its history.
    Join(String),
}

/// The exports and imports of one connection.
#[derive(Debug, Default)]
pub(crate) struct Mirrors {
    pub exports: BTreeMap<String, Export>,
    pub imports: BTreeMap<String, Import>,
}

impl Mirrors {
    /// Every wake-up service that other processes notify for this connection, with
    /// what its notifications are for: each import's samples and violations, each
    /// export's join service and each primitive export's inbox.
    pub fn wake_routes(&self) -> Vec<(EventSpec, Route)> {
        let imports = self.imports.iter().flat_map(|(name, i)| {
            i.receiver_wakes().iter().map(move |w| (*w, Route::Import(name.clone())))
        });
        let exports = self.exports.iter().flat_map(|(name, e)| {
            let inbox = e.inbox_wake().map(|w| (w, Route::Inbox(name.clone())));
            inbox.into_iter().chain([(e.join_wake(), Route::Join(name.clone()))])
        });
        imports.chain(exports).collect()
    }

    /// Serves what `route` is for; returns how many samples, adds or violations were
    /// taken. `rung`: its service rang (else this is a look for what may have come
    /// before its listener existed).
    pub fn serve(&mut self, route: &Route, rung: bool) -> usize {
        match route {
            Route::Import(name) => self.imports.get_mut(name).map_or(0, Import::pump),
            Route::Inbox(name) => self.exports.get(name).map_or(0, |e| e.take_inbox(rung)),
            Route::Join(name) => {
                if let Some(e) = self.exports.get(name) {
                    e.welcome();
                }
                0
            }
        }
    }

    /// Takes everything other processes sent: adds to the inboxes of the exports,
    /// samples, resets and violations of the imports; returns how many there were.
    pub fn pump(&mut self) -> usize {
        let inboxes: usize = self.exports.values().map(|e| e.take_inbox(false)).sum();
        inboxes + self.imports.values_mut().map(Import::pump).sum::<usize>()
    }
}

/// [`Mirrors`] behind a lock, with a generation the receiver thread compares to know
/// when to listen to another set of services, and its stop flag.
#[derive(Debug, Default)]
pub(crate) struct SharedMirrors {
    mirrors: Mutex<Mirrors>,
    generation: AtomicU64,
    stop: AtomicBool,
    /// Test support: the receiver thread panics at its next wake-up.
    #[cfg(feature = "test-seams")]
    panic_requested: AtomicBool,
    /// Wakes the receiver thread at once when the set changes (its doorbell service).
    doorbell: OnceLock<Notifier<ShmService>>,
}

impl SharedMirrors {
    /// The mirrors, to read or pump. Never held across a control call: the receiver
    /// thread pumps under it.
    pub fn lock(&self) -> MutexGuard<'_, Mirrors> {
        self.mirrors.lock()
    }

    /// Changes the set of mirrors with `f` and tells the receiver to listen again.
    pub fn change<R>(&self, f: impl FnOnce(&mut Mirrors) -> R) -> R {
        let r = f(&mut self.mirrors.lock());
        self.generation.fetch_add(1, Ordering::Release);
        self.ring();
        r
    }

    /// Installs the receiver's doorbell (once).
    pub fn set_doorbell(&self, notifier: Notifier<ShmService>) {
        if self.doorbell.set(notifier).is_err() {
            tracing::debug!("the receiver's doorbell was already set");
        }
    }

    /// Wakes the receiver thread (it then looks at the generation and its stop).
    pub fn ring(&self) {
        if let Some(bell) = self.doorbell.get() {
            if let Err(e) = bell.notify() {
                tracing::debug!(error = ?e, "cannot ring the receiver's doorbell");
            }
        }
    }

    /// Bumped by every [`SharedMirrors::change`].
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Acquire)
    }

    /// Asks the receiver thread to end.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
        self.ring();
    }

    /// Test support: makes the receiver thread panic at its next wake-up.
    #[cfg(feature = "test-seams")]
    pub fn request_panic(&self) {
        self.panic_requested.store(true, Ordering::Release);
        self.ring();
    }

    /// Test support: panics (the receiver thread) once [`SharedMirrors::request_panic`]
    /// was called. Without the `test-seams` feature, nothing.
    pub fn panic_if_requested(&self) {
        #[cfg(feature = "test-seams")]
        if self.panic_requested.load(Ordering::Acquire) {
            #[allow(clippy::panic, reason = "test support: a panic asked for")]
            {
                panic!("esgm-receiver: panic injected by a test");
            }
        }
    }

    /// True once [`SharedMirrors::stop`] was called.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }
}
