//! How an octet sequence ([`crate::Octets`]) is archived: as a plain byte vector, whose
//! bytes are normally copied into the archive, or — for an image whose pixels are
//! already in the output buffer — pointed at where they lie. And how it is decoded: by
//! copying the bytes, or — for a deserializer that can keep the archive's buffer alive
//! ([`HoldOctets`]) — by pointing at them where they lie.
//!
//! The second case is why this is not rkyv's own `Arc` support. [`crate::codec`]'s image decoding needs
//! the archived `image_data` vector to point at bytes it never writes. The only hook
//! rkyv gives inside the archived [`crate::value::ArchivedValue`] is this field
//! wrapper (the octets' archived field is private to `value.rs`, and the archived enum
//! can only be built by resolving a real `Value`). So the wrapper asks the writer,
//! through [`PlaceOctets`], whether an *empty* octet sequence stands for bytes already
//! in place. Every ordinary writer says no; only the image writer says yes, once.

use rkyv::Place;
use rkyv::de::Pool;
use rkyv::rancor::{Fallible, Source, Strategy};
use rkyv::ser::{Allocator, Writer};
use rkyv::vec::{ArchivedVec, VecResolver};
use rkyv::with::{ArchiveWith, DeserializeWith, SerializeWith};

use super::{OctetBytes, Octets};

/// Archives an octet sequence's bytes as a plain byte vector: the archived form has no
/// shared pointer bookkeeping, and readers see a `&[u8]` in place.
#[derive(Debug)]
pub struct SharedBytes;

/// Where [`SharedBytes`] put an octet sequence's bytes, and how many there are (which,
/// for bytes already in place, is not the length of the placeholder being archived).
pub struct SharedBytesResolver {
    at: VecResolver,
    len: usize,
}

impl std::fmt::Debug for SharedBytesResolver {
    // rkyv's `VecResolver` has no `Debug`; its position is not readable either.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SharedBytesResolver").field("len", &self.len).finish_non_exhaustive()
    }
}

/// A writer's say in where octet-sequence bytes come from (see the module docs).
///
/// Implemented for every writer the codec serializes with; code outside the codec has
/// no reason to implement it.
pub trait PlaceOctets<E> {
    /// Called when an *empty* octet sequence is serialized. `Ok(Some((pos, len)))`
    /// archives it as the `len` bytes already at archive position `pos` instead;
    /// `Ok(None)` archives it as the empty sequence it is.
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E>;
}

impl<T: PlaceOctets<E> + ?Sized, E> PlaceOctets<E> for &mut T {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        T::octets_in_place(self)
    }
}

/// Relative pointers in the archive are 32-bit (rkyv's default), so no archive
/// position may exceed this; rkyv would panic on the overflow instead of failing.
pub(crate) const MAX_ARCHIVE_LEN: usize = i32::MAX as usize;

/// An archive would be larger than [`MAX_ARCHIVE_LEN`].
#[derive(Debug, thiserror::Error)]
#[error("archive would exceed {MAX_ARCHIVE_LEN} bytes (32-bit relative pointers)")]
pub(crate) struct ArchiveTooLarge;

impl ArchiveWith<OctetBytes> for SharedBytes {
    type Archived = ArchivedVec<u8>;
    type Resolver = SharedBytesResolver;

    fn resolve_with(_: &OctetBytes, resolver: Self::Resolver, out: Place<Self::Archived>) {
        ArchivedVec::resolve_from_len(resolver.len, resolver.at, out);
    }
}

impl<S> SerializeWith<OctetBytes, S> for SharedBytes
where
    S: Fallible + Allocator + Writer + PlaceOctets<S::Error> + ?Sized,
    S::Error: Source,
{
    fn serialize_with(
        field: &OctetBytes,
        serializer: &mut S,
    ) -> Result<SharedBytesResolver, S::Error> {
        let field = field.as_slice();
        if field.is_empty() {
            if let Some((pos, len)) = serializer.octets_in_place()? {
                return Ok(SharedBytesResolver { at: VecResolver::from_pos(pos), len });
            }
        }
        // Checked here because octets are what makes an archive big; the resolver
        // below would panic on a relative pointer that does not fit.
        if serializer.pos().saturating_add(field.len()) > MAX_ARCHIVE_LEN {
            return Err(S::Error::new(ArchiveTooLarge));
        }
        let at = ArchivedVec::<u8>::serialize_from_slice(field, serializer)?;
        Ok(SharedBytesResolver { at, len: field.len() })
    }
}

/// A deserializer's say in where decoded octet sequences live: keep them where they
/// lie in the archive's buffer (which it must be able to keep alive), or copy them.
///
/// rkyv's own [`Pool`] copies; [`crate::codec::decode_holding`]'s deserializer holds.
pub trait HoldOctets {
    /// `Some` to keep `bytes` (a slice of the archive being decoded) where they are;
    /// `None` to copy them onto the heap.
    fn hold(&mut self, bytes: &[u8]) -> Option<Octets>;
}

impl HoldOctets for Pool {
    fn hold(&mut self, _: &[u8]) -> Option<Octets> {
        None
    }
}

impl<T: HoldOctets, E> HoldOctets for Strategy<T, E> {
    fn hold(&mut self, bytes: &[u8]) -> Option<Octets> {
        T::hold(self, bytes)
    }
}

impl<D: Fallible + HoldOctets + ?Sized> DeserializeWith<ArchivedVec<u8>, OctetBytes, D>
    for SharedBytes
{
    fn deserialize_with(field: &ArchivedVec<u8>, d: &mut D) -> Result<OctetBytes, D::Error> {
        Ok(match d.hold(field.as_slice()) {
            Some(held) => held.0,
            None => OctetBytes::Heap(field.as_slice().into()),
        })
    }
}
