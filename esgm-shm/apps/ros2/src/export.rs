//! Exporting: a trajectory published as a ROS 2 topic.
//!
//! `--export driving_direction[=/cmd_dir]` subscribes to the trajectory (by default the
//! topic is `/<trajectory>`) and publishes each structure that enters it, converted
//! ([`crate::mapping`]). A structure that does not map, a DDS write that fails and
//! samples the subscription's queue dropped because DDS fell behind are counted with
//! their cause.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use esgm_core::{
    EntityStructure, EntityTrajectoryStructure, Esgm, InProcessTrajectory, LookupError, RecvError,
    SubscribeOptions, Subscription,
};
use esgm_shm::ShmEsgm;
use ros2_client::{MessageTypeName, Node, Publisher};
use serde::Serialize;

use crate::generated;
use crate::mapping::{self, MappingError, RosType};
use crate::msgs;
use crate::node::{NodeError, TopicQos, bridged_topic, create_error, message_type_name};
use crate::stats::{Direction, LossCause, Stats, TopicCounters};
use crate::watch::Spawned;

/// One `--export`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportSpec {
    /// The trajectory.
    pub trajectory: String,
    /// The ROS 2 topic (absolute).
    pub topic: String,
}

/// An `--export` that cannot be carried out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    /// The spec is not `TRAJECTORY[=TOPIC]`.
    #[error("`{spec}`: write it as TRAJECTORY[=TOPIC], e.g. driving_direction=/cmd_dir")]
    Syntax {
        /// What was given.
        spec: String,
    },
    /// The trajectory does not exist, or cannot be read.
    #[error("cannot export trajectory `{trajectory}`: {source}")]
    Lookup {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: LookupError,
    },
    /// Its type has no ROS 2 message.
    #[error(transparent)]
    Mapping(#[from] MappingError),
    /// The topic or its publisher.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// Subscribing to the trajectory failed.
    #[error("cannot subscribe to `{trajectory}`: {source}")]
    Subscribe {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: esgm_core::QueryError,
    },
    /// The export thread could not be started.
    #[error("cannot start the thread exporting `{trajectory}`: {source}")]
    Thread {
        /// The trajectory.
        trajectory: String,
        /// The OS's reason.
        source: std::io::Error,
    },
}

impl ExportSpec {
    /// Parses `TRAJECTORY[=TOPIC]`.
    pub fn parse(spec: &str) -> Result<Self, ExportError> {
        let syntax = || ExportError::Syntax { spec: spec.to_owned() };
        let (trajectory, topic) = match spec.split_once('=') {
            Some((t, topic)) => (t, topic.to_owned()),
            None => (spec, format!("/{spec}")),
        };
        if trajectory.is_empty() || topic.len() < 2 {
            return Err(syntax());
        }
        Ok(Self { trajectory: trajectory.to_owned(), topic })
    }
}

/// How a structure becomes a message of the topic's type.
type Convert<M> = Box<dyn Fn(&Arc<EntityStructure>) -> Result<M, MappingError> + Send>;

/// Looks the trajectory up, makes its topic and publisher on `node`, and starts the
/// thread that exports it, until `stop`.
pub fn spawn(
    node: &mut Node,
    esgm: &ShmEsgm,
    spec: &ExportSpec,
    qos: TopicQos,
    stats: &Stats,
    stop: &Arc<AtomicBool>,
) -> Result<Spawned, ExportError> {
    let lookup = |source| ExportError::Lookup { trajectory: spec.trajectory.clone(), source };
    let handle = esgm.get_entity_trajectory_structure(&spec.trajectory).map_err(lookup)?;
    let type_name =
        esgm.get_entity_trajectory_structure_type(&spec.trajectory).map_err(lookup)?.name;
    let counters = stats.topic(&spec.topic, &handle, Direction::Export);
    let Ok(ros_type) = RosType::for_esgm_type(&type_name) else {
        // No standard message: its generated one (`esgm ros2 msg <Type>`).
        let schema = Arc::new(generated::Schema::new(&type_name, |t| {
            esgm.get_entity_structure_type(t).ok()
        })?);
        let name = MessageTypeName::new(generated::PACKAGE, &type_name);
        let convert: Convert<generated::Generated> = Box::new(move |es| {
            Ok(generated::Generated { structure: Arc::clone(es), schema: Arc::clone(&schema) })
        });
        return start(node, spec, name, qos, &handle, convert, counters, stop);
    };
    let name = message_type_name(ros_type);
    match ros_type {
        RosType::Image => {
            let convert: Convert<msgs::Image> = Box::new(|es| mapping::image_out(es));
            start(node, spec, name, qos, &handle, convert, counters, stop)
        }
        RosType::Pose2D => {
            let convert: Convert<msgs::Pose2D> = Box::new(|es| mapping::pose_out(es));
            start(node, spec, name, qos, &handle, convert, counters, stop)
        }
        RosType::Vector3 => {
            let convert: Convert<msgs::Vector3> = Box::new(|es| mapping::velocity_out(es));
            start(node, spec, name, qos, &handle, convert, counters, stop)
        }
    }
}

#[allow(clippy::too_many_arguments, reason = "one call per message kind, all of the same shape")]
fn start<M: Serialize + Send + 'static>(
    node: &mut Node,
    spec: &ExportSpec,
    message_type: MessageTypeName,
    qos: TopicQos,
    handle: &InProcessTrajectory,
    convert: Convert<M>,
    counters: Arc<TopicCounters>,
    stop: &Arc<AtomicBool>,
) -> Result<Spawned, ExportError> {
    let (topic, watched) =
        bridged_topic(node, &spec.topic, message_type, Direction::Export, qos, &counters)?;
    let publisher: Publisher<M> = node
        .create_publisher(&topic, None)
        .map_err(|e| create_error("publisher", &spec.topic, &e))?;
    let subscription = handle
        .subscribe(SubscribeOptions::default())
        .map_err(|source| ExportError::Subscribe { trajectory: spec.trajectory.clone(), source })?;
    let stop = Arc::clone(stop);
    let (trajectory, topic) = (spec.trajectory.clone(), spec.topic.clone());
    let thread = std::thread::Builder::new()
        .name(format!("ros2-export-{trajectory}"))
        .spawn(move || run(&subscription, &publisher, &*convert, &counters, &topic, &stop))
        .map_err(|source| ExportError::Thread { trajectory: spec.trajectory.clone(), source })?;
    Ok(Spawned { thread, watched })
}

/// How long the export thread waits for a sample before it looks at `stop` again.
const STOP_CHECK: Duration = Duration::from_millis(100);

fn run<M: Serialize + 'static>(
    subscription: &Subscription<esgm_core::Sample>,
    publisher: &Publisher<M>,
    convert: &(dyn Fn(&Arc<EntityStructure>) -> Result<M, MappingError> + Send),
    counters: &TopicCounters,
    topic: &str,
    stop: &AtomicBool,
) {
    let mut warned = [false; 2];
    let mut overflowed = 0;
    while !stop.load(Ordering::Relaxed) {
        let sample = match subscription.recv_timeout(STOP_CHECK) {
            Ok(s) => s,
            Err(RecvError::Timeout) => continue,
            Err(e) => {
                tracing::warn!(%topic, error = %e, "the exported trajectory is gone; stopping");
                return;
            }
        };
        let now = subscription.overflowed();
        if now > overflowed {
            counters.lost(LossCause::SlowSide, now - overflowed);
            overflowed = now;
        }
        // ROS 2 messages are made of owned values: an archived structure is converted.
        let sent = convert(&sample.structure.to_arc())
            .map_err(|e| (LossCause::Unconvertible, e.to_string()))
            .and_then(|m| {
                publisher.publish(m).map_err(|e| match e {
                    // A reliable reader that does not keep up blocks the writer past
                    // its blocking time.
                    ros2_client::WriteError::WouldBlock { .. } => {
                        (LossCause::SlowSide, e.to_string())
                    }
                    e => (LossCause::PublishFailed, e.to_string()),
                })
            });
        match sent {
            Ok(()) => counters.passed(),
            Err((cause, detail)) => {
                counters.lost(cause, 1);
                let slot = usize::from(cause != LossCause::Unconvertible);
                let first = !std::mem::replace(&mut warned[slot], true);
                if first {
                    tracing::warn!(%topic, ?cause, %detail,
                        "a sample not published (counted; further ones of this cause at debug level)");
                } else {
                    tracing::debug!(%topic, ?cause, %detail, "a sample not published");
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn specs_parse_with_the_topic_named_after_the_trajectory() {
        let s = ExportSpec::parse("driving_direction").unwrap();
        assert_eq!(s.topic, "/driving_direction");
        let s = ExportSpec::parse("robot_state=/esgm/pose").unwrap();
        assert_eq!((s.trajectory.as_str(), s.topic.as_str()), ("robot_state", "/esgm/pose"));
        for bad in ["", "=/x", "a="] {
            assert!(matches!(ExportSpec::parse(bad), Err(ExportError::Syntax { .. })), "{bad}");
        }
    }
}
