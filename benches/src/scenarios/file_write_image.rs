//! `file-write-image`: the baseline of `record-image`, the same bytes per frame — a
//! 640×480 RGB frame's 921,600 pixel bytes — written sequentially into a file by a
//! plain [`std::fs::File`] loop, in the same run.
//!
//! Each frame is rendered into a buffer first (untimed, as a camera renders it), then
//! one `write_all` of it is timed; no `fsync`, as the recorder hands its chunks to the
//! operating system without one. The row's `wait` is `event` only to pair it with
//! `record-image`'s: one thread writes, nothing waits.

use std::fs::File;
use std::io::Write as _;
use std::time::Instant;

use anyhow::Context as _;

use super::inproc_hop_image::PIXEL_BYTES;
use super::ipc_payload::pattern;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "file-write-image";

/// Frames of a full run and of a `--quick` one (as `record-image`): 280 MB at most, so
/// that a file fits in the page cache's dirty pages; beyond them both rows would
/// measure the disk's write-back, and whichever runs second the first's.
pub const FRAMES: (u64, u64) = (300, 50);

/// See the module docs.
#[derive(Debug, Clone, Copy)]
pub struct FileWriteImage;

/// Writes frame `i`'s pixels into `pixels`, as a camera renders it.
pub fn render(pixels: &mut [u8], i: u64) {
    let seed = i as u8;
    for (k, p) in pixels.iter_mut().enumerate() {
        *p = pattern(k, seed);
    }
}

impl Scenario for FileWriteImage {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "baseline of record-image: 921,600 bytes per frame written by a plain std::fs::File \
         loop into a temporary file"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let frames = ctx.samples(FRAMES.0, FRAMES.1);
        let warmup = ctx.warmup(frames);
        let dir = tempfile::tempdir().context("could not make a temporary folder")?;
        let path = dir.path().join("frames.raw");
        let mut file =
            File::create(&path).with_context(|| format!("could not create {}", path.display()))?;
        let mut pixels = vec![0u8; PIXEL_BYTES];
        let mut per_frame = Latency::new()?;
        let started = Instant::now();
        let mut rendering = std::time::Duration::ZERO;
        for i in 1..=warmup + frames {
            let render_start = Instant::now();
            render(&mut pixels, i);
            let rendered = render_start.elapsed();
            let start = Instant::now();
            file.write_all(&pixels).with_context(|| format!("writing {}", path.display()))?;
            if i > warmup {
                per_frame.record(start.elapsed());
                rendering += rendered;
            }
        }
        drop(file);
        dir.close().context("could not remove the temporary folder")?;
        let wall = started.elapsed();
        let mb_s = mb_per_s(per_frame.quantile(0.5));
        let row = per_frame
            .measurement(NAME, Wait::Event)
            .payload_bytes(PIXEL_BYTES as u64)
            .method(Method::PerItem)
            .wait_strategy("none (one thread writes)")
            .throughput(1e9 / per_frame.quantile(0.5).max(1) as f64, 0)
            .if_empty("no frame was written")
            .note(format!(
                "{mb_s:.0} MB/s at the p50 frame ({:.0} MB/s at p99); {frames} frames of {} bytes \
                 after {warmup} untimed; {:.1} s wall, of which {:.0} ms rendering (untimed)",
                mb_per_s(per_frame.quantile(0.99)),
                PIXEL_BYTES,
                wall.as_secs_f64(),
                rendering.as_secs_f64() * 1e3,
            ));
        Ok(vec![row])
    }
}

/// MB/s (10^6 bytes) of one frame's pixels handled in `ns`.
pub fn mb_per_s(ns: u64) -> f64 {
    PIXEL_BYTES as f64 * 1e3 / ns.max(1) as f64
}
