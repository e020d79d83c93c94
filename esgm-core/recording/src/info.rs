//! What a recording holds, for people and scripts (`esgm info`, like `ros2 bag info`).

use std::path::PathBuf;

use esgm_core::time::Time;

use crate::reader::{Damage, Recording};

/// A recording summarised.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RecordingInfo {
    /// The file.
    pub file: PathBuf,
    /// Its size in bytes.
    pub bytes: u64,
    /// True when the recorder finished it (summary and footer present).
    pub complete: bool,
    /// Where the readable part ends, if the file is damaged or cut off.
    pub damage: Option<Damage>,
    /// Bytes readable, and their share of the file.
    pub recovered_bytes: u64,
    /// Earliest valid time, ns.
    pub start_valid_time: Option<Time>,
    /// Latest valid time, ns.
    pub end_valid_time: Option<Time>,
    /// End − start, seconds.
    pub duration_s: f64,
    /// Structures over all trajectories.
    pub structures: u64,
    /// Per trajectory.
    pub trajectories: Vec<TrajectoryInfoLine>,
    /// Topics of other tools, not read.
    pub foreign_topics: Vec<String>,
    /// The recording's metadata.
    pub metadata: std::collections::BTreeMap<String, String>,
}

/// One trajectory of a [`RecordingInfo`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct TrajectoryInfoLine {
    /// Its name.
    pub name: String,
    /// `primitive`, `sampled`, `computed`, …
    pub kind: String,
    /// Its type.
    pub type_name: String,
    /// Structures readable.
    pub count: u64,
    /// Structures per second of valid time.
    pub rate_hz: f64,
    /// Bytes of its messages.
    pub bytes: u64,
    /// Losses by cause.
    pub losses: std::collections::BTreeMap<String, u64>,
    /// Policy violations seen while recording.
    pub violations: u64,
}

impl Recording {
    /// The summary `esgm info` prints.
    pub fn info(&self) -> RecordingInfo {
        let range = self.valid_range();
        RecordingInfo {
            file: self.path.clone(),
            bytes: self.file_len,
            complete: self.complete,
            damage: self.damage.clone(),
            recovered_bytes: self.readable_len,
            start_valid_time: range.map(|r| r.0),
            end_valid_time: range.map(|r| r.1),
            duration_s: range.map_or(0.0, |(a, b)| (b as f64 - a as f64) / 1e9),
            structures: self.trajectories.iter().fold(0, |a, t| a.saturating_add(t.count)),
            trajectories: self
                .trajectories
                .iter()
                .map(|t| TrajectoryInfoLine {
                    name: t.info.name.clone(),
                    kind: t.info.kind.name().to_owned(),
                    type_name: t.info.type_name.clone(),
                    count: t.count,
                    rate_hz: match t.valid_range {
                        Some((a, b)) if b > a && t.count > 1 => {
                            (t.count - 1) as f64 / ((b as f64 - a as f64) / 1e9)
                        }
                        _ => 0.0,
                    },
                    bytes: t.bytes,
                    losses: t.losses.clone(),
                    violations: t.violations,
                })
                .collect(),
            foreign_topics: self.foreign_topics.clone(),
            metadata: self.metadata.clone(),
        }
    }
}
