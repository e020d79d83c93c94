//! The handles a C program holds: 64-bit ids into one table of objects, so that a
//! freed, foreign or made-up handle is an error code and never a dangling pointer.
//!
//! An id is the slot's index plus one (so 0 is the null handle) in its low 32 bits and
//! the slot's generation in its high 32 bits; freeing a handle empties the slot and
//! bumps its generation, so the old id no longer matches. Each slot also records its
//! kind, so a sample handle passed where a trajectory is expected is named as what it
//! is. Objects are `Arc`s: a lookup clones one out and releases the table at once, so
//! a call that blocks (a subscription's receive) never holds the table, and freeing a
//! handle while another thread uses it is safe (the object lives until that call
//! returns).

use std::any::Any;
use std::sync::Arc;

use parking_lot::Mutex;

use crate::status::{Error, Result, esgm_status};

/// A C handle type: a `#[repr(C)]` struct around an id, and the object it names.
pub(crate) trait Handle: Copy {
    /// The object behind the handle.
    type Object: Any + Send + Sync;
    /// Its C type's name, for messages (`esgm_trajectory_t`).
    const KIND: &'static str;
    /// The id.
    fn id(self) -> u64;
    /// The handle of an id.
    fn from_id(id: u64) -> Self;
}

/// One slot: its generation and, while a handle names it, the object and its kind.
#[derive(Default)]
struct Slot {
    generation: u32,
    object: Option<(Arc<dyn Any + Send + Sync>, &'static str)>,
}

/// Every live object, by slot.
#[derive(Default)]
struct Table {
    slots: Vec<Slot>,
    free: Vec<u32>,
}

static TABLE: Mutex<Table> = Mutex::new(Table { slots: Vec::new(), free: Vec::new() });

fn split(id: u64) -> (usize, u32) {
    // The low half is the index plus one; the high half the generation.
    let low = (id & u64::from(u32::MAX)) as usize;
    (low.wrapping_sub(1), (id >> 32) as u32)
}

/// Makes a handle for `object`.
pub(crate) fn insert<H: Handle>(object: H::Object) -> H {
    insert_arc::<H>(Arc::new(object))
}

/// Makes a handle for an object already shared.
pub(crate) fn insert_arc<H: Handle>(object: Arc<H::Object>) -> H {
    let mut t = TABLE.lock();
    let index = match t.free.pop() {
        Some(i) => i as usize,
        None => {
            t.slots.push(Slot { generation: 1, object: None });
            t.slots.len() - 1
        }
    };
    let slot = &mut t.slots[index];
    slot.object = Some((object, H::KIND));
    let generation = slot.generation;
    H::from_id((u64::from(generation) << 32) | (index as u64 + 1))
}

/// Why `h` names nothing of kind `H`.
fn invalid<H: Handle>(h: H, t: &Table) -> Error {
    let id = h.id();
    if id == 0 {
        return Error::new(
            esgm_status::ESGM_INVALID_HANDLE,
            format!("a null {} (0): make one first", H::KIND),
        );
    }
    let (index, generation) = split(id);
    let what = match t.slots.get(index) {
        Some(slot) => match &slot.object {
            Some((_, kind)) if slot.generation == generation => {
                format!("is an {kind}, not an {}", H::KIND)
            }
            _ if generation != 0 && generation < slot.generation => {
                "was freed (or its ESGM was)".to_owned()
            }
            _ => "was never made by esgm".to_owned(),
        },
        None => "was never made by esgm".to_owned(),
    };
    Error::new(esgm_status::ESGM_INVALID_HANDLE, format!("{} {id:#x} {what}", H::KIND))
}

/// The object `h` names.
pub(crate) fn get<H: Handle>(h: H) -> Result<Arc<H::Object>> {
    let t = TABLE.lock();
    let (index, generation) = split(h.id());
    if let Some(Slot { generation: g, object: Some((object, _)) }) = t.slots.get(index) {
        if *g == generation {
            if let Ok(found) = Arc::clone(object).downcast::<H::Object>() {
                return Ok(found);
            }
        }
    }
    Err(invalid(h, &t))
}

/// Runs `f` on the object `h` names, with the table held: no reference is counted in
/// and out, for the short reads and writes that make up most calls (a sample's
/// attribute, a builder's setter). `f` must not use the table (it would wait for
/// itself): anything that makes, frees or looks up another handle uses [`get`].
pub(crate) fn with<H: Handle, R>(h: H, f: impl FnOnce(&H::Object) -> Result<R>) -> Result<R> {
    let t = TABLE.lock();
    let (index, generation) = split(h.id());
    if let Some(Slot { generation: g, object: Some((object, _)) }) = t.slots.get(index) {
        if *g == generation {
            if let Some(found) = object.downcast_ref::<H::Object>() {
                return f(found);
            }
        }
    }
    Err(invalid(h, &t))
}

/// Frees `h`, returning its object (which lives on while other calls hold it).
pub(crate) fn take<H: Handle>(h: H) -> Result<Arc<H::Object>> {
    let mut t = TABLE.lock();
    let (index, generation) = split(h.id());
    let matches = t.slots.get(index).is_some_and(|s| {
        s.generation == generation
            && s.object.as_ref().is_some_and(|(o, _)| o.as_ref().is::<H::Object>())
    });
    if !matches {
        return Err(invalid(h, &t));
    }
    let slot = &mut t.slots[index];
    let (object, _) = slot.object.take().ok_or_else(|| invalid(h, &Table::default()))?;
    // A slot whose generation would wrap is retired rather than reused, so an old id
    // can never match again.
    slot.generation = slot.generation.wrapping_add(1);
    if slot.generation != 0 {
        t.free.push(index as u32);
    }
    drop(t);
    object.downcast::<H::Object>().map_err(|_| Error::new(esgm_status::ESGM_INTERNAL, "kind"))
}

/// Frees `h` if it names an object of its kind; a null handle is fine (nothing to
/// free), as `free(NULL)` is.
pub(crate) fn free<H: Handle>(h: H) -> Result<()> {
    if h.id() == 0 {
        return Ok(());
    }
    take(h).map(drop)
}

/// Makes a `#[repr(C)]` struct holding an id (written out where it is declared, so
/// cbindgen sees it) the handle of an object.
macro_rules! handle {
    ($name:ident => $object:ty) => {
        impl $crate::handles::Handle for $name {
            type Object = $object;
            const KIND: &'static str = stringify!($name);
            fn id(self) -> u64 {
                self.id
            }
            fn from_id(id: u64) -> Self {
                Self { id }
            }
        }
    };
}
pub(crate) use handle;

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct test_a_t {
        id: u64,
    }
    handle!(test_a_t => String);
    #[derive(Debug, Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct test_b_t {
        id: u64,
    }
    handle!(test_b_t => u32);

    #[test]
    fn freed_foreign_and_null_handles_are_refused() {
        let a: test_a_t = insert("x".to_owned());
        assert_eq!(*get(a).unwrap(), "x");
        let as_b = test_b_t { id: a.id };
        let e = get(as_b).unwrap_err();
        assert!(e.message.contains("is an test_a_t, not an test_b_t"), "{}", e.message);
        let e = with(as_b, |_| Ok(())).unwrap_err();
        assert!(e.message.contains("is an test_a_t, not an test_b_t"), "{}", e.message);
        assert_eq!(with(a, |s| Ok(s.len())).unwrap(), 1);
        free(a).unwrap();
        let e = get(a).unwrap_err();
        assert!(e.message.contains("was freed"), "{}", e.message);
        let e = free(a).unwrap_err();
        assert_eq!(e.status, esgm_status::ESGM_INVALID_HANDLE);
        let e = get(test_a_t { id: 0xdead_beef_0000_0007 }).unwrap_err();
        assert!(e.message.contains("never made"), "{}", e.message);
        let e = get(test_a_t { id: 0 }).unwrap_err();
        assert!(e.message.contains("null"), "{}", e.message);
        free(test_a_t { id: 0 }).unwrap();
        // The slot is reused with a new generation: the old id stays dead.
        let again: test_a_t = insert("y".to_owned());
        assert_ne!(again.id, a.id);
        assert!(get(a).is_err());
        free(again).unwrap();
    }
}
