//! Importing: a ROS 2 topic read into a primitive trajectory this process writes.
//!
//! `--import /camera/image_raw:sensor_msgs/msg/Image[=camera]` subscribes to the topic
//! and adds each message, converted ([`crate::mapping`]), to the trajectory (by default
//! named after the topic: `camera_image_raw`), made with the library type if it does
//! not exist. `--import /blobs:esgm_msgs/msg/BlobSeq` reads the generated message of a
//! type of the system (`esgm ros2 msg BlobSeq` prints its definition) by that type's
//! layout ([`esgm_ros2msg::generated_in`]). An image's pixels are written once, into the trajectory's shared memory.
//! A message that does not decode, does not map or is refused by the trajectory's gate
//! is counted with its cause and logged (the first of each cause per topic at warn,
//! the rest at debug).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    CacheConstraint, Clock as _, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InProcessTrajectory, LookupError, SystemClock,
};
use esgm_ros2msg::generated_in::GeneratedSeed;
use esgm_shm::ShmEsgm;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::{MessageTypeName, Node, Subscription};
use serde::de::DeserializeOwned;

use crate::generated;
use crate::mapping::{self, MappingError, RosType};
use crate::msgs;
use crate::node::{NodeError, TopicQos, bridged_topic, create_error, message_type_name};
use crate::stats::{Direction, LossCause, Stats, TopicCounters};
use crate::watch::Spawned;

/// One `--import`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportSpec {
    /// The ROS 2 topic (absolute).
    pub topic: String,
    /// Its message type.
    pub message: Imported,
    /// The trajectory it goes into.
    pub trajectory: String,
}

/// The message type of an imported topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Imported {
    /// A standard message esgm maps to a library type.
    Standard(RosType),
    /// `esgm_msgs/msg/<Type>`: the message `esgm ros2 msg <Type>` defines for the esgm
    /// type `<Type>` of the system (as a ROS 2 node built with that definition
    /// publishes it).
    Generated(String),
}

impl Imported {
    /// The esgm type its structures have.
    pub fn esgm_type(&self) -> &str {
        match self {
            Imported::Standard(t) => t.esgm_type(),
            Imported::Generated(t) => t,
        }
    }
}

/// An `--import` that cannot be carried out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImportError {
    /// The spec is not `TOPIC:TYPE[=TRAJECTORY]`.
    #[error(
        "`{spec}`: write it as TOPIC:TYPE[=TRAJECTORY], e.g. /camera/image_raw:sensor_msgs/msg/Image"
    )]
    Syntax {
        /// What was given.
        spec: String,
    },
    /// The type does not map.
    #[error(transparent)]
    Mapping(#[from] MappingError),
    /// The topic or its subscription.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// The trajectory exists with another type.
    #[error("trajectory `{trajectory}` holds `{has}`, not the `{wants}` that {topic} maps to")]
    WrongType {
        /// The trajectory.
        trajectory: String,
        /// Its type.
        has: String,
        /// The type the topic maps to.
        wants: String,
        /// The topic.
        topic: String,
    },
    /// The trajectory could not be made.
    #[error("cannot make trajectory `{trajectory}`: {source}")]
    Create {
        /// The trajectory.
        trajectory: String,
        /// Why (boxed: it is large, and rare).
        source: Box<CreateError>,
    },
    /// The trajectory could not be looked up.
    #[error("cannot look up trajectory `{trajectory}`: {source}")]
    Lookup {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: LookupError,
    },
    /// The import thread could not be started.
    #[error("cannot start the thread importing {topic}: {source}")]
    Thread {
        /// The topic.
        topic: String,
        /// The OS's reason.
        source: std::io::Error,
    },
}

impl ImportSpec {
    /// Parses `TOPIC:TYPE[=TRAJECTORY]`.
    pub fn parse(spec: &str) -> Result<Self, ImportError> {
        let syntax = || ImportError::Syntax { spec: spec.to_owned() };
        let (topic, rest) = spec.split_once(':').ok_or_else(syntax)?;
        let (ros_type, trajectory) = match rest.split_once('=') {
            Some((t, name)) => (t, Some(name.to_owned())),
            None => (rest, None),
        };
        if topic.is_empty() || ros_type.is_empty() || trajectory.as_deref() == Some("") {
            return Err(syntax());
        }
        let generated = format!("{}/msg/", generated::PACKAGE);
        let message = match ros_type.strip_prefix(&generated) {
            Some(name) if !name.is_empty() => Imported::Generated(name.to_owned()),
            _ => Imported::Standard(RosType::parse(ros_type)?),
        };
        let trajectory = trajectory.unwrap_or_else(|| trajectory_for(topic));
        Ok(Self { topic: topic.to_owned(), message, trajectory })
    }
}

pub use esgm_ros2msg::mapping::trajectory_for;

/// A message type that can be imported.
trait Importable: DeserializeOwned + Send + 'static {
    /// The message as a structure for `trajectory`, received at `now`.
    fn structure(
        &self,
        trajectory: &InProcessTrajectory,
        now: i64,
    ) -> Result<EntityStructure, MappingError>;
}

impl Importable for msgs::Image {
    fn structure(
        &self,
        t: &InProcessTrajectory,
        now: i64,
    ) -> Result<EntityStructure, MappingError> {
        mapping::image_in(self, t, now)
    }
}

impl Importable for msgs::Pose2D {
    fn structure(
        &self,
        t: &InProcessTrajectory,
        now: i64,
    ) -> Result<EntityStructure, MappingError> {
        Ok(mapping::pose_in(self, t.name(), now))
    }
}

impl Importable for msgs::Vector3 {
    fn structure(
        &self,
        t: &InProcessTrajectory,
        now: i64,
    ) -> Result<EntityStructure, MappingError> {
        Ok(mapping::velocity_in(self, t.name(), now))
    }
}

/// The trajectory `spec` goes into: the existing one if its type is the topic's, else
/// a new primitive one of the library type, caching the topic's keep-last depth (what
/// a late ROS 2 reader of a transient-local topic would get).
fn trajectory(
    esgm: &ShmEsgm,
    spec: &ImportSpec,
    qos: TopicQos,
) -> Result<InProcessTrajectory, ImportError> {
    let wants = spec.message.esgm_type();
    let lookup = |source| ImportError::Lookup { trajectory: spec.trajectory.clone(), source };
    match esgm.get_entity_trajectory_structure_type(&spec.trajectory) {
        Ok(t) if t.name == wants => {}
        Ok(t) => {
            return Err(ImportError::WrongType {
                trajectory: spec.trajectory.clone(),
                has: t.name,
                wants: wants.to_owned(),
                topic: spec.topic.clone(),
            });
        }
        Err(LookupError::NoSuchEntityStructure { .. }) => {
            let policy = FluentStreamPolicy::default().cache(CacheConstraint::Elements(qos.depth));
            let created = esgm.create_trajectory(
                TrajectorySpec::primitive(&spec.trajectory, wants).policy(policy),
            );
            match created {
                Ok(t) => return Ok(t),
                // Made meanwhile by someone else: looked up below.
                Err(CreateError::EntityStructureAlreadyExists { .. }) => {}
                Err(source) => {
                    return Err(ImportError::Create {
                        trajectory: spec.trajectory.clone(),
                        source: Box::new(source),
                    });
                }
            }
        }
        Err(e) => return Err(lookup(e)),
    }
    esgm.get_entity_trajectory_structure(&spec.trajectory).map_err(lookup)
}

/// Subscribes to `spec.topic` on `node` and starts the thread that imports it, until
/// `stop`.
pub fn spawn(
    node: &mut Node,
    esgm: &ShmEsgm,
    spec: &ImportSpec,
    qos: TopicQos,
    stats: &Stats,
    stop: &Arc<AtomicBool>,
) -> Result<Spawned, ImportError> {
    // A generated message's layout is its esgm type's: known, and checked, before
    // anything is made.
    let schema = match &spec.message {
        Imported::Generated(t) => Some(Arc::new(generated::Schema::new(t, |name| {
            esgm.get_entity_structure_type(name).ok()
        })?)),
        Imported::Standard(_) => None,
    };
    let handle = trajectory(esgm, spec, qos)?;
    let counters = stats.topic(&spec.topic, &handle, Direction::Import);
    let started = Started { node, spec, qos, handle, counters, stop };
    match (&spec.message, schema) {
        (Imported::Standard(t @ RosType::Image), _) => started.standard::<msgs::Image>(*t),
        (Imported::Standard(t @ RosType::Pose2D), _) => started.standard::<msgs::Pose2D>(*t),
        (Imported::Standard(t @ RosType::Vector3), _) => started.standard::<msgs::Vector3>(*t),
        (Imported::Generated(t), Some(schema)) => started.generated(t, schema),
        (Imported::Generated(t), None) => Err(ImportError::Mapping(MappingError::UnknownMessage {
            name: t.clone(),
            known: "a registered esgm type".into(),
        })),
    }
}

/// What an import needs to subscribe and start its thread.
struct Started<'a> {
    node: &'a mut Node,
    spec: &'a ImportSpec,
    qos: TopicQos,
    handle: InProcessTrajectory,
    counters: Arc<TopicCounters>,
    stop: &'a Arc<AtomicBool>,
}

/// What the import thread reads next: `None` when nothing waits, else the structure
/// the message maps to (or why it does not).
type Read<M> = dyn FnMut(
        &Subscription<M>,
        &InProcessTrajectory,
        i64,
    ) -> ros2_client::ReadResult<Option<Result<EntityStructure, MappingError>>>
    + Send;

impl Started<'_> {
    /// A standard message of `t`, decoded as `M`.
    fn standard<M: Importable>(self, t: RosType) -> Result<Spawned, ImportError> {
        let read: Box<Read<M>> = Box::new(|subscription, handle, now| {
            Ok(subscription.take()?.map(|(message, _)| message.structure(handle, now)))
        });
        self.subscribe(message_type_name(t), read)
    }

    /// A generated message of `esgm_type`, read by its schema.
    fn generated(
        self,
        esgm_type: &str,
        schema: Arc<generated::Schema>,
    ) -> Result<Spawned, ImportError> {
        let read: Box<Read<EntityStructure>> = Box::new(move |subscription, _, now| {
            let seed = GeneratedSeed { schema: &schema, received: now };
            Ok(subscription.take_seed(seed)?.map(|(es, _)| Ok(es)))
        });
        self.subscribe(MessageTypeName::new(generated::PACKAGE, esgm_type), read)
    }

    fn subscribe<M: DeserializeOwned + Send + 'static>(
        self,
        message_type: MessageTypeName,
        read: Box<Read<M>>,
    ) -> Result<Spawned, ImportError> {
        let Started { node, spec, qos, handle, counters, stop } = self;
        let (topic, watched) =
            bridged_topic(node, &spec.topic, message_type, Direction::Import, qos, &counters)?;
        let subscription: Subscription<M> = node
            .create_subscription(&topic, None)
            .map_err(|e| create_error("subscription", &spec.topic, &e))?;
        let stop = Arc::clone(stop);
        let topic = spec.topic.clone();
        let thread = std::thread::Builder::new()
            .name(format!("ros2-import-{}", spec.trajectory))
            .spawn(move || run(subscription, read, &handle, &counters, &topic, &stop))
            .map_err(|source| ImportError::Thread { topic: spec.topic.clone(), source })?;
        Ok(Spawned { thread, watched })
    }
}

/// How long the import thread sleeps before it looks at `stop` again.
const STOP_CHECK: Duration = Duration::from_millis(100);

fn run<M: DeserializeOwned + Send + 'static>(
    mut subscription: Subscription<M>,
    mut read: Box<Read<M>>,
    handle: &InProcessTrajectory,
    counters: &TopicCounters,
    topic: &str,
    stop: &AtomicBool,
) {
    let mut warned = [false; 3];
    let mut warn = |cause: LossCause, detail: &dyn std::fmt::Display| {
        let i = match cause {
            LossCause::Malformed => 0,
            LossCause::Unconvertible => 1,
            _ => 2,
        };
        if std::mem::replace(&mut warned[i], true) {
            tracing::debug!(%topic, ?cause, %detail, "a ROS 2 message not imported");
        } else {
            tracing::warn!(%topic, ?cause, %detail,
                "a ROS 2 message not imported (counted; further ones of this cause at debug level)");
        }
    };
    // Readiness, with a timeout to look at `stop`; without it, a poll of `take` now and then.
    let mut poll = Poll::new()
        .and_then(|p| {
            p.registry().register(&mut subscription, Token(0), Interest::READABLE)?;
            Ok(p)
        })
        .map_err(|e| tracing::warn!(%topic, error = %e, "cannot wait for messages; polling"))
        .ok();
    let mut events = Events::with_capacity(4);
    while !stop.load(Ordering::Relaxed) {
        match &mut poll {
            Some(p) => {
                if let Err(e) = p.poll(&mut events, Some(STOP_CHECK)) {
                    tracing::debug!(%topic, error = %e, "interrupted wait for messages");
                }
            }
            None => std::thread::sleep(Duration::from_millis(5)),
        }
        // Edge-triggered: take everything that has arrived.
        loop {
            match read(&subscription, handle, SystemClock.now()) {
                Ok(Some(structure)) => match structure {
                    Ok(es) => match handle.add(es) {
                        Ok(_) => counters.passed(),
                        Err(e) => {
                            counters.lost(LossCause::Refused, 1);
                            warn(LossCause::Refused, &e);
                        }
                    },
                    Err(e) => {
                        counters.lost(LossCause::Unconvertible, 1);
                        warn(LossCause::Unconvertible, &e);
                    }
                },
                Ok(None) => break,
                Err(e) => {
                    counters.lost(LossCause::Malformed, 1);
                    warn(LossCause::Malformed, &format_args!("{e:?}"));
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
    fn specs_parse_and_name_their_trajectory() {
        let s = ImportSpec::parse("/camera/image_raw:sensor_msgs/msg/Image").unwrap();
        assert_eq!(
            (s.message, s.trajectory.as_str()),
            (Imported::Standard(RosType::Image), "camera_image_raw")
        );
        let s = ImportSpec::parse("/odom2d:geometry_msgs/msg/Pose2D=robot_state").unwrap();
        assert_eq!(
            (s.message, s.trajectory.as_str()),
            (Imported::Standard(RosType::Pose2D), "robot_state")
        );
        let s = ImportSpec::parse("/blobs:esgm_msgs/msg/BlobSeq").unwrap();
        assert_eq!(
            (s.message, s.trajectory.as_str()),
            (Imported::Generated("BlobSeq".into()), "blobs")
        );
        for bad in ["/camera", ":sensor_msgs/msg/Image", "/c:sensor_msgs/msg/Image="] {
            assert!(matches!(ImportSpec::parse(bad), Err(ImportError::Syntax { .. })), "{bad}");
        }
        assert!(matches!(
            ImportSpec::parse("/scan:sensor_msgs/msg/LaserScan"),
            Err(ImportError::Mapping(MappingError::UnknownMessage { .. }))
        ));
    }
}
