//! `record-image`: MB/s of 640×480 RGB frames recorded without compression, against
//! the same bytes written by a plain file loop ([`super::file_write_image`]) in the
//! same run; the goal is at least 0.7 × that baseline.
//!
//! The measuring process starts a coordinator on a thread of its own, connects
//! (`esgm_shm` `connect`), creates the primitive trajectory `record-frames` (`Image`,
//! a cache of [`CACHE`](super::ipc_connect_echo::CACHE)) and records it with
//! [`esgm_recording::Recorder`] into a file in a temporary folder, uncompressed
//! ([`Compression::None`]). Each frame is rendered into a loan of the trajectory's
//! shared memory first, as `connect-image` makes them (untimed, reported as the
//! producer's write); then one sample is the time from the `add` until the recorder
//! has written the frame (its statistics, polled without sleeping): the add, the
//! recorder's wake-up, and writing the frame (its `foxglove.RawImage` view, which
//! holds the pixels, and the lossless header) into the file. Frames go one at a time,
//! so the recorder never queues them.

use std::time::Instant;

use anyhow::Context as _;
use esgm_core::Value;
use esgm_recording::{Compression, RecordOptions, Recorder, RecordingWriter, recorder};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::unique_domain;

use super::file_write_image::{self, FRAMES, mb_per_s};
use super::inproc_hop_image::PIXEL_BYTES;
use super::ipc_connect_echo::{add, connect, create, make_for, stamped};
use super::ipc_payload::Kind;
use super::record_small::{file_bytes, handled, losses_note};
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// The scenario's name.
pub const NAME: &str = "record-image";
const FRAMES_TRAJECTORY: &str = "record-frames";

/// See the module docs.
#[derive(Debug, Clone, Copy)]
pub struct RecordImage;

impl Scenario for RecordImage {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "640x480 RGB frames written into loans (connect) and recorded uncompressed by \
         Recorder: MB/s, against file-write-image"
    }

    fn targets(&self) -> Vec<Target> {
        // ≥ 0.7 × the baseline's MB/s is ≤ 1 / 0.7 × its time per frame.
        vec![Target::at_most(NAME, file_write_image::NAME, Wait::Event, 1.0 / 0.7)]
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let frames = ctx.samples(FRAMES.0, FRAMES.1);
        let warmup = ctx.warmup(frames);

        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let domain = unique_domain("esgm-bench-rec-image");
        // Dropped last (declared first).
        let coordinator =
            Coordinator::spawn(&domain, Registry::new(esgm_core::TypeRegistry::with_library()))
                .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let esgm = connect(coordinator.domain(), "bench-camera")?;
        let trajectory = create(&esgm, FRAMES_TRAJECTORY, Kind::Image)?;
        let dir = tempfile::tempdir().context("could not make a temporary folder")?;
        let path = dir.path().join("record-image.mcap");
        let writer =
            RecordingWriter::create(&path, RecordOptions::default().compression(Compression::None))
                .with_context(|| format!("could not create {}", path.display()))?;
        let recorder = Recorder::start(
            &esgm,
            &[FRAMES_TRAJECTORY.to_owned()],
            writer,
            recorder::DEFAULT_BUFFER,
        )
        .context("could not start the recorder")?;

        let mut per_frame = Latency::new()?;
        let mut write = Latency::new()?;
        let (mut in_loans, mut stalled) = (0u64, None);
        let base = handled(&recorder);
        for i in 1..=warmup + frames {
            let making = Instant::now();
            let es = stamped(make_for(&trajectory, Kind::Image, i), i as i64);
            let made = making.elapsed();
            let held = es.get("image_data").and_then(Value::as_octets).is_some_and(|o| o.is_held());
            let start = Instant::now();
            add(&trajectory, es)?;
            if !wait_handled_spinning(&recorder, base + i) {
                stalled = Some(i);
                break;
            }
            if i > warmup {
                per_frame.record(start.elapsed());
                write.record(made);
                in_loans += u64::from(held);
            }
        }
        let (summary, stats) = recorder.stop().context("could not stop the recorder")?;
        let bytes = file_bytes(&summary)?;
        dir.close().context("could not remove the temporary folder")?;
        drop(trajectory);
        drop(esgm);
        drop(coordinator);

        let p50 = per_frame.quantile(0.5);
        let mut row = per_frame
            .measurement(NAME, Wait::Event)
            .payload_bytes(PIXEL_BYTES as u64)
            .method(Method::PerItem)
            .wait_strategy("block")
            .baseline(file_write_image::NAME)
            .producer_write_p50_ns(write.quantile(0.5))
            .throughput(1e9 / p50.max(1) as f64, stats.missed())
            .if_empty("no frame was recorded")
            .note(format!(
                "{:.0} MB/s at the p50 frame ({:.0} MB/s at p99), uncompressed; {} frames \
                 recorded in all, {in_loans} of {} timed frames rendered into loans",
                mb_per_s(p50),
                mb_per_s(per_frame.quantile(0.99)),
                stats.recorded(),
                per_frame.len()
            ))
            .note(losses_note(&stats))
            .note(format!(
                "file: {:.1} MB, {:.0} bytes per frame",
                bytes as f64 / 1e6,
                bytes as f64 / stats.recorded().max(1) as f64
            ));
        if let Some(i) = stalled {
            row = row.note(format!("STALLED: frame {i} was not recorded"));
        }
        Ok(vec![row])
    }
}

/// Waits until the recorder has handled `target` structures, yielding between looks;
/// false if it made no progress for [`super::record_small::STALL`] or failed.
fn wait_handled_spinning(recorder: &Recorder, target: u64) -> bool {
    let (mut last, mut since) = (handled(recorder), Instant::now());
    while last < target {
        if recorder.failed() {
            return false;
        }
        std::thread::yield_now();
        let now = handled(recorder);
        if now > last {
            (last, since) = (now, Instant::now());
        } else if since.elapsed() > super::record_small::STALL {
            return false;
        }
    }
    true
}
