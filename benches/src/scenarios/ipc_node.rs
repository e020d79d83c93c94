//! The iceoryx2 node of a benchmark process (measuring or peer).

use anyhow::Context as _;
use esgm_shm::ShmNode;
use iceoryx2::prelude::{
    CallbackProgression, LogLevel, Node, NodeBuilder, NodeState, SignalHandlingMode, set_log_level,
};

/// A node for this process's services.
///
/// Signal handling is off: by default an iceoryx2 node takes over SIGINT and SIGTERM
/// (to let a program shut down cleanly), which would make Ctrl-C do nothing while a
/// benchmark runs. iceoryx2's own log is cut to errors: its warnings (no config file,
/// the defaults used) are not news for a benchmark and would clutter the table.
pub fn ipc_node() -> anyhow::Result<ShmNode> {
    set_log_level(LogLevel::Error);
    NodeBuilder::new()
        .config(esgm_shm::iceoryx2_config())
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<esgm_shm::ShmService>()
        .context("could not create an iceoryx2 node")
}

/// Removes what iceoryx2 nodes of dead processes left behind (shared memory, service
/// entries): called after killing a peer process, which had no chance to clean up.
/// iceoryx2 does the same whenever a node is created; this just does not wait for that.
/// Best effort: a failure leaves the files to that next cleanup.
pub fn remove_dead_nodes() {
    set_log_level(LogLevel::Error);
    let _ = Node::<esgm_shm::ShmService>::list(esgm_shm::iceoryx2_config(), |state| {
        if let NodeState::Dead(node) = state {
            let _ = node.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    });
}
