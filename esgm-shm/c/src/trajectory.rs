//! A trajectory handle (`esgm_trajectory_t`, the seed's `EntityTrajectoryStructure`):
//! found by name, destroyed, read about (name, type, policy, start and end time,
//! statistics), reset, and asked for image loans. A handle follows its name: if the
//! name is re-pointed to a new trajectory, the handle reaches the new one.

use std::ffi::c_char;
use std::sync::Arc;

use esgm_shm::prelude::*;
use parking_lot::Mutex;

use crate::connect::{Domain, esgm_t, on, runtime};
use crate::handles::{self, handle};
use crate::image::esgm_image_loan_t;
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{copy_out, esgm_str_t, put, text};
use crate::types::esgm_type_t;

/// What a trajectory handle names: the runtime's handle and its ESGM.
#[derive(Debug)]
pub(crate) struct Traj {
    pub(crate) handle: InProcessTrajectory,
    pub(crate) domain: Arc<Domain>,
}

/// A trajectory of the system, by name: query it, subscribe to it, add to it.
/// Freeing the handle leaves the trajectory; `esgm_destroy_entity_trajectory_structure`
/// destroys it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_trajectory_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_trajectory_t => Traj);

/// The trajectory `t` names, while its ESGM lives.
pub(crate) fn traj(t: esgm_trajectory_t) -> Result<Arc<Traj>> {
    let found = handles::get(t)?;
    found.domain.check_open()?;
    Ok(found)
}

/// A handle for `handle`, written to `out`.
pub(crate) fn give(
    domain: &Arc<Domain>,
    handle: InProcessTrajectory,
    out: *mut esgm_trajectory_t,
) -> Result<()> {
    let h = handles::insert(Traj { handle, domain: Arc::clone(domain) });
    unsafe { put(out, "out", h) }.inspect_err(|_| {
        // The caller cannot receive it: nobody could ever free it.
        let _unreachable = handles::free(h);
    })
}

/// A handle on the trajectory `name` (E5); `ESGM_NO_SUCH_ENTITY_STRUCTURE` if there is
/// none (the message names the closest name there is).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_entity_trajectory_structure(
    esgm: esgm_t,
    name: *const c_char,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        crate::strings::writable(out, "out")?;
        let h =
            on!(&*rt, e => e.get_entity_trajectory_structure(name)).map_err(|e| Error::of(&e))?;
        give(&d, h, out)
    })
}

/// The type of the trajectory `name` (E5), as a new handle to free.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_entity_trajectory_structure_type(
    esgm: esgm_t,
    name: *const c_char,
    out: *mut esgm_type_t,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        crate::strings::writable(out, "out")?;
        let ty = on!(&*rt, e => e.get_entity_trajectory_structure_type(name))
            .map_err(|e| Error::of(&e))?;
        let h: esgm_type_t = handles::insert(Mutex::new(ty));
        unsafe { put(out, "out", h) }
    })
}

/// Destroys the trajectory `name` (E5): its name can be reused; handles on it fail
/// with `ESGM_NO_SUCH_ENTITY_STRUCTURE` and its subscriptions end.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_destroy_entity_trajectory_structure(
    esgm: esgm_t,
    name: *const c_char,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        on!(&*rt, e => e.destroy_entity_trajectory_structure(name)).map_err(|e| Error::of(&e))
    })
}

/// Every trajectory of the system as JSON (name, kind, type, inputs, source, where it
/// is written), copied into `buf` as `esgm_stats_json` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectories_json(
    esgm: esgm_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let listed = on!(&*rt, e => e.trajectories()).map_err(|e| Error::of(&e))?;
        let text = crate::connect::json(&listed)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}

/// Frees a trajectory handle (the trajectory stays). Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_free(t: esgm_trajectory_t) -> esgm_status {
    guard(|| handles::free(t))
}

/// Another handle on the same trajectory, to free separately.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_clone(
    t: esgm_trajectory_t,
    out: *mut esgm_trajectory_t,
) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        crate::strings::writable(out, "out")?;
        give(&found.domain, found.handle.clone(), out)
    })
}

/// The trajectory's name (`name`), valid while the handle lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_name(t: esgm_trajectory_t, out: *mut esgm_str_t) -> esgm_status {
    guard(|| {
        let found = handles::get(t)?;
        // The name lives in the handle's object, which the table keeps until freed.
        let name = esgm_str_t::of(found.handle.name());
        unsafe { put(out, "out", name) }
    })
}

/// Its type (`type`), as a new handle to free.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_type(t: esgm_trajectory_t, out: *mut esgm_type_t) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        crate::strings::writable(out, "out")?;
        let ty = found.handle.entity_type().map_err(|e| Error::of(&e))?;
        let h: esgm_type_t = handles::insert(Mutex::new(ty));
        unsafe { put(out, "out", h) }
    })
}

/// Its policy (`pol`: change, cache, filter, duration, order, delay, reorder) as JSON,
/// copied into `buf` as `esgm_stats_json` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_policy_json(
    t: esgm_trajectory_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        let policy = found.handle.policy().map_err(|e| Error::of(&e))?;
        let text = crate::connect::json(&policy)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}

/// The earliest valid time it holds (`start_time`); `ESGM_VALUE_NOT_AVAILABLE` when
/// empty.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_start_time(t: esgm_trajectory_t, out: *mut i64) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        let time = found.handle.start_time().map_err(|e| Error::of(&e))?;
        unsafe { put(out, "out", time) }
    })
}

/// The latest valid time it holds (`end_time`); `ESGM_VALUE_NOT_AVAILABLE` when empty.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_end_time(t: esgm_trajectory_t, out: *mut i64) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        let time = found.handle.end_time().map_err(|e| Error::of(&e))?;
        unsafe { put(out, "out", time) }
    })
}

/// Empties the trajectory (T5), in its writer and every reader; returns before they
/// all have.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_reset(t: esgm_trajectory_t) -> esgm_status {
    guard(|| traj(t)?.handle.reset().map_err(|e| Error::of(&e)))
}

/// Empties the trajectory (T5) and returns once its writer and every connected reader
/// have forgotten it.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_reset_blocking(t: esgm_trajectory_t) -> esgm_status {
    guard(|| traj(t)?.handle.reset_blocking().map_err(|e| Error::of(&e)))
}

/// A trajectory's main statistics (E7); `esgm_trajectory_stats_json` has all of
/// them, drops by cause included.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_trajectory_stats_t {
    /// Structures added.
    pub added: u64,
    /// Structures dropped, every cause together (policy, type, reset, lost…).
    pub dropped: u64,
    /// Policy violations reported.
    pub violations: u64,
    /// Samples evicted by the cache policy.
    pub evicted: u64,
    /// Samples stored now.
    pub stored: u64,
    /// Samples held for reordering now.
    pub held: u64,
    /// Subscribers now.
    pub subscribers: u64,
    /// Samples subscribers missed because their queue was full.
    pub subscriber_overflow: u64,
    /// Sample points a sampled trajectory missed.
    pub missed_sample_points: u64,
    /// Structures per second, recently.
    pub rate_hz: f64,
    /// Add delay (add time − valid time) percentiles in nanoseconds; -1 before any add.
    pub add_delay_p50: i64,
    /// 90th percentile.
    pub add_delay_p90: i64,
    /// 99th percentile.
    pub add_delay_p99: i64,
    /// Largest.
    pub add_delay_max: i64,
}

/// Writes its main statistics to `out`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_stats(
    t: esgm_trajectory_t,
    out: *mut esgm_trajectory_stats_t,
) -> esgm_status {
    guard(|| {
        let s = traj(t)?.handle.stats().map_err(|e| Error::of(&e))?;
        let n = |v: usize| v as u64;
        let stats = esgm_trajectory_stats_t {
            added: s.added,
            dropped: s.dropped_total,
            violations: s.violations,
            evicted: s.evicted,
            stored: n(s.stored),
            held: n(s.held),
            subscribers: n(s.subscribers),
            subscriber_overflow: s.subscriber_overflow,
            missed_sample_points: s.missed_sample_points,
            rate_hz: s.rate_hz,
            add_delay_p50: s.add_delay_p50.unwrap_or(-1),
            add_delay_p90: s.add_delay_p90.unwrap_or(-1),
            add_delay_p99: s.add_delay_p99.unwrap_or(-1),
            add_delay_max: s.add_delay_max.unwrap_or(-1),
        };
        unsafe { put(out, "out", stats) }
    })
}

/// Its statistics as JSON (drops by cause among them), copied into `buf` as
/// `esgm_stats_json` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_stats_json(
    t: esgm_trajectory_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let s = traj(t)?.handle.stats().map_err(|e| Error::of(&e))?;
        let text = crate::connect::json(&s)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}

/// A loan of the trajectory's own memory for one `width` × `height` image of `format`
/// (an `esgm_image_format`): its shared memory when this process writes it and other
/// processes read it, so the frame written there is never copied; else the heap.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_trajectory_image_loan(
    t: esgm_trajectory_t,
    width: i64,
    height: i64,
    format: i32,
    out: *mut esgm_image_loan_t,
) -> esgm_status {
    guard(|| {
        let found = traj(t)?;
        crate::strings::writable(out, "out")?;
        let allocator =
            found.handle.with_store(|s| s.octets_allocator()).map_err(|e| Error::of(&e))?;
        let loan = crate::image::lend(allocator.as_deref(), width, height, i64::from(format))?;
        unsafe { put(out, "out", loan) }
    })
}
