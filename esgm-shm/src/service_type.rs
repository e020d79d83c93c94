//! esgm's iceoryx2 service type: inter-process, with wake-ups on semaphores.
//!
//! iceoryx2 builds every port from a *service type* that picks one implementation per
//! concept (shared memory, connections, events, …). Its default inter-process type,
//! `ipc::Service`, wakes a sleeping listener with a Unix datagram: a notify is a
//! `sendto`, and every wait re-configures the socket (blocking mode, timeout) before
//! its `recv`. [`ShmService`] is `ipc::Service` with one change, the event
//! implementation: iceoryx2's own `SemaphoreShmCountingBitSet`, a process-shared
//! semaphore (a futex) beside the same bit set. Everything else — segments,
//! connections, request-response, node monitoring — is `ipc::Service`'s.
//!
//! Measured here (2 cores, pinned, a 50 µs gap before each notify so that the listener
//! sleeps, 20,000 round trips, one-way = round trip / 2): **3.0–3.2 µs** from notify to a
//! woken listener with semaphores, **13.7–15.3 µs** with `ipc::Service`'s datagrams. A
//! blocking subscriber pays that on every sample.
//!
//! # Kept apart from other iceoryx2 programs
//! A service type is part of what iceoryx2 expects of every process that opens a
//! service, and dead-node cleanup removes a crashed process's resources with the
//! cleaner's own types. So esgm's nodes live in their own iceoryx2 namespace
//! ([`shm_config`]: files under `/tmp/iceoryx2/esgm/`, shared memory named `esgm_…`),
//! where only `ShmService` nodes — esgm's — list, open and clean up. A raw iceoryx2
//! program that wants to open an esgm trajectory's services builds its node with
//! [`node_builder`] and uses `ShmService` as its service type.

use std::sync::OnceLock;

use iceoryx2::config::Config;
use iceoryx2::node::NodeBuilder;
use iceoryx2::prelude::{FileName, Path, SemanticString, ZeroCopySend};
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    arc_sync_policy, bag, dynamic_storage, event, hash, monitoring, reactor,
    resizable_shared_memory, serialize, shared_memory, static_storage, zero_copy_connection,
};

/// The iceoryx2 service type of every esgm port; see the module docs.
#[derive(Debug, Clone)]
pub struct ShmService {}

impl iceoryx2::service::Service for ShmService {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: std::fmt::Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: std::fmt::Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    /// The one difference from `ipc::Service` (see the module docs).
    type Event = event::SemaphoreShmCountingBitSet;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + std::fmt::Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + std::fmt::Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<ShmService> for ShmService {}

/// Where esgm's iceoryx2 files live, below the global one's root.
const ROOT_PATH: &[u8] = b"/tmp/iceoryx2/esgm/";
/// The name prefix of esgm's iceoryx2 files (shared memory in `/dev/shm`, node and
/// service files).
const PREFIX: &[u8] = b"esgm_";

/// The iceoryx2 configuration of esgm's nodes: the global one (the defaults, or an
/// `iceoryx2.toml` the user provides) in esgm's own namespace (see the module docs).
pub fn shm_config() -> &'static Config {
    static CONFIG: OnceLock<Config> = OnceLock::new();
    CONFIG.get_or_init(|| {
        let mut config = Config::global_config().clone();
        match (Path::new(ROOT_PATH), FileName::new(PREFIX)) {
            (Ok(root), Ok(prefix)) => {
                config.global.set_root_path(&root);
                config.global.prefix = prefix;
            }
            // Both are constants that iceoryx2 accepts; a test pins it.
            _ => tracing::error!("esgm's iceoryx2 namespace is invalid; using the global one"),
        }
        config
    })
}

/// A node builder in esgm's namespace ([`shm_config`]); finish it with
/// `.create::<ShmService>()`.
pub fn node_builder() -> NodeBuilder {
    NodeBuilder::new().config(shm_config())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_namespace_is_valid_and_apart_from_the_global_one() {
        let config = shm_config();
        assert_eq!(config.global.root_path().as_bytes(), ROOT_PATH);
        assert_eq!(config.global.prefix.as_bytes(), PREFIX);
        assert_ne!(config.global.prefix, Config::global_config().global.prefix);
    }
}
