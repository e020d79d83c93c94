//! `inproc-hop-image`: one hop of a 640×480 RGB image through the in-process runtime.
//!
//! The same ping-pong as `inproc-hop-small` (see [`super::inproc_echo`]), carrying a
//! 921,600-byte `Image`. Before each hop the producer writes every pixel of a fresh
//! frame straight into its shared buffer (timed apart, reported beside the hop); the
//! timed hop starts when the structure is complete. Each reader reads one pixel at
//! each end. In process the pixels are shared, never copied, so this hop should cost
//! about what the small one does: it is compared with `inproc-hop-small`, and the run
//! checks that the structure that came back is the allocation that was sent.

use std::sync::Arc;

use esgm_core::library::Image;
use esgm_core::{Clock, Entity, EntityStructure, Octets, SystemClock};

use super::inproc_echo::{Payload, ping_pong};
use super::inproc_hop_small;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "inproc-hop-image";

const WIDTH: usize = 640;
const HEIGHT: usize = 480;
/// Bytes of pixels: 640 × 480 × 3.
pub const PIXEL_BYTES: usize = WIDTH * HEIGHT * 3;

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct InprocHopImage;

impl Scenario for InprocHopImage {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "add of a 921,600-byte 640x480 RGB Image (pixels written before each hop) -> subscriber"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        Wait::BOTH
            .iter()
            .map(|&wait| {
                let run = ping_pong(ctx, wait, Frames)?;
                let shared = if run.shared {
                    "pixels shared, not copied: every structure came back as the allocation sent"
                } else {
                    "the structure came back as a different allocation: it was copied"
                };
                Ok(run
                    .one_way
                    .measurement(NAME, wait)
                    .payload_bytes(run.payload_bytes)
                    .method(Method::HalfRoundTrip)
                    .baseline(inproc_hop_small::NAME)
                    .producer_write_p50_ns(run.make.quantile(0.5))
                    .note(shared))
            })
            .collect()
    }
}

/// Fresh frames, each with a different pattern.
#[derive(Debug, Clone, Copy, Default)]
pub struct Frames;

impl Payload for Frames {
    const TYPE_NAME: &'static str = "Image";

    fn make(&mut self, i: u64) -> EntityStructure {
        let seed = i as u8;
        // Collected straight into the shared buffer: one allocation, one write of
        // every byte, no intermediate copy.
        let pixels: Arc<[u8]> = (0..PIXEL_BYTES).map(|k| (k as u8).wrapping_add(seed)).collect();
        let now = SystemClock.now();
        Image {
            width: WIDTH as i64,
            height: HEIGHT as i64,
            format: Image::FORMAT_RGB8,
            image_data: Octets::new(pixels),
        }
        .to_structure("camera", now, now)
    }

    fn touch(es: &esgm_core::SharedStructure) -> u64 {
        let Some(pixels) = es.get("image_data").and_then(|v| v.as_bytes()) else { return 0 };
        let first = pixels.first().copied().unwrap_or(0);
        let last = pixels.last().copied().unwrap_or(0);
        u64::from(first) + u64::from(last)
    }
}
