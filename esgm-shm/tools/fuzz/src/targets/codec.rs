//! The codec: [`codec::access`] (envelope and full validation), [`codec::decode`],
//! [`codec::decode_value`] and [`codec::decode_bytes`] on bytes at any alignment.
//!
//! An accepted archive is also read as each library type, as typed readers do: in
//! place through its view (`RobotState::view`), decoded (`from_structure`), and
//! through the layout check a subscription runs before taking a structure
//! ([`TypeChecker::check`]).
//!
//! Promises checked beyond "no panic": what `access` accepts decodes (every attribute
//! value too), re-encodes, and the re-encoding is accepted and encodes the same again;
//! `decode_bytes` on a misaligned copy agrees with `access` on an aligned one; a typed
//! view reads what decoding reads; a structure the layout check accepts as a type
//! decodes as it; every seed is accepted.

use esgm_core::codec::{
    self, ARCHIVE_ALIGNMENT, ArchivedEntityStructure, ENVELOPE_LEN, FORMAT_VERSION,
};
use esgm_core::library::{Blob, BlobSeq, DrivingDirection, Image, Pose, RobotState, Twist};
use esgm_core::value::Octets;
use esgm_core::{Entity, EntityStructure, TypeChecker, TypeRegistry, ViewError};
use esgm_shm::Block16;
use esgm_shm::unstable::blocks_for;

use crate::buffer::Blocks;
use crate::mutate::mutate;
use crate::rng::Rng;
use crate::structures;
use crate::target::{Broken, Target};

/// The codec target.
#[derive(Debug)]
pub struct Codec {
    seeds: Vec<Vec<u8>>,
    /// A reader's layout check of each library type (what a subscription runs on a
    /// decoded structure before taking it).
    checkers: Vec<TypeChecker>,
}

impl Codec {
    /// Encodes the seed structures, and an image written in place as a camera does.
    pub fn new() -> Result<Self, Broken> {
        let mut seeds = Vec::new();
        for es in structures::valid() {
            seeds.push(encode(&es)?);
        }
        seeds.push(in_place_image()?);
        let types = TypeRegistry::with_library();
        let checkers = types
            .names()
            .iter()
            .map(|name| TypeChecker::new(&types, name))
            .collect::<Result<_, _>>()
            .map_err(|e| Broken::new("the library's types check", e))?;
        Ok(Self { seeds, checkers })
    }
}

fn encode(es: &EntityStructure) -> Result<Vec<u8>, Broken> {
    codec::encode(es).map(|b| b.to_vec()).map_err(|e| Broken::new("a structure encodes", e))
}

/// An image as [`codec::encode_image_into`] lays it out in a camera's shared memory.
fn in_place_image() -> Result<Vec<u8>, Broken> {
    let pixels = 4 * 4 * 3;
    let mut out = vec![Block16::default(); blocks_for(pixels + codec::IMAGE_OVERHEAD_MAX)];
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
    let n = codec::encode_image_into("camera", 5, 6, 4, 4, 0, pixels, bytes)
        .map_err(|e| Broken::new("an image encodes in place", e))?;
    Ok(bytes[..n].to_vec())
}

/// Makes the envelope right for `data`'s length, so mutations reach rkyv's validation
/// instead of stopping at the length check.
pub fn fix_envelope(data: &mut [u8]) {
    if data.len() >= ENVELOPE_LEN {
        let len = (data.len() - ENVELOPE_LEN) as u64;
        data[..4].copy_from_slice(b"ESGM");
        data[4..8].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
        data[8..16].copy_from_slice(&len.to_le_bytes());
    }
}

/// A codec input: mostly a mutated seed with its envelope made right again, else a
/// random structure (nesting past the bound now and then) or random bytes.
pub fn codec_input(rng: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    match rng.below(20) {
        0 => {
            let n = rng.len(4096);
            let mut data = rng.bytes(n);
            if rng.chance(50) {
                fix_envelope(&mut data);
            }
            data
        }
        1 | 2 => {
            let es = structures::random(rng);
            let mut data = codec::encode(&es).map(|b| b.to_vec()).unwrap_or_default();
            if rng.chance(50) {
                mutate(rng, &mut data, seeds);
                fix_envelope(&mut data);
            }
            data
        }
        _ => {
            let mut data = rng.pick(seeds).clone();
            mutate(rng, &mut data, seeds);
            if rng.chance(80) {
                fix_envelope(&mut data);
            }
            data
        }
    }
}

/// Runs the codec's reading paths on `input`; see the module docs for the promises.
pub fn check_codec(
    input: &[u8],
    checkers: &[TypeChecker],
) -> Result<Option<EntityStructure>, Broken> {
    let buffer = Blocks::aligned(input);
    let accepted = codec::access(buffer.bytes());
    // The same bytes misaligned by 1 to 15, as a request payload or a file may be.
    let shifted = Blocks::shifted(input, 1 + input.len() % (ARCHIVE_ALIGNMENT - 1));
    let anywhere = codec::decode_bytes(shifted.bytes());
    let archived = match (accepted, anywhere) {
        (Err(_), Err(_)) => return Ok(None),
        (Ok(archived), Ok(_)) => archived,
        (Ok(_), Err(e)) => {
            return Err(Broken::new("decode_bytes agrees with access at any alignment", e));
        }
        (Err(e), Ok(_)) => {
            return Err(Broken::new("access agrees with decode_bytes at any alignment", e));
        }
    };
    let owned =
        codec::decode(archived).map_err(|e| Broken::new("an accepted archive decodes", e))?;
    for pair in archived.attributes.iter() {
        codec::decode_value(&pair.value)
            .map_err(|e| Broken::new("an accepted archive's values decode", e))?;
    }
    let again =
        codec::encode(&owned).map_err(|e| Broken::new("a decoded structure encodes again", e))?;
    let reread = codec::access(&again)
        .and_then(codec::decode)
        .map_err(|e| Broken::new("a re-encoded structure is accepted", e))?;
    read_as_library_types(archived, &owned)?;
    for checker in checkers {
        // A wrong layout is a reader's typed rejection (only time and panics count);
        // a right one must read as the type.
        if checker.check(&owned.attributes).is_ok() {
            read_checked(checker.type_name(), &owned)?;
        }
    }
    let third =
        codec::encode(&reread).map_err(|e| Broken::new("a decoded structure encodes again", e))?;
    if third[..] != again[..] {
        return Err(Broken::new(
            "decoding and encoding again is stable",
            format!("{} bytes became {}", again.len(), third.len()),
        ));
    }
    Ok(Some(owned))
}

/// Reads an archive as `T` in place (`view`, rebuilding `T` from the view's fields)
/// and decoded: both must fail, or both read the same (compared as printed, so NaNs
/// compare too).
fn read_as<T: Entity + std::fmt::Debug>(
    archived: &ArchivedEntityStructure,
    owned: &EntityStructure,
    view: impl FnOnce(&ArchivedEntityStructure) -> Result<T, ViewError>,
) -> Result<(), Broken> {
    let viewed = view(archived).ok().map(|t| format!("{t:?}"));
    let decoded = T::from_structure(owned).ok().map(|t| format!("{t:?}"));
    if viewed != decoded {
        return Err(Broken::new(
            "a typed view reads what decoding reads",
            format!("view {viewed:?}, decoded {decoded:?}"),
        ));
    }
    Ok(())
}

fn read_as_library_types(
    archived: &ArchivedEntityStructure,
    owned: &EntityStructure,
) -> Result<(), Broken> {
    read_as(archived, owned, |a| {
        Image::view(a).map(|v| Image {
            width: v.width(),
            height: v.height(),
            format: v.format(),
            image_data: Octets::from(v.image_data()),
        })
    })?;
    read_as(archived, owned, |a| {
        Blob::view(a).map(|v| Blob { x: v.x(), y: v.y(), size: v.size() })
    })?;
    read_as(archived, owned, |a| BlobSeq::view(a).map(|v| BlobSeq { items: v.items().to_vec() }))?;
    read_as(archived, owned, |a| {
        RobotState::view(a).map(|v| RobotState { x: v.x(), y: v.y(), dir: v.dir() })
    })?;
    read_as(archived, owned, |a| {
        DrivingDirection::view(a).map(|v| DrivingDirection { dir: v.dir(), speed: v.speed() })
    })?;
    read_as(archived, owned, |a| Pose::view(a).map(|v| Pose { pose: v.pose() }))?;
    read_as(archived, owned, |a| {
        Twist::view(a).map(|v| Twist { linear: v.linear(), angular: v.angular() })
    })
}

/// Decodes a structure the layout check accepted as `type_name` as that library type.
fn read_checked(type_name: &str, owned: &EntityStructure) -> Result<(), Broken> {
    fn read<T: Entity>(owned: &EntityStructure) -> Result<(), Broken> {
        T::from_structure(owned)
            .map(drop)
            .map_err(|e| Broken::new("a structure of a type's layout reads as the type", e))
    }
    match type_name {
        "Image" => read::<Image>(owned),
        "Blob" => read::<Blob>(owned),
        "BlobSeq" => read::<BlobSeq>(owned),
        "RobotState" => read::<RobotState>(owned),
        "DrivingDirection" => read::<DrivingDirection>(owned),
        "Pose" => read::<Pose>(owned),
        "Twist" => read::<Twist>(owned),
        _ => Ok(()),
    }
}

impl Target for Codec {
    fn name(&self) -> &'static str {
        "codec"
    }

    fn about(&self) -> &'static str {
        "codec::access, decode, decode_value, decode_bytes on archives"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        codec_input(rng, &self.seeds)
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        check_codec(input, &self.checkers).map(|_| ())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match check_codec(seed, &self.checkers)? {
            Some(_) => Ok(()),
            None => {
                let why = codec::access(Blocks::aligned(seed).bytes()).err();
                Err(Broken::new(
                    "a valid encoding is accepted",
                    why.map_or_else(String::new, |e| e.to_string()),
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_accepted_and_some_mutants_too() {
        let target = Codec::new().map_err(|e| e.to_string()).unwrap_or_else(|e| panic!("{e}"));
        for seed in target.seeds() {
            assert_eq!(target.accepts(seed), Ok(()));
        }
        let mut accepted = 0;
        for i in 0..500 {
            let input = target.input(&mut Rng::for_case(2, i));
            match check_codec(&input, &target.checkers) {
                Ok(Some(_)) => accepted += 1,
                Ok(None) => {}
                Err(broken) => panic!("case {i}: {broken}"),
            }
        }
        assert!(accepted > 25, "{accepted} of 500 accepted");
    }
}
