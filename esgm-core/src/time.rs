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

/// A [`Time`] duration as a `std::time::Duration`, saturating negative values to zero,
/// for the places (thread sleeps, channel timeouts) where std needs one.
pub fn to_std_duration(t: Time) -> std::time::Duration {
    std::time::Duration::from_nanos(u64::try_from(t).unwrap_or(0))
}
