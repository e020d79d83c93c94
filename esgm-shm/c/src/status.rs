//! What every function returns: a status named after the IDL's exceptions, and the
//! message of the last failure on the calling thread.
//!
//! One mapping from esgm's Rust errors to statuses, by the variant's name (every error
//! enum serialises, since errors cross processes, and its variants carry the IDL's
//! names), so a new error variant with an IDL name gets its status without a change
//! here. Every entry point runs inside `guard`: a panic is caught and becomes
//! `ESGM_INTERNAL`, never an unwind into C.

use std::cell::RefCell;
use std::ffi::{CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// The outcome of every esgm function. `ESGM_OK` is 0; every other value names what
/// went wrong, after the seed's IDL exceptions where one fits, and
/// `esgm_last_error_message()` says it in words with the name that was wrong.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(non_camel_case_types, reason = "a C enum, named as C code names them")]
pub enum esgm_status {
    /// Success.
    ESGM_OK = 0,
    /// No sample answers the query (an empty trajectory, a time outside what it holds),
    /// or a unit or sensor has no value now.
    ESGM_VALUE_NOT_AVAILABLE = 1,
    /// No trajectory of that name (or it was destroyed).
    ESGM_NO_SUCH_ENTITY_STRUCTURE = 2,
    /// No type of that name.
    ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE = 3,
    /// A trajectory of that name exists.
    ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS = 4,
    /// A type of that name exists.
    ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS = 5,
    /// No sensor of that name.
    ESGM_NO_SUCH_SENSOR = 6,
    /// No computational unit of that name.
    ESGM_NO_SUCH_COMP_UNIT = 7,
    /// A sensor of that name exists.
    ESGM_SENSOR_ALREADY_EXISTS = 8,
    /// A computational unit of that name exists.
    ESGM_COMP_UNIT_ALREADY_EXISTS = 9,
    /// The trajectory's policy refused the structure (blocking adds only; the others
    /// drop it, count it and say `ESGM_OUTCOME_DROPPED`).
    ESGM_POLICY_VIOLATION = 10,
    /// A policy that cannot be (a negative cache, a filter that does not type-check…).
    ESGM_ILLEGAL_POLICY = 11,
    /// A structure, input or definition that does not fit its type, or an attribute
    /// read as a sort it does not have.
    ESGM_INVALID_TYPE = 12,
    /// Not an operation of this trajectory or runtime (an add to a computed one…).
    ESGM_OPERATION_NOT_SUPPORTED = 13,
    /// A limit of the domain was reached; the message names it, its value and the
    /// setting that raises it.
    ESGM_LIMIT_REACHED = 14,
    /// The trajectory's writer has exited.
    ESGM_WRITER_GONE = 15,
    /// A part of the system did not answer (no coordinator, a process gone).
    ESGM_UNAVAILABLE = 16,
    /// A wait ended at its timeout with nothing to return.
    ESGM_TIMEOUT = 17,
    /// An attribute the structure does not have; the message lists those it has.
    ESGM_NO_SUCH_ATTRIBUTE = 18,
    /// A handle that is null, freed, of another kind or made up.
    ESGM_INVALID_HANDLE = 19,
    /// A null pointer, a string that is not UTF-8, a value out of range.
    ESGM_INVALID_ARGUMENT = 20,
    /// An index past the end of a list or sequence.
    ESGM_OUT_OF_RANGE = 21,
    /// The subscription ended: its trajectory was destroyed or its ESGM freed.
    ESGM_CLOSED = 22,
    /// Any other error esgm reports; the message says which.
    ESGM_ERROR = 98,
    /// A bug in esgm (a panic caught at the boundary); the message says where.
    ESGM_INTERNAL = 99,
}

use esgm_status::*;

/// A failed call: its status and the message for `esgm_last_error_message()`.
#[derive(Debug)]
pub(crate) struct Error {
    pub(crate) status: esgm_status,
    /// A static message (an empty poll's) costs no allocation.
    pub(crate) message: std::borrow::Cow<'static, str>,
}

impl Error {
    /// A failure with `status`, said as `message`.
    pub(crate) fn new(
        status: esgm_status,
        message: impl Into<std::borrow::Cow<'static, str>>,
    ) -> Self {
        Self { status, message: message.into() }
    }

    /// A bad argument (a null pointer, a value out of range).
    pub(crate) fn argument(message: impl Into<std::borrow::Cow<'static, str>>) -> Self {
        Self::new(ESGM_INVALID_ARGUMENT, message)
    }

    /// Any esgm error, its status picked by its variant's IDL name.
    pub(crate) fn of<E: serde::Serialize + std::fmt::Display>(e: &E) -> Self {
        Self::new(status_of_variant(variant(e).as_deref()), e.to_string())
    }
}

/// The result of everything inside an entry point.
pub(crate) type Result<T> = std::result::Result<T, Error>;

/// The variant name of a serialisable error enum (`"NoSuchEntityStructure"`).
fn variant<E: serde::Serialize>(e: &E) -> Option<String> {
    match serde_json::to_value(e).ok()? {
        serde_json::Value::String(s) => Some(s),
        serde_json::Value::Object(m) => m.keys().next().cloned(),
        _ => None,
    }
}

/// The status of an error variant named `variant`.
fn status_of_variant(variant: Option<&str>) -> esgm_status {
    match variant {
        Some("ValueNotAvailable") => ESGM_VALUE_NOT_AVAILABLE,
        Some("NoSuchEntityStructure") => ESGM_NO_SUCH_ENTITY_STRUCTURE,
        Some("NoSuchEntityStructureType") => ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE,
        Some("EntityStructureAlreadyExists") => ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS,
        Some("EntityStructureTypeAlreadyExists") => ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS,
        Some("NoSuchSensor") => ESGM_NO_SUCH_SENSOR,
        Some("NoSuchCompUnit") => ESGM_NO_SUCH_COMP_UNIT,
        Some("SensorAlreadyExists") => ESGM_SENSOR_ALREADY_EXISTS,
        Some("CompUnitAlreadyExists") => ESGM_COMP_UNIT_ALREADY_EXISTS,
        Some("PolicyViolation") => ESGM_POLICY_VIOLATION,
        Some("IllegalPolicy" | "IllegalFilter" | "IllegalOperator") => ESGM_ILLEGAL_POLICY,
        // A structure, an input or a definition that does not fit its type.
        Some(
            "InvalidType"
            | "InvalidInput"
            | "WrongInputCount"
            | "InvalidTypeDefinition"
            | "InvalidDefinition"
            | "InvalidDefault"
            | "TypeChange",
        ) => ESGM_INVALID_TYPE,
        Some("OperationNotSupported" | "InUse" | "Cycle" | "NoInputs") => {
            ESGM_OPERATION_NOT_SUPPORTED
        }
        Some("LimitReached") => ESGM_LIMIT_REACHED,
        Some("WriterGone") => ESGM_WRITER_GONE,
        Some("Unavailable" | "Incomplete" | "DeadlinePassed") => ESGM_UNAVAILABLE,
        _ => ESGM_ERROR,
    }
}

thread_local! {
    /// The message of the last failed call on this thread, NUL-terminated for C.
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

/// Keeps `message` as this thread's last error (a NUL inside is cut there). The same
/// message again (a reader polling an empty subscription) allocates nothing.
pub(crate) fn set_last_error(message: &str) {
    let cut = message.split('\0').next().unwrap_or_default();
    LAST_ERROR.with(|m| {
        if m.borrow().as_bytes() == cut.as_bytes() {
            return;
        }
        *m.borrow_mut() = CString::new(cut).unwrap_or_default();
    });
}

/// Runs an entry point's body: its error becomes the status and this thread's last
/// message; a panic becomes `ESGM_INTERNAL`, caught here so it never unwinds into C.
pub(crate) fn guard(body: impl FnOnce() -> Result<()>) -> esgm_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => ESGM_OK,
        Ok(Err(e)) => {
            set_last_error(&e.message);
            e.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".to_owned());
            set_last_error(&format!("internal error in esgm (please report it): {what}"));
            ESGM_INTERNAL
        }
    }
}

/// The message of the last call that failed on this thread: what was wrong, with the
/// name that was wrong (`no entity trajectory structure `robt``). Empty if none
/// failed. The text stays valid until the next failing call on this thread; copy it
/// to keep it.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_last_error_message() -> *const c_char {
    LAST_ERROR.with(|m| m.borrow().as_ptr())
}

/// The name of a status (`"ESGM_POLICY_VIOLATION"`), a static string; an unknown value
/// gives `"ESGM_UNKNOWN_STATUS"`.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_status_name(status: i32) -> *const c_char {
    let name: &'static [u8] = match status {
        0 => b"ESGM_OK\0",
        1 => b"ESGM_VALUE_NOT_AVAILABLE\0",
        2 => b"ESGM_NO_SUCH_ENTITY_STRUCTURE\0",
        3 => b"ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE\0",
        4 => b"ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS\0",
        5 => b"ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS\0",
        6 => b"ESGM_NO_SUCH_SENSOR\0",
        7 => b"ESGM_NO_SUCH_COMP_UNIT\0",
        8 => b"ESGM_SENSOR_ALREADY_EXISTS\0",
        9 => b"ESGM_COMP_UNIT_ALREADY_EXISTS\0",
        10 => b"ESGM_POLICY_VIOLATION\0",
        11 => b"ESGM_ILLEGAL_POLICY\0",
        12 => b"ESGM_INVALID_TYPE\0",
        13 => b"ESGM_OPERATION_NOT_SUPPORTED\0",
        14 => b"ESGM_LIMIT_REACHED\0",
        15 => b"ESGM_WRITER_GONE\0",
        16 => b"ESGM_UNAVAILABLE\0",
        17 => b"ESGM_TIMEOUT\0",
        18 => b"ESGM_NO_SUCH_ATTRIBUTE\0",
        19 => b"ESGM_INVALID_HANDLE\0",
        20 => b"ESGM_INVALID_ARGUMENT\0",
        21 => b"ESGM_OUT_OF_RANGE\0",
        22 => b"ESGM_CLOSED\0",
        98 => b"ESGM_ERROR\0",
        99 => b"ESGM_INTERNAL\0",
        _ => b"ESGM_UNKNOWN_STATUS\0",
    };
    name.as_ptr().cast()
}

/// Sets this thread's last error message: a unit or sensor callback that fails says
/// why here before it returns its status, and esgm logs and counts that reason. A null
/// `message` clears it.
#[unsafe(no_mangle)]
pub extern "C" fn esgm_set_last_error_message(message: *const c_char) {
    let set = || -> Result<()> {
        match unsafe { crate::strings::optional(message, "message") }? {
            Some(m) => set_last_error(m),
            None => set_last_error(""),
        }
        Ok(())
    };
    // Nothing to report a failure to: a message that is not UTF-8 says so instead.
    if let Err(e) = set() {
        set_last_error(&e.message);
    }
}

/// This thread's last error message, as Rust text.
pub(crate) fn last_error() -> String {
    LAST_ERROR.with(|m| m.borrow().to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_is_a_status_and_a_message() {
        let s = guard(|| panic!("boom"));
        assert_eq!(s, ESGM_INTERNAL);
        assert!(last_error().contains("boom"), "{}", last_error());
    }

    #[test]
    fn every_status_has_its_name() {
        for (status, name) in [
            (ESGM_OK, "ESGM_OK"),
            (ESGM_POLICY_VIOLATION, "ESGM_POLICY_VIOLATION"),
            (ESGM_CLOSED, "ESGM_CLOSED"),
            (ESGM_INTERNAL, "ESGM_INTERNAL"),
        ] {
            let got = unsafe { std::ffi::CStr::from_ptr(esgm_status_name(status as i32)) };
            assert_eq!(got.to_str().unwrap(), name);
        }
        let unknown = unsafe { std::ffi::CStr::from_ptr(esgm_status_name(1234)) };
        assert_eq!(unknown.to_str().unwrap(), "ESGM_UNKNOWN_STATUS");
    }
}
