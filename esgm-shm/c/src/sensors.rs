//! Sensors written in C or C++ (E6, seed 2.2): a `get_current_value` function esgm
//! calls at every sample time of every trajectory sampled from the sensor, with the
//! scheduled time. It answers as a unit does (`ESGM_OK` and a structure in `*out`,
//! `ESGM_VALUE_NOT_AVAILABLE`, or a failure with its reason).
//!
//! A camera gets its frame's memory from the call's context
//! (`esgm_sensor_image_loan`): the sampled trajectory's own shared memory, so the
//! frame it renders there is the one every reader reads, never copied. The context is
//! valid during the call only.

use std::ffi::{c_char, c_void};
use std::sync::Arc;

use esgm_shm::prelude::*;
use parking_lot::RwLock;

use crate::connect::{Gate, esgm_t, on, runtime};
use crate::handles::{self, handle};
use crate::image::esgm_image_loan_t;
use crate::status::{Error, esgm_status, guard, set_last_error};
use crate::strings::{put, text};
use crate::structure::esgm_structure_t;
use crate::units::{Missed, User, answer, as_callback, esgm_free_fn};

/// Where a sensor's call gets image loans: the trajectory's allocator, for the
/// duration of the call.
#[derive(Debug, Default)]
pub(crate) struct Context {
    allocator: RwLock<Option<Lent>>,
}

/// The allocator a call was given, lent for the call only.
#[derive(Debug, Clone, Copy)]
struct Lent(*const (dyn OctetsAllocator + 'static));

// SAFETY: the allocator is `Send + Sync` (the trait requires it); the pointer is only
// dereferenced under the context's read lock, which the call that lent it takes for
// writing (and empties) before it returns.
unsafe impl Send for Lent {}
// SAFETY: as for Send.
unsafe impl Sync for Lent {}

/// What a sensor's call may use while it runs: image loans of the sampled
/// trajectory's memory.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_sensor_context_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_sensor_context_t => Context);

/// A sensor's function: `user` as registered, the query time (the scheduled sample
/// time: stamp the structure's valid time with it), the call's context, and where to
/// put the structure. Returns an `esgm_status`.
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub type esgm_sensor_fn = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        qtime: i64,
        context: esgm_sensor_context_t,
        out: *mut esgm_structure_t,
    ) -> i32,
>;

/// A sensor written in C.
#[derive(Debug)]
struct CSensor {
    name: String,
    get:
        unsafe extern "C" fn(*mut c_void, i64, esgm_sensor_context_t, *mut esgm_structure_t) -> i32,
    user: Arc<User>,
    gate: Arc<Gate>,
}

impl CSensor {
    fn call(
        &self,
        qtime: Time,
        images: &dyn OctetsAllocator,
    ) -> Result<EntityStructure, SensorError> {
        let called = self.gate.enter(|| {
            // SAFETY (of the lifetime's erasure): the pointer is taken out of the
            // context below, under its write lock, before `images` goes.
            let erased: *const (dyn OctetsAllocator + 'static) =
                unsafe { std::mem::transmute::<*const dyn OctetsAllocator, _>(images) };
            let context = Arc::new(Context { allocator: RwLock::new(Some(Lent(erased))) });
            let ctx: esgm_sensor_context_t = handles::insert_arc(Arc::clone(&context));
            let mut out = esgm_structure_t::default();
            set_last_error("");
            // SAFETY: the user's function with the user's pointer; `ctx` and `out` are
            // valid for the call.
            let status =
                as_callback(|| unsafe { (self.get)(self.user.ptr(), qtime, ctx, &mut out) });
            let _freed_by_the_callback = handles::free(ctx);
            // Whoever kept the context's object (another thread using it) can no
            // longer reach the allocator.
            *context.allocator.write() = None;
            answer(&self.name, status, out)
        });
        match called {
            Some(Ok(es)) => Ok(es),
            Some(Err(Missed::NoValue)) => Err(SensorError::ValueNotAvailable),
            Some(Err(Missed::NotSupported)) => Err(SensorError::Failed {
                reason: format!("`{}` returned ESGM_OPERATION_NOT_SUPPORTED", self.name),
            }),
            Some(Err(Missed::Failed(reason))) => Err(SensorError::Failed { reason }),
            None => {
                Err(SensorError::Failed { reason: format!("`{}`: its ESGM was freed", self.name) })
            }
        }
    }
}

impl SensorInterface for CSensor {
    fn get_current_value(&self, qtime: Time) -> Result<EntityStructure, SensorError> {
        self.call(qtime, &HeapAllocator)
    }

    fn get_current_value_with(
        &self,
        qtime: Time,
        images: &dyn OctetsAllocator,
    ) -> Result<EntityStructure, SensorError> {
        self.call(qtime, images)
    }
}

/// Registers the sensor `name` producing structures of `type_name` (E6):
/// `get_current_value` is called at each sample time of every trajectory sampled from
/// it, with `user`, which `free_user` (may be null) releases once esgm calls it no
/// more. `ESGM_SENSOR_ALREADY_EXISTS` if the name is taken; then `user` is released at
/// once.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_add_sensor_interface(
    esgm: esgm_t,
    name: *const c_char,
    type_name: *const c_char,
    get_current_value: esgm_sensor_fn,
    user: *mut c_void,
    free_user: esgm_free_fn,
) -> esgm_status {
    let user = Arc::new(User::new(user, free_user));
    guard(move || {
        let (d, rt) = runtime(esgm)?;
        d.keep_user(&user);
        let name = unsafe { text(name, "name") }?;
        let type_name = unsafe { text(type_name, "type_name") }?;
        let get = get_current_value
            .ok_or_else(|| Error::argument("`get_current_value` is a null function pointer"))?;
        let sensor = CSensor { name: name.to_owned(), get, user, gate: Arc::clone(&d.gate) };
        on!(&*rt, e => e.add_sensor_interface(name, type_name, Arc::new(sensor)))
            .map_err(|e| Error::of(&e))
    })
}

/// Removes the sensor `name` (E6); `ESGM_OPERATION_NOT_SUPPORTED` while a trajectory
/// samples it.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_remove_sensor_interface(esgm: esgm_t, name: *const c_char) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let name = unsafe { text(name, "name") }?;
        on!(&*rt, e => e.remove_sensor_interface(name)).map_err(|e| Error::of(&e))
    })
}

/// A loan of the sampled trajectory's memory for one `width` × `height` image of
/// `format` (an `esgm_image_format`), during a sensor's call: render the frame into
/// it and set it as the structure's image. Its shared memory on the shared-memory
/// runtime (never copied after), the heap otherwise.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_sensor_image_loan(
    context: esgm_sensor_context_t,
    width: i64,
    height: i64,
    format: i32,
    out: *mut esgm_image_loan_t,
) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let c = handles::get(context)?;
        let lent = c.allocator.read();
        let Some(Lent(allocator)) = *lent else {
            return Err(Error::new(
                esgm_status::ESGM_INVALID_HANDLE,
                "the sensor's call this context belongs to has returned",
            ));
        };
        // SAFETY: the call that lent the allocator is under way: it empties the
        // context under the write lock, which waits for this read lock, before it
        // returns and the allocator goes.
        let allocator = unsafe { &*allocator };
        let loan = crate::image::lend(Some(allocator), width, height, i64::from(format))?;
        drop(lent);
        unsafe { put(out, "out", loan) }
    })
}
