//! Fluent stream policies (C1–C6, seed 3.3.3.1): the six constraints a trajectory
//! keeps, as one value.
//!
//! A [`FluentStreamPolicy`] is declarative: it says what the stream must satisfy, and
//! the store enforces it, dropping, counting and reporting whatever would break it
//! (C7). `validate` rejects a nonsensical policy with [`PolicyError::IllegalPolicy`]
//! before any trajectory exists, naming the field and the rule.
//!
//! The seed's numeric conventions (`0` = now / forever / any delay / keep all) are
//! accepted by [`FluentStreamPolicy::sampled`] and [`CacheConstraint::from_seed`];
//! inside esgm the enums say what they mean.

use crate::filter::FilterError;
use crate::time::Time;

/// C1: what must differ between consecutive samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ChangeConstraint {
    /// No restriction.
    #[default]
    Unconstrained,
    /// Each sample's value (attributes) must differ from the previous sample's.
    AnyChange,
    /// Each sample must differ from the previous in value, valid time or create time.
    AnyUpdate,
    /// Consecutive valid times must be at least this period apart (a sample every `t`
    /// time units). Samples that come too soon are dropped; skipped sample points are
    /// counted in the stats.
    SampleEvery(Time),
}

/// C2: which samples may be in the stream at the same time; the oldest go first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum CacheConstraint {
    /// Keep every sample.
    #[default]
    All,
    /// Keep samples whose valid time is less than `t` before the newest valid time.
    Duration(Time),
    /// Keep at most `n` samples (`0` means all, as in the seed).
    Elements(usize),
}

impl CacheConstraint {
    /// The seed's `long cache_size`: `0` keeps all, a negative size is illegal.
    pub fn from_seed(cache_size: i64) -> Result<Self, PolicyError> {
        match usize::try_from(cache_size) {
            Ok(0) => Ok(CacheConstraint::All),
            Ok(n) => Ok(CacheConstraint::Elements(n)),
            // `try_from` fails only for a negative size, which the error names.
            Err(_) => {
                Err(PolicyError::illegal("cache_size", cache_size, "must be 0 (all) or positive"))
            }
        }
    }
}

/// C4: the interval valid times must fall in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum DurationConstraint {
    /// Any valid time.
    #[default]
    Unbounded,
    /// Valid times within `[from, to]`, with the seed's rules: `from = 0` means the time
    /// the trajectory is created, `to = 0` means forever.
    Between {
        /// Start (inclusive); 0 = creation time.
        from: Time,
        /// End (inclusive); 0 = forever.
        to: Time,
    },
}

/// C5: how valid times of consecutive samples relate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum OrderConstraint {
    /// No restriction.
    #[default]
    Any,
    /// Each valid time is not less than the previous one.
    Monotone,
    /// Each valid time is greater than the previous one.
    StrictMonotone,
}

/// C6: the largest allowed add time − valid time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum DelayConstraint {
    /// Any delay (the seed's `delay = 0`).
    #[default]
    Any,
    /// At most this delay. With a monotone order and `reorder` on, samples are held
    /// this long and released in valid-time order, so out-of-order input within the
    /// delay still yields a monotone stream.
    Max(Time),
}

impl DelayConstraint {
    /// The seed's `delay` argument: `0` means any delay.
    pub fn from_seed(delay: Time) -> Result<Self, PolicyError> {
        match delay {
            0 => Ok(DelayConstraint::Any),
            d if d > 0 => Ok(DelayConstraint::Max(d)),
            d => Err(PolicyError::illegal("delay", d, "must be 0 (any) or positive")),
        }
    }
}

/// Which constraint a sample broke; the cause of a drop.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum Constraint {
    /// C1.
    Change,
    /// C2 (a sample older than a time cache's window).
    Cache,
    /// C3.
    Filter,
    /// C4.
    Duration,
    /// C5.
    Order,
    /// C6.
    Delay,
}

impl Constraint {
    /// Every constraint, for stats tables.
    pub const ALL: [Constraint; 6] = [
        Constraint::Change,
        Constraint::Cache,
        Constraint::Filter,
        Constraint::Duration,
        Constraint::Order,
        Constraint::Delay,
    ];

    /// Lower-case name, as used in stats and the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Constraint::Change => "change",
            Constraint::Cache => "cache",
            Constraint::Filter => "filter",
            Constraint::Duration => "duration",
            Constraint::Order => "order",
            Constraint::Delay => "delay",
        }
    }
}

impl std::fmt::Display for Constraint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The constraints of one trajectory (the seed's fluent stream constraints).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FluentStreamPolicy {
    /// C1.
    pub change: ChangeConstraint,
    /// C2.
    pub cache: CacheConstraint,
    /// C3: a predicate over attributes (see [`crate::filter`]); `None` keeps all.
    pub filter: Option<String>,
    /// C4.
    pub duration: DurationConstraint,
    /// C5.
    pub order: OrderConstraint,
    /// C6.
    pub delay: DelayConstraint,
    /// With a monotone order and a maximum delay: hold samples for the delay and
    /// release them in valid-time order (on by default, as in the seed). Off: in-order
    /// samples enter at once and out-of-order ones are order violations.
    pub reorder: bool,
}

impl Default for FluentStreamPolicy {
    fn default() -> Self {
        Self {
            change: ChangeConstraint::default(),
            cache: CacheConstraint::default(),
            filter: None,
            duration: DurationConstraint::default(),
            order: OrderConstraint::default(),
            delay: DelayConstraint::default(),
            reorder: true,
        }
    }
}

/// A policy is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum PolicyError {
    /// A field has a value that makes no sense (the seed's `IllegalPolicy`); fix the
    /// named field.
    #[error("illegal policy: {field} = {value}: {rule}")]
    IllegalPolicy {
        /// The policy field.
        field: String,
        /// The offending value, as written.
        value: String,
        /// The rule it breaks.
        rule: String,
    },
    /// The filter expression does not parse or does not type-check against the
    /// trajectory's type.
    #[error("illegal policy: filter: {0}")]
    IllegalFilter(#[from] FilterError),
}

impl PolicyError {
    /// An [`PolicyError::IllegalPolicy`] naming `field`, its `value` and the `rule`.
    pub fn illegal(field: &str, value: impl ToString, rule: &str) -> Self {
        PolicyError::IllegalPolicy {
            field: field.into(),
            value: value.to_string(),
            rule: rule.into(),
        }
    }
}

impl FluentStreamPolicy {
    /// No constraints: any order, any delay, keep everything (the seed's primitive and
    /// computed trajectories).
    pub fn unconstrained() -> Self {
        Self::default()
    }

    /// The seed's "reasonable set of constraints" (section 4.4): monotone order, the
    /// given maximum delay (0 = any) and cache size (0 = all).
    pub fn reasonable(delay: Time, cache_size: i64) -> Result<Self, PolicyError> {
        let p = Self {
            order: OrderConstraint::Monotone,
            delay: DelayConstraint::from_seed(delay)?,
            cache: CacheConstraint::from_seed(cache_size)?,
            ..Self::default()
        };
        p.validate()?;
        Ok(p)
    }

    /// The policy of a sampled trajectory, from `create_entity_trajectory_structure`'s
    /// arguments with the seed's zero rules (section 4.4.2): sample period → change,
    /// from/to → duration, delay → delay, cache_size → cache, plus monotone order. The
    /// sampler produces samples in order, so they are not held for the delay.
    pub fn sampled(
        from: Time,
        to: Time,
        sample_period: Time,
        delay: Time,
        cache_size: i64,
    ) -> Result<Self, PolicyError> {
        if sample_period <= 0 {
            return Err(PolicyError::illegal("sample_period", sample_period, "must be positive"));
        }
        let p = Self {
            change: ChangeConstraint::SampleEvery(sample_period),
            cache: CacheConstraint::from_seed(cache_size)?,
            filter: None,
            duration: DurationConstraint::Between { from, to },
            order: OrderConstraint::Monotone,
            delay: DelayConstraint::from_seed(delay)?,
            reorder: false,
        };
        p.validate()?;
        Ok(p)
    }

    /// Builder form: sets C1.
    #[must_use]
    pub fn change(mut self, c: ChangeConstraint) -> Self {
        self.change = c;
        self
    }
    /// Builder form: sets C2.
    #[must_use]
    pub fn cache(mut self, c: CacheConstraint) -> Self {
        self.cache = c;
        self
    }
    /// Builder form: sets C3.
    #[must_use]
    pub fn filter(mut self, expression: impl Into<String>) -> Self {
        self.filter = Some(expression.into());
        self
    }
    /// Builder form: sets C4.
    #[must_use]
    pub fn duration(mut self, c: DurationConstraint) -> Self {
        self.duration = c;
        self
    }
    /// Builder form: sets C5.
    #[must_use]
    pub fn order(mut self, c: OrderConstraint) -> Self {
        self.order = c;
        self
    }
    /// Builder form: sets C6.
    #[must_use]
    pub fn delay(mut self, c: DelayConstraint) -> Self {
        self.delay = c;
        self
    }
    /// Builder form: sets whether late samples are held and reordered.
    #[must_use]
    pub fn reorder(mut self, on: bool) -> Self {
        self.reorder = on;
        self
    }

    /// True if samples are held for the delay and released in valid-time order.
    pub fn holds_samples(&self) -> bool {
        self.reorder
            && self.order != OrderConstraint::Any
            && matches!(self.delay, DelayConstraint::Max(_))
    }

    /// Checks every field against its rule (the filter is checked when the trajectory
    /// is created, against its type).
    pub fn validate(&self) -> Result<(), PolicyError> {
        if let ChangeConstraint::SampleEvery(t) = self.change {
            if t <= 0 {
                return Err(PolicyError::illegal("change.sample_every", t, "must be positive"));
            }
        }
        match self.cache {
            CacheConstraint::Duration(t) if t <= 0 => {
                return Err(PolicyError::illegal("cache.duration", t, "must be positive"));
            }
            _ => {}
        }
        if let DurationConstraint::Between { from, to } = self.duration {
            if from < 0 {
                return Err(PolicyError::illegal(
                    "duration.from",
                    from,
                    "must be 0 (now) or positive",
                ));
            }
            if to < 0 {
                return Err(PolicyError::illegal(
                    "duration.to",
                    to,
                    "must be 0 (forever) or positive",
                ));
            }
            if to != 0 && from != 0 && to < from {
                return Err(PolicyError::illegal(
                    "duration.to",
                    to,
                    "must not be before duration.from",
                ));
            }
        }
        if let DelayConstraint::Max(d) = self.delay {
            if d <= 0 {
                return Err(PolicyError::illegal(
                    "delay",
                    d,
                    "must be positive (use Any for no bound)",
                ));
            }
        }
        if let Some(f) = &self.filter {
            if f.trim().is_empty() {
                return Err(PolicyError::illegal("filter", "\"\"", "must not be empty (use None)"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_zero_rules() {
        assert_eq!(CacheConstraint::from_seed(0), Ok(CacheConstraint::All));
        assert_eq!(CacheConstraint::from_seed(5), Ok(CacheConstraint::Elements(5)));
        assert!(matches!(
            CacheConstraint::from_seed(-1),
            Err(PolicyError::IllegalPolicy { ref field, .. }) if field == "cache_size"
        ));
        assert_eq!(DelayConstraint::from_seed(0), Ok(DelayConstraint::Any));
        assert!(DelayConstraint::from_seed(-5).is_err());
    }

    #[test]
    fn sampled_policy_translation() {
        let p = FluentStreamPolicy::sampled(0, 0, 1_000, 0, 5).unwrap();
        assert_eq!(p.change, ChangeConstraint::SampleEvery(1_000));
        assert_eq!(p.cache, CacheConstraint::Elements(5));
        assert_eq!(p.order, OrderConstraint::Monotone);
        assert_eq!(p.delay, DelayConstraint::Any);
        assert!(!p.holds_samples());
        let err = FluentStreamPolicy::sampled(0, 0, -1, 0, 5).unwrap_err();
        assert_eq!(err.to_string(), "illegal policy: sample_period = -1: must be positive");
        assert!(FluentStreamPolicy::sampled(0, 0, 0, 0, 5).is_err());
        assert!(FluentStreamPolicy::sampled(0, 0, 10, 0, -1).is_err());
        assert!(FluentStreamPolicy::sampled(100, 50, 10, 0, 1).is_err());
    }

    #[test]
    fn validation_rules() {
        let ok = FluentStreamPolicy::reasonable(100, 10).unwrap();
        assert!(ok.holds_samples());
        let bad = [
            FluentStreamPolicy::default().change(ChangeConstraint::SampleEvery(0)),
            FluentStreamPolicy::default().cache(CacheConstraint::Duration(-3)),
            FluentStreamPolicy::default().delay(DelayConstraint::Max(0)),
            FluentStreamPolicy::default().duration(DurationConstraint::Between { from: -1, to: 0 }),
            FluentStreamPolicy::default().filter("  "),
        ];
        for p in bad {
            assert!(p.validate().is_err(), "{p:?} accepted");
        }
    }
}
