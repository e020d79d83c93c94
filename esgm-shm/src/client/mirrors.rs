//! What a connection mirrors through shared memory — the trajectories it exports and
//! imports — shared by the location thread, which changes the set, and the receiver
//! thread, which feeds it from other processes.
//!
//! Each mirrored trajectory is its own object under its own lock ([`Mirror`]); the
//! set's lock guards only the index by name, and is never held while a mirror is
//! locked. A wake-up serves one trajectory and waits for no other (issue 23).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use iceoryx2::port::notifier::Notifier;

use parking_lot::{Mutex, MutexGuard};

use super::export::Export;
use super::import::Import;
use crate::data_plane::service::{EventSpec, ShmService};

/// One mirrored trajectory's import or export: a self-contained object with its own
/// lock. The receiver thread, a subscription that waits on its writer and the
/// location thread each lock the one trajectory they work on, never the whole set, so
/// nothing on the data path waits for, or grows with, the other trajectories.
pub(crate) type Mirror<T> = Arc<Mutex<T>>;

/// What a wake-up service's notifications are for: the one mirror the receiver
/// thread serves when it rings, held directly (no lookup by name, no lock on the set).
#[derive(Debug, Clone)]
pub(crate) enum Route {
    /// An import's samples or violations arrived.
    Import(Mirror<Import>),
    /// Another process added to an export's inbox (or asks for its blocking adds).
    Inbox(Mirror<Export>),
    /// A new reader of an export asks for its history.
    Join(Mirror<Export>),
}

impl Route {
    /// Serves what this route is for; returns how many samples, adds or violations
    /// were taken. `rung`: its service rang (else this is a look for what may have
    /// come before its listener existed). Locks this route's mirror only.
    pub fn serve(&self, rung: bool) -> usize {
        match self {
            Route::Import(import) => import.lock().pump(),
            Route::Inbox(export) => export.lock().take_inbox(rung),
            Route::Join(export) => {
                export.lock().welcome();
                0
            }
        }
    }
}

impl Route {
    /// The receiver's listener on `wake` counted in the writer's word, if it carries an
    /// import's samples ([`Import::receiving`]).
    pub fn receiving(&self, wake: &EventSpec) -> Option<super::coverage::Receiving> {
        match self {
            Route::Import(import) => import.lock().receiving(wake),
            Route::Inbox(_) | Route::Join(_) => None,
        }
    }
}

/// The exports and imports of one connection, by trajectory name. The map is only the
/// index: each entry is locked on its own ([`Mirror`]).
#[derive(Debug, Default)]
pub(crate) struct Mirrors {
    pub exports: BTreeMap<String, Mirror<Export>>,
    pub imports: BTreeMap<String, Mirror<Import>>,
}

impl Mirrors {
    /// Adds `import` under `name` (replacing and returning the one before).
    pub fn insert_import(&mut self, name: String, import: Import) -> Option<Mirror<Import>> {
        self.imports.insert(name, Arc::new(Mutex::new(import)))
    }

    /// Adds `export` under `name` (replacing and returning the one before).
    pub fn insert_export(&mut self, name: String, export: Export) -> Option<Mirror<Export>> {
        self.exports.insert(name, Arc::new(Mutex::new(export)))
    }

    /// Every mirror, as routes that take all they hold: for a sweep, done after the set's
    /// lock is released.
    fn everything(&self) -> Vec<Route> {
        let exports = self.exports.values().map(|e| Route::Inbox(Arc::clone(e)));
        exports.chain(self.imports.values().map(|i| Route::Import(Arc::clone(i)))).collect()
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
    /// The set of mirrors, to look one up or list them. Held only for that: a mirror
    /// is served under its own lock, after this one is released.
    pub fn lock(&self) -> MutexGuard<'_, Mirrors> {
        self.mirrors.lock()
    }

    /// The import of `name`, if this process reads it from another.
    pub fn import(&self, name: &str) -> Option<Mirror<Import>> {
        self.mirrors.lock().imports.get(name).cloned()
    }

    /// Every export (each to lock on its own).
    pub fn exports(&self) -> Vec<(String, Mirror<Export>)> {
        let mirrors = self.mirrors.lock();
        mirrors.exports.iter().map(|(n, e)| (n.clone(), Arc::clone(e))).collect()
    }

    /// Every import (each to lock on its own).
    pub fn imports(&self) -> Vec<(String, Mirror<Import>)> {
        let mirrors = self.mirrors.lock();
        mirrors.imports.iter().map(|(n, i)| (n.clone(), Arc::clone(i))).collect()
    }

    /// Every wake-up service that other processes notify for this connection, with
    /// what its notifications are for: each import's samples and violations, each
    /// export's join service and each primitive export's inbox. Each mirror is locked
    /// after the set's lock is released (never one inside the other).
    pub fn wake_routes(&self) -> Vec<(EventSpec, Route)> {
        let (exports, imports) = (self.exports(), self.imports());
        let imports = imports.into_iter().flat_map(|(_, i)| {
            let wakes = i.lock().receiver_wakes().to_vec();
            wakes.into_iter().map(move |w| (w, Route::Import(Arc::clone(&i))))
        });
        let exports = exports.into_iter().flat_map(|(_, e)| {
            let (inbox, join) = {
                let locked = e.lock();
                (locked.inbox_wake(), locked.join_wake())
            };
            let inbox = inbox.map(|w| (w, Route::Inbox(Arc::clone(&e))));
            inbox.into_iter().chain([(join, Route::Join(e))])
        });
        imports.chain(exports).collect()
    }

    /// Takes everything other processes sent: adds to the inboxes of the exports,
    /// samples, resets and violations of the imports; returns how many there were.
    /// The set's lock is held only to list them; each is served under its own.
    pub fn pump(&self) -> usize {
        let everything = self.mirrors.lock().everything();
        everything.iter().map(|route| route.serve(false)).sum()
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
