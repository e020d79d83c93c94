//! The ROS 2 node `esgm ros2` is on the graph, and the QoS of its topics.
//!
//! **Names.** Topics are absolute ROS 2 names (`/camera/image_raw`), which DDS sees as
//! `rt/camera/image_raw`, as every ROS 2 middleware on DDS writes them. The node is
//! `/esgm/<name>` (by default `esgm_<domain>`, so `ros2 node list` shows which esgm
//! system it bridges).
//!
//! **QoS**, as ROS 2's defaults: reliable, keep-last `depth` (10), volatile. An import
//! may ask for best effort (`--best-effort`), which also matches best-effort sensor
//! drivers (`rclcpp::SensorDataQoS`); a reliable reader never matches them.

use ros2_client::qos::{Durability, History};
use ros2_client::{Context, ContextOptions, Name, Node, NodeName, NodeOptions, QosProfile};

/// How a topic is delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicQos {
    /// Reliable (ROS 2's default) or best effort.
    pub reliable: bool,
    /// Keep-last depth.
    pub depth: usize,
}

impl Default for TopicQos {
    fn default() -> Self {
        Self { reliable: true, depth: 10 }
    }
}

impl TopicQos {
    /// As `ros2-client` takes it.
    pub fn profile(self) -> QosProfile {
        let base = QosProfile::publisher_default()
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: self.depth });
        if self.reliable {
            base.reliability_reliable(ros2_client::qos::WhenFull::DEFAULT)
        } else {
            base.reliability_best_effort()
        }
    }
}

/// Joining the ROS 2 graph failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NodeError {
    /// The DDS participant could not be made (no network interface, a domain id past
    /// what DDS ports allow).
    #[error("cannot join ROS 2 domain {domain_id}: {detail}")]
    Participant {
        /// `ROS_DOMAIN_ID`.
        domain_id: u16,
        /// DDS's words.
        detail: String,
    },
    /// The node's name is not a ROS 2 name.
    #[error("`{name}` is not a ROS 2 node name: {detail}")]
    NodeName {
        /// The name.
        name: String,
        /// Why.
        detail: String,
    },
    /// A topic's name is not a ROS 2 name (absolute, letters, digits, `_` and `/`).
    #[error("`{topic}` is not a ROS 2 topic name: {detail}")]
    TopicName {
        /// The name.
        topic: String,
        /// Why.
        detail: String,
    },
    /// The node, a topic, a publisher or a subscription could not be made.
    #[error("cannot create the {what} of `{topic}`: {detail}")]
    Create {
        /// What.
        what: &'static str,
        /// The topic (or node).
        topic: String,
        /// DDS's words.
        detail: String,
    },
}

/// The node, and the DDS participant under it.
pub struct RosNode {
    /// The node (dropped first: see `context`).
    pub node: Node,
    /// The participant, kept past the node: the node's own writers (parameter events)
    /// are dropped after its reference to the participant, and the last reference
    /// stopping the participant first made each exit log an error.
    context: Context,
}

impl RosNode {
    /// The DDS participant's context.
    pub fn context(&self) -> &Context {
        &self.context
    }
}

impl std::fmt::Debug for RosNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RosNode").field("node", &self.node.fully_qualified_name()).finish()
    }
}

/// Joins ROS 2 domain `domain_id` as the node `/esgm/<name>`.
pub fn join(domain_id: u16, name: &str) -> Result<RosNode, NodeError> {
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
        .map_err(|e| NodeError::Participant { domain_id, detail: e.to_string() })?;
    let node_name = NodeName::new("/esgm", name)
        .map_err(|e| NodeError::NodeName { name: name.to_owned(), detail: format!("{e:?}") })?;
    let node =
        context.new_node(node_name, NodeOptions::new().enable_rosout(false)).map_err(|e| {
            NodeError::Create { what: "node", topic: name.to_owned(), detail: format!("{e:?}") }
        })?;
    Ok(RosNode { node, context })
}

/// A standard message's type name as `ros2-client` takes it.
pub fn message_type_name(t: esgm_ros2msg::mapping::RosType) -> ros2_client::MessageTypeName {
    let (package, name) = t.package_and_name();
    ros2_client::MessageTypeName::new(package, name)
}

/// The topic of a bridged ROS 2 `topic` (absolute) of `message_type` on `node`, with
/// esgm's side of it for the [`crate::watch`] (`direction`, `qos`, where an
/// incompatible peer is counted): what an import and an export both make first.
pub fn bridged_topic(
    node: &mut ros2_client::Node,
    topic: &str,
    message_type: ros2_client::MessageTypeName,
    direction: crate::stats::Direction,
    qos: TopicQos,
    counters: &std::sync::Arc<crate::stats::TopicCounters>,
) -> Result<(ros2_client::dds::rustdds::Topic, crate::watch::Watched), NodeError> {
    let watched = crate::watch::Watched::new(
        topic,
        &message_type,
        direction,
        &qos.profile(),
        std::sync::Arc::clone(counters),
    );
    let made = node.create_topic(&topic_name(topic)?, message_type, &qos.profile());
    let made = made.map_err(|e| create_error("topic", topic, &e))?;
    Ok((made, watched))
}

/// Making `what` (a topic, a publisher, a subscription) for `topic` failed.
pub fn create_error(what: &'static str, topic: &str, e: &dyn std::fmt::Debug) -> NodeError {
    NodeError::Create { what, topic: topic.to_owned(), detail: format!("{e:?}") }
}

/// A ROS 2 topic name as `ros2-client` takes it.
pub fn topic_name(topic: &str) -> Result<Name, NodeError> {
    let bad = |detail: String| NodeError::TopicName { topic: topic.to_owned(), detail };
    if !topic.starts_with('/') {
        return Err(bad("esgm takes absolute names (`/camera/image_raw`)".into()));
    }
    Name::parse(topic).map_err(|e| bad(format!("{e:?}")))
}

/// The node name for esgm system `domain`: `esgm_<domain>`, with what ROS 2 names do
/// not allow replaced by `_`.
pub fn default_node_name(domain: &str) -> String {
    let cleaned: String =
        domain.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    format!("esgm_{cleaned}")
}
