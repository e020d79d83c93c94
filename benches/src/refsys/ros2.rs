//! `refsys-ros2`: the reference system on ROS 2's wire — DDS through `ros2-client`
//! (RustDDS), the crate `esgm-ros2` and the `ros2-*` rows are built on — one process
//! (and one DDS participant) per node, as upstream's nodes would be with one executor
//! each. Every node runs [`super::node`]'s logic; only how messages move is DDS's:
//! - **topics** are named as upstream's (`/FrontLidarDriver`, …; `rt/…` on DDS) and
//!   carry **`reference_interfaces/msg/Message4kb`**, upstream's own type, not a generic
//!   `sequence<uint8>`: its fields are all naturally aligned, so its CDR is exactly
//!   [`super::message`]'s 4,096 bytes after the 4-byte encapsulation header, with no
//!   length prefix and no `MultiArrayLayout` (what `std_msgs/msg/UInt8MultiArray` would
//!   add), i.e. what an rclcpp node of upstream puts on the same wire. It is written as
//!   512 little-endian 64-bit words ([`Wire`]), eight times fewer serde calls than 4,096
//!   octets; a big-endian writer's messages would be read byte-swapped (none here);
//! - **QoS** is upstream's: rclcpp's default with depth 1 — reliable, volatile, keep
//!   last 1 — on every publisher and subscription (`esgm_ros2::node::TopicQos`);
//!   upstream's command sinks subscribe with depth 10, here with 1, as esgm's queue of
//!   one;
//! - a node is **one thread**, as a single-threaded executor: its subscriptions
//!   registered in a mio `Poll`, each taken whenever it is readable, its timer (a sensor's,
//!   the behavior planner's) fired between takes at START + k × period on the system
//!   clock, a missed tick skipped as rcl's timers skip it. A **fusion** fires once both
//!   inputs have a message it has not used (DDS delivers each message once, so this is
//!   upstream's callback, unchanged); the **intersection**'s two connections share the
//!   node's thread (upstream gives each a callback group; one thread serves them in turn).
//!
//! **Set-up.** A node says `ready` ([`super::processes`]) only once each of its
//! subscriptions has matched its topic's writer and each of its publishers every reader
//! the topology gives its topic — seen in the participant's status events
//! (`RemoteWriterMatched`, `RemoteReaderMatched`; ros2-client's own counts of them
//! need a running `Spinner`), with a deadline — so the window does not start while
//! discovery still runs and the first messages go nowhere (volatile). Every timer
//! starts at START, so the sensors are in phase, as upstream's timers made together in
//! its one process are: the two lidars fire together, and the point cloud fusion waits
//! for the rear one only as long as the two transformers differ.
//!
//! **Network.** DDS discovery is multicast: every participant runs inside one network
//! namespace the run makes, whose only interface is its loopback (made as the
//! `ros2-*` rows make theirs, `ros2_hop::dds_namespace`), removed when the run ends,
//! also when it fails. No namespace (not root, no `ip`): the row is skipped with the
//! reason; DDS never runs in the host's namespace.

use std::collections::{BTreeSet, HashMap};
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};
use esgm_ros2::node::{RosNode, TopicQos, join, topic_name};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::rustdds::{DomainParticipantStatusEvent, GUID, StatusEvented as _};
use ros2_client::{MessageTypeName, Publisher, Subscription};
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::{self, SerializeTuple as _, Serializer};
use serde::{Deserialize, Serialize};

use super::message::{MESSAGE_LEN, Message};
use super::node::{Command, Cyclic, Fusion, Sensor, Transform, now_ns};
use super::processes::NodeSide;
use super::report::NodeReport;
use super::system::{RunSettings, System, SystemRun};
use super::topology::{Kind, NODES, Node, build_order};

use crate::scenarios::ros2_hop::dds_namespace;

/// The peer argument's first word of a node process: `ros2-node|NODE|CRUNCH|DIR`.
pub const NODE: &str = "ros2-node";
/// How long a node waits for DDS discovery to match its endpoints (24 participants
/// starting together on two cores); within the runner's set-up deadline.
const MATCH_PATIENCE: Duration = Duration::from_secs(60);
/// The longest a node blocks without looking at the clock (its end, a timer).
const POLL_AT_MOST: Duration = Duration::from_millis(100);
/// The message's ROS 2 package and name.
const MESSAGE_TYPE: (&str, &str) = ("reference_interfaces", "Message4kb");
/// 64-bit words of a message on the wire.
const WORDS: usize = MESSAGE_LEN / 8;

/// `reference_interfaces/msg/Message4kb` as CDR carries it (see the module docs): the
/// message's bytes as 512 little-endian 64-bit words, checked as a
/// [`Message`] when read.
#[derive(Debug, Clone)]
pub struct Wire(pub Message);

impl Serialize for Wire {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut words = serializer.serialize_tuple(WORDS)?;
        for chunk in self.0.as_bytes().chunks_exact(8) {
            let word: [u8; 8] = chunk.try_into().map_err(ser::Error::custom)?;
            words.serialize_element(&u64::from_le_bytes(word))?;
        }
        words.end()
    }
}

impl<'de> Deserialize<'de> for Wire {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Words;
        impl<'de> Visitor<'de> for Words {
            type Value = Wire;

            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "a Message4kb: {WORDS} 64-bit words")
            }

            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Wire, A::Error> {
                let mut bytes = [0u8; MESSAGE_LEN];
                for (i, chunk) in bytes.chunks_exact_mut(8).enumerate() {
                    let word: u64 = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(i, &"512 64-bit words"))?;
                    chunk.copy_from_slice(&word.to_le_bytes());
                }
                // Bytes from another process: checked before any node reads them.
                Message::from_bytes(&bytes).map(Wire).map_err(de::Error::custom)
            }
        }
        deserializer.deserialize_tuple(WORDS, Words)
    }
}

/// `refsys-ros2` (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Ros2;

impl System for Ros2 {
    fn name(&self) -> &'static str {
        "ros2"
    }

    fn summary(&self) -> &'static str {
        "ROS 2's wire: DDS through ros2-client (RustDDS), one process per node, in a \
         loopback-only network namespace"
    }

    /// A namespace is made and removed to find out.
    fn unavailable(&self) -> Option<String> {
        dds_namespace("refsys-probe").err()
    }

    fn run(&self, s: &RunSettings) -> anyhow::Result<SystemRun> {
        // Made first, so dropped last: after every node process is gone (the runner
        // kills what is left on an error).
        let ns = dds_namespace("refsys").map_err(|why| anyhow!(why))?;
        let exe = std::env::current_exe().context("cannot find the esgm-bench executable")?;
        let exe = exe.to_str().with_context(|| format!("{} is not UTF-8", exe.display()))?;
        let mut processes = Vec::new();
        for n in build_order() {
            let role = crate::peer_role::PeerRole {
                scenario: crate::scenarios::refsys::NAME.to_owned(),
                wait: crate::wait_mode::WaitMode::Block,
                // DDS participants meet in the namespace; there is no esgm domain.
                domain: "-".to_owned(),
                core: None,
                arg: Some(format!("{NODE}|{}|{}|{}", n.name, s.crunch, s.dir.display())),
            };
            let mut command = ns.command(exe);
            command.args(role.to_args());
            processes.push((n.name.to_owned(), command));
        }
        let count = processes.len();
        let (reports, usage, mut notes) = super::processes::run(processes, &[], s)?;
        notes.extend([
            "DDS: RustDDS through ros2-client, one participant per node process, all in a \
             loopback-only network namespace made for the run"
                .to_owned(),
            "message: reference_interfaces/msg/Message4kb, upstream's type; its CDR is the \
             4,096 bytes after a 4-byte header"
                .to_owned(),
            "QoS: reliable, volatile, keep last 1 on every endpoint (upstream's command sinks \
             subscribe with depth 10)"
                .to_owned(),
            "each node one thread taking its subscriptions on a mio poll, as a \
             single-threaded executor; every endpoint matched before the window opened"
                .to_owned(),
            "every timer from START on: the sensors in phase, as upstream's in one process"
                .to_owned(),
        ]);
        Ok(SystemRun { reports, usage, processes: count, notes })
    }
}

/// What a node does with its messages ([`super::node`]'s logic).
enum Logic {
    Sensor(Sensor),
    /// A transform, or the intersection's two connections (input `i` to output `i`).
    Transform(Vec<Transform>),
    Fusion(Fusion),
    Cyclic(Cyclic),
    Command(Command),
}

impl Logic {
    fn new(node: &'static Node, crunch: u64) -> Self {
        let name = node.name;
        match node.kind {
            Kind::Sensor { .. } => Logic::Sensor(Sensor::new(name)),
            Kind::Transform { input } => {
                Logic::Transform(vec![Transform::new(name, input, name, crunch)])
            }
            Kind::Intersection { connections } => Logic::Transform(
                connections.iter().map(|(i, o)| Transform::new(name, i, o, crunch)).collect(),
            ),
            Kind::Fusion { inputs } => Logic::Fusion(Fusion::new(name, inputs, crunch)),
            Kind::Cyclic { inputs, .. } => Logic::Cyclic(Cyclic::new(name, &inputs, crunch)),
            Kind::Command { input } => Logic::Command(Command::new(name, input)),
        }
    }

    /// Takes a message of input `index` (in [`Node::inputs`]'s order); what to publish
    /// on which topic, if anything.
    fn on_input(
        &mut self,
        node: &'static Node,
        index: usize,
        m: Message,
    ) -> Option<(&'static str, Message)> {
        match self {
            Logic::Transform(ts) => ts.get_mut(index).map(|t| (t.output(), t.on_input(&m))),
            Logic::Fusion(f) => f.on_input(index, m).map(|out| (node.name, out)),
            Logic::Cyclic(c) => {
                c.on_input(index, m);
                None
            }
            Logic::Command(c) => {
                c.on_input(&m);
                None
            }
            Logic::Sensor(_) => None,
        }
    }

    /// Its timer fired: what to publish.
    fn on_timer(&mut self, node: &'static Node) -> Option<(&'static str, Message)> {
        match self {
            Logic::Sensor(s) => Some((node.name, s.fire())),
            Logic::Cyclic(c) => Some((node.name, c.on_timer())),
            _ => None,
        }
    }

    fn report(&self) -> NodeReport {
        match self {
            Logic::Sensor(s) => s.report(),
            Logic::Transform(ts) => {
                let mut reports = ts.iter().map(Transform::report);
                let mut first = reports.next().unwrap_or_default();
                reports.for_each(|r| first.merge(r));
                first
            }
            Logic::Fusion(f) => f.report(),
            Logic::Cyclic(c) => c.report(),
            Logic::Command(c) => c.report(),
        }
    }
}

/// A node's timer period (a sensor's, the planner's), if it has one.
fn period_of(node: &Node) -> Option<Duration> {
    match node.kind {
        Kind::Sensor { period } | Kind::Cyclic { period, .. } => Some(period),
        _ => None,
    }
}

/// How many nodes read `topic`: the readers its publisher waits to match.
fn readers_of(topic: &str) -> usize {
    NODES.iter().filter(|n| n.inputs().contains(&topic)).count()
}

/// A node's place on the ROS 2 graph: its participant, publishers and subscriptions.
struct Endpoints {
    /// Dropped last: the participant outlives its endpoints.
    ros: RosNode,
    /// Per output topic.
    publishers: Vec<(&'static str, Publisher<Wire>)>,
    /// Per input topic, in [`Node::inputs`]'s order.
    subscriptions: Vec<(&'static str, Subscription<Wire>)>,
}

impl Endpoints {
    /// Joins DDS as `node` and makes its endpoints.
    fn create(node: &'static Node) -> anyhow::Result<Self> {
        let mut ros = join(0, node.name)?;
        let qos = TopicQos { reliable: true, depth: 1 }.profile();
        let topic = |ros: &mut RosNode, name: &str| -> anyhow::Result<_> {
            let ros_name = topic_name(&format!("/{name}"))?;
            let type_name = MessageTypeName::new(MESSAGE_TYPE.0, MESSAGE_TYPE.1);
            ros.node
                .create_topic(&ros_name, type_name, &qos)
                .map_err(|e| anyhow!("cannot create topic /{name}: {e:?}"))
        };
        let mut publishers = Vec::new();
        for output in node.outputs() {
            let t = topic(&mut ros, output)?;
            let p = ros
                .node
                .create_publisher(&t, None)
                .map_err(|e| anyhow!("cannot create the publisher of /{output}: {e:?}"))?;
            publishers.push((output, p));
        }
        let mut subscriptions = Vec::new();
        for input in node.inputs() {
            let t = topic(&mut ros, input)?;
            let s = ros
                .node
                .create_subscription(&t, None)
                .map_err(|e| anyhow!("cannot create the subscription of /{input}: {e:?}"))?;
            subscriptions.push((input, s));
        }
        Ok(Self { ros, publishers, subscriptions })
    }

    /// Waits until every subscription matched a writer and every publisher all the
    /// readers of its topic (see the module docs); fails after [`MATCH_PATIENCE`],
    /// naming what did not match.
    fn wait_for_matches(&self) -> anyhow::Result<()> {
        let listener = self.ros.context().domain_participant().status_listener();
        let mut matched: HashMap<GUID, BTreeSet<GUID>> = HashMap::new();
        let deadline = Instant::now() + MATCH_PATIENCE;
        loop {
            while let Some(event) = listener.try_recv_status() {
                match event {
                    DomainParticipantStatusEvent::RemoteReaderMatched {
                        local_writer,
                        remote_reader,
                    } => {
                        matched.entry(local_writer).or_default().insert(remote_reader);
                    }
                    DomainParticipantStatusEvent::RemoteWriterMatched {
                        local_reader,
                        remote_writer,
                    } => {
                        matched.entry(local_reader).or_default().insert(remote_writer);
                    }
                    DomainParticipantStatusEvent::ReaderLost { guid, .. }
                    | DomainParticipantStatusEvent::WriterLost { guid, .. } => {
                        matched.values_mut().for_each(|m| {
                            m.remove(&guid);
                        });
                    }
                    _ => {}
                }
            }
            let count = |guid: GUID| matched.get(&guid).map_or(0, BTreeSet::len);
            let mut missing = Vec::new();
            for (topic, p) in &self.publishers {
                let (have, want) = (count(p.guid()), readers_of(topic));
                if have < want {
                    missing.push(format!("publisher of /{topic}: {have} of {want} readers"));
                }
            }
            for (topic, s) in &self.subscriptions {
                if count(s.guid()) == 0 {
                    missing.push(format!("subscription of /{topic}: no writer"));
                }
            }
            if missing.is_empty() {
                return Ok(());
            }
            if Instant::now() >= deadline {
                bail!(
                    "DDS discovery matched not all endpoints within {MATCH_PATIENCE:?}: {}",
                    missing.join(", ")
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    fn publish(&self, topic: &str, m: Message) -> anyhow::Result<()> {
        let (_, p) = self
            .publishers
            .iter()
            .find(|(t, _)| *t == topic)
            .with_context(|| format!("no publisher of /{topic}"))?;
        p.publish(Wire(m)).map_err(|e| anyhow!("publishing on /{topic}: {e}"))
    }
}

/// A node's timer: fires at START + k × period while inside the window.
struct Timer {
    period: u64,
    next: u64,
}

impl Timer {
    /// After a tick: the next one, skipping those already missed (as rcl's timers do).
    fn advance(&mut self, now: u64) {
        self.next += self.period;
        if now >= self.next {
            self.next += ((now - self.next) / self.period + 1) * self.period;
        }
    }
}

/// Runs node `name` with `crunch` of work per message, writing its report into `dir`.
fn node_main(name: &str, crunch: u64, dir: &std::path::Path) -> anyhow::Result<()> {
    let node = super::topology::node(name).with_context(|| format!("no node {name}"))?;
    let mut endpoints = Endpoints::create(node)?;
    let mut poll = Poll::new().context("a mio poll for the subscriptions")?;
    for (i, (topic, s)) in endpoints.subscriptions.iter_mut().enumerate() {
        poll.registry()
            .register(s, Token(i), Interest::READABLE)
            .with_context(|| format!("registering the subscription of /{topic} with mio"))?;
    }
    endpoints.wait_for_matches()?;
    let mut logic = Logic::new(node, crunch);

    let (side, start, until) = NodeSide::ready()?;
    let end = until.saturating_add(u64::try_from(super::esgm::DRAIN.as_nanos()).unwrap_or(0));
    let mut timer = period_of(node).map(|p| Timer {
        period: u64::try_from(p.as_nanos()).unwrap_or(u64::MAX).max(1),
        next: start,
    });
    let mut events = Events::with_capacity(8);
    loop {
        // Taken before every wait: mio's readiness is edge-triggered.
        for i in 0..endpoints.subscriptions.len() {
            loop {
                let (topic, s) = &endpoints.subscriptions[i];
                let taken = s.take().map_err(|e| anyhow!("reading /{topic}: {e:?}"))?;
                let Some((Wire(m), _info)) = taken else { break };
                if let Some((out, message)) = logic.on_input(node, i, m) {
                    endpoints.publish(out, message)?;
                }
            }
        }
        let now = now_ns();
        if let Some(t) = timer.as_mut().filter(|t| now >= t.next) {
            if t.next < until {
                if let Some((out, message)) = logic.on_timer(node) {
                    endpoints.publish(out, message)?;
                }
            }
            t.advance(now);
            continue;
        }
        if now >= end {
            break;
        }
        let wake = timer.as_ref().map_or(end, |t| t.next.min(end));
        let left = Duration::from_nanos(wake - now).min(POLL_AT_MOST);
        // mio waits in whole milliseconds, rounded up: the last part is slept, so a
        // timer fires on time rather than up to a millisecond late.
        let whole_ms = Duration::from_millis(u64::try_from(left.as_millis()).unwrap_or(0));
        if whole_ms.is_zero() {
            std::thread::sleep(left);
        } else if let Err(e) = poll.poll(&mut events, Some(whole_ms)) {
            // EINTR: look again.
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(e).context("waiting for messages");
            }
        }
    }
    side.done(&[logic.report()], dir)
}

/// Runs this process as a node of `refsys-ros2` (`arg`: `ros2-node|NODE|CRUNCH|DIR`,
/// started inside the run's namespace). `None` if `arg` is not one of its processes'.
pub fn peer_main(arg: &str) -> Option<anyhow::Result<()>> {
    let mut parts = arg.splitn(4, '|');
    if parts.next() != Some(NODE) {
        return None;
    }
    let (Some(node), Some(crunch), Some(dir)) = (parts.next(), parts.next(), parts.next()) else {
        return Some(Err(anyhow!("a {NODE} process takes `{NODE}|NODE|CRUNCH|DIR`, not {arg:?}")));
    };
    Some(
        crunch
            .parse()
            .context("the crunch limit")
            .and_then(|crunch| node_main(node, crunch, std::path::Path::new(dir)))
            .with_context(|| format!("refsys-ros2 node {node}")),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wire_is_upstreams_message4kb_byte_for_byte() {
        let mut m = Message::default();
        m.push_hop("FrontLidarDriver", 7, 1, 1_795_000_000_000_000_000);
        m.set_result(564);
        let mut cdr = Vec::new();
        esgm_ros2msg::cdr::encode_into(&Wire(m.clone()), &mut cdr).unwrap();
        // The encapsulation header, then the message's bytes as they are.
        assert_eq!(cdr.len(), 4 + MESSAGE_LEN);
        assert_eq!(&cdr[4..], &m.as_bytes()[..]);
        let back: Wire = esgm_ros2msg::cdr::decode(&cdr).unwrap();
        assert_eq!(back.0, m);
        // A count of stats past the capacity is refused when read.
        cdr[4] = 64;
        assert!(esgm_ros2msg::cdr::decode::<Wire>(&cdr).is_err());
    }

    #[test]
    fn a_late_timer_skips_the_ticks_it_missed() {
        let mut t = Timer { period: 100, next: 1_000 };
        t.advance(1_010);
        assert_eq!(t.next, 1_100);
        t.advance(1_350);
        assert_eq!(t.next, 1_400);
    }

    #[test]
    fn every_topic_has_its_readers() {
        assert_eq!(readers_of("PointCloudFusion"), 2);
        assert_eq!(readers_of("Lanelet2MapLoader"), 3);
        assert_eq!(readers_of("EuclideanIntersection"), 1);
    }
}
