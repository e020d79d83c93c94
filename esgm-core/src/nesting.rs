//! A bound on how deeply archived values may nest, enforced while validating.
//!
//! Values nest (aggregates, frames, frame sequences), and rkyv validates nested values
//! recursively: a peer could send a structure nested hundreds of thousands deep and
//! overflow the reader's stack during validation, an abort no error handling can
//! catch. Every recursive field of [`crate::Value`] is archived through [`Nest`], whose
//! check counts the depth in the validation context and refuses more than
//! [`MAX_NESTING`] levels with a typed error instead.

use core::ops::{Deref, Range};

use rkyv::bytecheck::CheckBytes;
use rkyv::rancor::{Fallible, Source, Strategy};
use rkyv::validation::ArchiveContext;
use rkyv::validation::archive::ArchiveValidator;
use rkyv::with::{ArchiveWith, DeserializeWith, SerializeWith};
use rkyv::{Archive, Deserialize, Place, Portable, Serialize};

/// How many levels of nested values (frames in frames, aggregates in aggregates) a
/// structure may have. Robot data rarely goes past three.
pub const MAX_NESTING: usize = 64;

/// A validation context that counts nesting depth.
pub trait NestingContext<E = <Self as Fallible>::Error> {
    /// Enters one nesting level; fails past [`MAX_NESTING`].
    fn enter_nesting(&mut self) -> Result<(), E>;
    /// Leaves a level entered with [`NestingContext::enter_nesting`].
    fn leave_nesting(&mut self);
}

impl<T: NestingContext<E> + ?Sized, E> NestingContext<E> for Strategy<T, E> {
    fn enter_nesting(&mut self) -> Result<(), E> {
        T::enter_nesting(self)
    }
    fn leave_nesting(&mut self) {
        T::leave_nesting(self)
    }
}

/// The archived values nest more than [`MAX_NESTING`] levels deep.
#[derive(Debug)]
struct TooDeep;

impl core::fmt::Display for TooDeep {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "values nest more than {MAX_NESTING} levels deep")
    }
}

impl std::error::Error for TooDeep {}

/// The codec's validator: rkyv's archive checks plus the depth bound. (Entity
/// structures hold no shared pointers, so no shared-pointer validation is needed.)
#[derive(Debug)]
pub(crate) struct Validator<'a> {
    archive: ArchiveValidator<'a>,
    depth: usize,
}

impl<'a> Validator<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Self { archive: ArchiveValidator::new(bytes), depth: 0 }
    }
}

// SAFETY: every check is delegated unchanged to rkyv's own archive validator.
unsafe impl<E: Source> ArchiveContext<E> for Validator<'_> {
    fn check_subtree_ptr(&mut self, ptr: *const u8, layout: &core::alloc::Layout) -> Result<(), E> {
        self.archive.check_subtree_ptr(ptr, layout)
    }

    unsafe fn push_subtree_range(
        &mut self,
        root: *const u8,
        end: *const u8,
    ) -> Result<Range<usize>, E> {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { self.archive.push_subtree_range(root, end) }
    }

    unsafe fn pop_subtree_range(&mut self, range: Range<usize>) -> Result<(), E> {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { self.archive.pop_subtree_range(range) }
    }
}

impl<E: Source> NestingContext<E> for Validator<'_> {
    fn enter_nesting(&mut self) -> Result<(), E> {
        if self.depth >= MAX_NESTING {
            return Err(E::new(TooDeep));
        }
        self.depth += 1;
        Ok(())
    }

    fn leave_nesting(&mut self) {
        self.depth = self.depth.saturating_sub(1);
    }
}

/// Archives a recursive field as itself inside an [`ArchivedNest`], whose validation
/// counts one nesting level.
#[derive(Debug)]
pub struct Nest;

/// A nested value in the archive: the field's own archived form, read through `Deref`.
#[derive(Debug, Portable)]
#[rkyv(crate = rkyv)]
#[repr(transparent)]
pub struct ArchivedNest<T>(T);

impl<T> Deref for ArchivedNest<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0
    }
}

// SAFETY: `ArchivedNest<T>` is a transparent wrapper: valid exactly when the `T` it
// wraps is, which `T::check_bytes` decides; the depth bound only adds a refusal.
unsafe impl<T, C> CheckBytes<C> for ArchivedNest<T>
where
    T: CheckBytes<C>,
    C: Fallible + NestingContext + ?Sized,
    C::Error: Source,
{
    unsafe fn check_bytes(value: *const Self, context: &mut C) -> Result<(), C::Error> {
        context.enter_nesting()?;
        // SAFETY: `value` points to a `Self`, and `Self` is `T` (repr(transparent)).
        let result = unsafe { T::check_bytes(value.cast::<T>(), context) };
        context.leave_nesting();
        result
    }
}

impl<F: Archive> ArchiveWith<F> for Nest {
    type Archived = ArchivedNest<F::Archived>;
    type Resolver = F::Resolver;

    fn resolve_with(field: &F, resolver: Self::Resolver, out: Place<Self::Archived>) {
        // SAFETY: `ArchivedNest<F::Archived>` is repr(transparent) over `F::Archived`.
        field.resolve(resolver, unsafe { out.cast_unchecked::<F::Archived>() });
    }
}

impl<F: Serialize<S>, S: Fallible + ?Sized> SerializeWith<F, S> for Nest {
    fn serialize_with(field: &F, serializer: &mut S) -> Result<F::Resolver, S::Error> {
        field.serialize(serializer)
    }
}

impl<F, T, D> DeserializeWith<ArchivedNest<T>, F, D> for Nest
where
    T: Deserialize<F, D>,
    D: Fallible + ?Sized,
{
    fn deserialize_with(field: &ArchivedNest<T>, deserializer: &mut D) -> Result<F, D::Error> {
        field.0.deserialize(deserializer)
    }
}

#[cfg(test)]
mod tests {
    use super::MAX_NESTING;
    use crate::codec::{CodecError, access, decode, encode};
    use crate::value::Value;
    use crate::value::frame::{EntityFrame, EntityStructure};

    /// A structure whose one attribute nests `depth` levels (aggregates and frames
    /// alternating).
    fn nested(depth: usize) -> EntityStructure {
        let mut v = Value::Long(7);
        for level in 0..depth {
            v = if level % 2 == 0 {
                Value::Agg(vec![v])
            } else {
                Value::from(EntityFrame::new("f").with("inner", v))
            };
        }
        EntityStructure::new("deep", 1, 2).with("v", v)
    }

    #[test]
    fn nesting_up_to_the_bound_round_trips() {
        let es = nested(MAX_NESTING);
        let bytes = encode(&es).unwrap();
        assert_eq!(decode(access(&bytes).unwrap()).unwrap(), es);
    }

    #[test]
    fn deeper_nesting_is_refused_with_a_typed_error() {
        let bytes = encode(&nested(MAX_NESTING + 1)).unwrap();
        let err = access(&bytes).unwrap_err();
        assert!(matches!(err, CodecError::Malformed { .. }), "{err}");
        assert!(err.to_string().contains("nest more than 64 levels"), "{err}");
    }

    #[test]
    fn a_hostile_depth_cannot_overflow_a_small_reader_stack() {
        // Build, encode and drop the 100,000-deep value on a thread with room for its
        // recursion (our own encoder and destructor recurse; a peer's would too).
        let bytes = std::thread::Builder::new()
            .stack_size(1 << 30)
            .spawn(|| encode(&nested(100_000)).unwrap())
            .unwrap()
            .join()
            .unwrap();
        // Validate it where a reader would, on a small stack: refused, not a crash.
        let err = std::thread::Builder::new()
            .stack_size(256 * 1024)
            .spawn(move || access(&bytes).map(|_| ()).unwrap_err().to_string())
            .unwrap()
            .join()
            .unwrap();
        assert!(err.contains("nest more than"), "{err}");
    }
}
