//! The connection's iceoryx2 node, shared by the threads that open ports on it.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::data_plane::service::ShmNode;

/// The node every port of one connection is opened on. An iceoryx2 node may move
/// between threads but not be shared by them, so it sits behind a lock; ports are
/// opened rarely (control plane), never per sample.
///
/// The lock is held only while a port is opened, never across a trajectory store's
/// lock: a thread that adds holds its store's lock and may open a port (an inbox), so
/// the reverse order would deadlock.
#[derive(Debug, Clone)]
pub(crate) struct SharedNode(Arc<Mutex<ShmNode>>);

impl SharedNode {
    pub fn new(node: ShmNode) -> Self {
        Self(Arc::new(Mutex::new(node)))
    }

    /// Runs `f` with the node (to open a port on it).
    pub fn with<R>(&self, f: impl FnOnce(&ShmNode) -> R) -> R {
        f(&self.0.lock())
    }
}
