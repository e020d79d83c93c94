//! Time on the one timeline shared by every process of a host (M1).
//!
//! esgm keeps the seed's `Idl::Time` as a plain `i64` count of nanoseconds rather than a
//! newtype: it is what crosses process boundaries in the archived form and in iceoryx2
//! user headers, it is what users type on the command line, and arithmetic on it (valid
//! time − 5 s) reads naturally. The helpers below keep unit mistakes out of call sites.

/// A time-point or a duration in nanoseconds on the host's shared timeline.
///
/// Valid, create, add and query times all use it. `0` has the seed's special meanings
/// in policies ("now" for a start time, "forever" for an end time, "any" for a delay).
pub type Time = i64;

/// Nanoseconds per second, the seed's `TIMEUNITS_PER_SECOND`.
pub const TIMEUNITS_PER_SECOND: Time = 1_000_000_000;
/// Nanoseconds per millisecond, the seed's `TIMEUNITS_PER_MILLI_SECOND`.
pub const TIMEUNITS_PER_MILLI_SECOND: Time = 1_000_000;
/// Nanoseconds per microsecond.
pub const TIMEUNITS_PER_MICRO_SECOND: Time = 1_000;

/// `n` seconds as a [`Time`] duration.
pub const fn secs(n: i64) -> Time {
    n * TIMEUNITS_PER_SECOND
}

/// `n` milliseconds as a [`Time`] duration.
pub const fn millis(n: i64) -> Time {
    n * TIMEUNITS_PER_MILLI_SECOND
}

/// `n` microseconds as a [`Time`] duration.
pub const fn micros(n: i64) -> Time {
    n * TIMEUNITS_PER_MICRO_SECOND
}

/// A duration for people: milliseconds with one decimal below a second, seconds
/// with two above (`12.3 ms`, `4.56 s`), as `esgm why` and `Why::reasons` say it.
pub fn for_people(t: Time) -> String {
    let ms = t as f64 / 1e6;
    if ms.abs() < 1_000.0 { format!("{ms:.1} ms") } else { format!("{:.2} s", ms / 1e3) }
}

/// A [`Time`] duration as a `std::time::Duration`, saturating negative values to zero,
/// for the places (thread sleeps, channel timeouts) where std needs one.
pub fn to_std_duration(t: Time) -> std::time::Duration {
    std::time::Duration::from_nanos(u64::try_from(t).unwrap_or(0))
}

/// The longest duration a person may give esgm as seconds or as the period of a rate:
/// about 100 years. Longer spans overflow the clock's arithmetic (an `Instant` plus
/// them, a [`Time`] in nanoseconds), so they are refused when given, not when used.
pub const LONGEST_SPAN: std::time::Duration = std::time::Duration::from_secs(100 * 365 * 86_400);

/// Why a number given as seconds or as a rate is not a usable duration.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SpanError {
    /// Not a number, or infinite.
    #[error("{0} is not a finite number")]
    NotFinite(f64),
    /// Below zero (seconds) or not above zero (a rate).
    #[error("{0} is out of range: seconds must be ≥ 0 and a rate > 0")]
    OutOfRange(f64),
    /// Longer than [`LONGEST_SPAN`] (for a rate: its period is).
    #[error("{0} makes a span longer than 100 years")]
    TooLong(f64),
}

/// `seconds` as a duration: what a `--seconds`, `--interval` or `--window` argument
/// means. Refuses what `Duration::from_secs_f64` would panic on (NaN, infinity,
/// negatives) and spans so long that a deadline computed from them would overflow.
pub fn span_from_seconds(seconds: f64) -> Result<std::time::Duration, SpanError> {
    if !seconds.is_finite() {
        return Err(SpanError::NotFinite(seconds));
    }
    if seconds < 0.0 {
        return Err(SpanError::OutOfRange(seconds));
    }
    if seconds > LONGEST_SPAN.as_secs_f64() {
        return Err(SpanError::TooLong(seconds));
    }
    Ok(std::time::Duration::from_secs_f64(seconds))
}

/// The period of `hz` events per second: what a `max_rate` or a sensor's frequency
/// means. A rate must be finite and positive, and its period at most [`LONGEST_SPAN`].
pub fn period_from_rate(hz: f64) -> Result<std::time::Duration, SpanError> {
    if !hz.is_finite() {
        return Err(SpanError::NotFinite(hz));
    }
    if hz <= 0.0 {
        return Err(SpanError::OutOfRange(hz));
    }
    span_from_seconds(1.0 / hz).map_err(|_| SpanError::TooLong(hz))
}

#[cfg(test)]
mod span_tests {
    use super::*;

    #[test]
    fn seconds_that_would_panic_or_overflow_are_refused() {
        assert_eq!(span_from_seconds(f64::INFINITY), Err(SpanError::NotFinite(f64::INFINITY)));
        assert!(matches!(span_from_seconds(f64::NAN), Err(SpanError::NotFinite(_))));
        assert_eq!(span_from_seconds(-1.0), Err(SpanError::OutOfRange(-1.0)));
        assert_eq!(span_from_seconds(1e300), Err(SpanError::TooLong(1e300)));
        assert_eq!(span_from_seconds(1.5), Ok(std::time::Duration::from_millis(1500)));
        assert_eq!(span_from_seconds(0.0), Ok(std::time::Duration::ZERO));
    }

    #[test]
    fn rates_need_a_finite_positive_value_and_a_representable_period() {
        assert_eq!(period_from_rate(1e-20), Err(SpanError::TooLong(1e-20)));
        assert_eq!(period_from_rate(0.0), Err(SpanError::OutOfRange(0.0)));
        assert!(matches!(period_from_rate(f64::NAN), Err(SpanError::NotFinite(_))));
        assert_eq!(period_from_rate(4.0), Ok(std::time::Duration::from_millis(250)));
        // Periods shorter than a nanosecond are zero: the rate is unlimited in practice.
        assert_eq!(period_from_rate(1e12), Ok(std::time::Duration::ZERO));
    }
}
