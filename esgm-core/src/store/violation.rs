//! What happens to a structure offered to a trajectory: added, held, or dropped with a
//! cause (T4, C7).

use std::fmt;

use crate::policy::Constraint;
use crate::structure::SharedStructure;
use crate::time::Time;
use crate::type_check::InvalidType;

/// A structure broke a constraint of a trajectory's policy (the seed's
/// `PolicyViolation`). Returned by the blocking add forms, delivered to violation
/// subscribers, and counted in stats.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PolicyViolation {
    /// The trajectory.
    pub trajectory: String,
    /// The constraint that was broken.
    pub constraint: Constraint,
    /// The structure's valid time.
    pub valid_time: Time,
    /// The structure's create time.
    pub create_time: Time,
    /// When it was offered to the trajectory.
    pub add_time: Time,
    /// What exactly was wrong, for people (e.g. "valid time 5 is before 7").
    pub detail: String,
}

impl fmt::Display for PolicyViolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "policy violation in `{}`: {} constraint: {} (valid time {}, added at {})",
            self.trajectory, self.constraint, self.detail, self.valid_time, self.add_time
        )
    }
}

impl std::error::Error for PolicyViolation {}

/// Why a structure offered to a trajectory was not stored. Every drop is counted under
/// its cause.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum DropCause {
    /// It broke a policy constraint.
    Violation(Constraint),
    /// It did not fit the trajectory's type.
    InvalidType,
    /// It was held for reordering when the trajectory was reset.
    Reset,
    /// In a replica of a trajectory another process writes: the writer admitted it,
    /// but this process never received it (its queue was overwritten while it fell
    /// behind). Counted from the gap in the writer's sequence numbers.
    Lost,
    /// In a replica: bytes that arrived on the trajectory's service were not a valid
    /// sample of it, and were dropped unread (see [`Rejection`]).
    Rejected(Rejection),
    /// In a writer mirrored to other processes: admitted and stored here, but it could
    /// not be published to them (no shared-memory loan, encoding or sending failed).
    /// Its sequence number was used anyway, so each reader also counts it as
    /// [`DropCause::Lost`].
    Unpublished,
    /// A message on its way between this trajectory and another middleware (a ROS 2
    /// topic through `esgm ros2`) that the bridge lost: counted by the importing
    /// bridge on the trajectory it writes, by an exporting bridge on its replica.
    Bridge(BridgeLoss),
}

/// Why a bridge to another middleware lost a message ([`DropCause::Bridge`]): each is
/// the bridge's own count, so that `esgm stats` shows what never became a sample,
/// or never left as a message, beside what the trajectory itself dropped.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum BridgeLoss {
    /// The foreign message did not decode as its declared type.
    Undecodable,
    /// A field has no counterpart on the other side (an image encoding esgm has no
    /// format for, a sequence too long for its attribute).
    Unconvertible,
    /// The bridge fell behind: its queue on one side overflowed.
    Behind,
    /// The other middleware refused to send it.
    NotSent,
}

impl fmt::Display for BridgeLoss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BridgeLoss::Undecodable => "bridge_undecodable",
            BridgeLoss::Unconvertible => "bridge_unconvertible",
            BridgeLoss::Behind => "bridge_behind",
            BridgeLoss::NotSent => "bridge_not_sent",
        })
    }
}

/// Why a replica dropped bytes that arrived on its trajectory's service: hostile or
/// broken input from another process, counted by cause (`esgm stats`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum Rejection {
    /// The archive failed validation (bad offsets, lengths, nesting, values).
    Malformed,
    /// The header's type id is not the trajectory's type.
    WrongType,
    /// The header names a kind of sample this version does not know.
    UnknownKind,
    /// The header says more archive bytes than the sample holds.
    Truncated,
    /// A well-formed sample (or reset) from a publisher port that is not the one the
    /// registry names as the trajectory's writer: only the writer's gate admits
    /// structures, so anything else on the service bypassed it.
    NotWriter,
    /// A well-formed sample whose attributes do not match the trajectory's type (an
    /// attribute missing from the type, of another sort, or assigned twice), though
    /// its header names the type.
    WrongLayout,
    /// The sample names bytes in the trajectory's kept history that this reader cannot
    /// read (the file cannot be opened or mapped here).
    Unreadable,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Rejection::Malformed => "rejected_malformed",
            Rejection::WrongType => "rejected_wrong_type",
            Rejection::UnknownKind => "rejected_unknown_kind",
            Rejection::Truncated => "rejected_truncated",
            Rejection::NotWriter => "rejected_not_writer",
            Rejection::WrongLayout => "rejected_wrong_layout",
            Rejection::Unreadable => "rejected_unreadable",
        })
    }
}

impl fmt::Display for DropCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DropCause::Violation(c) => c.fmt(f),
            DropCause::InvalidType => f.write_str("invalid_type"),
            DropCause::Reset => f.write_str("reset"),
            DropCause::Lost => f.write_str("lost"),
            DropCause::Rejected(r) => r.fmt(f),
            DropCause::Unpublished => f.write_str("unpublished"),
            DropCause::Bridge(loss) => loss.fmt(f),
        }
    }
}

/// What an add did.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum AddOutcome {
    /// The structure entered the stream and was sent to subscribers.
    Added,
    /// The structure is held until `release_at` to restore valid-time order (C6); it
    /// enters the stream then unless an earlier-valid sample makes it a violation.
    Held {
        /// When it will be released.
        release_at: Time,
    },
    /// The structure broke a constraint, was dropped and counted (non-blocking forms
    /// only; the blocking forms return [`AddError::PolicyViolation`]).
    Dropped(PolicyViolation),
    /// The trajectory is written by another process: the structure (checked against
    /// the type here) was sent to it, and its policy gate decides; a violation there
    /// is counted in the trajectory's stats and reported to violation subscribers
    /// everywhere. Only the non-blocking forms answer this: the blocking forms wait
    /// for the writer's own outcome.
    Forwarded,
}

/// Errors of the add operations (T4).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum AddError {
    /// The structure does not fit the trajectory's type; fix the named attribute. It
    /// was dropped and counted.
    #[error("trajectory `{trajectory}`: {source}")]
    InvalidType {
        /// The trajectory.
        trajectory: String,
        /// What did not fit.
        source: InvalidType,
    },
    /// The structure broke a constraint (blocking forms only). It was dropped, counted
    /// and reported to violation subscribers.
    #[error(transparent)]
    PolicyViolation(Box<PolicyViolation>),
    /// The trajectory behind this handle was destroyed; get a new handle by name.
    #[error("no entity trajectory structure `{trajectory}` (destroyed)")]
    NoSuchEntityStructure {
        /// The trajectory's name.
        trajectory: String,
    },
    /// The trajectory does not accept structures from outside (e.g. a computed or
    /// sampled one fed by esgm itself).
    #[error("trajectory `{trajectory}` does not accept {operation}: it is fed by esgm")]
    OperationNotSupported {
        /// The trajectory.
        trajectory: String,
        /// The refused operation.
        operation: String,
    },
    /// The trajectory's writer is in another process, and this process cannot join
    /// the processes adding to it: a limit of the transport was reached (the error
    /// names the setting that raises it). Nothing was added.
    #[error(transparent)]
    LimitReached(#[from] crate::failures::LimitReached),
    /// The trajectory's writer was another process, which has exited (or let it go)
    /// without destroying it, and this process could not take it over: its writer is
    /// supervised and is being restarted, or it went while this add was on its way.
    /// Nothing was added (rather than sent to a queue nobody reads). Add again: the
    /// next add takes it over where that is allowed, or reaches the restarted writer.
    #[error("trajectory `{trajectory}`: its writer (process {pid}) has exited; nothing was added")]
    WriterGone {
        /// The trajectory.
        trajectory: String,
        /// The writer's pid, as the registry recorded it (0: not recorded).
        pid: u32,
    },
    /// The trajectory's writer is in another process and the structure could not be
    /// sent to it (see the reason); nothing was added.
    #[error("trajectory `{trajectory}`: cannot reach its writer: {reason}")]
    Unavailable {
        /// The trajectory.
        trajectory: String,
        /// Why.
        reason: crate::failures::Unreachable,
    },
}

/// Sends structures added to a replica to the process that writes the trajectory
/// (set with [`crate::TrajectoryStore::forward_adds`]); the transport implements it.
pub trait AddForwarder: Send + Sync + std::fmt::Debug {
    /// Sends `es`, already checked against the trajectory's type. Non-blocking
    /// (`blocking` false): answers [`AddOutcome::Forwarded`] once sent. Blocking: waits
    /// for the writer's gate and answers its outcome, a violation included
    /// ([`AddError::PolicyViolation`]), as an add in the writer's process would (T4).
    fn forward(&self, es: SharedStructure, blocking: bool) -> Result<AddOutcome, AddError>;

    /// True if the writer is known to be gone (its process exited, or it released the
    /// trajectory), so that an add would reach nobody. Asked before each add, without
    /// the store's lock: it must be cheap. The default knows of no writer that leaves.
    fn writer_gone(&self) -> bool {
        false
    }

    /// Asks to write `trajectory` here, since its writer is gone. Called without the
    /// store's lock, which the transport takes to make this store the writer's
    /// ([`crate::TrajectoryStore::adopt_adds`]). `Ok` means the add may go on: this
    /// store now admits adds itself, or another live writer serves them. An error is
    /// the add's. The default refuses ([`AddError::WriterGone`]), as for a writer that
    /// cannot be replaced.
    fn take_over(&self, trajectory: &str) -> Result<(), AddError> {
        Err(AddError::WriterGone { trajectory: trajectory.to_owned(), pid: 0 })
    }
}

/// How many of a trajectory's most recent drops its store remembers, with their
/// details ([`crate::esgm::Why`]).
pub const RECENT_DROPS: usize = 32;

/// One structure a trajectory dropped.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DropRecord {
    /// When.
    pub at: Time,
    /// Why.
    pub cause: DropCause,
    /// The structure's valid time.
    pub valid_time: Time,
    /// The rule it broke, in words.
    pub detail: String,
}
