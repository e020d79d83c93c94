//! [`SharedStructure`]: an entity structure as every reader of a trajectory holds it,
//! either owned on this process's heap or *archived where it arrived* (P7).
//!
//! Why two forms behind one type: a structure made in this process (a unit's output, a
//! program's `add`) is an [`EntityStructure`] already, and archiving it only to read it
//! back would cost an encode per add. A structure another process wrote arrives as an
//! rkyv archive in shared memory; decoding it into an [`EntityStructure`] costs an
//! allocation per string, sequence and frame, and a cache line per field, on every hop,
//! for readers that mostly look at a time and one or two attributes. So a replica keeps
//! the archive, checked once when it arrived, as its entry, and queries, subscriptions,
//! units and operators read it in place through the same accessors an owned structure
//! answers ([`SharedStructure::get`], [`ValueRef`], [`FrameRef`], typed views). An owned
//! [`EntityStructure`] is a conversion a reader asks for
//! ([`SharedStructure::to_structure`]), and even then octet sequences (images) stay
//! where they are.
//!
//! Both forms are shared by reference count: cloning a `SharedStructure` never copies
//! the structure, and an archived one keeps the memory it reads (a shared-memory chunk,
//! a kept history's entry, a heap buffer) alive through its [`OctetsHolder`] until the
//! last clone, and the last [`crate::Octets`] made from it, is dropped.

mod value_ref;

use std::fmt;
use std::ptr::NonNull;
use std::sync::Arc;

pub(crate) use value_ref::archived_sort as value_ref_sort;
pub use value_ref::{Attributes, FrameRef, FramesRef, ValueRef};

use crate::codec::{self, ArchivedEntityStructure, CodecError};
use crate::octets::OctetsHolder;
use crate::time::Time;
use crate::value::Value;
use crate::value::frame::{EntityFrame, EntityStructure};

/// An entity structure, owned or archived in place, shared by reference count (see the
/// module docs).
///
/// Its times are kept beside it, so that ordering and time queries never touch the
/// structure itself (for an archived one, a cache line of another process's memory).
#[derive(Clone)]
pub struct SharedStructure {
    valid_time: Time,
    create_time: Time,
    repr: Repr,
}

/// The form a [`SharedStructure`] is in, for code that reads either in its own way (a
/// transport copies an archive's bytes, and encodes an owned structure).
#[derive(Debug, Clone, Copy)]
pub enum StructureForm<'a> {
    /// Made in this process.
    Owned(&'a EntityStructure),
    /// Read in place from an archive.
    Archived {
        /// The archived structure, checked.
        structure: &'a ArchivedEntityStructure,
        /// The codec bytes (envelope and archive) it lies in.
        bytes: &'a [u8],
    },
}

#[derive(Clone)]
enum Repr {
    Owned(Arc<EntityStructure>),
    Archived(Archived),
}

/// An archive held where it lies: the holder keeps the bytes alive, `root` points at the
/// structure inside them, checked when it was made.
#[derive(Clone)]
struct Archived {
    holder: Arc<dyn OctetsHolder>,
    root: NonNull<ArchivedEntityStructure>,
}

// SAFETY: `root` points into `holder.bytes()`, which an `OctetsHolder` (itself
// `Send + Sync`) keeps valid and unchanged for its whole life; the archived structure
// is plain data read through shared references only.
unsafe impl Send for Archived {}
// SAFETY: as above.
unsafe impl Sync for Archived {}

impl Archived {
    fn get(&self) -> &ArchivedEntityStructure {
        // SAFETY: `root` was made from a checked `&ArchivedEntityStructure` inside
        // `holder.bytes()`, which stay valid and unchanged while `holder` lives.
        unsafe { self.root.as_ref() }
    }
}

/// Bytes held on this process's heap, for an archive copied out of memory that could
/// not be held (a reader past its budget of borrowed samples, a file read back).
struct HeapArchive(codec::ArchiveBuffer);

impl OctetsHolder for HeapArchive {
    fn bytes(&self) -> &[u8] {
        &self.0
    }

    fn on_heap(&self) -> bool {
        true
    }
}

impl SharedStructure {
    /// An archived structure read in place in `holder`'s bytes (envelope and archive,
    /// as [`codec::encode`] writes them), checked first: use this for bytes another
    /// process, a file or a network wrote.
    pub fn archived(holder: Arc<dyn OctetsHolder>) -> Result<Self, CodecError> {
        let root = NonNull::from(codec::access(holder.bytes())?);
        Ok(Self::from_archived(Archived { holder, root }))
    }

    /// An archived structure read in place, from codec bytes copied into an aligned heap
    /// buffer and checked: for bytes that cannot be held where they are (a request's
    /// payload, a file's record, a reader past its borrow budget).
    pub fn archived_copy(bytes: &[u8]) -> Result<Self, CodecError> {
        let mut copy = codec::ArchiveBuffer::new();
        copy.extend_from_slice(bytes);
        Self::archived_buffer(copy)
    }

    /// An archived structure read in place in `buffer` (codec bytes on this process's
    /// heap, already copied there), checked.
    pub fn archived_buffer(buffer: codec::ArchiveBuffer) -> Result<Self, CodecError> {
        Self::archived(Arc::new(HeapArchive(buffer)))
    }

    /// An archived structure that `root` points at inside `holder`'s bytes, checked by
    /// the caller already (a shared-memory sample its subscriber validated). `None` if
    /// `root` does not lie within the holder's bytes.
    ///
    /// # Safety
    /// `root` must be the result of [`codec::access`] (full validation) on bytes that
    /// `holder` keeps valid and unchanged for its whole life.
    pub unsafe fn archived_checked(
        holder: Arc<dyn OctetsHolder>,
        root: &ArchivedEntityStructure,
    ) -> Option<Self> {
        let bytes = holder.bytes().as_ptr_range();
        let at = std::ptr::from_ref(root).cast::<u8>();
        let end = at.wrapping_add(std::mem::size_of::<ArchivedEntityStructure>());
        if !(bytes.start <= at && end <= bytes.end) {
            return None;
        }
        Some(Self::from_archived(Archived { holder, root: NonNull::from(root) }))
    }

    fn from_archived(archived: Archived) -> Self {
        let root = archived.get();
        Self {
            valid_time: root.valid_time.to_native(),
            create_time: root.create_time.to_native(),
            repr: Repr::Archived(archived),
        }
    }

    /// The name of the represented entity.
    pub fn name(&self) -> &str {
        match &self.repr {
            Repr::Owned(es) => &es.name,
            Repr::Archived(a) => a.get().name.as_str(),
        }
    }

    /// When the content is true of the world (Definition 3.3.4).
    pub fn valid_time(&self) -> Time {
        self.valid_time
    }

    /// When the content was created (Definition 3.3.5).
    pub fn create_time(&self) -> Time {
        self.create_time
    }

    /// The value of an attribute, read in place; `None` if the structure has none of
    /// that name.
    pub fn get(&self, attribute: &str) -> Option<ValueRef<'_>> {
        self.attributes().find(|(name, _)| *name == attribute).map(|(_, v)| v)
    }

    /// An owned copy of one attribute's value (octet sequences stay where they are):
    /// for a value kept beyond the structure, or compared with a [`Value`].
    pub fn value(&self, attribute: &str) -> Option<Value> {
        self.get(attribute).map(|v| v.to_value())
    }

    /// The attribute/value pairs in the structure's order, read in place.
    pub fn attributes(&self) -> Attributes<'_> {
        match &self.repr {
            Repr::Owned(es) => Attributes::owned(&es.attributes),
            Repr::Archived(a) => Attributes::archived(&a.get().attributes, &a.holder),
        }
    }

    /// How many attributes the structure assigns.
    pub fn attribute_count(&self) -> usize {
        match &self.repr {
            Repr::Owned(es) => es.attributes.len(),
            Repr::Archived(a) => a.get().attributes.len(),
        }
    }

    /// The archived form, read in place, when the structure is one (it came from another
    /// process, a file or the network); `None` for a structure made in this process.
    pub fn archived_structure(&self) -> Option<&ArchivedEntityStructure> {
        match &self.repr {
            Repr::Archived(a) => Some(a.get()),
            Repr::Owned(_) => None,
        }
    }

    /// The codec bytes (envelope and archive) an archived structure is read from, where
    /// they lie: a transport that forwards the structure copies these, never encodes it
    /// again. `None` for an owned structure.
    pub fn archive_bytes(&self) -> Option<&[u8]> {
        match &self.repr {
            Repr::Archived(a) => Some(a.holder.bytes()),
            Repr::Owned(_) => None,
        }
    }

    /// The structure's codec bytes (envelope and archive), to send or store: an
    /// archived structure's are copied as they are (never decoded and encoded again),
    /// an owned one is encoded.
    pub fn to_codec_bytes(
        &self,
    ) -> Result<rkyv::util::AlignedVec<{ codec::ARCHIVE_ALIGNMENT }>, CodecError> {
        match &self.repr {
            Repr::Owned(es) => codec::encode(es),
            Repr::Archived(a) => {
                let mut out = rkyv::util::AlignedVec::<{ codec::ARCHIVE_ALIGNMENT }>::new();
                out.extend_from_slice(a.holder.bytes());
                Ok(out)
            }
        }
    }

    /// The holder of an archived structure's bytes (a transport recognises its own, to
    /// send a loan instead of copying); `None` for an owned structure.
    pub fn holder(&self) -> Option<&Arc<dyn OctetsHolder>> {
        match &self.repr {
            Repr::Archived(a) => Some(&a.holder),
            Repr::Owned(_) => None,
        }
    }

    /// The owned structure, when it is one (made in this process); `None` for an
    /// archived one, which [`Self::to_structure`] converts.
    pub fn as_owned(&self) -> Option<&Arc<EntityStructure>> {
        match &self.repr {
            Repr::Owned(es) => Some(es),
            Repr::Archived(_) => None,
        }
    }

    /// The structure in the form it is in, for code that treats the two apart.
    pub fn form(&self) -> StructureForm<'_> {
        match &self.repr {
            Repr::Owned(es) => StructureForm::Owned(es),
            Repr::Archived(a) => {
                StructureForm::Archived { structure: a.get(), bytes: a.holder.bytes() }
            }
        }
    }

    /// True if the structure is read in place from an archive (see the module docs).
    pub fn is_archived(&self) -> bool {
        matches!(self.repr, Repr::Archived(_))
    }

    /// An owned [`EntityStructure`]: a clone of an owned one, or the archive's fields
    /// copied out, but octet sequences, which stay held where they lie (an image is
    /// never copied by it). The conversion a reader asks for when it wants to keep or
    /// change the structure.
    pub fn to_structure(&self) -> EntityStructure {
        match &self.repr {
            Repr::Owned(es) => es.as_ref().clone(),
            Repr::Archived(_) => EntityStructure {
                name: self.name().to_owned(),
                valid_time: self.valid_time,
                create_time: self.create_time,
                attributes: self.attributes().to_pairs(),
            },
        }
    }

    /// The owned structure behind an `Arc`: shared (no copy) when it is owned already,
    /// converted as [`Self::to_structure`] otherwise.
    pub fn to_arc(&self) -> Arc<EntityStructure> {
        match &self.repr {
            Repr::Owned(es) => Arc::clone(es),
            Repr::Archived(_) => Arc::new(self.to_structure()),
        }
    }

    /// The structure's name and attributes as an owned frame (dropping the times), e.g.
    /// to nest it inside another structure.
    pub fn to_frame(&self) -> EntityFrame {
        match &self.repr {
            Repr::Owned(es) => es.to_frame(),
            Repr::Archived(_) => EntityFrame {
                name: self.name().to_owned(),
                attributes: self.attributes().to_pairs(),
            },
        }
    }

    /// An address that identifies the structure in memory: equal for two handles when
    /// [`Self::ptr_eq`] is true (to remember which structures were seen).
    pub fn identity(&self) -> *const () {
        match &self.repr {
            Repr::Owned(es) => Arc::as_ptr(es).cast(),
            Repr::Archived(a) => a.root.as_ptr().cast_const().cast(),
        }
    }

    /// True if both handles share one structure in memory (no copy between them).
    pub fn ptr_eq(&self, other: &SharedStructure) -> bool {
        match (&self.repr, &other.repr) {
            (Repr::Owned(a), Repr::Owned(b)) => Arc::ptr_eq(a, b),
            (Repr::Archived(a), Repr::Archived(b)) => a.root == b.root,
            _ => false,
        }
    }

    /// Approximate bytes this structure holds (see [`Value::approx_heap_bytes`]): an
    /// archive counts its bytes, held in shared memory or copied here, once however
    /// many handles and values read it (`seen` remembers it by address).
    pub fn approx_bytes(&self, seen: &mut std::collections::HashSet<usize>) -> usize {
        match &self.repr {
            Repr::Owned(es) => es.approx_bytes(seen),
            Repr::Archived(a) => {
                let bytes = a.holder.bytes();
                let held = if seen.insert(bytes.as_ptr() as usize) { bytes.len() } else { 0 };
                std::mem::size_of::<Self>() + held
            }
        }
    }
}

impl From<EntityStructure> for SharedStructure {
    fn from(es: EntityStructure) -> Self {
        Arc::new(es).into()
    }
}

impl From<Arc<EntityStructure>> for SharedStructure {
    fn from(es: Arc<EntityStructure>) -> Self {
        Self { valid_time: es.valid_time, create_time: es.create_time, repr: Repr::Owned(es) }
    }
}

/// Equal when the contents are: the same name, times and attribute values in the same
/// order, whichever form each side is in.
impl PartialEq for SharedStructure {
    fn eq(&self, other: &Self) -> bool {
        if self.ptr_eq(other) {
            return true;
        }
        if let (Repr::Owned(a), Repr::Owned(b)) = (&self.repr, &other.repr) {
            return a == b;
        }
        self.same_content(other.name(), (other.valid_time, other.create_time), other.attributes())
    }
}

impl SharedStructure {
    /// True if this structure has exactly this name, these times and these attributes,
    /// in this order.
    fn same_content(
        &self,
        name: &str,
        (valid, create): (Time, Time),
        attrs: Attributes<'_>,
    ) -> bool {
        self.valid_time == valid
            && self.create_time == create
            && self.name() == name
            && self.attribute_count() == attrs.len()
            && self.attributes().zip(attrs).all(|((n, v), (m, w))| n == m && v == w)
    }
}

impl PartialEq<EntityStructure> for SharedStructure {
    fn eq(&self, other: &EntityStructure) -> bool {
        match &self.repr {
            Repr::Owned(es) => es.as_ref() == other,
            Repr::Archived(_) => self.same_content(
                &other.name,
                (other.valid_time, other.create_time),
                Attributes::owned(&other.attributes),
            ),
        }
    }
}

impl fmt::Debug for SharedStructure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut s = f.debug_struct("SharedStructure");
        s.field("name", &self.name())
            .field("valid_time", &self.valid_time)
            .field("create_time", &self.create_time);
        if self.is_archived() {
            s.field("archived", &true);
        }
        s.field("attributes", &self.attributes().debug()).finish()
    }
}

/// Serialized as an [`EntityStructure`] (the CLI's JSON, the control plane): an
/// archived structure is decoded for it, which only people and tools ask for.
impl serde::Serialize for SharedStructure {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match &self.repr {
            Repr::Owned(es) => es.serialize(s),
            Repr::Archived(_) => self.to_structure().serialize(s),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::value::Octets;

    struct Bytes(rkyv::util::AlignedVec<{ codec::ARCHIVE_ALIGNMENT }>);
    impl OctetsHolder for Bytes {
        fn bytes(&self) -> &[u8] {
            &self.0
        }
    }

    fn sample() -> EntityStructure {
        let blob = EntityFrame::new("b1").with("x", 1i64).with("size", 3i64);
        EntityStructure::new("cam", 100, 101)
            .with("width", 4i64)
            .with("speed", 2.5)
            .with("image_data", Octets::from(vec![7u8; 64]))
            .with("items", vec![blob.clone(), blob])
            .with("label", "hello")
            .with("nested", Value::Agg(vec![Value::Double(1.5), Value::Bool(true)]))
    }

    fn archived(es: &EntityStructure) -> (SharedStructure, Arc<dyn OctetsHolder>) {
        let holder: Arc<dyn OctetsHolder> = Arc::new(Bytes(codec::encode(es).unwrap()));
        (SharedStructure::archived(Arc::clone(&holder)).unwrap(), holder)
    }

    #[test]
    fn an_archived_structure_reads_like_an_owned_one_without_decoding() {
        let es = sample();
        let (a, holder) = archived(&es);
        let o = SharedStructure::from(es.clone());
        for s in [&a, &o] {
            assert_eq!((s.name(), s.valid_time(), s.create_time()), ("cam", 100, 101));
            assert_eq!(s.get("width").and_then(|v| v.as_long()), Some(4));
            assert_eq!(s.get("speed").and_then(|v| v.as_double()), Some(2.5));
            assert_eq!(s.get("label").and_then(|v| v.as_str()), Some("hello"));
            let items = s.get("items").and_then(|v| v.as_frames()).unwrap();
            assert_eq!(items.len(), 2);
            assert_eq!(items.get(1).unwrap().get("size").and_then(|v| v.as_long()), Some(3));
            assert_eq!(s.attribute_count(), 6);
            assert!(s.get("missing").is_none());
        }
        assert!(a.is_archived() && !o.is_archived());
        let pixels = a.get("image_data").and_then(|v| v.as_bytes()).unwrap();
        assert!(holder.bytes().as_ptr_range().contains(&pixels.as_ptr()), "read in place");
        assert_eq!(a, o, "equal by content");
        assert_eq!(a, es);
        assert_eq!(a.to_structure(), es);
    }

    #[test]
    fn octets_made_from_an_archive_hold_it_and_are_not_copied() {
        let (a, holder) = archived(&sample());
        let octets = a.get("image_data").and_then(|v| v.as_octets()).unwrap();
        assert!(octets.is_held());
        assert_eq!(Arc::strong_count(&holder), 3, "the test, the structure, the octets");
        drop(a);
        assert_eq!(&octets[..], &[7u8; 64][..]);
        drop(octets);
        assert_eq!(Arc::strong_count(&holder), 1);
        let decoded = archived(&sample()).0.to_structure();
        assert!(decoded.get("image_data").and_then(Value::as_octets).unwrap().is_held());
    }

    #[test]
    fn bad_bytes_are_refused_and_a_root_outside_its_holder_is_not_taken() {
        assert!(SharedStructure::archived_copy(&[0u8; 64]).is_err());
        let bytes = codec::encode(&sample()).unwrap();
        let root = codec::access(&bytes).unwrap();
        let elsewhere: Arc<dyn OctetsHolder> = Arc::new(Bytes(codec::encode(&sample()).unwrap()));
        // SAFETY: the root was checked; the holder does not contain it, which is refused.
        assert!(unsafe { SharedStructure::archived_checked(elsewhere, root) }.is_none());
        let copy = SharedStructure::archived_copy(&bytes).unwrap();
        assert_eq!(copy, sample());
    }
}
