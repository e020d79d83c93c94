//! Writing an image's pixels straight into shared memory.
//!
//! A camera asks its publisher for an [`ImageLoan`], fills [`ImageLoan::pixels_mut`]
//! (or the uninitialised view, see below) with the frame, and calls
//! [`ImageLoan::send`] with the entity's name and times. The pixels sit at a fixed
//! offset of the loan ([`crate::data_plane::image_layout`]); sending has the codec complete an
//! ordinary `Image` entity structure around them
//! ([`esgm_core::codec::encode_image_into`]: a few hundred bytes of envelope, names,
//! attributes and root) and sends. The pixels are written once, by the camera, where
//! every reader — subscribers, workers, a cache — reads them, whatever name each frame
//! is sent under.
//!
//! # Initialisation
//! Rust may only hand out `&mut [u8]` over initialised memory, and a loan is not.
//! [`ImageLoan::pixels_mut`] therefore zeroes the pixel range on first use (one memset
//! of the frame). A camera that writes every pixel anyway can skip it: copy a finished
//! frame in with [`ImageLoan::write_pixels`], or write through
//! [`ImageLoan::pixels_uninit_mut`] and then promise with the unsafe
//! [`ImageLoan::assume_pixels_init`]. If neither happened, [`ImageLoan::send`] zeroes
//! the pixels, so a loan can never publish uninitialised memory. The bytes around the
//! pixels are zeroed at send, before the codec writes the archive over them, so the
//! slack after the archive never carries an earlier sample's bytes.
//!
//! [`ImageLoan::into_structure`] completes the archive without sending: the frame
//! becomes a [`StructureLoan`], sent when the moment comes.
//!
//! Dropping a loan without sending returns the memory to the publisher.
//!
//! # Measured
//! With `examples/wait_strategies.rs` (release, both ends busy-waiting), a 640×480 RGB
//! frame written in place crossed processes in 2.1 µs p50 (one-way, round trip with a
//! small reply / 2) against 2.5 µs for a small structure in the same run: the hop does
//! not depend on the image size. The producer's own loan + zeroing + writing of the
//! frame took 48 µs p50 — two passes over 921,600 bytes, one of which
//! `pixels_uninit_mut` avoids. (Measured with the earlier template layout; sending
//! now encodes the few hundred bytes around the pixels instead of copying a template.)

use crate::data_plane::service::ShmService;
use std::mem::MaybeUninit;
use std::ops::Range;

use esgm_core::codec;
use esgm_core::library::Image;
use esgm_core::{Entity, Octets, Time};
use iceoryx2::sample_mut_uninit::SampleMutUninit;

use crate::data_plane::image_layout::{IMAGE_NAME_MAX, IMAGE_PIXELS_OFFSET, ImageError};
use crate::data_plane::payload::{Block16, SampleHeader, as_uninit_bytes, copy_into, zero_fill};
use crate::data_plane::publisher::{PublishError, Published, TrajectoryPublisher};
use crate::data_plane::structure_loan::StructureLoan;

type UninitSample = SampleMutUninit<ShmService, [MaybeUninit<Block16>], SampleHeader>;

/// Shared memory holding an image under construction; see the module docs.
pub struct ImageLoan<'p> {
    publisher: &'p TrajectoryPublisher,
    chunk: ImageChunk,
}

impl std::fmt::Debug for ImageLoan<'_> {
    // iceoryx2's uninitialised sample has no `Debug`; say what the loan is for.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageLoan")
            .field("trajectory", &self.publisher.trajectory())
            .field("size", &(self.chunk.width, self.chunk.height, self.chunk.format))
            .field("pixel_len", &self.chunk.pixel_len)
            .field("pixels_init", &self.chunk.pixels_init)
            .finish_non_exhaustive()
    }
}

impl<'p> ImageLoan<'p> {
    /// A loan for an image, of the publisher that made `chunk`.
    pub(crate) fn new(publisher: &'p TrajectoryPublisher, chunk: ImageChunk) -> Self {
        Self { publisher, chunk }
    }

    /// Width in pixels.
    pub fn width(&self) -> i64 {
        self.chunk.width
    }

    /// Height in pixels.
    pub fn height(&self) -> i64 {
        self.chunk.height
    }

    /// Pixel format (`Image::FORMAT_*`).
    pub fn format(&self) -> i64 {
        self.chunk.format
    }

    /// Bytes of pixels (width × height × bytes per pixel).
    pub fn pixel_len(&self) -> usize {
        self.chunk.pixel_len
    }

    /// The pixels in shared memory, row-major as the format says. Zeroed on the first
    /// call (see the module docs); write the frame here.
    pub fn pixels_mut(&mut self) -> &mut [u8] {
        self.chunk.pixels_mut()
    }

    /// The pixels as not-yet-initialised memory, for a writer that fills every byte
    /// (e.g. a copy from a driver buffer) and wants to skip the zeroing. Follow with
    /// [`Self::assume_pixels_init`].
    pub fn pixels_uninit_mut(&mut self) -> &mut [MaybeUninit<u8>] {
        self.chunk.pixels_uninit()
    }

    /// Copies a whole frame (exactly [`Self::pixel_len`] bytes, e.g. a driver's or a
    /// decoder's buffer) into the pixels, without zeroing them first.
    pub fn write_pixels(&mut self, frame: &[u8]) -> Result<(), ImageError> {
        self.chunk.write_pixels(frame)
    }

    /// Declares the pixels initialised.
    ///
    /// # Safety
    /// Every byte of [`Self::pixels_uninit_mut`] must have been written (or
    /// [`Self::pixels_mut`] called) since the loan was made.
    pub unsafe fn assume_pixels_init(&mut self) {
        self.chunk.pixels_init = true;
    }

    /// Completes the image as entity `name` with the given times and sends it, the
    /// pixels staying where they were written: [`Self::into_structure`], then
    /// [`StructureLoan::send`].
    ///
    /// Any name of up to [`IMAGE_NAME_MAX`] bytes is sent in place, a different one
    /// every frame if need be. A longer name does not fit the layout: that frame is
    /// copied once into an ordinary structure instead (correct, but not zero-copy).
    pub fn send(
        self,
        name: &str,
        valid_time: Time,
        create_time: Time,
    ) -> Result<Published, PublishError> {
        self.into_structure(name, valid_time, create_time)?.send()
    }

    /// Completes the image as entity `name` with the given times — the codec writes the
    /// archive around the pixels — without sending it yet: a camera that captures ahead
    /// of the moment a frame must go does all of its writing before that moment, then
    /// only sends (after [`StructureLoan::set_times`] if the times are known late).
    ///
    /// Names longer than [`IMAGE_NAME_MAX`] are copied, as for [`Self::send`].
    pub fn into_structure(
        self,
        name: &str,
        valid_time: Time,
        create_time: Time,
    ) -> Result<StructureLoan<'p>, PublishError> {
        self.chunk.complete(self.publisher, name, valid_time, create_time)
    }
}

/// The loaned memory of an image under construction, apart from the publisher that
/// lent it: what a runtime keeps while the pixels are written and the structure goes
/// through its gate, before the publisher completes and sends it
/// ([`ImageChunk::complete`]).
pub(crate) struct ImageChunk {
    sample: UninitSample,
    width: i64,
    height: i64,
    format: i64,
    pixel_len: usize,
    pixels_init: bool,
}

impl std::fmt::Debug for ImageChunk {
    // iceoryx2's loaned sample has no `Debug`; the image's sizes say what it is.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageChunk")
            .field("size", &(self.width, self.height, self.format))
            .field("pixel_len", &self.pixel_len)
            .finish_non_exhaustive()
    }
}

impl ImageChunk {
    /// A loan of at least `image_layout::image_loan_len(pixel_len)` bytes for an image
    /// of these sizes (already checked by the publisher).
    pub(crate) fn new(
        sample: UninitSample,
        (width, height, format): (i64, i64, i64),
        pixel_len: usize,
    ) -> Self {
        Self { sample, width, height, format, pixel_len, pixels_init: false }
    }

    /// Width, height and format.
    pub(crate) fn size(&self) -> (i64, i64, i64) {
        (self.width, self.height, self.format)
    }

    fn pixel_range(&self) -> Range<usize> {
        IMAGE_PIXELS_OFFSET..IMAGE_PIXELS_OFFSET + self.pixel_len
    }

    fn pixels_uninit(&mut self) -> &mut [MaybeUninit<u8>] {
        let range = self.pixel_range();
        let bytes = as_uninit_bytes(self.sample.payload_mut());
        // The publisher loaned room for the whole image; clamp rather than panic anyway.
        let len = bytes.len();
        &mut bytes[range.start.min(len)..range.end.min(len)]
    }

    /// The pixels, zeroed on the first call.
    pub(crate) fn pixels_mut(&mut self) -> &mut [u8] {
        let was_init = self.pixels_init;
        self.pixels_init = true;
        let pixels = self.pixels_uninit();
        if was_init {
            // SAFETY: the range was initialised by an earlier call (zeroed and possibly
            // written since) or promised by `assume_pixels_init`.
            unsafe { &mut *(pixels as *mut [MaybeUninit<u8>] as *mut [u8]) }
        } else {
            zero_fill(pixels)
        }
    }

    fn write_pixels(&mut self, frame: &[u8]) -> Result<(), ImageError> {
        let expected = self.pixel_len;
        if frame.len() != expected || !copy_into(self.pixels_uninit(), frame) {
            return Err(ImageError::FrameLength { expected, found: frame.len() });
        }
        self.pixels_init = true;
        Ok(())
    }

    /// Completes the image as entity `name` with the given times, for `publisher`
    /// (the one that lent the chunk), ready to send.
    pub(crate) fn complete<'p>(
        mut self,
        publisher: &'p TrajectoryPublisher,
        name: &str,
        valid_time: Time,
        create_time: Time,
    ) -> Result<StructureLoan<'p>, PublishError> {
        if !self.pixels_init {
            self.pixels_mut();
        }
        if name.len() > IMAGE_NAME_MAX {
            return self.into_copied(publisher, name, valid_time, create_time);
        }
        let pixels = self.pixel_range();
        let bytes = as_uninit_bytes(self.sample.payload_mut());
        let len = bytes.len();
        // Everything but the pixels is still uninitialised: zero it, so the whole loan
        // is bytes. The codec then writes the archive around the pixels, and what it
        // does not use (the loan's slack) stays zero.
        zero_fill(&mut bytes[..pixels.start.min(len)]);
        zero_fill(&mut bytes[pixels.end.min(len)..]);
        // SAFETY: the pixels were initialised above (zeroed, written, or promised) and
        // every other byte of the payload was just zeroed.
        let mut sample = unsafe { self.sample.assume_init() };
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(sample.payload_mut());
        let archive_len = codec::encode_image_into(
            name,
            valid_time,
            create_time,
            self.width,
            self.height,
            self.format,
            self.pixel_len,
            bytes,
        )
        .map_err(PublishError::Encode)?;
        Ok(StructureLoan::new(
            publisher,
            sample,
            archive_len,
            (valid_time, create_time),
            SampleHeader::FLAG_IMAGE_IN_PLACE,
        ))
    }

    fn into_copied<'p>(
        mut self,
        publisher: &'p TrajectoryPublisher,
        name: &str,
        valid_time: Time,
        create_time: Time,
    ) -> Result<StructureLoan<'p>, PublishError> {
        tracing::debug!(trajectory = %publisher.trajectory(), name_len = name.len(),
            max = IMAGE_NAME_MAX, "image name too long to send in place: copying this frame");
        let pixels = Octets::from(&*self.pixels_mut());
        let image = Image {
            width: self.width,
            height: self.height,
            format: self.format,
            image_data: pixels,
        };
        // Return the loan before loaning again for the copy.
        drop(self);
        publisher.loan_structure(&image.to_structure(name, valid_time, create_time))
    }
}
