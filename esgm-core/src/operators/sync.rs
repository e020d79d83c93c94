//! sync(s1..sn) (G2): a stream of states, each holding one item of every input, valid at
//! the same time.
//!
//! Three policies, each a [`Synchronizer`]:
//! - [`ExactSync`] emits a set when every input has an item with the same valid time.
//! - [`ApproximateSync`] matches items whose valid times differ, choosing exactly the sets
//!   ROS `message_filters`' ApproximateTime policy chooses on the same input (the
//!   requirement G2 states), optionally bounded by a tolerance
//!   ([`ApproximateConfig::tolerance`]).
//! - [`EpsilonSync`] emits a set as soon as every input has an item within a tolerance
//!   of the oldest, as message_filters' ApproximateEpsilonTime policy does.
//!
//! Every policy's bound on how far apart a set's valid times may be is called the
//! *tolerance*, in Rust, in configuration files (`tolerance = "20ms"`) and on the
//! command line (`--tolerance 20ms`). message_filters calls it `max_interval_duration`
//! (ApproximateTime) and `epsilon` (ApproximateEpsilonTime).
//!
//! ## Design decisions
//! - **Pure.** A synchronizer owns its queues and nothing else: [`Synchronizer::push`]
//!   takes one item and returns the sets that became decidable, in valid-time order. The
//!   runtime owns threads, channels and clocks; the algorithm stays deterministic and is
//!   tested by feeding stamps.
//! - **Generic over the item** through [`Stamped`], so the runtime syncs [`Sample`]s
//!   (stamped by their valid time) and tests sync bare stamps.
//! - **Nothing is lost silently.** Every item discarded without being part of an emitted
//!   set is counted in [`Synchronizer::dropped`], and by input and reason in
//!   [`Synchronizer::drops`]; together with what was emitted and
//!   [`Synchronizer::queued`] it accounts for every item pushed.
//!
//! ## Example
//! ```
//! use esgm_core::operators::sync::{ApproximateConfig, ApproximateSync, Stamped, SyncError};
//! use esgm_core::{Time, millis};
//!
//! #[derive(Debug, PartialEq)]
//! struct Reading(Time, &'static str);
//! impl Stamped for Reading {
//!     fn stamp(&self) -> Time {
//!         self.0
//!     }
//! }
//!
//! let config = ApproximateConfig::default().tolerance(millis(20));
//! let mut sync = ApproximateSync::new(2, config)?;
//! assert!(sync.push(0, Reading(millis(0), "camera"))?.is_empty());
//! // A later camera frame could still pair better with this scan: wait.
//! assert!(sync.push(1, Reading(millis(5), "lidar"))?.is_empty());
//! // This one cannot: the first pair is provably the best and comes out.
//! let sets = sync.push(0, Reading(millis(100), "camera"))?;
//! assert_eq!(sets, vec![vec![Reading(millis(0), "camera"), Reading(millis(5), "lidar")]]);
//! # Ok::<(), SyncError>(())
//! ```

mod approximate;
mod drops;
mod epsilon;
mod exact;

pub use approximate::{ApproximateConfig, ApproximateSync};
pub use drops::{InputDrops, SyncDropReason};
pub use epsilon::{EpsilonConfig, EpsilonSync};
pub use exact::{ExactConfig, ExactSync};

use crate::{Sample, Time};

/// The attribute of every sync trajectory's structures that holds its members' valid
/// times, in input order (a `LongSeq` of nanoseconds): which samples were matched.
pub const MEMBER_VALID_TIMES: &str = "member_valid_times";
/// The attribute of every sync trajectory's structures that holds its members' create
/// times, in input order (a `LongSeq` of nanoseconds).
pub const MEMBER_CREATE_TIMES: &str = "member_create_times";

/// A sync trajectory's type from its state type (one frame per input): the state with
/// [`MEMBER_VALID_TIMES`] and [`MEMBER_CREATE_TIMES`] added. The one definition every
/// place that synthesizes a sync's type uses (the runtime's catalog, the coordinator).
#[must_use]
pub fn with_member_times(
    state: crate::types::EntityStructureType,
) -> crate::types::EntityStructureType {
    state
        .attr(MEMBER_VALID_TIMES, crate::value::ValueSort::LongSeq)
        .attr(MEMBER_CREATE_TIMES, crate::value::ValueSort::LongSeq)
}

/// An item that carries the time it is valid at: what sync matches on.
///
/// Sync is generic over the item so the same algorithm serves esgm's [`Sample`] (and
/// anything else with a time stamp) without copying it into another shape.
pub trait Stamped {
    /// The valid time sync matches on.
    fn stamp(&self) -> Time;
}

impl Stamped for Sample {
    /// A sample is matched by the valid time of its structure (M3).
    fn stamp(&self) -> Time {
        self.structure.valid_time()
    }
}

/// Why a synchronizer could not be created or could not take an item.
#[derive(Debug, Clone, PartialEq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum SyncError {
    /// The item was pushed on an input the synchronizer does not have (or a setting
    /// named one). Use an index below the number of inputs it was created with.
    #[error("no such input {input}: this sync has {inputs} inputs (0..{inputs})")]
    NoSuchInput {
        /// The index that was given.
        input: usize,
        /// How many inputs the synchronizer has.
        inputs: usize,
    },
    /// A sync over zero inputs has nothing to synchronize. Create it with at least one.
    #[error("a sync needs at least one input")]
    NoInputs,
    /// A queue size of zero could never hold an item. Use at least 1 (2 or more is
    /// recommended: with 1 the approximate policy drops many items).
    #[error("the queue size must be at least 1")]
    ZeroQueueSize,
    /// A duration setting was negative. Give zero or a positive duration, in
    /// nanoseconds.
    #[error("{setting} must not be negative, got {value} ns")]
    NegativeDuration {
        /// Which setting was negative.
        setting: String,
        /// The value that was given.
        value: Time,
    },
    /// The age penalty was negative, infinite or NaN. Give a finite value `>= 0`
    /// (message_filters' default is 0.1; 0 compares set sizes without penalty).
    #[error("the age penalty must be finite and at least 0, got {0}")]
    InvalidAgePenalty(f64),
}

/// A sync(s1..sn) policy: takes items one input at a time, gives complete sets.
///
/// The runtime holds a synchronizer behind this trait so one worker serves both
/// policies; [`SyncPolicy::create`] picks the implementation.
pub trait Synchronizer<T> {
    /// How many inputs (s1..sn) the synchronizer matches.
    fn inputs(&self) -> usize;

    /// Feeds one item arriving on input `input` (items on one input should arrive in
    /// valid-time order). Returns every set that became decidable, in valid-time order;
    /// each set holds one item per input, indexed by input.
    ///
    /// # Errors
    /// [`SyncError::NoSuchInput`] if `input` is not below [`Synchronizer::inputs`]; the
    /// item is then not taken and nothing changes.
    fn push(&mut self, input: usize, item: T) -> Result<Vec<Vec<T>>, SyncError>;

    /// How many items were discarded without being part of an emitted set.
    fn dropped(&self) -> u64;

    /// The discarded items of each input (by input index), by reason: what `why`
    /// says of a sync that does not produce. They sum to [`Synchronizer::dropped`].
    fn drops(&self) -> &[InputDrops];

    /// How many items are held, waiting for a decision.
    fn queued(&self) -> usize;

    /// How many items of input `input` are held (0 for an input it does not have).
    fn queued_on(&self, input: usize) -> usize;
}

/// Which sync policy to use, with its settings: what a sync trajectory declares.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum SyncPolicy {
    /// Sets of items with identical valid times ([`ExactSync`]).
    Exact(ExactConfig),
    /// Sets chosen as ROS message_filters' ApproximateTime does ([`ApproximateSync`]).
    Approximate(ApproximateConfig),
    /// Sets emitted as soon as every input has an item within the tolerance of the
    /// oldest, as ROS message_filters' ApproximateEpsilonTime does ([`EpsilonSync`]).
    Epsilon(EpsilonConfig),
}

impl Default for SyncPolicy {
    /// Exact matching: the policy that never pairs items of different valid times.
    fn default() -> Self {
        SyncPolicy::Exact(ExactConfig::default())
    }
}

/// A sync policy written as words that do not make one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SyncWordsError {
    /// Not `exact`, `approximate` or `epsilon`.
    #[error("unknown sync policy `{0}` (exact, approximate or epsilon)")]
    Unknown(String),
    /// `approximate` or `epsilon` without a tolerance.
    #[error("sync policy `{0}` needs a tolerance")]
    NeedsTolerance(&'static str),
    /// `exact` with a tolerance, which it would ignore.
    #[error("an exact sync has no tolerance (approximate or epsilon use one)")]
    ToleranceForExact,
}

impl SyncPolicy {
    /// The policy named by `word` (`exact`, `approximate` or `epsilon`; unset: exact
    /// without a tolerance, approximate with one), matching within `tolerance` and
    /// keeping `queue_size` items per input: how a system file, the command line and
    /// Python name it.
    ///
    /// # Errors
    /// [`SyncWordsError`]: an unknown word, or a tolerance missing or given in vain.
    pub fn from_words(
        word: Option<&str>,
        tolerance: Option<Time>,
        queue_size: usize,
    ) -> Result<Self, SyncWordsError> {
        Ok(match (word.map(str::trim), tolerance) {
            (None | Some("exact"), None) => {
                SyncPolicy::Exact(ExactConfig::default().queue_size(queue_size))
            }
            (Some("exact"), Some(_)) => return Err(SyncWordsError::ToleranceForExact),
            (None | Some("approximate"), Some(t)) => SyncPolicy::Approximate(
                ApproximateConfig::default().queue_size(queue_size).tolerance(t),
            ),
            (Some("epsilon"), Some(t)) => {
                SyncPolicy::Epsilon(EpsilonConfig::default().queue_size(queue_size).tolerance(t))
            }
            (Some("approximate"), None) => {
                return Err(SyncWordsError::NeedsTolerance("approximate"));
            }
            (Some("epsilon"), None) => return Err(SyncWordsError::NeedsTolerance("epsilon")),
            (Some(other), _) => return Err(SyncWordsError::Unknown(other.to_owned())),
        })
    }

    /// Creates a synchronizer of this policy over `inputs` inputs.
    ///
    /// # Errors
    /// As [`ExactSync::new`] and [`ApproximateSync::new`]: the settings are checked
    /// here, before any item flows.
    pub fn create<T>(&self, inputs: usize) -> Result<Box<dyn Synchronizer<T> + Send>, SyncError>
    where
        T: Stamped + Send + 'static,
    {
        Ok(match self {
            SyncPolicy::Exact(config) => Box::new(ExactSync::new(inputs, config.clone())?),
            SyncPolicy::Approximate(config) => {
                Box::new(ApproximateSync::new(inputs, config.clone())?)
            }
            SyncPolicy::Epsilon(config) => Box::new(EpsilonSync::new(inputs, config.clone())?),
        })
    }
}

/// Test support: a bare stamp is its own item, so scenarios read as lists of times.
#[cfg(test)]
impl Stamped for Time {
    fn stamp(&self) -> Time {
        *self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::frame::EntityStructure;
    use std::sync::Arc;

    #[test]
    fn a_sample_is_stamped_by_its_valid_time() {
        let sample = Sample::new(Arc::new(EntityStructure::new("car", 42, 45)), 50, 50);
        assert_eq!(sample.stamp(), 42);
    }

    #[test]
    fn policies_create_working_synchronizers() -> Result<(), SyncError> {
        for policy in [SyncPolicy::default(), SyncPolicy::Approximate(ApproximateConfig::default())]
        {
            let mut sync = policy.create::<Time>(2)?;
            assert_eq!(sync.inputs(), 2);
            assert!(sync.push(0, 7)?.is_empty());
            assert_eq!(sync.push(1, 7)?, vec![vec![7, 7]]);
            assert_eq!(sync.queued(), 0);
            assert_eq!(sync.dropped(), 0);
        }
        Ok(())
    }

    #[test]
    fn settings_are_checked_at_creation() {
        let approx = |c: ApproximateConfig| SyncPolicy::Approximate(c).create::<Time>(2).err();
        assert_eq!(SyncPolicy::default().create::<Time>(0).err(), Some(SyncError::NoInputs));
        assert_eq!(
            SyncPolicy::Exact(ExactConfig::default().queue_size(0)).create::<Time>(2).err(),
            Some(SyncError::ZeroQueueSize)
        );
        assert_eq!(
            approx(ApproximateConfig::default().queue_size(0)),
            Some(SyncError::ZeroQueueSize)
        );
        assert_eq!(
            approx(ApproximateConfig::default().tolerance(-1)),
            Some(SyncError::NegativeDuration { setting: "tolerance".into(), value: -1 })
        );
        assert_eq!(
            approx(ApproximateConfig::default().inter_message_lower_bound(1, -5)),
            Some(SyncError::NegativeDuration {
                setting: "inter_message_lower_bound".into(),
                value: -5
            })
        );
        assert_eq!(
            approx(ApproximateConfig::default().inter_message_lower_bound(2, 5)),
            Some(SyncError::NoSuchInput { input: 2, inputs: 2 })
        );
        assert!(matches!(
            approx(ApproximateConfig::default().age_penalty(-0.5)),
            Some(SyncError::InvalidAgePenalty(_))
        ));
        assert!(matches!(
            approx(ApproximateConfig::default().age_penalty(f64::NAN)),
            Some(SyncError::InvalidAgePenalty(_))
        ));
    }

    #[test]
    fn policies_by_their_words() {
        let words = |w, t| SyncPolicy::from_words(w, t, 7);
        assert_eq!(words(None, None), Ok(SyncPolicy::Exact(ExactConfig::default().queue_size(7))));
        assert_eq!(
            words(None, Some(5)),
            Ok(SyncPolicy::Approximate(ApproximateConfig::default().queue_size(7).tolerance(5)))
        );
        assert_eq!(
            words(Some("epsilon"), Some(5)),
            Ok(SyncPolicy::Epsilon(EpsilonConfig::default().queue_size(7).tolerance(5)))
        );
        assert_eq!(words(Some("epsilon"), None), Err(SyncWordsError::NeedsTolerance("epsilon")));
        assert_eq!(words(Some("exact"), Some(5)), Err(SyncWordsError::ToleranceForExact));
        assert_eq!(words(Some("nearest"), None), Err(SyncWordsError::Unknown("nearest".into())));
    }
}
