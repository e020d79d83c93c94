//! Views: the encodings Foxglove decodes, written beside esgm's lossless channel.
//!
//! A recording keeps every structure losslessly in esgm's own channel; a *view* is a
//! second rendering of the same structure that a general tool can show without knowing
//! esgm. Two views exist:
//!
//! - [`raw_image`]: structures of an image type (width, height, format, pixels) as
//!   Foxglove's well-known `foxglove.RawImage`, in protobuf. The pixels are stored once,
//!   in that message: [`raw_image::encode_raw_image`] and
//!   [`raw_image::decode_raw_image`] give the pixels' byte range, so the lossless
//!   channel can cut them out and splice them back.
//! - [`json`]: any structure as JSON with a JSON Schema, so its numeric attributes can
//!   be plotted.
//!
//! Each view says what goes into the MCAP schema record through a [`ViewSchema`].
//!
//! ## Design decisions
//! - **The RawImage message is encoded by hand**: it has seven fields, and writing it
//!   directly lets the encoder report where the pixels landed and the decoder borrow
//!   them in place. Only the schema (a `FileDescriptorSet`) is built with `prost-types`,
//!   so its descriptor is exactly what `protoc` would describe.
//! - **Octets never go into JSON**: an image in JSON would be a megabyte of numbers per
//!   frame; the JSON view gives an octet sequence's length instead.

use esgm_core::ValueSort;

pub mod json;
pub mod raw_image;
mod wire;

pub use json::{encode_json, json_schema};
pub use raw_image::{
    ImageAttrs, RAW_IMAGE_SCHEMA_NAME, RawImageRef, decode_raw_image, encode_raw_image, image_view,
    raw_image_schema,
};

/// What an MCAP schema record of a view holds, and the message encoding of the channels
/// that use it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViewSchema {
    /// The schema's name (`foxglove.RawImage`, or the entity structure type's name).
    pub name: String,
    /// The MCAP schema encoding (`protobuf`, `jsonschema`).
    pub encoding: &'static str,
    /// The MCAP message encoding of channels using this schema (`protobuf`, `json`).
    pub message_encoding: &'static str,
    /// The schema record's data (a serialized `FileDescriptorSet`, or JSON Schema text).
    pub data: Vec<u8>,
}

/// Why a structure could not be rendered as a view.
///
/// Every variant means the structure does not have the shape its type promised; check
/// it against its type (a type-checked trajectory never produces one) or record it in
/// the lossless channel only.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ViewError {
    /// The structure lacks an attribute the view needs.
    #[error("attribute `{attribute}` is missing")]
    MissingAttribute {
        /// The attribute.
        attribute: &'static str,
    },
    /// An attribute has a different sort than the view needs.
    #[error("attribute `{attribute}` is {found}, expected {expected}")]
    WrongSort {
        /// The attribute.
        attribute: &'static str,
        /// The sort the view needs.
        expected: ValueSort,
        /// The sort found.
        found: ValueSort,
    },
    /// An image dimension is negative or too large for the view's 32-bit field.
    #[error("attribute `{attribute}` is {value}, outside 0..=4294967295")]
    DimensionOutOfRange {
        /// `width`, `height` or the row length `step`.
        attribute: &'static str,
        /// The value found.
        value: i64,
    },
    /// The image's `format` is not one the view knows (see
    /// [`esgm_core::library::Image`]'s `FORMAT_*` constants).
    #[error("image format {format} is unknown")]
    UnknownFormat {
        /// The format found.
        format: i64,
    },
    /// The pixel bytes are not width × height × bytes per pixel.
    #[error(
        "image_data has {found} bytes, expected {width}×{height}×{bytes_per_pixel} = {expected}"
    )]
    PixelCount {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Bytes a pixel of the image's format.
        bytes_per_pixel: usize,
        /// Width × height × bytes per pixel (saturating).
        expected: u64,
        /// The bytes found.
        found: usize,
    },
    /// The JSON serializer failed. Writing into a `Vec` with string keys cannot fail,
    /// so this is a bug in the view: report it.
    #[error("JSON encoding failed: {0}")]
    Json(#[from] serde_json::Error),
}

/// Why view bytes could not be decoded. Each variant names the byte offset in the
/// message where decoding stopped; the message is damaged or not of the view's schema.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The message ends inside a field.
    #[error("message truncated at byte {offset}: {needed} more bytes needed")]
    Truncated {
        /// Where the incomplete item starts.
        offset: usize,
        /// Bytes missing past the end.
        needed: usize,
    },
    /// A varint runs longer than 10 bytes.
    #[error("varint at byte {offset} is longer than 10 bytes")]
    VarintTooLong {
        /// Where the varint starts.
        offset: usize,
    },
    /// A field uses a wire type protobuf does not define, or a deprecated group.
    #[error("field {field} at byte {offset} has unsupported wire type {wire_type}")]
    UnsupportedWireType {
        /// The field number.
        field: u64,
        /// The wire type found.
        wire_type: u8,
        /// Where the field's tag starts.
        offset: usize,
    },
    /// A known field is encoded with a wire type other than its schema's.
    #[error("field {field} at byte {offset} has wire type {found}, expected {expected}")]
    WrongWireType {
        /// The field number.
        field: u64,
        /// The wire type the schema gives it.
        expected: u8,
        /// The wire type found.
        found: u8,
        /// Where the field's tag starts.
        offset: usize,
    },
    /// Field number 0, which protobuf forbids.
    #[error("field number 0 at byte {offset}")]
    FieldZero {
        /// Where the tag starts.
        offset: usize,
    },
    /// A string field is not UTF-8.
    #[error("string field {field} at byte {offset} is not UTF-8")]
    InvalidUtf8 {
        /// The field number.
        field: u64,
        /// Where the string's bytes start.
        offset: usize,
    },
}
