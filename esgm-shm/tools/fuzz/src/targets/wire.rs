//! The bridge's wire messages ([`esgm_bridge::wire`]): what an importing
//! `esgm-bridge` decodes from every message another host sends on Zenoh, a header
//! checked by comparison and the codec bytes behind it validated.
//!
//! esgm-bridge is built without its `zenoh` feature here: the wire format needs none,
//! and Zenoh takes minutes to build on two cores.
//!
//! Promises checked beyond "no panic": a message that decodes encodes again to one
//! that decodes the same (header and structure); [`wire::split`] agrees with
//! [`wire::decode`] on the header; [`wire::is_reset`] says what the header says;
//! [`wire::set_skipped`] changes the skipped count and nothing else; every seed
//! decodes.

use esgm_bridge::wire::{self, Header, Kind};
use esgm_core::codec;

use crate::mutate::mutate;
use crate::rng::Rng;
use crate::structures;
use crate::target::{Broken, Target};
use crate::targets::codec::fix_envelope;

/// The wire target.
#[derive(Debug)]
pub struct Wire {
    seeds: Vec<Vec<u8>>,
}

impl Wire {
    /// A message of every seed structure, with type names short, long and empty, and a
    /// reset.
    pub fn new() -> Result<Self, Broken> {
        let mut seeds = Vec::new();
        let names = ["RobotState", "", "Image", &"T".repeat(wire::MAX_TYPE_NAME)];
        for (n, es) in structures::valid().iter().enumerate() {
            let bytes = codec::encode(es).map_err(|e| Broken::new("a structure encodes", e))?;
            let header = Header {
                session: 0x5eed,
                writer: 3,
                sequence: n as u64,
                add_time: es.create_time,
                skipped: n as u64 / 2,
                type_hash: 0xfeed_f00d,
                type_name: names[n % names.len()].to_owned(),
                kind: Kind::Structure,
                lineage: (n % 2 == 1).then(|| {
                    esgm_core::Lineage::of(vec![esgm_core::InputRef {
                        trajectory: "camera".into(),
                        generation: n as u64,
                        valid_time: n as i64,
                        add_time: n as i64 + 1,
                    }])
                }),
            };
            seeds.push(wire::encode(&header, &bytes));
        }
        let reset = Header {
            session: 1,
            writer: 1,
            sequence: u64::MAX,
            add_time: i64::MIN,
            skipped: u64::MAX,
            type_hash: 0,
            type_name: "RobotState".into(),
            kind: Kind::Reset,
            lineage: None,
        };
        seeds.push(wire::encode(&reset, &[]));
        Ok(Self { seeds })
    }
}

/// Bytes after the fixed header where its 8-byte fields are (session … type hash).
const FIELDS: [usize; 6] = [8, 16, 24, 32, 40, 48];

/// Sets one header field to a boundary value, keeping magic and version mostly.
fn mutate_header(rng: &mut Rng, data: &mut [u8]) {
    if data.len() < wire::FIXED_LEN {
        return;
    }
    match rng.below(4) {
        0 => {
            let at = *rng.pick(&FIELDS);
            let v = *rng.pick(&[0, 1, u64::MAX, i64::MAX as u64, i64::MIN as u64]);
            data[at..at + 8].copy_from_slice(&v.to_le_bytes());
        }
        1 => {
            // Header or type-name length.
            let at = *rng.pick(&[6usize, 56]);
            let v = *rng.pick(&[0u16, 1, 15, 16, 17, 1024, 1025, u16::MAX]);
            data[at..at + 2].copy_from_slice(&v.to_le_bytes());
        }
        2 => data[58] = *rng.pick(&[0u8, 1, 2, 0xff]),
        _ => data[4..6].copy_from_slice(&rng.pick(&[0u16, 2, u16::MAX]).to_le_bytes()),
    }
}

impl Target for Wire {
    fn name(&self) -> &'static str {
        "wire"
    }

    fn about(&self) -> &'static str {
        "esgm_bridge::wire::decode and split, as an importing bridge reads a message"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        if rng.chance(3) {
            let n = rng.len(4096);
            return rng.bytes(n);
        }
        let mut data = rng.pick(&self.seeds).clone();
        match rng.below(3) {
            0 => mutate_header(rng, &mut data),
            1 => {
                // The codec bytes behind a header that stays right.
                let hlen =
                    wire::split(&data).map_or(data.len(), |(_, body)| data.len() - body.len());
                let mut body = data.split_off(hlen);
                mutate(rng, &mut body, &self.seeds);
                if rng.chance(80) {
                    fix_envelope(&mut body);
                }
                data.extend(body);
            }
            _ => {
                mutate(rng, &mut data, &self.seeds);
                if rng.chance(50) {
                    mutate_header(rng, &mut data);
                }
            }
        }
        data
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        check(input).map(|_| ())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match check(seed)? {
            true => Ok(()),
            false => Err(Broken::new("a message as an exporter sends it decodes", "refused")),
        }
    }
}

/// Decodes `input` as an importer does; `Ok(false)` when it is refused.
fn check(input: &[u8]) -> Result<bool, Broken> {
    let split = wire::split(input);
    let Ok((header, es)) = wire::decode(input) else { return Ok(false) };
    let Ok((split, _)) = split else {
        return Err(Broken::new("split accepts what decode accepts", format!("{header:?}")));
    };
    if split != header {
        return Err(Broken::new("split and decode read the same header", format!("{split:?}")));
    }
    if wire::is_reset(input) != (header.kind == Kind::Reset) {
        return Err(Broken::new("is_reset says what the header says", format!("{header:?}")));
    }
    let mut skipped = input.to_vec();
    wire::set_skipped(&mut skipped, header.skipped ^ 0x5a5a);
    match wire::split(&skipped) {
        Ok((h, _)) if h == Header { skipped: header.skipped ^ 0x5a5a, ..header.clone() } => {}
        other => {
            return Err(Broken::new(
                "set_skipped changes the skipped count alone",
                format!("{:?}", other.map(|(h, _)| h)),
            ));
        }
    }
    let body = match &es {
        Some(es) => {
            codec::encode(es).map_err(|e| Broken::new("a decoded structure encodes", e))?.to_vec()
        }
        None => Vec::new(),
    };
    let again = wire::encode(&header, &body);
    // Compared as archives: a NaN read from the bytes is not equal to itself.
    let same = |back: &Option<esgm_core::EntityStructure>| match back {
        Some(back) => codec::encode(back).is_ok_and(|b| b.as_slice() == body.as_slice()),
        None => body.is_empty(),
    };
    match wire::decode(&again) {
        Ok((h, back)) if h == header && same(&back) => Ok(true),
        Ok(_) => Err(Broken::new("a re-encoded message decodes the same", format!("{header:?}"))),
        Err(e) => Err(Broken::new("a re-encoded message decodes", e)),
    }
}
