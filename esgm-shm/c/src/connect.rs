//! The ESGM itself (`esgm_t`): joining a system of processes in shared memory
//! (`esgm_connect`, `esgm_connect_from_env` for a worker the supervisor started) or
//! running one in this process (`esgm_in_process`); and what the seed's `Esgm`
//! interface asks of the whole system: ping, reset, stats, memory, log level, flush,
//! and serving this process's units and sensors until the system ends.

use std::ffi::c_char;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use esgm_shm::prelude::*;
use parking_lot::RwLock;

use crate::handles::{self, handle};
use crate::status::{Error, Result, esgm_status, guard};
use crate::strings::{copy_out, esgm_str_t, optional, put};

/// Either runtime, behind one handle.
#[derive(Debug)]
pub(crate) enum Runtime {
    /// In this process.
    Local(InProcessEsgm),
    /// Across processes, through `connect`.
    Shm(ShmEsgm),
}

/// Runs `$body` with `$e` bound to whichever runtime `$rt` is.
macro_rules! on {
    ($rt:expr, $e:ident => $body:expr) => {
        match $rt {
            $crate::connect::Runtime::Local($e) => $body,
            $crate::connect::Runtime::Shm($e) => $body,
        }
    };
}
pub(crate) use on;

/// Whether esgm may still call a domain's callbacks: calls hold the gate's read side
/// while they run; `esgm_free` closes it on its write side, so it waits for the calls
/// under way, and none starts after it returns.
#[derive(Debug, Default)]
pub(crate) struct Gate {
    closed: RwLock<bool>,
}

impl Gate {
    /// Runs `call` unless the gate is closed (then `None`).
    pub(crate) fn enter<R>(&self, call: impl FnOnce() -> R) -> Option<R> {
        let open = self.closed.read_recursive();
        if *open {
            return None;
        }
        let r = call();
        drop(open);
        Some(r)
    }

    /// Closes the gate, waiting for the calls under way.
    fn close(&self) {
        *self.closed.write() = true;
    }
}

thread_local! {
    /// Set while this thread runs a user's callback, so `esgm_free` called from one
    /// (which would wait for itself) is refused.
    pub(crate) static IN_CALLBACK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// What an `esgm_t` names: the runtime, until `esgm_free`.
#[derive(Debug)]
pub(crate) struct Domain {
    runtime: RwLock<Option<Arc<Runtime>>>,
    closed: AtomicBool,
    /// The gate every unit and sensor callback of this ESGM passes.
    pub(crate) gate: Arc<Gate>,
    /// The user pointers of its units and sensors, released when it is freed (esgm's
    /// own threads may hold a unit a little longer; the gate keeps them from calling).
    users: parking_lot::Mutex<Vec<std::sync::Weak<crate::units::User>>>,
    /// Opens this process's shared memory files to the users the domain admits, while
    /// it lives (a worker of a domain started with `--allow-group`).
    _widener: Option<esgm_shm::process::access::Widener>,
}

impl Domain {
    fn new(runtime: Runtime, widener: Option<esgm_shm::process::access::Widener>) -> Self {
        Self {
            runtime: RwLock::new(Some(Arc::new(runtime))),
            closed: AtomicBool::new(false),
            gate: Arc::new(Gate::default()),
            users: parking_lot::Mutex::new(Vec::new()),
            _widener: widener,
        }
    }

    /// The runtime, unless `esgm_free` was called.
    pub(crate) fn runtime(&self) -> Result<Arc<Runtime>> {
        self.runtime.read().clone().ok_or_else(freed)
    }

    /// Remembers a unit's or sensor's user pointer, to release it when freed.
    pub(crate) fn keep_user(&self, user: &Arc<crate::units::User>) {
        let mut users = self.users.lock();
        users.retain(|u| u.strong_count() > 0);
        users.push(Arc::downgrade(user));
    }

    /// Fails once `esgm_free` was called: handles made from this ESGM stop working.
    pub(crate) fn check_open(&self) -> Result<()> {
        if self.closed.load(Ordering::Acquire) { Err(freed()) } else { Ok(()) }
    }
}

fn freed() -> Error {
    Error::new(esgm_status::ESGM_CLOSED, "the ESGM this handle belongs to was freed (esgm_free)")
}

/// The ESGM: one system of processes joined through shared memory, or one in this
/// process. Every other handle is made from one.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_t {
    /// The handle's id; 0 is the null handle.
    pub id: u64,
}

handle!(esgm_t => Domain);

/// The domain `esgm_t` names.
pub(crate) fn domain(esgm: esgm_t) -> Result<Arc<Domain>> {
    let d = handles::get(esgm)?;
    d.check_open()?;
    Ok(d)
}

/// The runtime of `esgm`.
pub(crate) fn runtime(esgm: esgm_t) -> Result<(Arc<Domain>, Arc<Runtime>)> {
    let d = domain(esgm)?;
    let rt = d.runtime()?;
    Ok((d, rt))
}

fn connected(builder: ShmEsgmBuilder, out: *mut esgm_t, widen: bool) -> Result<()> {
    crate::strings::writable(out, "out")?;
    let esgm = builder.connect().map_err(|e| match &e {
        ConnectError::LimitReached(_) => Error::new(esgm_status::ESGM_LIMIT_REACHED, e.to_string()),
        _ => Error::new(
            esgm_status::ESGM_UNAVAILABLE,
            format!("{e} (is a coordinator running? `esgm up --domain …`)"),
        ),
    })?;
    let widener = if widen {
        esgm_shm::prelude::share_domain(esgm.domain()).map_err(|e| {
            Error::new(esgm_status::ESGM_ERROR, format!("cannot open the domain's files: {e}"))
        })?
    } else {
        None
    };
    let h = handles::insert(Domain::new(Runtime::Shm(esgm), widener));
    unsafe { put(out, "out", h) }
}

/// Joins the system of `domain` (started by `esgm up --domain DOMAIN` or `esgm demo`);
/// a null `domain` means `ESGM_DOMAIN` from the environment, else `esgm`. Fails with
/// `ESGM_UNAVAILABLE` when no coordinator answers, `ESGM_LIMIT_REACHED` when the domain
/// has as many processes as it admits.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_connect(domain: *const c_char, out: *mut esgm_t) -> esgm_status {
    guard(|| {
        let name = unsafe { optional(domain, "domain") }?;
        let mut builder = ShmEsgm::builder().from_env();
        if let Some(d) = name {
            builder = builder.domain(d);
        }
        connected(builder, out, false)
    })
}

/// Joins the system as a named process: `host` is this process's name in the registry
/// (`esgm ps`), null for a unique one of its own.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_connect_as(
    domain: *const c_char,
    host: *const c_char,
    out: *mut esgm_t,
) -> esgm_status {
    guard(|| {
        let name = unsafe { optional(domain, "domain") }?;
        let host = unsafe { optional(host, "host") }?;
        let mut builder = ShmEsgm::builder().from_env();
        if let Some(d) = name {
            builder = builder.domain(d);
        }
        if let Some(h) = host {
            builder = builder.host(h);
        }
        connected(builder, out, false)
    })
}

/// Joins the system a supervisor started this process for: the domain, the process's
/// name and the access to its files come from the environment `esgm up` gives every
/// program a system file declares (`ESGM_DOMAIN`, `ESGM_WORKER`, `ESGM_SHM_ACCESS`).
/// The name the unit or sensor was declared under is `ESGM_NAME` (`getenv`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_connect_from_env(out: *mut esgm_t) -> esgm_status {
    guard(|| connected(ShmEsgm::builder().from_env(), out, true))
}

/// An ESGM in this process (the embedded runtime), with the library types: the same
/// calls, no other process, nothing in shared memory.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_in_process(out: *mut esgm_t) -> esgm_status {
    guard(|| {
        crate::strings::writable(out, "out")?;
        let h = handles::insert(Domain::new(Runtime::Local(InProcessEsgm::default()), None));
        unsafe { put(out, "out", h) }
    })
}

/// Leaves the system (or stops the in-process one): waits for this ESGM's unit and
/// sensor callbacks under way and calls none after it returns, releases their user
/// pointers, and makes every trajectory and subscription handle made from it fail
/// with `ESGM_CLOSED`. Samples stay readable until freed: their images stay mapped.
/// A null handle is fine. Not from a callback of the same ESGM (it would wait for
/// itself): that is `ESGM_OPERATION_NOT_SUPPORTED`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_free(esgm: esgm_t) -> esgm_status {
    guard(|| {
        if esgm.id == 0 {
            return Ok(());
        }
        if IN_CALLBACK.with(std::cell::Cell::get) {
            // Checked before the handle goes, so the call can be made again from
            // outside the callback.
            handles::get(esgm)?;
            return Err(Error::new(
                esgm_status::ESGM_OPERATION_NOT_SUPPORTED,
                "esgm_free from a unit's or sensor's callback would wait for that callback; \
                 free the ESGM from the thread that made it",
            ));
        }
        let d = handles::take(esgm)?;
        d.closed.store(true, Ordering::Release);
        d.gate.close();
        // Nothing calls a callback of this ESGM any more: its user pointers go now.
        for user in d.users.lock().drain(..) {
            if let Some(u) = user.upgrade() {
                u.release();
            }
        }
        let runtime = d.runtime.write().take();
        // The runtime (its threads, its connection) goes now, unless a call of another
        // thread still holds it: then when that call returns.
        drop(runtime);
        Ok(())
    })
}

/// Writes true to `out` if the system answers (its coordinator, for a connected
/// ESGM).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_ping(esgm: esgm_t, out: *mut bool) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let alive = on!(&*rt, e => e.ping());
        unsafe { put(out, "out", alive) }
    })
}

/// The domain's name (`"esgm"` for an in-process ESGM), valid while `esgm` lives.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_domain_name(esgm: esgm_t, out: *mut esgm_str_t) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let name = match &*rt {
            Runtime::Shm(e) => esgm_str_t::of(e.domain()),
            Runtime::Local(_) => esgm_str_t::of("in-process"),
        };
        // The text lives in the runtime, which `d` keeps in the handle table.
        drop(d);
        unsafe { put(out, "out", name) }
    })
}

/// Waits until every structure added before the call was processed by every unit, sync
/// and merge, delivered to every subscriber and entered in every other process's
/// replica; `ESGM_UNAVAILABLE` if that takes longer than `timeout_ns`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_flush(esgm: esgm_t, timeout_ns: i64) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let timeout = duration(timeout_ns, "timeout_ns")?;
        let deadline = Instant::now() + timeout;
        on!(&*rt, e => e.flush(deadline)).map_err(|e| Error::of(&e))
    })
}

/// A timeout in nanoseconds as a duration (negative is refused: use a large one).
pub(crate) fn duration(ns: i64, what: &str) -> Result<Duration> {
    u64::try_from(ns)
        .map(Duration::from_nanos)
        .map_err(|_| Error::argument(format!("`{what}` is {ns}; a time span must be 0 or more")))
}

/// Empties every trajectory of the system (E7), in every process that holds one.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_reset(esgm: esgm_t) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        on!(&*rt, e => Esgm::reset(e)).map_err(|e| Error::of(&e))
    })
}

/// The system's statistics (E7) as JSON: every trajectory's listing, store statistics
/// (added, dropped by cause, violations, rate, add delays) and worker counters. Copied
/// into `buf` (`capacity` bytes, NUL-terminated); `len` gets the full length, so a
/// call with a null `buf` and capacity 0 asks the size. `ESGM_OUT_OF_RANGE` when cut.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_stats_json(
    esgm: esgm_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let stats = on!(&*rt, e => e.stats()).map_err(|e| Error::of(&e))?;
        let text = json(&stats)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}

/// The memory in use (E7) as JSON, added up over every process; as
/// [`esgm_stats_json`].
#[unsafe(no_mangle)]
pub extern "C" fn esgm_memory_stats_json(
    esgm: esgm_t,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let stats = on!(&*rt, e => e.memory_stats()).map_err(|e| Error::of(&e))?;
        let text = json(&stats)?;
        unsafe { copy_out(&text, buf, capacity, len) }
    })
}

/// `value` as JSON text.
pub(crate) fn json<T: serde::Serialize>(value: &T) -> Result<String> {
    serde_json::to_string(value)
        .map_err(|e| Error::new(esgm_status::ESGM_INTERNAL, format!("cannot write JSON: {e}")))
}

/// The log levels of `esgm_set_log_level`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_log_level {
    /// Errors only.
    ESGM_LOG_ERROR = 0,
    /// Warnings and errors.
    ESGM_LOG_WARN = 1,
    /// Informational messages.
    ESGM_LOG_INFO = 2,
    /// Debugging detail (every drop).
    ESGM_LOG_DEBUG = 3,
    /// Everything.
    ESGM_LOG_TRACE = 4,
}

/// Sets the log level of every process of the system (E7): each running process's
/// log filter is replaced. `level` is an `esgm_log_level`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_set_log_level(esgm: esgm_t, level: i32) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let level = match level {
            0 => LogLevel::Error,
            1 => LogLevel::Warn,
            2 => LogLevel::Info,
            3 => LogLevel::Debug,
            4 => LogLevel::Trace,
            other => {
                return Err(Error::argument(format!(
                    "log level {other} is none of ESGM_LOG_ERROR (0) … ESGM_LOG_TRACE (4)"
                )));
            }
        };
        on!(&*rt, e => e.set_log_level(level)).map_err(|e| Error::of(&e))
    })
}

/// The log level (an `esgm_log_level`).
#[unsafe(no_mangle)]
pub extern "C" fn esgm_get_log_level(esgm: esgm_t, out: *mut i32) -> esgm_status {
    guard(|| {
        let (_, rt) = runtime(esgm)?;
        let level = match on!(&*rt, e => e.log_level()) {
            LogLevel::Error => 0,
            LogLevel::Warn => 1,
            LogLevel::Info => 2,
            LogLevel::Debug => 3,
            LogLevel::Trace => 4,
        };
        unsafe { put(out, "out", level) }
    })
}

/// Asked every quarter second by `esgm_serve_while`: nonzero to go on serving.
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub type esgm_go_on_fn = Option<unsafe extern "C" fn(user: *mut std::ffi::c_void) -> i32>;

/// Serves this process's units and sensors until the system ends: returns `ESGM_OK`
/// once its coordinator has been gone for `patience_ns` (`esgm down`), the main loop
/// of a worker a system file declares. An in-process ESGM has no coordinator:
/// `ESGM_OPERATION_NOT_SUPPORTED`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_serve(esgm: esgm_t, patience_ns: i64) -> esgm_status {
    esgm_serve_while(esgm, patience_ns, None, std::ptr::null_mut())
}

/// [`esgm_serve`], also returning (with `ESGM_TIMEOUT`) as soon as `go_on(user)`,
/// asked every quarter second, returns 0: a program that handles its own signals
/// stops this way. A null `go_on` serves until the system ends.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_serve_while(
    esgm: esgm_t,
    patience_ns: i64,
    go_on: esgm_go_on_fn,
    user: *mut std::ffi::c_void,
) -> esgm_status {
    guard(|| {
        let (d, rt) = runtime(esgm)?;
        let patience = duration(patience_ns, "patience_ns")?;
        let Runtime::Shm(e) = &*rt else {
            return Err(Error::new(
                esgm_status::ESGM_OPERATION_NOT_SUPPORTED,
                "an in-process ESGM has no coordinator to serve until it goes; keep the \
                 process running instead",
            ));
        };
        let gone = e.serve_while(patience, || {
            if d.closed.load(Ordering::Acquire) {
                return false;
            }
            // SAFETY: the caller's function, called with the caller's pointer.
            go_on.is_none_or(|f| unsafe { f(user) } != 0)
        });
        if gone {
            Ok(())
        } else if d.closed.load(Ordering::Acquire) {
            Err(freed())
        } else {
            Err(Error::new(esgm_status::ESGM_TIMEOUT, "stopped: go_on returned 0"))
        }
    })
}

/// Logs esgm's messages to stderr, filtered by `RUST_LOG` (default: warnings), as
/// every esgm program does; `esgm_set_log_level` and `esgm log-level` change the
/// filter while the process runs. Call once, first thing; later calls do nothing. A
/// program that does not call it hears nothing from esgm but its statuses.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_init_logging() -> esgm_status {
    static ONCE: std::sync::Once = std::sync::Once::new();
    guard(|| {
        ONCE.call_once(init_logging);
        Ok(())
    })
}

/// Now on the host's one timeline (nanoseconds of the system clock), the time every
/// process of a system stamps with.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_now() -> i64 {
    SystemClock.now()
}

/// esgm's version (`"0.1.0"`), a static string.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}
