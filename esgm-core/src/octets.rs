//! Octet sequences (images, blobs of bytes): [`Octets`], a shared, immutable byte
//! buffer whose bytes either live on this process's heap or are *held* where someone
//! else put them — typically a shared-memory chunk another process wrote.
//!
//! Why two homes: a camera image crosses a process boundary in shared memory, and the
//! reader's cache, its units and its subscribers should read the pixels there, not a
//! copy. A runtime that receives such a chunk keeps it borrowed for as long as any
//! [`Octets`] points into it and says so through an [`OctetsHolder`]; everything else in
//! esgm (the store, queries, units, the codec) sees one `&[u8]` either way.

use std::fmt;
use std::ops::{Deref, Range};
use std::sync::Arc;

use rkyv::{Archive, Deserialize, Serialize};

/// How an octet sequence is archived (re-exported where users name it, in
/// [`crate::codec`]).
pub(crate) mod archive;

/// Something that keeps bytes alive outside this process's heap — a borrowed
/// shared-memory sample — for as long as any [`Octets`] made from it exists.
///
/// Dropping the last `Arc` of a holder is the signal that its bytes may be given back
/// (e.g. the sample returned to its publisher). `bytes` must return the same slice
/// every time, valid for the holder's whole life.
pub trait OctetsHolder: Send + Sync + 'static {
    /// The held bytes.
    fn bytes(&self) -> &[u8];

    /// The holder as `Any`, for a transport that recognises its own holders (a loan
    /// it can send instead of copying); `None` by default.
    fn as_any(&self) -> Option<&dyn std::any::Any> {
        None
    }

    /// True if the held bytes are on this process's heap after all (an archive copied
    /// there), so that [`Octets::is_held`] says where bytes really are; false by
    /// default.
    fn on_heap(&self) -> bool {
        false
    }
}

/// Where an [`Octets`]'s bytes are.
#[derive(Clone)]
pub(crate) enum OctetBytes {
    /// On this process's heap, shared by reference count.
    Heap(Arc<[u8]>),
    /// A range of a holder's bytes (e.g. pixels in a shared-memory sample).
    Held { holder: Arc<dyn OctetsHolder>, range: Range<usize> },
}

impl OctetBytes {
    pub(crate) fn as_slice(&self) -> &[u8] {
        match self {
            OctetBytes::Heap(bytes) => bytes,
            // The range was checked against these bytes when the value was made.
            OctetBytes::Held { holder, range } => &holder.bytes()[range.clone()],
        }
    }
}

/// An immutable, shared byte buffer: the payload of an octet sequence.
///
/// Cloning shares the bytes. In the archived form it is a plain byte vector, so a
/// reader in another process reads the pixels in place; a runtime that receives one
/// can keep it there ([`Octets::held`]) instead of copying it to its heap.
#[derive(Clone, Archive, Serialize, Deserialize)]
#[rkyv(derive(Debug))]
pub struct Octets(#[rkyv(with = archive::SharedBytes)] pub(crate) OctetBytes);

impl Octets {
    /// Wraps bytes without copying them again.
    pub fn new(bytes: impl Into<Arc<[u8]>>) -> Self {
        Octets(OctetBytes::Heap(bytes.into()))
    }

    /// The bytes `range` of `holder`, without copying them; `None` if the range is not
    /// within the holder's bytes.
    pub fn held(holder: Arc<dyn OctetsHolder>, range: Range<usize>) -> Option<Self> {
        let len = holder.bytes().len();
        (range.start <= range.end && range.end <= len)
            .then_some(Octets(OctetBytes::Held { holder, range }))
    }

    /// The holder of held bytes (see [`OctetsHolder::as_any`]); `None` for heap bytes.
    pub fn holder(&self) -> Option<&Arc<dyn OctetsHolder>> {
        match &self.0 {
            OctetBytes::Held { holder, .. } => Some(holder),
            OctetBytes::Heap(_) => None,
        }
    }

    /// True if the bytes are held elsewhere (e.g. in shared memory another process
    /// wrote) rather than on this process's heap.
    pub fn is_held(&self) -> bool {
        matches!(&self.0, OctetBytes::Held { holder, .. } if !holder.on_heap())
    }

    /// True if both handles read the same bytes in memory (no copy was made between
    /// them).
    pub fn ptr_eq(&self, other: &Octets) -> bool {
        std::ptr::eq(self.as_ptr(), other.as_ptr()) && self.len() == other.len()
    }
}

impl Default for Octets {
    fn default() -> Self {
        Octets::new(Vec::new())
    }
}

impl PartialEq for Octets {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl Eq for Octets {}

/// Octets cross the control plane and JSON output as a byte sequence; images travel on
/// the data plane, not here.
impl serde::Serialize for Octets {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(self)
    }
}

impl<'de> serde::Deserialize<'de> for Octets {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(Octets::from(Vec::<u8>::deserialize(d)?))
    }
}

impl ArchivedOctets {
    /// The bytes, read in place (in shared memory for a cross-process reader).
    pub fn as_slice(&self) -> &[u8] {
        self.0.as_slice()
    }
}

impl Deref for Octets {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        self.0.as_slice()
    }
}

impl From<Vec<u8>> for Octets {
    fn from(v: Vec<u8>) -> Self {
        Octets::new(v)
    }
}

impl From<&[u8]> for Octets {
    fn from(v: &[u8]) -> Self {
        Octets::new(v)
    }
}

impl fmt::Debug for Octets {
    // Never dump a megabyte of pixels into a log line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let place = if self.is_held() { ", held" } else { "" };
        write!(f, "Octets({} bytes{place})", self.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Chunk(Vec<u8>);
    impl OctetsHolder for Chunk {
        fn bytes(&self) -> &[u8] {
            &self.0
        }
    }

    #[test]
    fn clones_share_bytes() {
        let a = Octets::from(vec![1u8; 1024]);
        let b = a.clone();
        assert!(a.ptr_eq(&b));
        assert!(!a.is_held());
        assert_eq!(format!("{a:?}"), "Octets(1024 bytes)");
    }

    #[test]
    fn held_octets_read_the_holders_bytes_and_release_it_last() {
        let holder: Arc<dyn OctetsHolder> = Arc::new(Chunk((0..=255).collect()));
        let o = Octets::held(Arc::clone(&holder), 10..20).unwrap();
        assert!(o.is_held());
        assert_eq!(&o[..], &(10..20).collect::<Vec<u8>>()[..]);
        assert_eq!(o, Octets::from((10..20).collect::<Vec<u8>>()), "equal by content");
        assert!(std::ptr::eq(o.as_ptr(), holder.bytes()[10..].as_ptr()), "not a copy");
        assert_eq!(format!("{o:?}"), "Octets(10 bytes, held)");
        let c = o.clone();
        drop(o);
        assert_eq!(Arc::strong_count(&holder), 2, "a clone still holds");
        drop(c);
        assert_eq!(Arc::strong_count(&holder), 1);
        assert!(Octets::held(Arc::clone(&holder), 250..257).is_none(), "out of range");
    }
}
