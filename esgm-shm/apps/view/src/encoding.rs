//! How a trajectory's structures are shown to Foxglove: the channel's schema and each
//! message's bytes, from esgm-recording's view encoders (one implementation for
//! recordings and live views).

use esgm_core::{EntityStructure, EntityStructureType};
use esgm_recording::view::{self, ViewError, ViewSchema};

/// The encoding of one channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// An image type: `foxglove.RawImage`, protobuf.
    RawImage,
    /// Any other type: JSON with a JSON Schema.
    Json,
}

impl Encoding {
    /// The encoding of structures of `ty`, and the schema its channel announces.
    /// `lookup` resolves the element types of nested frames.
    pub fn of(
        ty: &EntityStructureType,
        lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
    ) -> (Self, ViewSchema) {
        match view::image_view(ty) {
            Some(_) => (Encoding::RawImage, view::raw_image_schema()),
            None => (Encoding::Json, view::json_schema(ty, lookup)),
        }
    }

    /// Appends the message for `es` to `out`; `frame_id` names an image's frame.
    pub fn encode(
        self,
        es: &EntityStructure,
        frame_id: &str,
        out: &mut Vec<u8>,
    ) -> Result<(), ViewError> {
        match self {
            Encoding::RawImage => view::encode_raw_image(es, frame_id, out).map(|_| ()),
            Encoding::Json => view::encode_json(es, out),
        }
    }
}
