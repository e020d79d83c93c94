//! Creating trajectories of every kind with every policy setting.
//!
//! The seed's three constructors keep their names and arguments
//! (`esgm_create_primitive_entity_trajectory_structure`,
//! `esgm_create_entity_trajectory_structure`,
//! `esgm_create_computed_entity_trajectory_structure`). Every other trajectory (sync,
//! merge, generated) and every policy (C1–C6) is a spec (`esgm_spec_t`): made for one
//! kind, given its settings, then created with `esgm_create_trajectory`.
//!
//! ```c
//! esgm_spec_t spec;
//! esgm_spec_primitive("robot_state", "RobotState", &spec);
//! esgm_spec_order(spec, ESGM_ORDER_MONOTONE);
//! esgm_spec_delay(spec, 50 * ESGM_MILLISECOND);
//! esgm_spec_cache_count(spec, 600);
//! esgm_create_trajectory(esgm, spec, &robot_state);
//! esgm_spec_free(spec);
//! ```

use std::ffi::c_char;

use esgm_shm::prelude::*;
use parking_lot::Mutex;

use crate::connect::{esgm_t, on, runtime};
use crate::handles::{self, handle};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{optional, put, text, texts};
use crate::trajectory::{esgm_trajectory_t, give};

/// A trajectory described in full (its source and its policy), to create with
/// `esgm_create_trajectory`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_spec_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_spec_t => Mutex<TrajectorySpec>);

/// C1: what must differ between consecutive samples (`esgm_spec_change`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_change {
    /// No restriction.
    ESGM_CHANGE_NONE = 0,
    /// Each value differs from the previous one.
    ESGM_CHANGE_ANY_CHANGE = 1,
    /// Each sample differs in value, valid time or create time.
    ESGM_CHANGE_ANY_UPDATE = 2,
    /// Valid times at least `period` apart (a sample every period).
    ESGM_CHANGE_SAMPLE_EVERY = 3,
}

/// C5: how consecutive valid times relate (`esgm_spec_order`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_order {
    /// No restriction.
    ESGM_ORDER_ANY = 0,
    /// Never earlier than the previous.
    ESGM_ORDER_MONOTONE = 1,
    /// Always later than the previous.
    ESGM_ORDER_STRICT_MONOTONE = 2,
}

fn made(spec: TrajectorySpec, out: *mut esgm_spec_t) -> Result<()> {
    crate::strings::writable(out, "out")?;
    let h = handles::insert(Mutex::new(spec));
    unsafe { put(out, "out", h) }
}

/// A spec of a primitive trajectory `name` of `type_name`, which programs add to (E2).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_primitive(
    name: *const c_char,
    type_name: *const c_char,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let type_name = unsafe { text(type_name, "type_name") }?;
        made(TrajectorySpec::primitive(name, type_name), out)
    })
}

/// A spec of a trajectory `name` sampled from `sensor` every `sample_period` ns (E3),
/// from now on (`esgm_spec_between` bounds it).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_sampled(
    name: *const c_char,
    sensor: *const c_char,
    sample_period: i64,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let sensor = unsafe { text(sensor, "sensor") }?;
        let spec =
            TrajectorySpec::sampled(name, sensor, sample_period).map_err(|e| Error::of(&e))?;
        made(spec, out)
    })
}

/// A spec of a trajectory `name` computed by the unit `unit` from the `n` trajectories
/// `inputs`, in the unit's order (E4).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_computed(
    name: *const c_char,
    unit: *const c_char,
    inputs: *const *const c_char,
    n: usize,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let unit = unsafe { text(unit, "unit") }?;
        let inputs = unsafe { texts(inputs, n, "inputs") }?;
        made(TrajectorySpec::computed(name, unit, inputs), out)
    })
}

/// A spec of a synchronized trajectory `name` (G2): states holding one sample of each
/// of the `n` `inputs` valid at the same time, as ROS message_filters match them.
/// `sync_policy` is `"exact"` (null: exact, or approximate when a tolerance is given),
/// `"approximate"` or `"epsilon"`; `tolerance_ns` is the largest difference of valid
/// times (negative: none, for exact); `queue_size` items are kept per input.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_sync(
    name: *const c_char,
    inputs: *const *const c_char,
    n: usize,
    sync_policy: *const c_char,
    tolerance_ns: i64,
    queue_size: usize,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let inputs = unsafe { texts(inputs, n, "inputs") }?;
        let word = unsafe { optional(sync_policy, "sync_policy") }?;
        let tolerance = (tolerance_ns >= 0).then_some(tolerance_ns);
        let sync = SyncPolicy::from_words(word, tolerance, queue_size).map_err(|e| {
            Error::new(esgm_status::ESGM_ILLEGAL_POLICY, format!("trajectory `{name}`: {e}"))
        })?;
        made(TrajectorySpec::sync(name, inputs, sync), out)
    })
}

/// A spec of a merged trajectory `name` (G3): every sample of the `n` `inputs` (of one
/// type), as they come.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_merge(
    name: *const c_char,
    inputs: *const *const c_char,
    n: usize,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let inputs = unsafe { texts(inputs, n, "inputs") }?;
        made(TrajectorySpec::merge(name, inputs), out)
    })
}

/// A spec of a trajectory `name` sampled every `sample_period` ns from fluent
/// generators (G1, G4): each of the `n` `generators` is `"TRAJECTORY[:APPROXIMATION[:MERGE]]"`
/// (`"robot_state:linear"`; approximation none, closest, most-recent or linear; merge
/// keep-first, keep-last, average or median). One generator gives its values, several
/// their state, and with a `unit` (null for none) that unit's temporal function of
/// them (its `compute_at`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_generated(
    name: *const c_char,
    generators: *const *const c_char,
    n: usize,
    sample_period: i64,
    unit: *const c_char,
    out: *mut esgm_spec_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { text(name, "name") }?;
        let entries = unsafe { texts(generators, n, "generators") }?;
        let unit = unsafe { optional(unit, "unit") }?;
        if entries.is_empty() {
            return Err(Error::argument(format!(
                "trajectory `{name}`: generators needs at least one trajectory"
            )));
        }
        let generators = entries
            .iter()
            .map(|g| parse_generator(g))
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| {
                Error::new(esgm_status::ESGM_ILLEGAL_POLICY, format!("trajectory `{name}`: {e}"))
            })?;
        let spec = match unit {
            Some(u) => TrajectorySpec::sampled_function(name, u, generators, sample_period),
            None => TrajectorySpec::sampled_generators(name, generators, sample_period),
        };
        made(spec, out)
    })
}

/// Frees a spec. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_free(spec: esgm_spec_t) -> esgm_status {
    guard(|| handles::free(spec))
}

/// Changes the spec `spec` with `change`.
fn with(
    spec: esgm_spec_t,
    change: impl FnOnce(TrajectorySpec) -> Result<TrajectorySpec>,
) -> esgm_status {
    guard(|| {
        let s = handles::get(spec)?;
        let mut s = s.lock();
        let current = s.clone();
        *s = change(current)?;
        Ok(())
    })
}

/// A sampled or generated trajectory's start and end (valid times, ns; 0 = now and
/// forever, as the seed has them); also its duration constraint (C4).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_between(spec: esgm_spec_t, from: i64, to: i64) -> esgm_status {
    with(spec, |s| Ok(s.between(from, to)))
}

/// A generated trajectory reads its generators `lag` ns before each sample time (so an
/// interpolation has a sample after the time it reads at).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_lag(spec: esgm_spec_t, lag: i64) -> esgm_status {
    with(spec, |s| Ok(s.lag(lag)))
}

/// C2: keep every sample.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_cache_all(spec: esgm_spec_t) -> esgm_status {
    with(spec, |s| {
        let p = s.policy.clone().cache(CacheConstraint::All);
        Ok(s.policy(p))
    })
}

/// C2: keep the last `n` samples (0: every sample, as the seed's `cache_size`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_cache_count(spec: esgm_spec_t, n: usize) -> esgm_status {
    with(spec, |s| {
        let cache = if n == 0 { CacheConstraint::All } else { CacheConstraint::Elements(n) };
        let p = s.policy.clone().cache(cache);
        Ok(s.policy(p))
    })
}

/// C2: keep the samples valid less than `span` ns before the newest.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_cache_duration(spec: esgm_spec_t, span: i64) -> esgm_status {
    with(spec, |s| {
        let p = s.policy.clone().cache(CacheConstraint::Duration(span));
        Ok(s.policy(p))
    })
}

/// C1: `change` is an `esgm_change`; `period` (ns) is for `ESGM_CHANGE_SAMPLE_EVERY`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_change(spec: esgm_spec_t, change: i32, period: i64) -> esgm_status {
    with(spec, |s| {
        let c = match change {
            0 => ChangeConstraint::Unconstrained,
            1 => ChangeConstraint::AnyChange,
            2 => ChangeConstraint::AnyUpdate,
            3 => ChangeConstraint::SampleEvery(period),
            other => {
                return Err(Error::argument(format!(
                    "change {other} is none of ESGM_CHANGE_NONE (0) … ESGM_CHANGE_SAMPLE_EVERY (3)"
                )));
            }
        };
        let p = s.policy.clone().change(c);
        Ok(s.policy(p))
    })
}

/// C3: a filter over attributes (`"size > 10 && x < 320"`), type-checked against the
/// trajectory's type when it is created (`ESGM_ILLEGAL_POLICY` names what is wrong).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_filter(spec: esgm_spec_t, expression: *const c_char) -> esgm_status {
    let expression = unsafe { text(expression, "expression") }.map(str::to_owned);
    with(spec, |s| {
        let p = s.policy.clone().filter(expression?);
        Ok(s.policy(p))
    })
}

/// C4: valid times within `[from, to]` (0 = the creation time, and forever).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_duration(spec: esgm_spec_t, from: i64, to: i64) -> esgm_status {
    with(spec, |s| {
        let p = s.policy.clone().duration(DurationConstraint::Between { from, to });
        Ok(s.policy(p))
    })
}

/// C5: `order` is an `esgm_order`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_order(spec: esgm_spec_t, order: i32) -> esgm_status {
    with(spec, |s| {
        let o = match order {
            0 => OrderConstraint::Any,
            1 => OrderConstraint::Monotone,
            2 => OrderConstraint::StrictMonotone,
            other => {
                return Err(Error::argument(format!(
                    "order {other} is none of ESGM_ORDER_ANY (0) … ESGM_ORDER_STRICT_MONOTONE (2)"
                )));
            }
        };
        let p = s.policy.clone().order(o);
        Ok(s.policy(p))
    })
}

/// C6: at most `max_delay` ns from valid time to add time (0: any delay, as the
/// seed's); with a monotone order, late samples within it are held and released in
/// valid-time order unless `esgm_spec_reorder(spec, false)`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_delay(spec: esgm_spec_t, max_delay: i64) -> esgm_status {
    with(spec, |s| {
        let d = DelayConstraint::from_seed(max_delay).map_err(|e| Error::of(&e))?;
        let p = s.policy.clone().delay(d);
        Ok(s.policy(p))
    })
}

/// C6: whether samples within the delay are held and reordered.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_reorder(spec: esgm_spec_t, reorder: bool) -> esgm_status {
    with(spec, |s| {
        let p = s.policy.clone().reorder(reorder);
        Ok(s.policy(p))
    })
}

/// How many processes may read the trajectory at once (default: the domain's
/// `--readers`); a reader past it gets `ESGM_LIMIT_REACHED`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_readers(spec: esgm_spec_t, readers: usize) -> esgm_status {
    with(spec, |s| Ok(s.readers(readers)))
}

/// Re-points an existing name to the new trajectory (subscribers stay attached)
/// instead of failing with `ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_spec_replace(spec: esgm_spec_t, replace: bool) -> esgm_status {
    with(spec, |mut s| {
        s.replace = replace;
        Ok(s)
    })
}

/// Creates the trajectory `spec` describes (the spec stays, to free).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_trajectory(
    esgm: esgm_t,
    spec: esgm_spec_t,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let spec = handles::get(spec)?.lock().clone();
        crate::strings::writable(out, "out")?;
        let h = on!(&*rt, e => e.create_trajectory(spec)).map_err(|e| Error::of(&e))?;
        give(&d, h, out)
    })
}

/// The seed's `create_primitive_entity_trajectory_structure(name, type_name)` (E2).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_primitive_entity_trajectory_structure(
    esgm: esgm_t,
    name: *const c_char,
    type_name: *const c_char,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        let type_name = unsafe { text(type_name, "type_name") }?;
        crate::strings::writable(out, "out")?;
        let h = on!(&*rt, e => e.create_primitive_entity_trajectory_structure(name, type_name))
            .map_err(|e| Error::of(&e))?;
        give(&d, h, out)
    })
}

/// The seed's `create_entity_trajectory_structure(name, sensor, from, to,
/// sample_period, delay, cache_size)` (E3): `sensor` pulled every `sample_period` ns
/// (from = 0: now; to = 0: forever; delay = 0: any; cache_size = 0: all);
/// `ESGM_ILLEGAL_POLICY` for a nonsensical policy.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "the seed's signature")]
pub extern "C" fn esgm_create_entity_trajectory_structure(
    esgm: esgm_t,
    name: *const c_char,
    sensor: *const c_char,
    from: i64,
    to: i64,
    sample_period: i64,
    delay: i64,
    cache_size: i64,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        let sensor = unsafe { text(sensor, "sensor") }?;
        crate::strings::writable(out, "out")?;
        let h = on!(&*rt, e => e.create_entity_trajectory_structure(
            name, sensor, from, to, sample_period, delay, cache_size,
        ))
        .map_err(|e| Error::of(&e))?;
        give(&d, h, out)
    })
}

/// The seed's `create_computed_entity_trajectory_structure(name, cu, inputs)` (E4):
/// the unit `cu` runs on every update of any of the `n` `inputs`, with the latest
/// sample of each, in this order.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_computed_entity_trajectory_structure(
    esgm: esgm_t,
    name: *const c_char,
    cu: *const c_char,
    inputs: *const *const c_char,
    n: usize,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        let cu = unsafe { text(cu, "cu") }?;
        let inputs = unsafe { texts(inputs, n, "inputs") }?;
        crate::strings::writable(out, "out")?;
        let h = on!(&*rt, e => e.create_computed_entity_trajectory_structure(name, cu, &inputs))
            .map_err(|e| Error::of(&e))?;
        give(&d, h, out)
    })
}
