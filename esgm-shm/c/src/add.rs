//! Adding structures (T4): `add` and `create_at`/`create_at_now` drop a structure the
//! trajectory's policy refuses (counted, and told to violation subscribers) and say so
//! in the outcome; their `_blocking` forms wait for the writer's gate, in whichever
//! process writes the trajectory, and return `ESGM_POLICY_VIOLATION`.
//!
//! Every add takes its structure: the handle is freed whether the add succeeded or
//! not, and an image in it is handed over where it is.

use std::ffi::c_char;

use esgm_shm::prelude::*;

use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{put, text};
use crate::structure::{self, esgm_structure_t};
use crate::trajectory::{esgm_trajectory_t, traj};

/// What became of an added structure.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_outcome {
    /// It entered the trajectory.
    ESGM_OUTCOME_ADDED = 0,
    /// It is held for reordering within the delay (C6), and released in valid-time
    /// order.
    ESGM_OUTCOME_HELD = 1,
    /// It was sent to the trajectory's writer in another process, whose gate decides
    /// (a blocking add waits for that decision instead).
    ESGM_OUTCOME_FORWARDED = 2,
    /// The policy refused it: dropped, counted and reported (non-blocking adds).
    ESGM_OUTCOME_DROPPED = 3,
}

pub(crate) fn outcome_of(o: &AddOutcome) -> esgm_outcome {
    match o {
        AddOutcome::Added => esgm_outcome::ESGM_OUTCOME_ADDED,
        AddOutcome::Held { .. } => esgm_outcome::ESGM_OUTCOME_HELD,
        AddOutcome::Forwarded => esgm_outcome::ESGM_OUTCOME_FORWARDED,
        _ => esgm_outcome::ESGM_OUTCOME_DROPPED,
    }
}

/// Adds `es` to `t` and writes the outcome to `outcome` (if not null).
fn added(
    t: esgm_trajectory_t,
    es: Result<EntityStructure>,
    blocking: bool,
    outcome: *mut i32,
) -> Result<()> {
    let found = traj(t);
    // The structure is taken first, so its handle goes whatever else is wrong.
    let es = es?;
    let found = found?;
    let o = if blocking { found.handle.add_blocking(es) } else { found.handle.add(es) }
        .map_err(|e| Error::of(&e))?;
    if outcome.is_null() {
        return Ok(());
    }
    unsafe { put(outcome, "outcome", outcome_of(&o) as i32) }
}

/// T4: adds the structure `s` (which it takes) to `t`; a policy violation drops it
/// (`ESGM_OUTCOME_DROPPED`). `outcome` (an `esgm_outcome`) may be null.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_add(
    t: esgm_trajectory_t,
    s: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| added(t, structure::take(s), false, outcome))
}

/// T4: adds the structure `s` (which it takes) to `t` and waits for the writer's
/// gate: `ESGM_POLICY_VIOLATION` (the message says which constraint) if it refused.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_add_blocking(
    t: esgm_trajectory_t,
    s: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| added(t, structure::take(s), true, outcome))
}

/// Which of the IDL's `create_at` forms.
#[derive(Debug, Clone, Copy)]
enum Create {
    At(i64),
    AtBlocking(i64),
    Now,
    NowBlocking,
}

/// Adds a structure `name` with the attributes of `attributes` (taken; its own name
/// and times are not used) by the `how` form of `create_at`, through the trajectory's
/// own operation (its clock stamps the create time).
fn created(
    t: esgm_trajectory_t,
    name: *const c_char,
    attributes: esgm_structure_t,
    how: Create,
    outcome: *mut i32,
) -> Result<()> {
    let attrs = structure::take(attributes);
    let found = traj(t);
    let name = unsafe { text(name, "name") }?;
    let attrs = AttributeList(attrs?.attributes);
    let h = &found?.handle;
    let o = match how {
        Create::At(vt) => h.create_at(name, vt, attrs),
        Create::AtBlocking(vt) => h.create_at_blocking(name, vt, attrs),
        Create::Now => h.create_at_now(name, attrs),
        Create::NowBlocking => h.create_at_now_blocking(name, attrs),
    }
    .map_err(|e| Error::of(&e))?;
    if outcome.is_null() {
        return Ok(());
    }
    unsafe { put(outcome, "outcome", outcome_of(&o) as i32) }
}

/// T4 (`create_at`): adds a structure `name` valid at `valid_time` with the
/// attributes of `attributes` (a structure, which it takes; its name and times are
/// not used).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_at(
    t: esgm_trajectory_t,
    name: *const c_char,
    valid_time: i64,
    attributes: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| created(t, name, attributes, Create::At(valid_time), outcome))
}

/// T4 (`create_at_blocking`): `esgm_create_at`, waiting for the gate.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_at_blocking(
    t: esgm_trajectory_t,
    name: *const c_char,
    valid_time: i64,
    attributes: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| created(t, name, attributes, Create::AtBlocking(valid_time), outcome))
}

/// T4 (`create_at_now`): adds a structure `name` valid now (the trajectory's clock).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_at_now(
    t: esgm_trajectory_t,
    name: *const c_char,
    attributes: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| created(t, name, attributes, Create::Now, outcome))
}

/// T4 (`create_at_now_blocking`): `esgm_create_at_now`, waiting for the gate.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_create_at_now_blocking(
    t: esgm_trajectory_t,
    name: *const c_char,
    attributes: esgm_structure_t,
    outcome: *mut i32,
) -> esgm_status {
    guard(|| created(t, name, attributes, Create::NowBlocking, outcome))
}
