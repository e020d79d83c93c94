//! Every message through `esgm ros2`, counted per topic: how many passed, and each one
//! lost with its cause. Printed as JSON lines (`--report-every`, and when it stops), so
//! a bridge that receives nothing says so, and why.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::{BridgeLoss, EntityTrajectoryStructure as _, InProcessTrajectory};
use serde::Serialize;
use std::sync::Mutex;

/// Which way a topic goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// A ROS 2 topic read into a trajectory.
    Import,
    /// A trajectory published as a ROS 2 topic.
    Export,
}

/// Why a message or sample did not get through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LossCause {
    /// The DDS sample did not decode as the topic's message type.
    Malformed,
    /// A field has no counterpart on the other side ([`crate::mapping::MappingError`]).
    Unconvertible,
    /// The trajectory's gate refused the structure (its policy or type).
    Refused,
    /// The esgm side fell behind: the subscription's queue overflowed.
    SlowSide,
    /// DDS refused to send it.
    PublishFailed,
}

impl LossCause {
    /// The cause as the trajectory's statistics count it (`esgm stats`); `None` for a
    /// refusal, which the trajectory's gate counted itself (as its violation or type).
    pub fn bridge_loss(self) -> Option<BridgeLoss> {
        match self {
            LossCause::Malformed => Some(BridgeLoss::Undecodable),
            LossCause::Unconvertible => Some(BridgeLoss::Unconvertible),
            LossCause::Refused => None,
            LossCause::SlowSide => Some(BridgeLoss::Behind),
            LossCause::PublishFailed => Some(BridgeLoss::NotSent),
        }
    }
}

const CAUSES: [LossCause; 5] = [
    LossCause::Malformed,
    LossCause::Unconvertible,
    LossCause::Refused,
    LossCause::SlowSide,
    LossCause::PublishFailed,
];

/// One topic's counters, kept here for the bridge's report and counted on the
/// trajectory too (its writer's store for an import, this process's replica for an
/// export), where `esgm stats` shows them.
#[derive(Debug)]
pub struct TopicCounters {
    topic: String,
    trajectory: InProcessTrajectory,
    direction: Direction,
    passed: AtomicU64,
    lost: [AtomicU64; CAUSES.len()],
    /// Peers that cannot match esgm's side (QoS or type), and why the last one.
    incompatible: AtomicU64,
    incompatibility: Mutex<Option<String>>,
}

impl TopicCounters {
    /// One more message through.
    pub fn passed(&self) {
        self.passed.fetch_add(1, Ordering::Relaxed);
    }

    /// `n` lost for `cause`: in the report, and in the trajectory's statistics.
    pub fn lost(&self, cause: LossCause, n: u64) {
        if let Some(i) = CAUSES.iter().position(|c| *c == cause) {
            self.lost[i].fetch_add(n, Ordering::Relaxed);
        }
        if let Some(loss) = cause.bridge_loss() {
            if let Err(e) = self.trajectory.count_bridge_loss(loss, n) {
                // Destroyed meanwhile: the report still counts it.
                tracing::debug!(topic = %self.topic, error = %e, "loss not counted on the trajectory");
            }
        }
    }

    /// One more peer that cannot match esgm's side of the topic ([`crate::watch`]).
    pub fn incompatible(&self, why: &str) {
        self.incompatible.fetch_add(1, Ordering::Relaxed);
        *self.incompatibility.lock().unwrap_or_else(std::sync::PoisonError::into_inner) =
            Some(why.to_owned());
    }

    /// Lost so far for `cause`.
    pub fn lost_for(&self, cause: LossCause) -> u64 {
        CAUSES.iter().position(|c| *c == cause).map_or(0, |i| self.lost[i].load(Ordering::Relaxed))
    }
}

/// One topic's counters as reported.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TopicReport {
    /// The ROS 2 topic.
    pub topic: String,
    /// The esgm trajectory.
    pub trajectory: String,
    /// Which way.
    pub direction: Direction,
    /// Messages through.
    pub passed: u64,
    /// Losses by cause (causes with none are left out).
    pub lost: Vec<(LossCause, u64)>,
    /// Peers on the topic that cannot match esgm's side (QoS or type): DDS delivers
    /// nothing between them.
    pub incompatible: u64,
    /// Why the last of them cannot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub incompatibility: Option<String>,
}

/// The counters of every topic of one `esgm ros2`.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    topics: Arc<Mutex<Vec<Arc<TopicCounters>>>>,
}

impl Stats {
    /// The counters of a new topic, bridged to `trajectory`.
    pub fn topic(
        &self,
        topic: &str,
        trajectory: &InProcessTrajectory,
        direction: Direction,
    ) -> Arc<TopicCounters> {
        let counters = Arc::new(TopicCounters {
            topic: topic.to_owned(),
            trajectory: trajectory.clone(),
            direction,
            passed: AtomicU64::new(0),
            lost: Default::default(),
            incompatible: AtomicU64::new(0),
            incompatibility: Mutex::new(None),
        });
        self.topics
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(Arc::clone(&counters));
        counters
    }

    /// Every topic's counters now.
    pub fn snapshot(&self) -> Vec<TopicReport> {
        let topics = self.topics.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        topics
            .iter()
            .map(|t| TopicReport {
                topic: t.topic.clone(),
                trajectory: t.trajectory.name().to_owned(),
                direction: t.direction,
                passed: t.passed.load(Ordering::Relaxed),
                lost: CAUSES.iter().map(|c| (*c, t.lost_for(*c))).filter(|(_, n)| *n > 0).collect(),
                incompatible: t.incompatible.load(Ordering::Relaxed),
                incompatibility: t
                    .incompatibility
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .clone(),
            })
            .collect()
    }
}
