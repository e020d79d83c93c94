//! Subscriptions (T3, C7): every structure added to a trajectory from now on (after
//! the last N it holds, if asked), in add order, received one at a time with a
//! timeout; and every policy violation of a trajectory, the same way.
//!
//! A receive sleeps on the trajectory (on shared memory, on its writer's futex word),
//! so it wakes within microseconds of the add. A long wait is cut into slices, so a
//! subscription whose ESGM is freed returns `ESGM_CLOSED` within one.

use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_shm::prelude::*;

use crate::connect::Domain;
use crate::handles::{self, handle};
use crate::sample::{esgm_sample_t, give};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{esgm_str_t, put};
use crate::trajectory::{esgm_trajectory_t, traj};

/// A subscription and the ESGM it belongs to.
#[derive(Debug)]
pub(crate) struct Subscribed<T> {
    subscription: Subscription<T>,
    domain: Arc<Domain>,
}

/// A subscription to a trajectory's structures: receive them in add order, free it
/// to unsubscribe.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_subscription_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_subscription_t => Subscribed<Sample>);

/// A subscription to a trajectory's policy violations.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_violations_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_violations_t => Subscribed<PolicyViolation>);

/// One policy violation: which constraint a structure broke, and when.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_violation_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_violation_t => PolicyViolation);

/// How long one slice of a wait lasts before the ESGM is looked at again.
const SLICE: Duration = Duration::from_millis(100);

/// The next item of `s`, waiting at most `timeout_ns` (negative: for ever).
fn receive<T>(s: &Subscribed<T>, timeout_ns: i64, what: &str) -> Result<T> {
    if timeout_ns == 0 {
        // A poll (a spinning reader): what is there, without reading a clock or
        // formatting a message.
        s.domain.check_open()?;
        return match s.subscription.poll() {
            Ok(Some(item)) => Ok(item),
            Ok(None) => Err(Error::new(esgm_status::ESGM_TIMEOUT, "nothing to receive now")),
            Err(e) => Err(Error::new(
                esgm_status::ESGM_CLOSED,
                format!("{e} (the trajectory was destroyed)"),
            )),
        };
    }
    let deadline =
        (timeout_ns >= 0).then(|| Instant::now() + Duration::from_nanos(timeout_ns.unsigned_abs()));
    loop {
        s.domain.check_open()?;
        let slice =
            deadline.map_or(SLICE, |d| d.saturating_duration_since(Instant::now()).min(SLICE));
        match s.subscription.recv_timeout(slice) {
            Ok(item) => return Ok(item),
            Err(RecvError::Timeout) => {
                if deadline.is_some_and(|d| Instant::now() >= d) {
                    return Err(Error::new(
                        esgm_status::ESGM_TIMEOUT,
                        format!("no {what} arrived within {timeout_ns} ns"),
                    ));
                }
            }
            Err(e) => {
                return Err(Error::new(
                    esgm_status::ESGM_CLOSED,
                    format!("{e} (the trajectory was destroyed)"),
                ));
            }
        }
    }
}

/// T3: subscribes to `t`: every structure added from now on, after the last `last`
/// it holds (0: none), kept in a queue of `queue` samples (0: 64) for a slow reader;
/// what overflows it is counted (`esgm_subscription_overflowed`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_subscribe(
    t: esgm_trajectory_t,
    queue: usize,
    last: usize,
    out: *mut esgm_subscription_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let found = traj(t)?;
        let options =
            SubscribeOptions::default().capacity(if queue == 0 { 64 } else { queue }).last(last);
        let subscription = found.handle.subscribe(options).map_err(|e| Error::of(&e))?;
        let h: esgm_subscription_t =
            handles::insert(Subscribed { subscription, domain: Arc::clone(&found.domain) });
        unsafe { put(out, "out", h) }
    })
}

/// The next structure, waiting at most `timeout_ns` (0: only what is there; negative:
/// for ever): `ESGM_TIMEOUT` when none came, `ESGM_CLOSED` when the trajectory was
/// destroyed or the ESGM freed.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_subscription_recv(
    sub: esgm_subscription_t,
    timeout_ns: i64,
    out: *mut esgm_sample_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let s = handles::get(sub)?;
        let sample = receive(&s, timeout_ns, "sample")?;
        give(sample, out)
    })
}

/// The samples this subscription missed because its queue was full.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_subscription_overflowed(
    sub: esgm_subscription_t,
    out: *mut u64,
) -> esgm_status {
    guard(|| {
        let n = handles::get(sub)?.subscription.overflowed();
        unsafe { put(out, "out", n) }
    })
}

/// T3 (`unsubscribe`): ends the subscription and frees its handle. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_unsubscribe(sub: esgm_subscription_t) -> esgm_status {
    guard(|| handles::free(sub))
}

/// C7: subscribes to the policy violations of `t` from now on, kept in a queue of
/// `queue` (0: 64).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_subscribe_violations(
    t: esgm_trajectory_t,
    queue: usize,
    out: *mut esgm_violations_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let found = traj(t)?;
        let subscription = found
            .handle
            .subscribe_violations(if queue == 0 { 64 } else { queue })
            .map_err(|e| Error::of(&e))?;
        let h: esgm_violations_t =
            handles::insert(Subscribed { subscription, domain: Arc::clone(&found.domain) });
        unsafe { put(out, "out", h) }
    })
}

/// The next violation, waiting as `esgm_subscription_recv` does.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_violations_recv(
    sub: esgm_violations_t,
    timeout_ns: i64,
    out: *mut esgm_violation_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let s = handles::get(sub)?;
        let v = receive(&s, timeout_ns, "violation")?;
        let h: esgm_violation_t = handles::insert(v);
        unsafe { put(out, "out", h) }
    })
}

/// Ends a violations subscription and frees its handle. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_violations_free(sub: esgm_violations_t) -> esgm_status {
    guard(|| handles::free(sub))
}

/// A violation, as `esgm_violation_info` reads it; the texts are valid while its handle
/// lives.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_violation_info_t {
    /// The trajectory.
    pub trajectory: esgm_str_t,
    /// The constraint broken: `"change"`, `"cache"`, `"filter"`, `"duration"`,
    /// `"order"` or `"delay"`.
    pub constraint: esgm_str_t,
    /// What exactly was wrong, for people.
    pub detail: esgm_str_t,
    /// The structure's valid time (ns).
    pub valid_time: i64,
    /// Its create time (ns).
    pub create_time: i64,
    /// When it was offered (ns).
    pub add_time: i64,
}

/// What the violation `v` says.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_violation_info(
    v: esgm_violation_t,
    out: *mut esgm_violation_info_t,
) -> esgm_status {
    guard(|| {
        let found = handles::get(v)?;
        let info = esgm_violation_info_t {
            trajectory: esgm_str_t::of(&found.trajectory),
            constraint: esgm_str_t::of(found.constraint.name()),
            detail: esgm_str_t::of(&found.detail),
            valid_time: found.valid_time,
            create_time: found.create_time,
            add_time: found.add_time,
        };
        unsafe { put(out, "out", info) }
    })
}

/// Frees a violation. Null is fine.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_violation_free(v: esgm_violation_t) -> esgm_status {
    guard(|| handles::free(v))
}
