//! Queries (T1, T2) on a trajectory, answered from this process's copy of it (its
//! store, or its replica of another process's): latest, n-th latest, the most current,
//! between two valid times, at one, the closest at or before one, and approximated at
//! one. `ESGM_VALUE_NOT_AVAILABLE` where nothing answers, as the seed raises
//! `ValueNotAvailable`.

use esgm_shm::prelude::*;

use crate::handles;
use crate::sample::{esgm_sample_list_t, esgm_sample_t, give};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::put;
use crate::structure::esgm_structure_t;
use crate::trajectory::{esgm_trajectory_t, traj};

/// How `esgm_get_at_approximating` answers when no sample is valid exactly then
/// (the seed's `ValueApproximationConstraint`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_approximation {
    /// No approximation: only a sample valid exactly then.
    ESGM_APPROXIMATION_NONE = 0,
    /// The sample closest in valid time, before or after (before wins a tie).
    ESGM_APPROXIMATION_CLOSEST = 1,
    /// The latest sample valid before (`get_closest_at_or_before`).
    ESGM_APPROXIMATION_MOST_RECENT = 2,
    /// A default value (a structure's attributes), valid then.
    ESGM_APPROXIMATION_DEFAULT = 3,
    /// Linear interpolation of numeric attributes between the samples before and
    /// after; others hold the value before.
    ESGM_APPROXIMATION_LINEAR = 4,
    /// Linear, refusing an answer with an attribute that could not be interpolated.
    ESGM_APPROXIMATION_LINEAR_STRICT = 5,
}

/// Runs `query` on `t` and gives its sample.
fn one(
    t: esgm_trajectory_t,
    out: *mut esgm_sample_t,
    query: impl FnOnce(&InProcessTrajectory) -> std::result::Result<Sample, QueryError>,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let found = traj(t)?;
        let sample = query(&found.handle).map_err(|e| Error::of(&e))?;
        give(sample, out)
    })
}

/// The latest sample added (T1).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_latest(t: esgm_trajectory_t, out: *mut esgm_sample_t) -> esgm_status {
    one(t, out, |h| h.get_latest())
}

/// The most current value: the sample with the latest valid time (the seed's
/// `get_latest_vtime`), which differs from the latest added when structures arrive
/// out of order.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_latest_vtime(
    t: esgm_trajectory_t,
    out: *mut esgm_sample_t,
) -> esgm_status {
    one(t, out, |h| h.get_latest_vtime())
}

/// The `n`-th latest sample (0: the latest).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_nth_latest(
    t: esgm_trajectory_t,
    n: usize,
    out: *mut esgm_sample_t,
) -> esgm_status {
    one(t, out, |h| h.get_nth_latest(n))
}

/// The sample valid exactly at `time`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_at(
    t: esgm_trajectory_t,
    time: i64,
    out: *mut esgm_sample_t,
) -> esgm_status {
    one(t, out, |h| h.get_at(time))
}

/// The sample with the latest valid time not after `time`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_closest_at_or_before(
    t: esgm_trajectory_t,
    time: i64,
    out: *mut esgm_sample_t,
) -> esgm_status {
    one(t, out, |h| h.get_closest_at_or_before(time))
}

/// The samples valid from `from` to `to` (inclusive), in valid-time order (T1); an
/// empty list when none are.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_between(
    t: esgm_trajectory_t,
    from: i64,
    to: i64,
    out: *mut esgm_sample_list_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let found = traj(t)?;
        let samples = found.handle.get_between(from, to).map_err(|e| Error::of(&e))?;
        let h: esgm_sample_list_t = handles::insert(samples);
        unsafe { put(out, "out", h) }
    })
}

/// The value at `time` approximated by `approximation` (an `esgm_approximation`, T2).
/// `ESGM_APPROXIMATION_DEFAULT` answers with the attributes of `default_value` (a
/// structure, which is not taken; a null handle for the other approximations).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_at_approximating(
    t: esgm_trajectory_t,
    time: i64,
    approximation: i32,
    default_value: esgm_structure_t,
    out: *mut esgm_sample_t,
) -> esgm_status {
    guard(|| {
        let aprx = approximation_of(approximation, default_value)?;
        crate::strings::writable(out, "out")?;
        let found = traj(t)?;
        let sample = found.handle.get_at_approximating(time, &aprx).map_err(|e| Error::of(&e))?;
        give(sample, out)
    })
}

/// The approximation of a C value.
fn approximation_of(
    approximation: i32,
    default_value: esgm_structure_t,
) -> Result<ValueApproximation> {
    Ok(match approximation {
        0 => ValueApproximation::None,
        1 => ValueApproximation::Closest,
        2 => ValueApproximation::MostRecent,
        3 => {
            let b = handles::get(default_value).map_err(|e| {
                Error::argument(format!(
                    "ESGM_APPROXIMATION_DEFAULT needs a default value: {}",
                    e.message
                ))
            })?;
            let attributes = b.lock().frame.attributes.clone();
            ValueApproximation::Default(attributes)
        }
        4 => ValueApproximation::Linear,
        5 => ValueApproximation::LinearStrict,
        other => {
            return Err(Error::argument(format!(
                "approximation {other} is none of ESGM_APPROXIMATION_NONE (0) … \
                 ESGM_APPROXIMATION_LINEAR_STRICT (5)"
            )));
        }
    })
}
