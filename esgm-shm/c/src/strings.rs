//! Text across the boundary: C strings in (checked for null and UTF-8, with the
//! argument named when they are not), and text out, either borrowed from an object the
//! caller holds (`esgm_str_t`: pointer and length, valid while the handle lives) or
//! copied into the caller's buffer, as `snprintf` does.

use std::ffi::{CStr, c_char};

use crate::status::{Error, Result, esgm_status};

/// Text esgm lends: `len` bytes of UTF-8 at `ptr`, not NUL-terminated, valid while
/// the handle it was read from lives. A C++ `std::string_view` of it costs nothing.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
#[allow(non_camel_case_types, reason = "a C type, named as C code names them")]
pub struct esgm_str_t {
    /// The first byte (never null: an empty text points at a static byte).
    pub ptr: *const c_char,
    /// Its length in bytes.
    pub len: usize,
}

impl esgm_str_t {
    /// A view of `s`, which must outlive every use the caller makes of it.
    pub(crate) fn of(s: &str) -> Self {
        let ptr = if s.is_empty() { c"".as_ptr() } else { s.as_ptr().cast() };
        Self { ptr, len: s.len() }
    }
}

/// The text at `p`, named `what` in the error when it is null or not UTF-8.
///
/// # Safety
/// `p` is null or points at a NUL-terminated string that stays valid and unchanged
/// for `'a`.
pub(crate) unsafe fn text<'a>(p: *const c_char, what: &str) -> Result<&'a str> {
    if p.is_null() {
        return Err(Error::argument(format!("`{what}` is a null pointer; pass a string")));
    }
    // SAFETY: not null, and NUL-terminated by the caller's contract.
    let c = unsafe { CStr::from_ptr(p) };
    c.to_str().map_err(|e| {
        Error::argument(format!(
            "`{what}` is not UTF-8 (byte {} of \"{}\")",
            e.valid_up_to(),
            c.to_string_lossy()
        ))
    })
}

/// The text at `p`, or `None` when `p` is null.
///
/// # Safety
/// As [`text`].
pub(crate) unsafe fn optional<'a>(p: *const c_char, what: &str) -> Result<Option<&'a str>> {
    if p.is_null() { Ok(None) } else { unsafe { text(p, what) }.map(Some) }
}

/// `n` strings at `p` (an array of C strings), each checked, named `what[i]`.
///
/// # Safety
/// `p` is null (then `n` must be 0) or points at `n` pointers as [`text`] takes.
pub(crate) unsafe fn texts<'a>(
    p: *const *const c_char,
    n: usize,
    what: &str,
) -> Result<Vec<&'a str>> {
    if n == 0 {
        return Ok(Vec::new());
    }
    let items = unsafe { slice(p, n, what) }?;
    items.iter().enumerate().map(|(i, s)| unsafe { text(*s, &format!("{what}[{i}]")) }).collect()
}

/// `n` items at `p`, named `what` when `p` is null though `n` is not 0.
///
/// # Safety
/// `p` is null (then `n` must be 0) or points at `n` initialised items that stay
/// valid for `'a`.
pub(crate) unsafe fn slice<'a, T>(p: *const T, n: usize, what: &str) -> Result<&'a [T]> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(Error::argument(format!("`{what}` is a null pointer but its length is {n}")));
    }
    if !p.is_aligned() {
        return Err(Error::argument(format!("`{what}` is not aligned for its items")));
    }
    // SAFETY: not null, aligned, and `n` valid items by the caller's contract.
    Ok(unsafe { std::slice::from_raw_parts(p, n) })
}

/// Writes `value` where `out` points, or says which argument is null.
///
/// # Safety
/// `out` is null or valid for a write of a `T`.
pub(crate) unsafe fn put<T>(out: *mut T, what: &str, value: T) -> Result<()> {
    if out.is_null() {
        return Err(Error::argument(format!("`{what}` is a null pointer; pass where to write")));
    }
    if !out.is_aligned() {
        return Err(Error::argument(format!("`{what}` is not aligned for what it receives")));
    }
    // SAFETY: not null and aligned; valid for a write by the caller's contract.
    unsafe { out.write(value) };
    Ok(())
}

/// Checks that `out` can be written before the work that fills it is done, so a
/// failed check leaves nothing made and unreturned.
pub(crate) fn writable<T>(out: *mut T, what: &str) -> Result<()> {
    if out.is_null() {
        return Err(Error::argument(format!("`{what}` is a null pointer; pass where to write")));
    }
    if !out.is_aligned() {
        return Err(Error::argument(format!("`{what}` is not aligned for what it receives")));
    }
    Ok(())
}

/// Copies `text` into the caller's buffer `buf` of `capacity` bytes, NUL-terminated
/// (cut to fit), and writes its full length (without the NUL) to `len` if not null, so
/// a caller can ask again with a buffer big enough. `buf` may be null with capacity 0
/// to ask the length only.
///
/// # Safety
/// `buf` is null or valid for `capacity` bytes of writes; `len` is null or valid for a
/// write.
pub(crate) unsafe fn copy_out(
    text: &str,
    buf: *mut c_char,
    capacity: usize,
    len: *mut usize,
) -> Result<()> {
    if !len.is_null() {
        unsafe { put(len, "len", text.len()) }?;
    }
    if capacity == 0 {
        return Ok(());
    }
    if buf.is_null() {
        return Err(Error::argument(format!(
            "`buf` is a null pointer but its capacity is {capacity}"
        )));
    }
    let n = text.len().min(capacity - 1);
    // SAFETY: `buf` has `capacity` > n bytes by the caller's contract.
    unsafe {
        std::ptr::copy_nonoverlapping(text.as_ptr(), buf.cast::<u8>(), n);
        buf.add(n).write(0);
    }
    if n < text.len() {
        return Err(Error::new(
            esgm_status::ESGM_OUT_OF_RANGE,
            format!("the text is {} bytes; a buffer of {capacity} holds {n} of them", text.len()),
        ));
    }
    Ok(())
}
