//! The writers the codec serializes with, and their answer to [`PlaceOctets`]: every
//! one of these archives octet sequences as they are (only the image writer in
//! [`super::image`] places them).

use rkyv::rancor::Strategy;
use rkyv::ser::writer::Buffer;
use rkyv::ser::{Positional, Serializer, Writer};
use rkyv::util::AlignedVec;

use crate::octets::archive::PlaceOctets;

/// A writer that only counts: serializing through it measures an archive without
/// allocating or copying a byte (octet sequences are counted, not read).
#[derive(Debug, Default)]
pub(crate) struct CountingWriter {
    len: usize,
}

impl CountingWriter {
    /// Bytes written so far.
    pub(crate) fn len(&self) -> usize {
        self.len
    }
}

impl Positional for CountingWriter {
    fn pos(&self) -> usize {
        self.len
    }
}

impl<E> Writer<E> for CountingWriter {
    fn write(&mut self, bytes: &[u8]) -> Result<(), E> {
        self.len += bytes.len();
        Ok(())
    }
}

impl<E> PlaceOctets<E> for CountingWriter {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        Ok(None)
    }
}

impl<E, const A: usize> PlaceOctets<E> for AlignedVec<A> {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        Ok(None)
    }
}

impl<E> PlaceOctets<E> for Buffer<'_> {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        Ok(None)
    }
}

/// rkyv hands field wrappers its serializer, not the writer: forward to the writer.
impl<W: PlaceOctets<E>, A, H, E> PlaceOctets<E> for Strategy<Serializer<W, A, H>, E> {
    fn octets_in_place(&mut self) -> Result<Option<(usize, usize)>, E> {
        self.writer.octets_in_place()
    }
}
