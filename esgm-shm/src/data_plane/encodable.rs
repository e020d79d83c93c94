//! A structure on its way into shared memory: owned, to be encoded, or archived
//! already (it came from another process, a file or the network), whose codec bytes
//! are copied as they are — an archive's pointers are relative, so its bytes are valid
//! wherever they are put — and never decoded and encoded again.

use std::mem::MaybeUninit;

use esgm_core::codec::{self, CodecError};
use esgm_core::{EntityStructure, SharedStructure, StructureForm, Time};

use crate::data_plane::payload::copy_into;
use crate::data_plane::size_hint::archived_size_hint;

/// A structure to write into shared memory (see the module docs).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Encodable<'a> {
    /// Encoded by the codec.
    Owned(&'a EntityStructure),
    /// Copied: the codec bytes (envelope and archive) and the structure's two times.
    Archived { bytes: &'a [u8], valid_time: Time, create_time: Time },
}

impl<'a> From<&'a EntityStructure> for Encodable<'a> {
    fn from(es: &'a EntityStructure) -> Self {
        Encodable::Owned(es)
    }
}

impl<'a> From<&'a SharedStructure> for Encodable<'a> {
    fn from(s: &'a SharedStructure) -> Self {
        match s.form() {
            StructureForm::Owned(es) => Encodable::Owned(es),
            StructureForm::Archived { bytes, .. } => Encodable::Archived {
                bytes,
                valid_time: s.valid_time(),
                create_time: s.create_time(),
            },
        }
    }
}

impl Encodable<'_> {
    /// The structure's valid and create times.
    pub fn times(&self) -> (Time, Time) {
        match self {
            Encodable::Owned(es) => (es.valid_time, es.create_time),
            Encodable::Archived { valid_time, create_time, .. } => (*valid_time, *create_time),
        }
    }

    /// Bytes to loan for it: a bound for an owned one (see `size_hint`), the exact
    /// length of an archived one.
    pub fn size_hint(&self) -> usize {
        match self {
            Encodable::Owned(es) => archived_size_hint(es),
            Encodable::Archived { bytes, .. } => bytes.len(),
        }
    }

    /// The exact number of bytes it takes.
    pub fn encoded_len(&self) -> Result<usize, CodecError> {
        match self {
            Encodable::Owned(es) => codec::encoded_len(es),
            Encodable::Archived { bytes, .. } => Ok(bytes.len()),
        }
    }

    /// Writes it at the start of `out` and returns its length; on
    /// [`CodecError::BufferTooSmall`] retry with the length it names.
    pub fn write_into_uninit(&self, out: &mut [MaybeUninit<u8>]) -> Result<usize, CodecError> {
        match self {
            Encodable::Owned(es) => codec::encode_into_uninit(es, out),
            Encodable::Archived { bytes, .. } => match copy_into(out, bytes) {
                true => Ok(bytes.len()),
                false => {
                    Err(CodecError::BufferTooSmall { available: out.len(), needed: bytes.len() })
                }
            },
        }
    }

    /// [`Self::write_into_uninit`] for initialised memory.
    pub fn write_into(&self, out: &mut [u8]) -> Result<usize, CodecError> {
        match self {
            Encodable::Owned(es) => codec::encode_into(es, out),
            Encodable::Archived { bytes, .. } => match out.get_mut(..bytes.len()) {
                Some(to) => {
                    to.copy_from_slice(bytes);
                    Ok(bytes.len())
                }
                None => {
                    Err(CodecError::BufferTooSmall { available: out.len(), needed: bytes.len() })
                }
            },
        }
    }
}
