//! The iceoryx2 service settings both ends of a mirrored trajectory derive from its
//! policy and type, and those of its inbox (other processes' adds to a primitive).

use esgm_core::policy::FluentStreamPolicy;
use esgm_core::value::ValueSort;
use esgm_core::{
    CacheConstraint, EntityStructureType, EntityTrajectoryStructure, InProcessTrajectory,
};

use iceoryx2::prelude::ServiceName;

use crate::data_plane::capacity::Readers;
use crate::data_plane::qos::{DEFAULT_MAX_HISTORY, TrajectoryQos, history_bound, history_qos};
use crate::data_plane::service_name::{NameError, TrajectoryServiceNames};

/// The most samples of a trajectory carrying octets (images, blobs of bytes) kept in
/// shared memory for late readers when its cache has no element bound: every kept
/// sample reserves its full size in every reader's segment, so `All` with the default
/// 1024 would map gigabytes for a camera.
pub(crate) const MAX_OCTET_HISTORY: usize = 16;

/// Samples a replica may keep borrowed beyond its cache's bound: structures that units,
/// subscriptions and query answers still read after the cache evicted them (see
/// [`crate::client::holdings`]). Past it, their archives are copied (and counted).
pub(crate) const HOLD_SLACK: usize = 8;

/// The service settings every process opens a trajectory's data service with, writer
/// and readers alike (iceoryx2 refuses an opener that asks for more than the creator
/// set, and any of them may come first): the publisher keeps the cache's bound of
/// samples, so a replica made late starts with the writer's view, and a replica may
/// borrow that many plus `HOLD_SLACK`, so the images it holds stay in shared memory.
/// A trajectory of `entity_type` with octets and no element bound keeps
/// `MAX_OCTET_HISTORY`. Public for readers outside a connection (esgm-bridge's
/// exporter), which must ask for the same.
///
/// One publisher: the writer's. Every other process adds through the writer's inbox
/// and gate, so a second publisher could only be one that bypasses the gate; while
/// the writer lives, no other process can open one. (A writer that crashed is
/// removed by iceoryx2's dead-node cleanup when its successor's node is made.)
///
/// The trajectory's `readers` (its record's [`crate::control::TrajectoryRecord::readers`])
/// size its subscribers and nodes ([`crate::DomainLimits`]).
pub fn bridge_qos(
    policy: &FluentStreamPolicy,
    entity_type: &EntityStructureType,
    readers: Readers,
) -> TrajectoryQos {
    let octets = entity_type.attributes.iter().any(|a| a.sort == ValueSort::OctetSeq);
    let bound = match policy.cache {
        CacheConstraint::Elements(n) if n > 0 => n,
        _ if octets => MAX_OCTET_HISTORY,
        _ => history_bound(policy.cache, DEFAULT_MAX_HISTORY),
    };
    let qos = history_qos(bound, TrajectoryQos::default());
    // Readers read every structure in place, in the writer's chunk, for as long as a
    // value reads it ([`crate::client::holdings`]): a replica borrows its cache's bound
    // and the slack its values hold beyond it.
    let max_borrowed_samples = qos.max_borrowed_samples + HOLD_SLACK;
    let qos = TrajectoryQos { max_borrowed_samples, max_publishers: 1, ..qos }.readers(readers);
    // The writer of images reads its own samples back ([`own_subscriber`]).
    TrajectoryQos { max_subscribers: qos.max_subscribers + own_subscriber(entity_type), ..qos }
}

/// Subscribers of a trajectory of `entity_type` that its writer itself holds beside
/// its readers: one for images, which the writer's store keeps as its own subscriber
/// received them (in shared memory), none otherwise.
pub(crate) fn own_subscriber(entity_type: &EntityStructureType) -> usize {
    usize::from(entity_type.attributes.iter().any(|a| a.sort == ValueSort::OctetSeq))
}

/// The largest structure of `entity_type` a writer's pool is sized for, if the type
/// bounds its structures' size: every attribute a number, time, position, rotation or
/// boolean. The publisher then loans from one fixed-size pool
/// ([`crate::data_plane::publisher::SampleSizing::Fixed`]); a growable one keeps bookkeeping for
/// 255 possible segments, about 2 MiB of private memory per publisher and 300 KiB per
/// reader connected to it (iceoryx2 0.10, measured), whatever the samples' size.
/// `None` for strings, sequences, frames and octets, whose structures grow.
///
/// The bound leaves room for an entity name of a few kilobytes; a structure that
/// still does not fit is refused by the publisher and counted as a failure.
pub(crate) fn fixed_sample_len(entity_type: &EntityStructureType) -> Option<usize> {
    const ROOM: usize = 4096;
    let fixed = |sort: ValueSort| {
        matches!(
            sort,
            ValueSort::Altitude
                | ValueSort::Bool
                | ValueSort::Double
                | ValueSort::Long
                | ValueSort::Pos2
                | ValueSort::Position
                | ValueSort::PositionAltitude
                | ValueSort::PositionAltitudeRotation
                | ValueSort::Rotation
                | ValueSort::Time
                | ValueSort::Vec
        )
    };
    if entity_type.attributes.is_empty() || !entity_type.attributes.iter().all(|a| fixed(a.sort)) {
        return None;
    }
    // An attribute archives as its name and a value of at most a few dozen bytes.
    let attributes: usize = entity_type.attributes.iter().map(|a| a.name.len() + 128).sum();
    Some((ROOM + attributes).next_multiple_of(1024))
}

/// The bridged history of `handle`'s trajectory, warning once where a cache without
/// an element bound is cut to [`MAX_OCTET_HISTORY`] for other processes.
pub(crate) fn handle_qos(
    handle: &InProcessTrajectory,
    policy: &FluentStreamPolicy,
    readers: Readers,
) -> TrajectoryQos {
    let entity_type = handle.entity_type().unwrap_or_else(|_| EntityStructureType::new(""));
    let qos = bridge_qos(policy, &entity_type, readers);
    let unbounded = !matches!(policy.cache, CacheConstraint::Elements(n) if n > 0);
    if unbounded && qos.history_size == MAX_OCTET_HISTORY {
        tracing::warn!(trajectory = %handle.name(), kept = MAX_OCTET_HISTORY,
            "a trajectory of octets (images) without an element cache: other processes \
             receive the last {MAX_OCTET_HISTORY} of its history; set `cache = N`");
    }
    qos
}

pub(crate) use crate::data_plane::service_name::generation_domain;

/// The domain of inbox services: other processes' adds to a primitive trajectory.
pub(crate) fn inbox_domain(domain: &str) -> String {
    format!("{domain}:inbox")
}

/// The join service of `trajectory` in `domain` (`<domain>:join`): an event service a
/// reader rings once it has subscribed, and the writer answers by handing it the
/// history at once ([`super::export::Export::welcome`]) instead of at its next
/// maintenance tick or sample.
pub(crate) fn join_service(domain: &str, trajectory: &str) -> Result<ServiceName, NameError> {
    Ok(*TrajectoryServiceNames::new(&format!("{domain}:join"), trajectory)?.wake())
}

/// Inbox services keep nothing for late subscribers (an add is delivered once) and
/// queue generously: a full queue loses adds. Every process using the trajectory may
/// add (one publisher each, with the tools' reserve); only its writer subscribes (a
/// restarted writer may overlap its former self).
pub(crate) fn inbox_qos(readers: Readers) -> TrajectoryQos {
    TrajectoryQos {
        history_size: 0,
        subscriber_buffer_size: INBOX_QUEUE,
        max_publishers: readers.ports(),
        max_subscribers: 2,
        max_nodes: readers.nodes(),
        ..TrajectoryQos::default()
    }
}

/// Adds from other processes one writer queues per adder before the oldest is lost.
pub(crate) const INBOX_QUEUE: usize = 1024;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octet_trajectories_without_an_element_cache_keep_a_short_history() {
        let image = EntityStructureType::new("Image").attr("image_data", ValueSort::OctetSeq);
        let reading = EntityStructureType::new("Reading").attr("x", ValueSort::Double);
        let all = FluentStreamPolicy::default();
        let r = Readers::default();
        assert_eq!(bridge_qos(&all, &image, r).history_size, MAX_OCTET_HISTORY);
        assert_eq!(bridge_qos(&all, &reading, r).history_size, DEFAULT_MAX_HISTORY);
        let hundred = FluentStreamPolicy::default().cache(CacheConstraint::Elements(100));
        assert_eq!(bridge_qos(&hundred, &image, r).history_size, 100, "an explicit bound is kept");
        assert_eq!(bridge_qos(&all, &reading, r).max_publishers, 1, "the writer's alone");
        assert_eq!(fixed_sample_len(&image), None, "octets grow");
        assert!(fixed_sample_len(&reading).is_some_and(|n| n >= 4096));
        let named = EntityStructureType::new("Named").attr("s", ValueSort::String);
        assert_eq!(fixed_sample_len(&named), None, "strings grow");
        let tf = bridge_qos(&all, &reading, Readers(64));
        assert_eq!(tf.max_subscribers, Readers(64).ports(), "every reader and the tools");
    }
}
