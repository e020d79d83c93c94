//! Images written by their producer straight into the shared memory of the trajectory
//! they are added to, through the ordinary add — so a camera behind `connect` writes
//! each frame once, where every reader in every process reads it.
//!
//! An exported trajectory of images gives its producers a [`LoanAllocator`] (its
//! store's [`esgm_core::OctetsAllocator`]): a buffer is a loan from the trajectory's
//! publisher ([`crate::data_plane::image_loan`]), and the finished pixels become an
//! [`Octets`] held by a [`LoanHolder`] that owns the loan. The structure made with
//! them goes through the writer's gate like any other. When it enters the stream, the
//! export's tap finds the loan in its `image_data`, has the codec complete the
//! archive around the pixels and sends the loan — no encode of the pixels, no copy.
//! The writer's own store then keeps the structure as its own self-subscriber
//! received it: the pixels are read through a received sample, which keeps the chunk
//! borrowed for as long as a value in this process reads it (as in every reader, see
//! [`crate::client::holdings`]); the loan's holder reads the same received bytes from then on.
//!
//! A kept trajectory (a primitive one, whose history outlives its writer) lends its
//! kept history's memory instead ([`crate::data_plane::kept::KeptImage`]): the image
//! is completed there, kept where it was written, and read there by every reader; the
//! writer's store reads it through its own hold of the file. Written once either way.
//!
//! A structure whose shape is not an image the layout can complete (other
//! attributes, sizes that differ from the loan's), or whose pixels were already sent,
//! is encoded the ordinary way: its pixels are copied once, never lost.

use std::any::Any;
use std::sync::{Arc, OnceLock, Weak};

use esgm_core::value::{OctetsHolder, Value};
use esgm_core::{EntityStructure, Octets, OctetsAllocator, PixelBuffer, PixelStorage};
use parking_lot::Mutex;

use crate::data_plane::image_loan::ImageChunk;
use crate::data_plane::kept::KeptImage;

/// The memory an image is written into: a loan of the trajectory's publisher, or of
/// its kept history.
#[derive(Debug)]
pub(crate) enum Chunk {
    /// The publisher's: sent in place.
    Shm(ImageChunk),
    /// The kept history's: kept where it was written.
    Kept(KeptImage),
}

impl Chunk {
    /// Width, height and format the loan was made for.
    pub fn size(&self) -> (i64, i64, i64) {
        match self {
            Chunk::Shm(c) => c.size(),
            Chunk::Kept(k) => k.size(),
        }
    }

    fn pixels_mut(&mut self) -> &mut [u8] {
        match self {
            Chunk::Shm(c) => c.pixels_mut(),
            Chunk::Kept(k) => k.pixels_mut(),
        }
    }

    /// What keeps the loan's memory mapped after the loan itself is gone: a kept
    /// history's file, which the writer unmaps when it moves to a new one. A
    /// publisher's segment stays mapped while its publisher lives, which outlives the
    /// loan's holder's reads (see [`LoanHolder::rescue`]).
    fn mapping(&self) -> Option<Arc<dyn Any + Send + Sync>> {
        match self {
            Chunk::Shm(_) => None,
            Chunk::Kept(k) => Some(k.mapping()),
        }
    }
}

/// The attributes of an image the layout completes around its pixels.
const IMAGE_ATTRIBUTES: [&str; 4] = ["width", "height", "format", "image_data"];

/// Hands out loans of one exported trajectory's publisher as image buffers.
#[derive(Debug)]
pub(crate) struct LoanAllocator<T: Send + 'static> {
    /// The export's outlet (gone when the export is).
    outlet: Weak<Mutex<T>>,
    /// Loans the outlet's memory: `(outlet, width, height, format)`.
    loan: fn(&mut T, i64, i64, i64) -> Option<Chunk>,
}

impl<T: Send + 'static> LoanAllocator<T> {
    pub fn new(outlet: &Arc<Mutex<T>>, loan: fn(&mut T, i64, i64, i64) -> Option<Chunk>) -> Self {
        Self { outlet: Arc::downgrade(outlet), loan }
    }
}

impl<T: Send + std::fmt::Debug + 'static> OctetsAllocator for LoanAllocator<T> {
    fn image(&self, width: i64, height: i64, format: i64) -> Option<PixelBuffer> {
        let outlet = self.outlet.upgrade()?;
        let chunk = (self.loan)(&mut outlet.lock(), width, height, format)?;
        let owner = Arc::as_ptr(&outlet) as *const () as usize;
        Some(PixelBuffer::new(Box::new(LoanStorage { chunk, owner })))
    }
}

/// A buffer being written: the loan itself.
struct LoanStorage {
    chunk: Chunk,
    owner: usize,
}

impl PixelStorage for LoanStorage {
    fn pixels_mut(&mut self) -> &mut [u8] {
        self.chunk.pixels_mut()
    }

    fn freeze(mut self: Box<Self>) -> Octets {
        let pixels = self.chunk.pixels_mut();
        let (ptr, len) = (pixels.as_ptr(), pixels.len());
        let holder = LoanHolder {
            ptr,
            len,
            _mapping: self.chunk.mapping(),
            chunk: Mutex::new(Some(self.chunk)),
            sent: OnceLock::new(),
            owner: self.owner,
        };
        // The range is the holder's whole length: never out of range.
        Octets::held(Arc::new(holder), 0..len).unwrap_or_default()
    }
}

/// Finished pixels in a loan not sent yet; once sent, the same pixels as this
/// process received them (see the module docs).
pub(crate) struct LoanHolder {
    ptr: *const u8,
    len: usize,
    /// Keeps `ptr` mapped for the holder's life (a kept history's file).
    _mapping: Option<Arc<dyn Any + Send + Sync>>,
    chunk: Mutex<Option<Chunk>>,
    sent: OnceLock<Octets>,
    /// The outlet whose publisher lent the chunk.
    owner: usize,
}

// SAFETY: `ptr..ptr+len` are the pixels of the loaned chunk this holder owns (mapped
// and written by nobody once frozen) until it is sent; from then on `bytes` reads the
// received copy in `sent` instead, which owns its own sample. A chunk taken and not
// sent is rescued (copied into `sent`) before its memory can be lent again; a kept
// history's file stays mapped while the holder lives (`_mapping`). The chunk itself
// sits behind a lock and is iceoryx2's thread-safe variant.
unsafe impl Send for LoanHolder {}
// SAFETY: as above; `&LoanHolder` gives only shared reads of the pixels.
unsafe impl Sync for LoanHolder {}

impl OctetsHolder for LoanHolder {
    fn bytes(&self) -> &[u8] {
        if let Some(sent) = self.sent.get() {
            return sent;
        }
        // SAFETY: see the `Send` impl. The chunk is taken only to be sent, and `sent` is
        // set right after, while the structure is in the hands of the writer's store
        // (under its lock): no reader is between the two.
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    fn as_any(&self) -> Option<&dyn Any> {
        Some(self)
    }
}

impl LoanHolder {
    /// The loan, if not taken yet, to send.
    pub fn take(&self) -> Option<Chunk> {
        self.chunk.lock().take()
    }

    /// The pixels as sent and received: what this holder reads from now on.
    pub fn sent(&self, pixels: Octets) {
        if pixels.len() == self.len && self.sent.set(pixels).is_err() {
            tracing::debug!("a loan's pixels were sent twice");
        }
    }

    /// The pixels of a loan taken and not sent (a structure that did not match its
    /// loan, a failed send or keep): copied onto the heap, read from there from now on.
    /// Called while the writer's outlet is locked, so that no new loan has written
    /// over the chunk's memory yet; a holder already sent keeps what it reads.
    pub fn rescue(&self) {
        if self.sent.get().is_some() {
            return;
        }
        let copy = Octets::from(self.bytes().to_vec());
        if self.sent.set(copy).is_err() {
            tracing::debug!("a loan's pixels were sent while being rescued");
        }
    }
}

/// The loan in `es`'s pixels, if `es` is an image the layout can complete around them
/// and the loan is `owner`'s; otherwise `None` (it is encoded, see the module docs).
pub(crate) fn loaned_image(es: &EntityStructure, owner: usize) -> Option<Arc<dyn OctetsHolder>> {
    if es.attributes.len() != IMAGE_ATTRIBUTES.len()
        || !IMAGE_ATTRIBUTES.iter().all(|a| es.get(a).is_some())
    {
        return None;
    }
    let Some(Value::OctetSeq(pixels)) = es.get("image_data") else { return None };
    let holder = pixels.holder()?;
    let loan = holder.as_any()?.downcast_ref::<LoanHolder>()?;
    (loan.owner == owner && pixels.len() == loan.len).then(|| Arc::clone(holder))
}

/// `holder` as the loan holder [`loaned_image`] found in it.
pub(crate) fn as_loan(holder: &Arc<dyn OctetsHolder>) -> Option<&LoanHolder> {
    holder.as_any()?.downcast_ref::<LoanHolder>()
}
