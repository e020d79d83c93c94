//! The coordinator's registry on disk: saved after every change, and a change that
//! cannot be saved is undone and refused, never acknowledged and then lost in a crash.
//!
//! A failed save (a full disk, a state directory made read-only) rolls the registry
//! back to what was last saved, answers each change of the batch with
//! [`ControlError::NotSaved`], and is counted: `esgm ps` and `esgm stats` show the
//! count and the last reason ([`SaveHealth`], in [`super::Response::Pong`]).

use esgm_core::TypeRegistry;
use serde::{Deserialize, Serialize};

use super::protocol::ControlError;
use super::registry::Registry;
use super::state::{Snapshot, StateDir, StateError};

/// How the coordinator's saves went: what `esgm ps` and `esgm stats` warn of.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SaveHealth {
    /// Saves that failed since the coordinator started (each undid its changes).
    pub failures: u64,
    /// Why the last save failed, while saves fail (`None` once one succeeds again).
    pub failing: Option<String>,
}

/// Keeps the registry saved in a state directory, and what was last saved.
#[derive(Debug)]
pub(crate) struct Persistence {
    dir: StateDir,
    /// The types a registry starts from (what [`Registry::restore`] builds on).
    types: TypeRegistry,
    /// The registry as on disk: what a failed save returns to.
    saved: Snapshot,
    health: SaveHealth,
}

impl Persistence {
    /// Keeps `registry`, which is what `dir` holds now (restored from it, or new), in
    /// `dir`; `types` are the types it was built on.
    pub fn new(dir: StateDir, types: TypeRegistry, registry: &Registry) -> Self {
        Self { dir, types, saved: registry.snapshot(), health: SaveHealth::default() }
    }

    /// The state directory.
    pub fn dir(&self) -> &StateDir {
        &self.dir
    }

    /// How saves went.
    pub fn health(&self) -> &SaveHealth {
        &self.health
    }

    /// Writes `registry`; on failure it is rolled back to what was last saved, and the
    /// error returned is what each change in flight is answered with.
    pub fn save(&mut self, registry: &mut Registry) -> Result<(), ControlError> {
        let snapshot = registry.snapshot();
        match self.dir.save(&snapshot) {
            Ok(()) => {
                self.saved = snapshot;
                self.health.failing = None;
                Ok(())
            }
            Err(e) => Err(self.failed(registry, &e)),
        }
    }

    fn failed(&mut self, registry: &mut Registry, e: &StateError) -> ControlError {
        self.health.failures += 1;
        self.health.failing = Some(e.to_string());
        let undone = registry.roll_back(self.types.clone(), self.saved.clone());
        if let Err(restore) = &undone {
            // Not expected: the snapshot was taken from a registry that held it.
            tracing::error!(error = %restore, "cannot roll the registry back to what was saved");
        }
        tracing::error!(error = %e, failures = self.health.failures, rolled_back = undone.is_ok(),
            "cannot save the registry: the changes since the last save are refused");
        ControlError::NotSaved { reason: e.to_string() }
    }
}
