//! Computational units written in C or C++ (E6, seed 2.3): a `compute` function esgm
//! calls on its worker threads with the latest sample of each input, in input order,
//! whenever an input is updated (and optionally `compute_at`, a temporal function, for
//! generated trajectories).
//!
//! The function returns a status: `ESGM_OK` with a structure made into `*out` (an
//! output), `ESGM_VALUE_NOT_AVAILABLE` for no output this time, anything else for a
//! failure, whose reason is the message it set with `esgm_set_last_error_message`:
//! logged and counted as the worker's failed calls (`esgm stats`), never fatal. The
//! inputs' handles are valid during the call only (`esgm_sample_clone` keeps one).
//!
//! A program a system file declares (`[[unit]] program = "…"`) connects with
//! `esgm_connect_from_env`, registers its unit under `getenv("ESGM_NAME")`, and calls
//! `esgm_serve`; `esgm up` starts, supervises and restarts it.

use std::ffi::{c_char, c_void};
use std::sync::Arc;

use esgm_shm::prelude::*;

use crate::connect::{Gate, IN_CALLBACK, esgm_t, on, runtime};
use crate::handles;
use crate::sample::{View, esgm_sample_t};
use crate::status::{Error, esgm_status, guard, last_error, set_last_error};
use crate::strings::{text, texts};
use crate::structure::{self, esgm_structure_t};

/// A unit's function: `user` as registered, `n` input samples, the query time (or the
/// time of a temporal function), and where to put its output. Returns an
/// `esgm_status`.
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub type esgm_compute_fn = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        inputs: *const esgm_sample_t,
        n: usize,
        time: i64,
        out: *mut esgm_structure_t,
    ) -> i32,
>;

/// Releases a user pointer esgm was given, once esgm calls nothing with it any more.
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub type esgm_free_fn = Option<unsafe extern "C" fn(user: *mut c_void)>;

/// A user's pointer and how to release it: once, when the unit or sensor goes, or when
/// its ESGM is freed (which first makes sure nothing calls it any more).
#[derive(Debug)]
pub(crate) struct User {
    ptr: *mut c_void,
    free: parking_lot::Mutex<esgm_free_fn>,
}

// SAFETY: esgm only hands the pointer back to the user's own functions, which the
// registration's contract says may be called from any thread.
unsafe impl Send for User {}
// SAFETY: as for Send: esgm never reads or writes through the pointer itself.
unsafe impl Sync for User {}

impl User {
    /// `ptr`, released by `free` (if any) once.
    pub(crate) fn new(ptr: *mut c_void, free: esgm_free_fn) -> Self {
        Self { ptr, free: parking_lot::Mutex::new(free) }
    }

    /// The pointer, to pass back.
    pub(crate) fn ptr(&self) -> *mut c_void {
        self.ptr
    }

    /// Calls the release function, unless it was called already.
    pub(crate) fn release(&self) {
        if let Some(f) = self.free.lock().take() {
            // SAFETY: the user's release function with the user's pointer, once.
            unsafe { f(self.ptr) };
        }
    }
}

impl Drop for User {
    fn drop(&mut self) {
        self.release();
    }
}

/// Runs `call` as a user's callback: marked, so it cannot free its own ESGM.
pub(crate) fn as_callback<R>(call: impl FnOnce() -> R) -> R {
    let was = IN_CALLBACK.with(|c| c.replace(true));
    let r = call();
    IN_CALLBACK.with(|c| c.set(was));
    r
}

/// Why a callback's status is not an output: no value, unsupported, or failed with the
/// reason it set.
pub(crate) enum Missed {
    NoValue,
    NotSupported,
    Failed(String),
}

/// The structure a callback returned with `status`, taking `out`.
pub(crate) fn answer(
    name: &str,
    status: i32,
    out: esgm_structure_t,
) -> Result<EntityStructure, Missed> {
    let reason = last_error();
    let result = match status {
        0 if out.id == 0 => {
            Err(Missed::Failed(format!("`{name}` returned ESGM_OK without a structure in *out")))
        }
        0 => structure::take(out).map_err(|e| {
            Missed::Failed(format!("`{name}` returned an unusable structure: {}", e.message))
        }),
        1 => Err(Missed::NoValue),
        13 => Err(Missed::NotSupported),
        other => {
            // SAFETY: `esgm_status_name` returns a static NUL-terminated string.
            let status_name =
                unsafe { std::ffi::CStr::from_ptr(crate::status::esgm_status_name(other)) };
            Err(Missed::Failed(format!(
                "`{name}` failed with {}{}",
                status_name.to_string_lossy(),
                if reason.is_empty() { String::new() } else { format!(": {reason}") }
            )))
        }
    };
    if result.is_err() && out.id != 0 {
        // A structure made for an output that is not one.
        let _not_an_output = handles::free(out);
    }
    result
}

/// A unit written in C.
#[derive(Debug)]
struct CUnit {
    name: String,
    compute: unsafe extern "C" fn(
        *mut c_void,
        *const esgm_sample_t,
        usize,
        i64,
        *mut esgm_structure_t,
    ) -> i32,
    compute_at: esgm_compute_fn,
    user: Arc<User>,
    gate: Arc<Gate>,
}

impl CUnit {
    fn call(
        &self,
        f: unsafe extern "C" fn(
            *mut c_void,
            *const esgm_sample_t,
            usize,
            i64,
            *mut esgm_structure_t,
        ) -> i32,
        inputs: &[Sample],
        time: Time,
    ) -> Result<EntityStructure, ComputeError> {
        let called = self.gate.enter(|| {
            let handles: Vec<esgm_sample_t> =
                inputs.iter().map(|s| handles::insert(View::of(s.clone()))).collect();
            let mut out = esgm_structure_t::default();
            set_last_error("");
            // SAFETY: the user's function, with the user's pointer and arguments valid
            // for the call: `handles` lives until it returns, `out` is ours.
            let status = as_callback(|| unsafe {
                f(self.user.ptr(), handles.as_ptr(), handles.len(), time, &mut out)
            });
            for h in handles {
                // An input the callback freed itself (it must not) is gone already.
                let _freed_by_the_callback = handles::free(h);
            }
            answer(&self.name, status, out)
        });
        match called {
            Some(Ok(es)) => Ok(es),
            Some(Err(Missed::NoValue)) => Err(ComputeError::ValueNotAvailable),
            Some(Err(Missed::NotSupported)) => Err(ComputeError::OperationNotSupported),
            Some(Err(Missed::Failed(reason))) => Err(ComputeError::Failed { reason }),
            None => {
                Err(ComputeError::Failed { reason: format!("`{}`: its ESGM was freed", self.name) })
            }
        }
    }
}

impl CompUnit for CUnit {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        self.call(self.compute, inputs, qtime)
    }

    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        match self.compute_at {
            Some(f) => self.call(f, inputs, t),
            None => Err(ComputeError::OperationNotSupported),
        }
    }
}

/// What a unit declares about one input: a type's name, or `"EntityFrame"` (the seed's
/// `ENTITY_FRAME_TYPE`: any structure).
fn input_type(name: &str) -> InputType {
    match ValueSort::parse(name) {
        Some(s @ (ValueSort::EntityFrame | ValueSort::AnyValue)) => InputType::Sort(s),
        _ => InputType::Type(name.to_owned()),
    }
}

/// Registers the computational unit `name` (E6): it produces structures of
/// `type_name` from `n` inputs whose types are `input_types` (type names;
/// `"EntityFrame"` accepts any structure, as the seed's `ENTITY_FRAME_TYPE`).
/// `compute` is called on every update of an input of a trajectory computed by it;
/// `compute_at` (may be null) answers a generated trajectory's temporal function.
/// Both get `user`, which `free_user` (may be null) releases once esgm calls neither
/// any more (the unit removed, or its ESGM freed). `ESGM_COMP_UNIT_ALREADY_EXISTS` if
/// the name is taken; then `user` is released at once.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments, reason = "the seed's arguments and a C closure")]
pub extern "C" fn esgm_add_comp_unit(
    esgm: esgm_t,
    name: *const c_char,
    type_name: *const c_char,
    input_types: *const *const c_char,
    n: usize,
    compute: esgm_compute_fn,
    compute_at: esgm_compute_fn,
    user: *mut c_void,
    free_user: esgm_free_fn,
) -> esgm_status {
    // Whatever happens, the user's pointer is released exactly once: by the unit when
    // it goes, or here when it is never made.
    let user = Arc::new(User::new(user, free_user));
    guard(move || {
        let (d, rt) = runtime(esgm)?;
        d.keep_user(&user);
        let name = unsafe { text(name, "name") }?;
        let type_name = unsafe { text(type_name, "type_name") }?;
        let inputs = unsafe { texts(input_types, n, "input_types") }?;
        let compute =
            compute.ok_or_else(|| Error::argument("`compute` is a null function pointer"))?;
        let unit =
            CUnit { name: name.to_owned(), compute, compute_at, user, gate: Arc::clone(&d.gate) };
        let inputs = inputs.iter().map(|t| input_type(t)).collect();
        on!(&*rt, e => e.add_comp_unit(name, type_name, inputs, Arc::new(unit)))
            .map_err(|e| Error::of(&e))
    })
}

/// Removes the unit `name` (E6); `ESGM_OPERATION_NOT_SUPPORTED` while a trajectory
/// uses it. Its user pointer is released once esgm calls it no more.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_remove_comp_unit(esgm: esgm_t, name: *const c_char) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        on!(&*rt, e => e.remove_comp_unit(name)).map_err(|e| Error::of(&e))
    })
}

/// Unused status names stay checked by the compiler: `answer` matches their values.
const _: () = {
    assert!(esgm_status::ESGM_OK as i32 == 0);
    assert!(esgm_status::ESGM_VALUE_NOT_AVAILABLE as i32 == 1);
    assert!(esgm_status::ESGM_OPERATION_NOT_SUPPORTED as i32 == 13);
};
