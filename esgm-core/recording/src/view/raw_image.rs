//! Image structures as Foxglove's well-known `foxglove.RawImage`, in protobuf.
//!
//! The schema is Foxglove's published `foxglove/RawImage.proto` (proto3, package
//! `foxglove`):
//!
//! | field | number | type |
//! |---|---|---|
//! | `timestamp` | 1 | `google.protobuf.Timestamp` |
//! | `width` | 2 | `fixed32` |
//! | `height` | 3 | `fixed32` |
//! | `encoding` | 4 | `string` |
//! | `step` | 5 | `fixed32` |
//! | `data` | 6 | `bytes` |
//! | `frame_id` | 7 | `string` |
//!
//! The schema record holds a serialized `google.protobuf.FileDescriptorSet` with that
//! file and its dependency `google/protobuf/timestamp.proto`, which is what Foxglove and
//! the `mcap` tools decode protobuf channels with.

use std::ops::Range;

use esgm_core::library::Image;
use esgm_core::{EntityStructure, EntityStructureType, Time, Value, ValueSort};
use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};

use super::wire::{self, FieldReader, Payload};
use super::{DecodeError, ViewError, ViewSchema};

/// The schema name of Foxglove's raw image, as MCAP schema records and Foxglove name it.
pub const RAW_IMAGE_SCHEMA_NAME: &str = "foxglove.RawImage";

/// The MCAP schema and message encoding of the view: protobuf.
const PROTOBUF: &str = "protobuf";

const NANOS_PER_SECOND: i64 = 1_000_000_000;

// Field numbers of foxglove.RawImage and google.protobuf.Timestamp.
const F_TIMESTAMP: u32 = 1;
const F_WIDTH: u32 = 2;
const F_HEIGHT: u32 = 3;
const F_ENCODING: u32 = 4;
const F_STEP: u32 = 5;
const F_DATA: u32 = 6;
const F_FRAME_ID: u32 = 7;
const F_SECONDS: u32 = 1;
const F_NANOS: u32 = 2;

/// The MCAP schema of the view: `foxglove.RawImage` as a protobuf `FileDescriptorSet`.
pub fn raw_image_schema() -> ViewSchema {
    ViewSchema {
        name: RAW_IMAGE_SCHEMA_NAME.to_owned(),
        encoding: PROTOBUF,
        message_encoding: PROTOBUF,
        data: file_descriptor_set().encode_to_vec(),
    }
}

fn field(name: &str, json_name: &str, number: u32, ty: Type) -> FieldDescriptorProto {
    FieldDescriptorProto {
        name: Some(name.to_owned()),
        json_name: Some(json_name.to_owned()),
        number: Some(number as i32),
        // proto3 singular fields are LABEL_OPTIONAL in descriptors.
        label: Some(Label::Optional as i32),
        r#type: Some(ty as i32),
        ..Default::default()
    }
}

/// `google/protobuf/timestamp.proto` and `foxglove/RawImage.proto`, dependency first
/// (the order `protoc --include_imports` writes).
fn file_descriptor_set() -> FileDescriptorSet {
    let timestamp = FileDescriptorProto {
        name: Some("google/protobuf/timestamp.proto".to_owned()),
        package: Some("google.protobuf".to_owned()),
        message_type: vec![DescriptorProto {
            name: Some("Timestamp".to_owned()),
            field: vec![
                field("seconds", "seconds", F_SECONDS, Type::Int64),
                field("nanos", "nanos", F_NANOS, Type::Int32),
            ],
            ..Default::default()
        }],
        syntax: Some("proto3".to_owned()),
        ..Default::default()
    };
    let raw_image = FileDescriptorProto {
        name: Some("foxglove/RawImage.proto".to_owned()),
        package: Some("foxglove".to_owned()),
        dependency: vec!["google/protobuf/timestamp.proto".to_owned()],
        message_type: vec![DescriptorProto {
            name: Some("RawImage".to_owned()),
            field: vec![
                FieldDescriptorProto {
                    type_name: Some(".google.protobuf.Timestamp".to_owned()),
                    ..field("timestamp", "timestamp", F_TIMESTAMP, Type::Message)
                },
                field("frame_id", "frameId", F_FRAME_ID, Type::String),
                field("width", "width", F_WIDTH, Type::Fixed32),
                field("height", "height", F_HEIGHT, Type::Fixed32),
                field("encoding", "encoding", F_ENCODING, Type::String),
                field("step", "step", F_STEP, Type::Fixed32),
                field("data", "data", F_DATA, Type::Bytes),
            ],
            ..Default::default()
        }],
        syntax: Some("proto3".to_owned()),
        ..Default::default()
    };
    FileDescriptorSet { file: vec![timestamp, raw_image] }
}

/// Where an image type keeps what a raw image needs: the positions of its attributes in
/// the type's attribute list.
///
/// A type is shown as an image when it has `Long` attributes `width`, `height` and
/// `format` and an `OctetSeq` attribute `image_data`, as
/// [`esgm_core::library::Image`] does; other attributes may sit beside them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageAttrs {
    /// Index of `width` (pixels, `Long`).
    pub width: usize,
    /// Index of `height` (pixels, `Long`).
    pub height: usize,
    /// Index of `format` (`Long`, an `Image::FORMAT_*` constant).
    pub format: usize,
    /// Index of `image_data` (the pixels, `OctetSeq`).
    pub image_data: usize,
}

/// The attributes of `ty` that make it an image, or `None` if it is not one.
pub fn image_view(ty: &EntityStructureType) -> Option<ImageAttrs> {
    let find = |name: &str, sort: ValueSort| {
        ty.attributes.iter().position(|a| a.name == name && a.sort == sort)
    };
    Some(ImageAttrs {
        width: find("width", ValueSort::Long)?,
        height: find("height", ValueSort::Long)?,
        format: find("format", ValueSort::Long)?,
        image_data: find("image_data", ValueSort::OctetSeq)?,
    })
}

/// Foxglove's encoding name and the bytes per pixel of an esgm image format.
fn encoding_of(format: i64) -> Option<(&'static str, usize)> {
    let name = match format {
        Image::FORMAT_RGB8 => "rgb8",
        Image::FORMAT_MONO8 => "mono8",
        _ => return None,
    };
    Some((name, Image::bytes_per_pixel(format)?))
}

fn long(es: &EntityStructure, attribute: &'static str) -> Result<i64, ViewError> {
    match es.get(attribute) {
        None => Err(ViewError::MissingAttribute { attribute }),
        Some(Value::Long(v)) => Ok(*v),
        Some(v) => {
            Err(ViewError::WrongSort { attribute, expected: ValueSort::Long, found: v.sort() })
        }
    }
}

fn dimension(es: &EntityStructure, attribute: &'static str) -> Result<u32, ViewError> {
    let value = long(es, attribute)?;
    u32::try_from(value).map_err(|_| ViewError::DimensionOutOfRange { attribute, value })
}

/// Appends a `foxglove.RawImage` message for the image structure `es` to `out`, and
/// returns the byte range of its pixels (the `data` field's contents) within `out`.
///
/// The timestamp is the structure's valid time; `frame_id` names the image's frame of
/// reference (Foxglove's Image panel shows it; any string will do). The pixels are
/// copied once, into `out`. On error `out` is left as it was.
///
/// ```
/// use esgm_core::{Entity, library::Image};
/// use esgm_recording::view::{decode_raw_image, encode_raw_image};
///
/// let image = Image { width: 2, height: 1, format: Image::FORMAT_MONO8, image_data: vec![7, 9].into() };
/// let mut out = Vec::new();
/// let pixels = encode_raw_image(&image.to_structure("camera", 1_500_000_000, 0), "cam", &mut out)?;
/// assert_eq!(&out[pixels.clone()], &[7, 9]);
/// let decoded = decode_raw_image(&out)?;
/// assert_eq!(decoded.timestamp_ns(), Some(1_500_000_000));
/// assert_eq!((decoded.width, decoded.encoding, decoded.data_range), (2, "mono8", pixels));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn encode_raw_image(
    es: &EntityStructure,
    frame_id: &str,
    out: &mut Vec<u8>,
) -> Result<Range<usize>, ViewError> {
    let width = dimension(es, "width")?;
    let height = dimension(es, "height")?;
    let format = long(es, "format")?;
    let (encoding, bytes_per_pixel) =
        encoding_of(format).ok_or(ViewError::UnknownFormat { format })?;
    let pixels = match es.get("image_data") {
        None => return Err(ViewError::MissingAttribute { attribute: "image_data" }),
        Some(Value::OctetSeq(o)) => &o[..],
        Some(v) => {
            return Err(ViewError::WrongSort {
                attribute: "image_data",
                expected: ValueSort::OctetSeq,
                found: v.sort(),
            });
        }
    };
    let step = u64::from(width) * bytes_per_pixel as u64;
    let expected = step.saturating_mul(u64::from(height));
    if pixels.len() as u64 != expected {
        return Err(ViewError::PixelCount {
            width,
            height,
            bytes_per_pixel,
            expected,
            found: pixels.len(),
        });
    }
    let step = u32::try_from(step).map_err(|_| ViewError::DimensionOutOfRange {
        attribute: "step",
        value: i64::try_from(step).unwrap_or(i64::MAX),
    })?;

    out.reserve(pixels.len() + frame_id.len() + 64);
    put_timestamp(out, es.valid_time);
    wire::put_fixed32(out, F_WIDTH, width);
    wire::put_fixed32(out, F_HEIGHT, height);
    wire::put_len(out, F_ENCODING, encoding.as_bytes());
    wire::put_fixed32(out, F_STEP, step);
    let data = wire::put_len(out, F_DATA, pixels);
    wire::put_len(out, F_FRAME_ID, frame_id.as_bytes());
    Ok(data)
}

/// Appends field 1, a `google.protobuf.Timestamp`: seconds since the epoch, floored,
/// and non-negative nanoseconds, as the Timestamp rules require for times before 1970.
fn put_timestamp(out: &mut Vec<u8>, t: Time) {
    let seconds = t.div_euclid(NANOS_PER_SECOND);
    let nanos = t.rem_euclid(NANOS_PER_SECOND);
    // proto3 omits zero scalars; an int64 is its two's complement as a varint.
    let fields = [(F_SECONDS, seconds as u64), (F_NANOS, nanos as u64)];
    let len: usize =
        fields.iter().filter(|f| f.1 != 0).map(|&(_, v)| 1 + wire::varint_len(v)).sum();
    wire::put_tag(out, F_TIMESTAMP, wire::LEN);
    wire::put_varint(out, len as u64);
    for (number, v) in fields.into_iter().filter(|f| f.1 != 0) {
        wire::put_varint_field(out, number, v);
    }
}

/// A decoded `foxglove.RawImage`, borrowing its strings and pixels from the message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawImageRef<'a> {
    /// Whole seconds of the timestamp since the epoch (negative before 1970).
    pub timestamp_sec: i64,
    /// Nanoseconds past `timestamp_sec` (0..1e9 in a valid Timestamp).
    pub timestamp_nsec: i32,
    /// The frame of reference.
    pub frame_id: &'a str,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Foxglove's pixel encoding (`rgb8`, `mono8`, …).
    pub encoding: &'a str,
    /// Bytes a row.
    pub step: u32,
    /// The pixels.
    pub data: &'a [u8],
    /// Where `data` lies within the decoded message (empty, at the message's end, if
    /// the message has no `data` field).
    pub data_range: Range<usize>,
}

impl RawImageRef<'_> {
    /// The timestamp in nanoseconds since the epoch, as an esgm [`Time`]; `None` if it
    /// does not fit (more than about 292 years from 1970).
    pub fn timestamp_ns(&self) -> Option<Time> {
        // In i128: near i64::MIN the seconds alone overflow, the sum does not.
        let ns = i128::from(self.timestamp_sec) * i128::from(NANOS_PER_SECOND)
            + i128::from(self.timestamp_nsec);
        // Out of range is the only failure, and `None` is documented for it.
        Time::try_from(ns).ok()
    }
}

/// Parses a `foxglove.RawImage` message. Fields may come in any order, a repeated field
/// keeps its last value (a repeated timestamp is merged), and unknown fields are
/// skipped, as protobuf parsers do. Fields absent from the message have their proto3
/// defaults (zero, empty).
pub fn decode_raw_image(bytes: &[u8]) -> Result<RawImageRef<'_>, DecodeError> {
    let mut image = RawImageRef {
        timestamp_sec: 0,
        timestamp_nsec: 0,
        frame_id: "",
        width: 0,
        height: 0,
        encoding: "",
        step: 0,
        data: &[],
        data_range: bytes.len()..bytes.len(),
    };
    let mut fields = FieldReader::new(bytes, 0, bytes.len());
    while let Some(f) = fields.next_field()? {
        let fixed32 = || match f.payload {
            Payload::I32(v) => Ok(v),
            _ => Err(f.wrong_wire_type(wire::I32)),
        };
        let len = || match f.payload {
            Payload::Len(start, end) => Ok(start..end),
            _ => Err(f.wrong_wire_type(wire::LEN)),
        };
        let string = |range: Range<usize>| {
            std::str::from_utf8(&bytes[range.clone()])
                .map_err(|_| DecodeError::InvalidUtf8 { field: f.number, offset: range.start })
        };
        match f.number {
            1 => {
                let range = len()?;
                let mut ts = FieldReader::new(bytes, range.start, range.end);
                while let Some(t) = ts.next_field()? {
                    match (t.number, t.payload) {
                        (1, Payload::Varint(v)) => image.timestamp_sec = v as i64,
                        // int32 travels sign-extended to 64 bits; keep the low 32.
                        (2, Payload::Varint(v)) => image.timestamp_nsec = v as u32 as i32,
                        (1 | 2, _) => return Err(t.wrong_wire_type(wire::VARINT)),
                        _ => {}
                    }
                }
            }
            2 => image.width = fixed32()?,
            3 => image.height = fixed32()?,
            4 => image.encoding = string(len()?)?,
            5 => image.step = fixed32()?,
            6 => {
                let range = len()?;
                image.data = &bytes[range.clone()];
                image.data_range = range;
            }
            7 => image.frame_id = string(len()?)?,
            _ => {}
        }
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use esgm_core::Entity;

    use super::*;

    fn image(width: i64, height: i64, format: i64) -> EntityStructure {
        let bpp = Image::bytes_per_pixel(format).unwrap_or(1) as i64;
        let pixels: Vec<u8> = (0..width * height * bpp).map(|i| i as u8).collect();
        Image { width, height, format, image_data: pixels.into() }.to_structure("cam", 0, 0)
    }

    #[test]
    fn the_library_image_type_is_an_image_and_others_are_not() {
        let attrs = image_view(&Image::entity_structure_type()).unwrap();
        assert_eq!(attrs, ImageAttrs { width: 0, height: 1, format: 2, image_data: 3 });
        let blob = esgm_core::library::Blob::entity_structure_type();
        assert_eq!(image_view(&blob), None);
        let mut wrong = Image::entity_structure_type();
        wrong.attributes[3].sort = ValueSort::LongSeq;
        assert_eq!(image_view(&wrong), None, "image_data must be octets");
    }

    #[test]
    fn an_encoded_image_decodes_to_its_fields_and_pixels() {
        for (format, encoding, bpp) in
            [(Image::FORMAT_RGB8, "rgb8", 3), (Image::FORMAT_MONO8, "mono8", 1)]
        {
            let mut es = image(4, 3, format);
            es.valid_time = 1_700_000_000_123_456_789;
            let mut out = vec![0xee; 5]; // the message is appended, not written at 0
            let range = encode_raw_image(&es, "camera_link", &mut out).unwrap();
            let pixels = es.get("image_data").unwrap().as_octets().unwrap();
            assert_eq!(&out[range.clone()], &pixels[..]);
            let msg = &out[5..];
            let d = decode_raw_image(msg).unwrap();
            assert_eq!((d.width, d.height, d.step), (4, 3, 4 * bpp));
            assert_eq!((d.encoding, d.frame_id), (encoding, "camera_link"));
            assert_eq!((d.timestamp_sec, d.timestamp_nsec), (1_700_000_000, 123_456_789));
            assert_eq!(d.timestamp_ns(), Some(es.valid_time));
            assert_eq!(d.data, &pixels[..]);
            assert_eq!(d.data_range, range.start - 5..range.end - 5);
        }
    }

    #[test]
    fn the_bytes_are_canonical_protobuf() {
        // 1 × 1 mono8 at t = 1.5 s, worked out by hand from the protobuf encoding rules.
        let mut es = image(1, 1, Image::FORMAT_MONO8);
        es.valid_time = 1_500_000_000;
        let mut out = Vec::new();
        let range = encode_raw_image(&es, "f", &mut out).unwrap();
        #[rustfmt::skip]
        let expected: &[u8] = &[
            0x0a, 0x08, 0x08, 0x01, 0x10, 0x80, 0xca, 0xb5, 0xee, 0x01, // timestamp {1 s, 5e8 ns}
            0x15, 1, 0, 0, 0,                                           // width fixed32 1
            0x1d, 1, 0, 0, 0,                                           // height fixed32 1
            0x22, 5, b'm', b'o', b'n', b'o', b'8',                       // encoding
            0x2d, 1, 0, 0, 0,                                           // step fixed32 1
            0x32, 1, 0,                                                 // data
            0x3a, 1, b'f',                                              // frame_id
        ];
        assert_eq!(out, expected);
        assert_eq!(range, 34..35);
    }

    #[test]
    fn times_before_1970_have_floored_seconds_and_positive_nanos() {
        for (t, sec, nsec) in [
            (-1, -1, 999_999_999),
            (-1_000_000_000, -1, 0),
            (-1_500_000_000, -2, 500_000_000),
            (0, 0, 0),
            (i64::MIN, -9_223_372_037, 145_224_192),
            (i64::MAX, 9_223_372_036, 854_775_807),
        ] {
            let mut es = image(1, 1, Image::FORMAT_MONO8);
            es.valid_time = t;
            let mut out = Vec::new();
            encode_raw_image(&es, "", &mut out).unwrap();
            let d = decode_raw_image(&out).unwrap();
            assert_eq!((d.timestamp_sec, d.timestamp_nsec), (sec, nsec), "{t}");
            assert_eq!(d.timestamp_ns(), Some(t));
        }
    }

    #[test]
    fn fields_in_any_order_unknown_fields_and_defaults() {
        let mut msg = Vec::new();
        wire::put_varint_field(&mut msg, 99, 5); // unknown varint
        let data = wire::put_len(&mut msg, F_DATA, &[1, 2, 3]);
        wire::put_len(&mut msg, F_ENCODING, b"mono8");
        wire::put_fixed32(&mut msg, 100, 0); // unknown fixed32
        msg.extend_from_slice(&[0x99, 0x06, 0, 0, 0, 0, 0, 0, 0, 0]); // field 99 fixed64
        wire::put_fixed32(&mut msg, F_WIDTH, 3);
        wire::put_fixed32(&mut msg, F_WIDTH, 1); // the last one wins
        let d = decode_raw_image(&msg).unwrap();
        assert_eq!((d.width, d.height, d.step, d.encoding, d.frame_id), (1, 0, 0, "mono8", ""));
        assert_eq!(d.timestamp_ns(), Some(0));
        assert_eq!((d.data, d.data_range), (&[1u8, 2, 3][..], data));

        let d = decode_raw_image(&[]).unwrap();
        assert_eq!((d.data, d.data_range), (&[][..], 0..0));
    }

    #[test]
    fn malformed_messages_are_typed_errors_with_offsets() {
        let mut es = image(2, 2, Image::FORMAT_RGB8);
        es.valid_time = 42;
        let mut good = Vec::new();
        let range = encode_raw_image(&es, "cam", &mut good).unwrap();
        // Cut inside the pixels: the data field's length prefix is where it breaks.
        let err = decode_raw_image(&good[..range.start + 3]).unwrap_err();
        assert!(matches!(err, DecodeError::Truncated { offset, .. } if offset == range.start - 1));
        // width with the wire type of a varint.
        let err = decode_raw_image(&[0x10, 0x01]).unwrap_err();
        assert_eq!(err, DecodeError::WrongWireType { field: 2, expected: 5, found: 0, offset: 0 });
        // An encoding that is not UTF-8.
        let err = decode_raw_image(&[0x22, 0x01, 0xff]).unwrap_err();
        assert_eq!(err, DecodeError::InvalidUtf8 { field: 4, offset: 2 });
        // A damaged timestamp names its offset in the whole message.
        let err = decode_raw_image(&[0x15, 0, 0, 0, 0, 0x0a, 0x02, 0x08, 0xff]).unwrap_err();
        assert_eq!(err, DecodeError::Truncated { offset: 8, needed: 1 });
    }

    #[test]
    fn structures_that_are_not_images_say_what_is_wrong() {
        let mut out = Vec::new();
        let no_width = EntityStructure::new("cam", 0, 0).with("height", 1i64);
        assert!(matches!(
            encode_raw_image(&no_width, "", &mut out),
            Err(ViewError::MissingAttribute { attribute: "width" })
        ));
        let mut es = image(2, 2, Image::FORMAT_RGB8);
        es.set("format", 7i64);
        assert!(matches!(
            encode_raw_image(&es, "", &mut out),
            Err(ViewError::UnknownFormat { format: 7 })
        ));
        es.set("format", Image::FORMAT_MONO8); // 12 bytes where 4 are expected
        assert!(matches!(
            encode_raw_image(&es, "", &mut out),
            Err(ViewError::PixelCount { expected: 4, found: 12, bytes_per_pixel: 1, .. })
        ));
        es.set("width", -2i64);
        assert!(matches!(
            encode_raw_image(&es, "", &mut out),
            Err(ViewError::DimensionOutOfRange { attribute: "width", value: -2 })
        ));
        es.set("width", 2.0);
        assert!(matches!(
            encode_raw_image(&es, "", &mut out),
            Err(ViewError::WrongSort { attribute: "width", found: ValueSort::Double, .. })
        ));
        es.set("width", 2i64);
        es.set("image_data", "pixels");
        assert!(matches!(
            encode_raw_image(&es, "", &mut out),
            Err(ViewError::WrongSort { attribute: "image_data", found: ValueSort::String, .. })
        ));
        assert!(out.is_empty(), "a failed encode appends nothing");
    }

    #[test]
    fn the_schema_is_a_descriptor_set_of_rawimage_and_timestamp() {
        let schema = raw_image_schema();
        assert_eq!(
            (schema.name.as_str(), schema.encoding, schema.message_encoding),
            ("foxglove.RawImage", "protobuf", "protobuf")
        );
        let set = FileDescriptorSet::decode(&schema.data[..]).unwrap();
        let names: Vec<_> = set.file.iter().map(|f| f.name()).collect();
        assert_eq!(names, ["google/protobuf/timestamp.proto", "foxglove/RawImage.proto"]);
        let raw = &set.file[1];
        assert_eq!((raw.package(), raw.syntax()), ("foxglove", "proto3"));
        let fields: Vec<_> = raw.message_type[0]
            .field
            .iter()
            .map(|f| (f.name(), f.number(), f.r#type(), f.type_name()))
            .collect();
        assert_eq!(
            fields,
            [
                ("timestamp", 1, Type::Message, ".google.protobuf.Timestamp"),
                ("frame_id", 7, Type::String, ""),
                ("width", 2, Type::Fixed32, ""),
                ("height", 3, Type::Fixed32, ""),
                ("encoding", 4, Type::String, ""),
                ("step", 5, Type::Fixed32, ""),
                ("data", 6, Type::Bytes, ""),
            ]
        );
    }
}
