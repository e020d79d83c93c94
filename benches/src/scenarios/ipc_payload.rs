//! What the cross-process esgm and socket scenarios carry, and how a reader uses it in
//! place: the small structure and the image, both as the codec archives them.
//!
//! A reader "holds" a structure when it has the validated archive and has read what a
//! consumer would: the `x` of a `RobotState`, or one pixel at each end of an `Image`
//! (checked against the frame's pattern, so a torn or shifted frame is an error, not a
//! silently fast hop).

use anyhow::{Context as _, bail};
use esgm_core::EntityStructure;
use esgm_core::codec::{ArchivedEntityStructure, ArchivedValue};
use esgm_core::library::Image;

use super::inproc_echo::Payload;
use super::inproc_hop_image::{Frames, PIXEL_BYTES};
use super::inproc_hop_small::Small;

/// Image width in pixels.
pub const IMAGE_WIDTH: i64 = 640;
/// Image height in pixels.
pub const IMAGE_HEIGHT: i64 = 480;
/// RGB, 3 bytes per pixel.
pub const IMAGE_FORMAT: i64 = Image::FORMAT_RGB8;
/// The entity name of every image, as [`Frames`] names it (the image publisher lays
/// its loans out for it).
pub const IMAGE_NAME: &str = "camera";

/// The two payloads of the cross-process scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A `RobotState`: three doubles, about 120 bytes archived.
    Small,
    /// A 640×480 RGB `Image`: 921,600 bytes of pixels.
    Image,
}

impl Kind {
    /// esgm's own row of this payload (`esgm-small`, `esgm-image`): the row a peer's
    /// row of the same size is held to.
    pub fn esgm_row(self) -> &'static str {
        match self {
            Kind::Small => super::ipc_esgm_small::NAME,
            Kind::Image => super::ipc_esgm_image::NAME,
        }
    }

    /// The registered type name.
    pub fn type_name(self) -> &'static str {
        match self {
            Kind::Small => Small::TYPE_NAME,
            Kind::Image => Frames::TYPE_NAME,
        }
    }

    /// An upper bound of the archived size (envelope included).
    pub fn max_bytes(self) -> usize {
        match self {
            Kind::Small => 4096,
            Kind::Image => 1 << 20,
        }
    }

    /// Samples of a full run and of a `--quick` one.
    pub fn samples(self) -> (u64, u64) {
        match self {
            Kind::Small => (100_000, 10_000),
            Kind::Image => (10_000, 1_000),
        }
    }

    /// The `i`-th structure, complete, made on the heap (the socket scenarios' producer
    /// write; esgm writes images into its loan instead).
    pub fn make(self, i: u64) -> EntityStructure {
        match self {
            Kind::Small => Small.make(i),
            Kind::Image => Frames.make(i),
        }
    }

    /// Reads what a consumer reads (see the module docs); fails on a structure that is
    /// not what was sent.
    pub fn read(self, archived: &ArchivedEntityStructure) -> anyhow::Result<u64> {
        match self {
            Kind::Small => match attribute(archived, "x")? {
                ArchivedValue::Double(x) => Ok(x.to_native().to_bits()),
                _ => bail!("attribute x of the RobotState is not a double"),
            },
            Kind::Image => {
                let pixels = match attribute(archived, "image_data")? {
                    ArchivedValue::OctetSeq(o) => o.as_slice(),
                    _ => bail!("attribute image_data of the Image is not an octet sequence"),
                };
                check_frame(pixels)
            }
        }
    }
}

/// Reads what a consumer reads of a structure delivered as a value (an
/// [`esgm_core::Sample`] from a subscription): the `x` of a `RobotState`, or one pixel
/// at each end of an `Image`, checked as [`Kind::read`] checks an archive. Returns the
/// value read and whether the pixels are held in shared memory rather than copied
/// onto this process's heap ([`esgm_core::Octets::is_held`]; always false for a small structure).
pub fn read_value(kind: Kind, es: &esgm_core::SharedStructure) -> anyhow::Result<(u64, bool)> {
    match kind {
        Kind::Small => match es.get("x").and_then(|v| v.as_double()) {
            Some(x) => Ok((x.to_bits(), false)),
            None => bail!("the RobotState has no double x"),
        },
        Kind::Image => {
            let Some(pixels) = es.get("image_data") else {
                bail!("the Image has no octet sequence image_data")
            };
            let (Some(bytes), shared) = (pixels.as_bytes(), pixels.octets_are_shared()) else {
                bail!("the Image's image_data is not an octet sequence")
            };
            Ok((check_frame(bytes)?, shared))
        }
    }
}

/// Reads one pixel at each end of a frame and checks them against the frame sent
/// ([`pattern`]); returns their sum (for `black_box`). Public for readers of pixels
/// that come in another form (a ROS 2 message's `data`).
pub fn check_frame(pixels: &[u8]) -> anyhow::Result<u64> {
    let (Some(&first), Some(&last)) = (pixels.first(), pixels.last()) else {
        bail!("the image has no pixels")
    };
    if pixels.len() != PIXEL_BYTES || last != pattern(PIXEL_BYTES - 1, first) {
        bail!(
            "the image's pixels are not the frame sent ({} bytes, first {first}, last {last})",
            pixels.len()
        );
    }
    Ok(u64::from(first) + u64::from(last))
}

/// The names and sequences of the cross-process ping-pongs (`ipc_esgm_echo` on the
/// data plane, `ipc_connect_echo` through `connect`): one protocol, two transports.
pub mod protocol {
    /// The measuring process's trajectory.
    pub const PING: &str = "ping";
    /// The peer's trajectory.
    pub const PONG: &str = "pong";
    /// The peer's "my image reply is made".
    pub const READY: &str = "ready";
    /// The measuring process's "I have read your image reply".
    pub const DONE: &str = "done";
    /// The sequence of start-up pings; measured pings count from 1.
    pub const HELLO: i64 = 0;
    /// The sequence that tells the peer to stop.
    pub const STOP: i64 = -1;
}

/// The byte at `index` of a frame whose first byte is `seed`: the pattern of
/// [`Frames`], so a reader can check the far end against the near one.
pub fn pattern(index: usize, seed: u8) -> u8 {
    (index as u8).wrapping_add(seed)
}

fn attribute<'a>(
    archived: &'a ArchivedEntityStructure,
    name: &str,
) -> anyhow::Result<&'a ArchivedValue> {
    archived
        .attributes
        .iter()
        .find(|p| p.name.as_str() == name)
        .map(|p| &p.value)
        .with_context(|| format!("the structure has no attribute {name}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::{Entity, Octets, codec};

    #[test]
    fn readers_accept_what_is_made_and_refuse_a_torn_frame() {
        for kind in [Kind::Small, Kind::Image] {
            let bytes = codec::encode(&kind.make(7)).unwrap();
            assert!(bytes.len() <= kind.max_bytes());
            kind.read(codec::access(&bytes).unwrap()).unwrap();
            assert!(!read_value(kind, &kind.make(7).into()).unwrap().1, "made on the heap");
        }
        assert_eq!(Kind::Image.make(7).name, IMAGE_NAME);
        let blank = Image {
            width: IMAGE_WIDTH,
            height: IMAGE_HEIGHT,
            format: IMAGE_FORMAT,
            image_data: Octets::from(vec![0u8; PIXEL_BYTES]),
        }
        .to_structure(IMAGE_NAME, 1, 1);
        let bytes = codec::encode(&blank).unwrap();
        assert!(Kind::Image.read(codec::access(&bytes).unwrap()).is_err());
        assert!(read_value(Kind::Image, &blank.into()).is_err());
        assert!(read_value(Kind::Image, &Kind::Small.make(1).into()).is_err());
    }
}
