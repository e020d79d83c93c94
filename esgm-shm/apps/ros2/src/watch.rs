//! What DDS matches silently never: a peer on a bridged topic whose QoS is
//! incompatible with esgm's side, or whose message type is another. DDS then delivers
//! nothing, and says so only in a status event (dora #2735 is a bridge that "silently
//! receives nothing"). The watch reads what discovery knows about every endpoint of the
//! bridged topics, and for each peer that cannot match logs one error naming the QoS
//! policy with both sides' settings (or both types), and counts it in the topic's
//! report (`incompatible`).

use std::collections::BTreeSet;
use std::sync::Arc;

use ros2_client::QosProfile;
use ros2_client::dds::rustdds::qos::QosPolicyId;
use ros2_client::dds::rustdds::{DomainParticipant, GUID, QosPolicies, RTPSEntity as _};

use crate::stats::{Direction, TopicCounters};

/// One bridged topic, as DDS names it.
#[derive(Debug)]
pub struct Watched {
    /// `rt/camera/image_raw`.
    pub dds_topic: String,
    /// `sensor_msgs::msg::dds_::Image_`.
    pub dds_type: String,
    /// esgm's side of it: a reader for an import, a writer for an export.
    pub direction: Direction,
    /// The QoS esgm's reader requests, or its writer offers.
    pub qos: QosPolicies,
    /// Where an incompatible peer is counted.
    pub counters: Arc<TopicCounters>,
}

/// A bridged topic's thread, and what the watch looks at for it.
#[derive(Debug)]
pub struct Spawned {
    /// The thread moving its messages, until told to stop.
    pub thread: std::thread::JoinHandle<()>,
    /// The topic as DDS names it, with esgm's QoS on it.
    pub watched: Watched,
}

impl Watched {
    /// ROS 2 topic `topic` (absolute) of `message_type`, esgm's side of it with `qos`.
    pub fn new(
        topic: &str,
        message_type: &ros2_client::MessageTypeName,
        direction: Direction,
        qos: &QosProfile,
        counters: Arc<TopicCounters>,
    ) -> Self {
        Self {
            dds_topic: format!("rt{topic}"),
            dds_type: message_type.dds_msg_type(),
            direction,
            qos: qos.into(),
            counters,
        }
    }
}

/// The bridged topics, and the peers already reported.
#[derive(Debug, Default)]
pub struct Watch {
    topics: Vec<Watched>,
    reported: BTreeSet<(String, GUID)>,
}

/// Why a peer cannot match esgm's side of a topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mismatch {
    /// A QoS policy the writer does not offer as the reader requests.
    Qos {
        /// The policy.
        policy: QosPolicyId,
        /// The writer's setting.
        offered: String,
        /// The reader's setting.
        requested: String,
    },
    /// Another message type on the same topic.
    Type {
        /// The peer's type.
        theirs: String,
    },
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Mismatch::Qos { policy, offered, requested } => write!(
                f,
                "incompatible QoS {policy:?}: the writer offers {offered}, the reader requests {requested}"
            ),
            Mismatch::Type { theirs } => write!(f, "another message type: {theirs}"),
        }
    }
}

impl Watch {
    /// Watches `topic` too.
    pub fn add(&mut self, topic: Watched) {
        self.topics.push(topic);
    }

    /// Looks at every endpoint discovery knows on the watched topics; reports each
    /// peer that cannot match, once. Returns how many were new.
    pub fn check(&mut self, dp: &DomainParticipant) -> usize {
        let own = dp.guid().prefix;
        let writers = dp.discovered_writers();
        let readers = dp.discovered_readers();
        let mut new = 0;
        for topic in &self.topics {
            let peers: Vec<(GUID, &str, QosPolicies)> = match topic.direction {
                Direction::Import => writers
                    .iter()
                    .map(|w| &w.publication_topic_data)
                    .filter(|p| p.topic_name == topic.dds_topic)
                    .map(|p| (p.key, p.type_name.as_str(), p.qos()))
                    .collect(),
                Direction::Export => readers
                    .iter()
                    .map(|r| (&r.reader_proxy, &r.subscription_topic_data))
                    .filter(|(_, s)| *s.topic_name() == topic.dds_topic)
                    .map(|(proxy, s)| (proxy.remote_reader_guid, s.type_name().as_str(), s.qos()))
                    .collect(),
            };
            for (peer, type_name, qos) in peers {
                if peer.prefix == own || self.reported.contains(&(topic.dds_topic.clone(), peer)) {
                    continue;
                }
                let Some(why) = mismatch(topic, type_name, &qos) else { continue };
                self.reported.insert((topic.dds_topic.clone(), peer));
                new += 1;
                let side = match topic.direction {
                    Direction::Import => "a writer",
                    Direction::Export => "a reader",
                };
                tracing::error!(topic = %topic.dds_topic, peer = ?peer, "{side} on the topic cannot match esgm's: {why}; DDS delivers nothing between them");
                topic.counters.incompatible(&why.to_string());
            }
        }
        new
    }
}

/// Why a peer with `type_name` and `qos` cannot match `topic`'s esgm side, if it
/// cannot.
fn mismatch(topic: &Watched, type_name: &str, qos: &QosPolicies) -> Option<Mismatch> {
    if type_name != topic.dds_type {
        return Some(Mismatch::Type { theirs: type_name.to_owned() });
    }
    let (offered, requested) = match topic.direction {
        Direction::Import => (qos, &topic.qos),
        Direction::Export => (&topic.qos, qos),
    };
    let policy = offered.compliance_failure_wrt(requested)?;
    Some(Mismatch::Qos {
        policy,
        offered: setting(offered, policy),
        requested: setting(requested, policy),
    })
}

/// `qos`'s setting of `policy`, in ROS 2's words where it has them.
fn setting(qos: &QosPolicies, policy: QosPolicyId) -> String {
    let p = QosProfile::from(qos);
    match policy {
        QosPolicyId::Reliability => format!("{:?}", p.reliability),
        QosPolicyId::Durability => format!("{:?}", p.durability),
        QosPolicyId::Deadline => format!("deadline {:?}", p.deadline),
        QosPolicyId::Liveliness => {
            format!("{:?} (lease {:?})", p.liveliness, p.liveliness_lease)
        }
        QosPolicyId::Lifespan => format!("lifespan {:?}", p.lifespan),
        other => format!("its {other:?} setting"),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::node::TopicQos;
    use crate::stats::Stats;

    fn watched(direction: Direction, reliable: bool) -> Watched {
        let esgm = esgm_core::InProcessEsgm::builder().create();
        let t =
            esgm_core::Esgm::create_primitive_entity_trajectory_structure(&esgm, "camera", "Image")
                .unwrap();
        Watched {
            dds_topic: "rt/camera".into(),
            dds_type: "sensor_msgs::msg::dds_::Image_".into(),
            direction,
            qos: TopicQos { reliable, depth: 10 }.profile().into(),
            counters: Stats::default().topic("/camera", &t, direction),
        }
    }

    #[test]
    fn a_best_effort_writer_cannot_feed_a_reliable_reader() {
        let best_effort: QosPolicies = TopicQos { reliable: false, depth: 10 }.profile().into();
        let reliable: QosPolicies = TopicQos { reliable: true, depth: 10 }.profile().into();
        let topic = watched(Direction::Import, true);
        let why = mismatch(&topic, "sensor_msgs::msg::dds_::Image_", &best_effort).unwrap();
        assert!(matches!(&why, Mismatch::Qos { policy: QosPolicyId::Reliability, .. }), "{why:?}");
        assert!(why.to_string().contains("BestEffort"), "{why}");
        assert_eq!(mismatch(&topic, "sensor_msgs::msg::dds_::Image_", &reliable), None);
        // A best-effort reader takes from a reliable writer.
        let topic = watched(Direction::Import, false);
        assert_eq!(mismatch(&topic, "sensor_msgs::msg::dds_::Image_", &reliable), None);
        // esgm's reliable writer feeds a best-effort reader, not the other way round.
        let topic = watched(Direction::Export, false);
        assert!(mismatch(&topic, "sensor_msgs::msg::dds_::Image_", &reliable).is_some());
    }

    #[test]
    fn another_type_on_the_topic_is_named() {
        let reliable: QosPolicies = TopicQos { reliable: true, depth: 10 }.profile().into();
        let topic = watched(Direction::Import, true);
        let why = mismatch(&topic, "sensor_msgs::msg::dds_::CompressedImage_", &reliable);
        assert_eq!(
            why,
            Some(Mismatch::Type { theirs: "sensor_msgs::msg::dds_::CompressedImage_".into() })
        );
    }
}
