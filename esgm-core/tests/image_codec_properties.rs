//! Property tests of the in-place image encoder: for any name, times, sizes and
//! pixels, `encode_image_into` around pixels already in a buffer gives an archive that
//! validates and decodes to exactly what the ordinary encoder gives for the same
//! `library::Image`, without touching the pixels.

// Helpers outside `#[test]` functions: a panic there is a failed test with a message.
#![allow(clippy::unwrap_used)]

use esgm_core::codec::{
    self, ARCHIVE_ALIGNMENT, CodecError, IMAGE_NAME_MAX, IMAGE_OVERHEAD_MAX, IMAGE_PIXELS_OFFSET,
    access, decode, encode, encode_image_into,
};
use esgm_core::library::Image;
use esgm_core::{Entity, Octets};
use proptest::prelude::*;

/// A zeroed buffer whose start is 16-aligned, as a shared-memory loan is.
fn aligned(len: usize) -> Vec<u128> {
    const _: () = assert!(std::mem::align_of::<u128>() >= ARCHIVE_ALIGNMENT);
    vec![0u128; len.div_ceil(16)]
}

fn bytes(buf: &mut [u128]) -> &mut [u8] {
    // SAFETY: `u128` has no padding and any bytes are a valid `u8`; the length covers
    // exactly the borrowed slice.
    unsafe { std::slice::from_raw_parts_mut(buf.as_mut_ptr().cast::<u8>(), buf.len() * 16) }
}

/// Names over all of Unicode, from empty (inline in the archive) to past the limit.
fn name() -> impl Strategy<Value = String> {
    prop_oneof![
        "\\PC{0,12}",
        "\\PC{0,80}",
        (IMAGE_NAME_MAX - 4..IMAGE_NAME_MAX + 4).prop_map(|n| "n".repeat(n)),
    ]
}

proptest! {
    #[test]
    fn in_place_image_equals_the_ordinary_encoding(
        name in name(),
        valid_time in any::<i64>(),
        create_time in any::<i64>(),
        width in any::<i64>(),
        height in any::<i64>(),
        format in any::<i64>(),
        pixels in proptest::collection::vec(any::<u8>(), 0..600),
        slack in 0usize..64,
    ) {
        let pixel_len = pixels.len();
        let mut buf = aligned(pixel_len + IMAGE_OVERHEAD_MAX + slack);
        let out = bytes(&mut buf);
        out[IMAGE_PIXELS_OFFSET..][..pixel_len].copy_from_slice(&pixels);
        let result = encode_image_into(
            &name, valid_time, create_time, width, height, format, pixel_len, out,
        );
        if name.len() > IMAGE_NAME_MAX {
            let too_long = matches!(result, Err(CodecError::NameTooLong { .. }));
            prop_assert!(too_long, "{result:?}");
            return Ok(());
        }
        let n = result.unwrap();
        prop_assert!(n <= pixel_len + IMAGE_OVERHEAD_MAX);
        prop_assert_eq!(&out[IMAGE_PIXELS_OFFSET..][..pixel_len], &pixels[..]);

        let image = Image { width, height, format, image_data: Octets::from(pixels.clone()) };
        let expected = image.to_structure(name.as_str(), valid_time, create_time);
        let archived = access(&out[..n]).unwrap();
        prop_assert_eq!(archived.name.as_str(), name.as_str());
        prop_assert_eq!(decode(archived).unwrap(), expected.clone());
        // The ordinary encoder's bytes decode to the same structure.
        let ordinary = encode(&expected).unwrap();
        prop_assert_eq!(decode(access(&ordinary).unwrap()).unwrap(), expected);
        // The archived pixels are the bytes where they were written, not a copy.
        let archived_pixels = match &archived.attributes[3].value {
            codec::ArchivedValue::OctetSeq(o) => o.as_slice(),
            other => return Err(TestCaseError::fail(format!("image_data is {other:?}"))),
        };
        prop_assert_eq!(
            archived_pixels.as_ptr() as usize - out.as_ptr() as usize,
            IMAGE_PIXELS_OFFSET
        );
    }
}
