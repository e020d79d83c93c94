//! The sample header and payload: [`esgm_shm::check_sample`], the checks every reader
//! runs on a sample taken from shared memory, with either validation setting.
//!
//! An input is a 64-byte [`SampleHeader`] followed by the payload; the payload is laid
//! out in blocks, as the loaned slice is. Promises checked beyond "no panic": a
//! structure accepted with validation decodes, its bytes are the header's archive
//! length, its times are the header's; the deferred setting accepts whatever the
//! validating one does and rejects nothing for a reason the validating one would not
//! see first; a reset is accepted only as a reset; every seed is accepted.

use esgm_core::codec;
use esgm_shm::{ReceiveError, Validation};
use esgm_shm::{SampleHeader, SampleVerdict, check_sample, type_id};

use crate::buffer::Blocks;
use crate::mutate::mutate;
use crate::rng::Rng;
use crate::structures;
use crate::target::{Broken, Target};
use crate::targets::codec::fix_envelope;

const HEADER_LEN: usize = std::mem::size_of::<SampleHeader>();

/// The type id the fuzzed reader expects.
fn expected() -> u64 {
    type_id("esgm-fuzz")
}

/// The sample target.
#[derive(Debug)]
pub struct Sample {
    seeds: Vec<Vec<u8>>,
}

fn sample(header: &SampleHeader, payload: &[u8]) -> Vec<u8> {
    let mut out = bytemuck::bytes_of(header).to_vec();
    out.extend_from_slice(payload);
    out
}

impl Sample {
    /// A sample of each seed structure as a publisher sends it, and a reset marker.
    pub fn new() -> Result<Self, Broken> {
        let mut seeds = Vec::new();
        for (sequence, es) in structures::valid().iter().enumerate() {
            let bytes = codec::encode(es).map_err(|e| Broken::new("a structure encodes", e))?;
            let header = SampleHeader {
                valid_time: es.valid_time,
                create_time: es.create_time,
                add_time: es.create_time,
                archive_len: bytes.len() as u64,
                type_id: expected(),
                sequence: sequence as u64,
                kind: SampleHeader::KIND_STRUCTURE,
                flags: 0,
                kept: 0,
            };
            seeds.push(sample(&header, &bytes));
        }
        let reset = SampleHeader {
            type_id: expected(),
            sequence: 99,
            kind: SampleHeader::KIND_RESET,
            ..SampleHeader::default()
        };
        seeds.push(sample(&reset, &[]));
        Ok(Self { seeds })
    }
}

/// The header of an input (zeros where the input is shorter).
fn header_of(input: &[u8]) -> SampleHeader {
    let mut bytes = [0u8; HEADER_LEN];
    let n = input.len().min(HEADER_LEN);
    bytes[..n].copy_from_slice(&input[..n]);
    bytemuck::pod_read_unaligned(&bytes)
}

/// Sets one header field, by index in declaration order, to a boundary value.
fn mutate_header(rng: &mut Rng, header: &mut SampleHeader, payload_len: usize) {
    let len = payload_len as u64;
    let times = [0, 1, -1, i64::MIN, i64::MAX, header.valid_time.wrapping_add(1)];
    match rng.below(8) {
        0 => header.valid_time = *rng.pick(&times),
        1 => header.create_time = *rng.pick(&times),
        2 => {
            header.archive_len = *rng.pick(&[
                0,
                15,
                16,
                17,
                len.wrapping_sub(1),
                len,
                len + 1,
                len.next_multiple_of(16),
                1 << 32,
                u64::MAX,
            ]);
        }
        3 => header.type_id = *rng.pick(&[0, expected() ^ 1, u64::MAX, type_id("RobotState")]),
        4 => header.kind = *rng.pick(&[0, 1, 2, 3, u32::MAX]),
        5 => header.flags = rng.next_u64() as u32,
        6 => header.kept = rng.next_u64(),
        _ => header.sequence = rng.next_u64(),
    }
}

impl Target for Sample {
    fn name(&self) -> &'static str {
        "sample"
    }

    fn about(&self) -> &'static str {
        "esgm_shm::check_sample (type id, kind, archive length, validation, times)"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        if rng.chance(5) {
            let n = HEADER_LEN + rng.len(4096);
            return rng.bytes(n);
        }
        let seed = rng.pick(&self.seeds);
        let mut header = header_of(seed);
        let mut payload = seed.get(HEADER_LEN..).unwrap_or_default().to_vec();
        let what = rng.below(4);
        if what != 0 {
            let payloads: Vec<Vec<u8>> = self
                .seeds
                .iter()
                .map(|s| s.get(HEADER_LEN..).unwrap_or_default().to_vec())
                .collect();
            mutate(rng, &mut payload, &payloads);
            if rng.chance(80) {
                fix_envelope(&mut payload);
                header.archive_len = payload.len() as u64;
            }
        }
        if what != 1 {
            for _ in 0..1 + rng.below(2) {
                mutate_header(rng, &mut header, payload.len());
            }
        }
        sample(&header, &payload)
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        check(input).map(|_| ())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match check(seed)? {
            Ok(_) => Ok(()),
            Err(e) => Err(Broken::new("a sample as a publisher sends it is accepted", e)),
        }
    }
}

/// Runs the reader's checks with both validation settings; `Ok(Err(_))` is a rejection.
fn check(input: &[u8]) -> Result<Result<(), ReceiveError>, Broken> {
    let header = header_of(input);
    let payload = Blocks::aligned(input.get(HEADER_LEN..).unwrap_or_default());
    let payload = payload.payload();
    let deferred = check_sample(&header, payload, expected(), Validation::OnAccess);
    let validated = check_sample(&header, payload, expected(), Validation::InPlace);
    match (validated, deferred) {
        (
            Ok(SampleVerdict::Structure { bytes, archived: Some(archived) }),
            Ok(SampleVerdict::Structure { bytes: later, archived: None }),
        ) => {
            if bytes.len() as u64 != header.archive_len || later.len() != bytes.len() {
                return Err(Broken::new(
                    "the accepted bytes are the header's archive length",
                    format!("{} bytes, header says {}", bytes.len(), header.archive_len),
                ));
            }
            if archived.valid_time != header.valid_time
                || archived.create_time != header.create_time
            {
                return Err(Broken::new(
                    "an accepted sample's times are its header's",
                    format!("{:?}", header),
                ));
            }
            let decoded = codec::decode(archived)
                .map_err(|e| Broken::new("an accepted sample decodes", e))?;
            // The in-place reader (what every replica keeps) reads what the decoder
            // decodes, attribute by attribute, nested values included.
            let in_place = esgm_core::SharedStructure::archived_copy(bytes)
                .map_err(|e| Broken::new("an accepted sample is read in place", e))?;
            // Compared as bytes: a NaN is not equal to itself, its bits are.
            let same = codec::encode(&in_place.to_structure()).ok().as_deref()
                == codec::encode(&decoded).ok().as_deref();
            if !same {
                return Err(Broken::new(
                    "the in-place reader reads what the decoder decodes",
                    format!("{in_place:?} / {decoded:?}"),
                ));
            }
            Ok(Ok(()))
        }
        (
            Ok(SampleVerdict::Kept { index, len, .. }),
            Ok(SampleVerdict::Kept { index: later, len: later_len, .. }),
        ) => {
            let named = header.kind == SampleHeader::KIND_KEPT
                && header.kept.checked_sub(1) == Some(index)
                && len as u64 == header.archive_len
                && (later, later_len) == (index, len);
            if !named {
                return Err(Broken::new(
                    "a kept entry is named by its header's index and length",
                    format!("{header:?}"),
                ));
            }
            Ok(Ok(()))
        }
        (Ok(SampleVerdict::Reset { sequence }), Ok(SampleVerdict::Reset { .. })) => {
            if header.kind != SampleHeader::KIND_RESET || sequence != header.sequence {
                return Err(Broken::new("only a reset marker resets", format!("{header:?}")));
            }
            Ok(Ok(()))
        }
        (Err(ReceiveError::Malformed(e)), Ok(SampleVerdict::Structure { archived: None, .. })) => {
            Ok(Err(ReceiveError::Malformed(e)))
        }
        (Err(validated), Err(deferred)) => {
            if std::mem::discriminant(&validated) != std::mem::discriminant(&deferred) {
                return Err(Broken::new(
                    "both validation settings reject for the same reason",
                    format!("{validated} / {deferred}"),
                ));
            }
            Ok(Err(validated))
        }
        (validated, deferred) => Err(Broken::new(
            "the deferred setting accepts what validation accepts",
            format!("{validated:?} / {deferred:?}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Most inputs must get past the header to the archive's validation, and some be
    /// accepted: a fuzzer stopped by the first check tests nothing else.
    #[test]
    fn inputs_reach_validation_and_some_pass() {
        let target = Sample::new().map_err(|e| e.to_string()).unwrap_or_else(|e| panic!("{e}"));
        let (mut validated, mut accepted) = (0, 0);
        for i in 0..2_000 {
            let input = target.input(&mut Rng::for_case(9, i));
            match check(&input) {
                Ok(Ok(())) => accepted += 1,
                Ok(Err(ReceiveError::Malformed(_))) => validated += 1,
                Ok(Err(_)) => {}
                Err(broken) => panic!("case {i}: {broken}"),
            }
        }
        assert!(validated > 400, "{validated} of 2000 reached validation");
        assert!(accepted > 100, "{accepted} of 2000 accepted");
    }
}
