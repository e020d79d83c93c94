//! Recordings ([`esgm_recording::Recording`]): what `esgm info`, `replay`, `load` and
//! `compare` read from an MCAP file, which a crash, a truncated copy or anyone who
//! sends one may have damaged. The file is opened, summarised as `esgm info` does
//! ([`Recording::info`], [`RecordedTrajectory::lost`]) and every sample read with
//! [`Samples::next`](esgm_recording::Samples).
//!
//! An input is a whole file, written to a temporary path (the reader opens a path).
//! The seeds are recordings written by [`RecordingWriter`] with each compression;
//! mutations of an uncompressed chunk would mostly stop at its CRC, so most inputs
//! have their chunks' CRCs cleared (zero: "not checked", as MCAP allows) and reach
//! the records inside. Promises checked beyond "no panic": a file not changed since
//! it was opened reads its samples without an error up to the damage `open` found,
//! and no more of them than `open` counted; every seed opens complete and undamaged.
//!
//! [`RecordedTrajectory::lost`]: esgm_recording::RecordedTrajectory::lost

use std::path::PathBuf;

use esgm_core::Entity;
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::library::{Image, RobotState};
use esgm_recording::{
    Compression, EventKind, RecordOptions, RecordedEvent, Recording, RecordingWriter, TypeSchema,
};

use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};

/// MCAP's chunk opcode.
const OP_CHUNK: u8 = 0x06;
/// Bytes of a record's opcode and length.
const RECORD_HEAD: usize = 9;
/// Where a chunk's uncompressed CRC sits in its body: after its start time, end
/// time and uncompressed size.
const CHUNK_CRC_AT: usize = 24;

/// The recording target.
#[derive(Debug)]
pub struct RecordingTarget {
    seeds: Vec<Vec<u8>>,
    /// Where each case's file is written.
    file: PathBuf,
    _dir: tempfile::TempDir,
}

fn info(name: &str, kind: TrajectoryKind, type_name: &str) -> TrajectoryInfo {
    TrajectoryInfo::new(name, kind, type_name)
}

/// A recording of robot states and images (with their Foxglove views), a violation
/// and a loss, in chunks of `chunk` bytes.
fn seed(dir: &std::path::Path, compression: Compression, chunk: u64) -> Result<Vec<u8>, Broken> {
    let path = dir.join(format!("seed-{compression:?}-{chunk}.mcap"));
    let broken = |e: &dyn std::fmt::Display| Broken::new("a seed recording is written", e);
    let options = RecordOptions::default().compression(compression).chunk_size(chunk);
    let mut w = RecordingWriter::create(&path, options).map_err(|e| broken(&e))?;
    let schema = |t| TypeSchema::collect(t, &|_| None);
    let robot = w
        .add_trajectory(
            info("robot_state", TrajectoryKind::Primitive, "RobotState"),
            schema(RobotState::entity_structure_type()),
        )
        .map_err(|e| broken(&e))?;
    let images = w
        .add_trajectory(
            info("images", TrajectoryKind::Sampled, "Image"),
            schema(Image::entity_structure_type()),
        )
        .map_err(|e| broken(&e))?;
    for i in 0..6i64 {
        let rs = RobotState { x: i as f64, y: -1.0, dir: 90.0 }.to_structure(
            "robot",
            1_000 + i * 100,
            1_001 + i * 100,
        );
        let pixels: Vec<u8> = (0..4 * 2 * 3).map(|p| (p * 7 + i) as u8).collect();
        let im =
            Image { width: 4, height: 2, format: Image::FORMAT_RGB8, image_data: pixels.into() }
                .to_structure("camera", 1_000 + i * 250, 1_001 + i * 250);
        w.write(robot, &rs, 5_000 + i, 6_000 + i).map_err(|e| broken(&e))?;
        // Sequence 3 of the images is missing: a gap the reader counts.
        if i != 3 {
            w.write(images, &im, 7_000 + i, 8_000 + i).map_err(|e| broken(&e))?;
        }
    }
    for (kind, cause) in [(EventKind::Violation, "order"), (EventKind::Loss, "recorder_overflow")] {
        let event = RecordedEvent {
            trajectory: "images".into(),
            kind,
            cause: cause.into(),
            count: 1,
            valid_time: Some(1_750),
            time: 9_000,
            detail: "seed".into(),
        };
        w.write_event(&event).map_err(|e| broken(&e))?;
    }
    w.finish().map_err(|e| broken(&e))?;
    std::fs::read(&path).map_err(|e| broken(&e))
}

/// Clears the CRC of every chunk a walk of the top-level records finds (MCAP: zero
/// means "not checked"), so mutations inside a chunk reach the records in it.
fn clear_chunk_crcs(data: &mut [u8]) {
    let mut at = 8usize;
    while let Some(head) = data.get(at..at + RECORD_HEAD) {
        let opcode = head[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let Ok(len) = usize::try_from(u64::from_le_bytes(len)) else { return };
        let body = at + RECORD_HEAD;
        if opcode == OP_CHUNK {
            if let Some(crc) = data.get_mut(body + CHUNK_CRC_AT..body + CHUNK_CRC_AT + 4) {
                crc.fill(0);
            }
        }
        let Some(next) = body.checked_add(len) else { return };
        at = next;
    }
}

impl RecordingTarget {
    /// Writes the seed recordings (zstd, lz4 and uncompressed, in one chunk or many)
    /// in a temporary directory, where each case's file goes too.
    pub fn new() -> Result<Self, Broken> {
        let dir = tempfile::tempdir()
            .map_err(|e| Broken::new("a temporary directory for recordings", e))?;
        let mut seeds = Vec::new();
        for (compression, chunk) in [
            (Compression::None, 512),
            (Compression::None, 4 << 20),
            (Compression::Zstd, 1024),
            (Compression::Lz4, 4 << 20),
        ] {
            seeds.push(seed(dir.path(), compression, chunk)?);
        }
        let file = dir.path().join("case.mcap");
        Ok(Self { seeds, file, _dir: dir })
    }

    /// Opens `input` as a recording; `Ok(None)` when it is refused at open.
    fn read(&self, input: &[u8]) -> Result<Option<Recording>, Broken> {
        std::fs::write(&self.file, input)
            .map_err(|e| Broken::new("the case's file is written", e))?;
        let Ok(recording) = Recording::open(&self.file) else { return Ok(None) };
        let info = recording.info();
        let _lost: u64 =
            recording.trajectories.iter().map(|t| t.lost()).fold(0, u64::saturating_add);
        let samples =
            recording.samples().map_err(|e| Broken::new("a file that opened opens again", e))?;
        let mut read = 0u64;
        for sample in samples {
            if let Err(e) = sample {
                return Err(Broken::new(
                    "an unchanged file reads to the damage open found, without an error",
                    e,
                ));
            }
            read += 1;
        }
        if read > info.structures {
            return Err(Broken::new(
                "no more samples read than open counted",
                format!("{read} read, {} counted", info.structures),
            ));
        }
        Ok(Some(recording))
    }
}

impl Target for RecordingTarget {
    fn name(&self) -> &'static str {
        "recording"
    }

    fn about(&self) -> &'static str {
        "esgm_recording::Recording::open, info and every Samples::next, on damaged MCAP files"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        let mut data = rng.pick(&self.seeds).clone();
        mutate(rng, &mut data, &self.seeds);
        if rng.chance(80) {
            clear_chunk_crcs(&mut data);
        }
        data
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        self.read(input).map(|_| ())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match self.read(seed)? {
            Some(r) if r.complete && r.damage.is_none() && r.trajectories.len() == 2 => Ok(()),
            Some(r) => Err(Broken::new("a seed reads complete", format!("{:?}", r.damage))),
            None => Err(Broken::new("a seed opens", "refused")),
        }
    }
}
