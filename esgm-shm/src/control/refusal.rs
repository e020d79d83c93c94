//! Why the coordinator refuses a request that breaks one of its rules about who may
//! do what ([`super::protocol::ControlError::NotAllowed`]): each rule is a variant, so
//! a caller acts on it without reading a message.

use esgm_core::esgm::TrajectoryKind;
use serde::{Deserialize, Serialize};

/// A rule of the coordinator that a request broke.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Refusal {
    /// The coordinator could not tell which process asked (iceoryx2 did not name the
    /// client's node), and the request is one only a known process may make.
    #[error("a process the coordinator cannot identify may not {action}")]
    UnknownOrigin {
        /// What it asked to do (`report on \`cam\``, `name the writer of \`x\``).
        action: String,
    },
    /// A process reported on another one's record: only the supervisor, or the
    /// process itself, may.
    #[error(
        "process {pid} may not report on `{process}` (pid {}); only its supervisor or itself may",
        reported.map_or_else(|| "none".to_owned(), |p| p.to_string())
    )]
    NotItsRecord {
        /// The asking process.
        pid: u32,
        /// The process reported on.
        process: String,
        /// The pid the report named.
        reported: Option<u32>,
    },
    /// The trajectory (of this generation) has no writer placed.
    #[error("`{trajectory}` has no writer placed at generation {generation}")]
    NotPlaced {
        /// The trajectory.
        trajectory: String,
        /// The generation asked about.
        generation: u64,
    },
    /// The request is about a former generation of the name (destroyed and created
    /// again since): look it up again.
    #[error(
        "`{trajectory}` is generation {current}, not {asked}: the request is about a former trajectory"
    )]
    FormerGeneration {
        /// The trajectory.
        trajectory: String,
        /// Its generation now.
        current: u64,
        /// The generation the request named.
        asked: u64,
    },
    /// Another live process writes the trajectory: a second one cannot make readers
    /// take its samples for the writer's.
    #[error(
        "process {holder} writes `{trajectory}`; process {pid} may not take it over while it lives"
    )]
    WriterLives {
        /// The trajectory.
        trajectory: String,
        /// The writer's pid.
        holder: u32,
        /// The asking process.
        pid: u32,
    },
    /// Only the process that writes a trajectory may release it.
    #[error("only the process that writes `{trajectory}` may release it")]
    NotTheWriter {
        /// The trajectory.
        trajectory: String,
    },
    /// A sampled, computed or operator trajectory is written where its sensor or unit
    /// runs, and cannot be taken over by another process.
    #[error(
        "`{trajectory}` is {kind:?}: its writer is where its sensor or unit is, and cannot move"
    )]
    CannotMove {
        /// The trajectory.
        trajectory: String,
        /// Its kind.
        kind: TrajectoryKind,
    },
    /// The trajectory's writer is a process the coordinator supervises: it is
    /// restarted, and takes its trajectory back.
    #[error(
        "`{trajectory}` is written by `{writer}`, which the coordinator restarts; it takes the trajectory back"
    )]
    Supervised {
        /// The trajectory.
        trajectory: String,
        /// The supervised writer.
        writer: String,
    },
}
