//! A synthetic camera scene: bright discs moving over a dark, noisy background.
//!
//! The frame is split into a grid of cells, one per disc, and each disc moves on a
//! Lissajous curve inside its cell while its radius breathes (as an object coming closer
//! and going away would). Keeping every disc in its own cell, with background around
//! it, means discs never touch: the ground truth is unambiguous and a correct detector
//! must find exactly one blob per disc.

use std::f64::consts::TAU;

use esgm_core::Time;
use esgm_core::library::{Blob, Image};
use esgm_core::value::Octets;

use crate::frame_source::{FrameSource, MAX_DIMENSION, RenderError, check_buffer};
use crate::noise::{XorShift64, mix};

/// Background channel values are `BACKGROUND_BASE + (noise & BACKGROUND_NOISE_MASK)`:
/// at most 39, far below any sensible detection threshold.
const BACKGROUND_BASE: u8 = 8;
const BACKGROUND_NOISE_MASK: u8 = 0x1F;
/// Disc pixels lose up to this much of their colour to noise.
const BLOB_NOISE_MASK: u8 = 0x0F;
/// Background pixels kept between a disc and the edge of its cell, so neighbouring discs
/// never touch, even under 8-connectivity.
const CELL_MARGIN: f64 = 2.0;
/// The smallest cell side that still fits a disc worth detecting.
const MIN_CELL_SIDE: f64 = 16.0;
/// Radii breathe by this fraction around their base value.
const BREATHING: f64 = 0.2;
/// Bright colours whose luminance stays above 180 after noise, so any threshold between
/// the background's 39 and that separates discs from background.
const PALETTE: [[u8; 3]; 6] = [
    [255, 255, 255],
    [255, 255, 64],
    [64, 255, 255],
    [128, 255, 128],
    [255, 180, 220],
    [255, 200, 80],
];

/// A deterministic scene of moving bright discs: a [`FrameSource`] with ground truth.
///
/// Build one with [`SyntheticScene::builder`].
#[derive(Debug, Clone)]
pub struct SyntheticScene {
    width: u32,
    height: u32,
    seed: u64,
    discs: Vec<MovingDisc>,
}

/// The settings of a [`SyntheticScene`]; [`SyntheticSceneBuilder::create`] checks them.
#[derive(Debug, Clone)]
pub struct SyntheticSceneBuilder {
    width: u32,
    height: u32,
    blobs: usize,
    seed: u64,
}

/// A [`SyntheticScene`] could not be built from its settings.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SceneBuildError {
    /// A side is zero or above [`MAX_DIMENSION`]: choose a size between 1 and that.
    #[error("a {width}×{height} frame is not supported: each side must be 1..={max} pixels")]
    UnsupportedSize {
        /// The width asked for.
        width: u32,
        /// The height asked for.
        height: u32,
        /// The largest side supported.
        max: u32,
    },
    /// The frame is too small to give each blob a cell of its own: ask for fewer blobs
    /// or a larger frame.
    #[error(
        "{blobs} blobs do not fit a {width}×{height} frame: each needs a cell of at least 16×16 pixels"
    )]
    TooManyBlobs {
        /// The number of blobs asked for.
        blobs: usize,
        /// The frame width.
        width: u32,
        /// The frame height.
        height: u32,
    },
}

/// One disc's trajectory, fixed at build time.
#[derive(Debug, Clone, Copy)]
struct MovingDisc {
    /// The middle of its trajectory (its cell's centre), in pixel coordinates.
    home: (f64, f64),
    /// How far it swings from `home` in x and y.
    amplitude: (f64, f64),
    /// Periods of the x, y and radius oscillations in ns, each positive.
    periods: [Time; 3],
    /// Phases of the x, y and radius oscillations in radians.
    phases: [f64; 3],
    /// Radius around which it breathes, in pixels.
    base_radius: f64,
    colour: [u8; 3],
}

impl MovingDisc {
    /// Centre and radius at time `t`.
    fn at(&self, t: Time) -> (f64, f64, f64) {
        // Phases are taken modulo integer periods, so huge (wall-clock) times lose no
        // precision.
        let wave = |k: usize| {
            let period = self.periods[k];
            (TAU * (t.rem_euclid(period) as f64 / period as f64) + self.phases[k]).sin()
        };
        let x = self.home.0 + self.amplitude.0 * wave(0);
        let y = self.home.1 + self.amplitude.1 * wave(1);
        let r = self.base_radius * (1.0 + BREATHING * wave(2));
        (x, y, r)
    }
}

/// The horizontal runs of pixels `(row, first column, last column)` whose centres lie in
/// the disc, clipped to the frame. Painting and ground truth both use it, so the truth's
/// areas are exactly the painted pixel counts.
fn disc_spans(
    (cx, cy, r): (f64, f64, f64),
    width: u32,
    height: u32,
) -> impl Iterator<Item = (usize, usize, usize)> {
    let last_col = f64::from(width) - 1.0;
    let first_row = (cy - r).ceil().max(0.0);
    let last_row = (cy + r).floor().min(f64::from(height) - 1.0);
    // Empty when the disc misses the frame (never, for discs kept inside their cells).
    let rows = first_row as usize..(last_row + 1.0).max(first_row) as usize;
    rows.filter_map(move |row| {
        let dy = row as f64 - cy;
        let half = (r * r - dy * dy).sqrt();
        if half.is_nan() {
            return None;
        }
        let x0 = (cx - half).ceil().max(0.0);
        let x1 = (cx + half).floor().min(last_col);
        (x0 <= x1).then_some((row, x0 as usize, x1 as usize))
    })
}

impl SyntheticScene {
    /// Settings for a scene, defaulting to the seed's 640×480 camera with 3 blobs and
    /// seed 0.
    pub fn builder() -> SyntheticSceneBuilder {
        SyntheticSceneBuilder::default()
    }

    /// The number of discs in the scene.
    pub fn blob_count(&self) -> usize {
        self.discs.len()
    }

    /// The seed the scene was built from.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The ground truth at time `t`, one [`Blob`] per disc in build order: the disc's
    /// centre rounded to the nearest pixel and its area as the exact number of pixels
    /// painted. What a perfect detector reports, up to rounding of the centroid.
    pub fn truth(&self, t: Time) -> Vec<Blob> {
        self.discs
            .iter()
            .map(|disc| {
                let (cx, cy, r) = disc.at(t);
                let size = disc_spans((cx, cy, r), self.width, self.height)
                    .map(|(_, x0, x1)| (x1 - x0 + 1) as i64)
                    .sum();
                Blob { x: cx.round() as i64, y: cy.round() as i64, size }
            })
            .collect()
    }

    /// Paints the frame for `t` into `out`; never panics, whatever `out`'s length
    /// (callers check it first).
    fn paint(&self, t: Time, out: &mut [u8]) {
        // The noise differs frame to frame, as a real sensor's does, yet is a pure
        // function of seed and time.
        let mut noise = XorShift64::new(mix(self.seed) ^ t as u64);
        for chunk in out.chunks_mut(8) {
            let word = noise.next_u64().to_le_bytes();
            for (byte, n) in chunk.iter_mut().zip(word) {
                *byte = BACKGROUND_BASE + (n & BACKGROUND_NOISE_MASK);
            }
        }
        let width = self.width as usize;
        for disc in &self.discs {
            for (row, x0, x1) in disc_spans(disc.at(t), self.width, self.height) {
                let start = (row * width + x0) * 3;
                let end = (row * width + x1 + 1) * 3;
                let Some(run) = out.get_mut(start..end) else { continue };
                for pixel in run.chunks_exact_mut(3) {
                    for (channel, colour) in pixel.iter_mut().zip(disc.colour) {
                        // Reuse the background noise under the disc as its noise.
                        *channel = colour.saturating_sub(*channel & BLOB_NOISE_MASK);
                    }
                }
            }
        }
    }
}

impl FrameSource for SyntheticScene {
    fn width(&self) -> u32 {
        self.width
    }

    fn height(&self) -> u32 {
        self.height
    }

    fn render_into(&self, t: Time, out: &mut [u8]) -> Result<(), RenderError> {
        check_buffer(self.frame_len(), out)?;
        self.paint(t, out);
        Ok(())
    }

    fn frame(&self, t: Time) -> Image {
        let mut pixels = vec![0u8; self.frame_len()];
        self.paint(t, &mut pixels);
        Image {
            width: i64::from(self.width),
            height: i64::from(self.height),
            format: Image::FORMAT_RGB8,
            image_data: Octets::from(pixels),
        }
    }
}

impl Default for SyntheticSceneBuilder {
    fn default() -> Self {
        Self { width: 640, height: 480, blobs: 3, seed: 0 }
    }
}

impl SyntheticSceneBuilder {
    /// Frame width in pixels (default 640).
    pub fn width(mut self, width: u32) -> Self {
        self.width = width;
        self
    }

    /// Frame height in pixels (default 480).
    pub fn height(mut self, height: u32) -> Self {
        self.height = height;
        self
    }

    /// Number of moving discs (default 3); zero gives a background-only scene.
    pub fn blobs(mut self, blobs: usize) -> Self {
        self.blobs = blobs;
        self
    }

    /// Seed of the disc sizes, colours and trajectories and of the noise (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Checks the settings and lays the discs out.
    pub fn create(self) -> Result<SyntheticScene, SceneBuildError> {
        let Self { width, height, blobs, seed } = self;
        if !(1..=MAX_DIMENSION).contains(&width) || !(1..=MAX_DIMENSION).contains(&height) {
            return Err(SceneBuildError::UnsupportedSize { width, height, max: MAX_DIMENSION });
        }
        let too_many = SceneBuildError::TooManyBlobs { blobs, width, height };
        if blobs > (width as usize * height as usize) {
            return Err(too_many);
        }
        let (w, h) = (f64::from(width), f64::from(height));
        // A grid whose cells are about square: columns / rows ≈ width / height.
        let cols = if blobs == 0 {
            1
        } else {
            ((blobs as f64 * w / h).sqrt().ceil() as usize).clamp(1, blobs)
        };
        let rows = blobs.div_ceil(cols).max(1);
        let (cell_w, cell_h) = (w / cols as f64, h / rows as f64);
        if blobs > 0 && cell_w.min(cell_h) < MIN_CELL_SIDE {
            return Err(too_many);
        }
        // The largest radius, breathing included, that stays CELL_MARGIN inside a cell.
        let room = (cell_w.min(cell_h) - 1.0) / 2.0 - CELL_MARGIN;
        let mut rng = XorShift64::new(seed);
        let discs = (0..blobs)
            .map(|i| {
                let (col, row) = ((i % cols) as f64, (i / cols) as f64);
                let base_radius = room * (0.3 + 0.3 * rng.next_unit());
                let max_radius = base_radius * (1.0 + BREATHING);
                let period = |rng: &mut XorShift64| (4.0e9 + 12.0e9 * rng.next_unit()) as Time;
                let periods = [period(&mut rng), period(&mut rng), period(&mut rng)];
                let phases = [rng.next_unit() * TAU, rng.next_unit() * TAU, rng.next_unit() * TAU];
                let colour = PALETTE[(rng.next_u64() % PALETTE.len() as u64) as usize];
                MovingDisc {
                    home: (
                        col * cell_w + (cell_w - 1.0) / 2.0,
                        row * cell_h + (cell_h - 1.0) / 2.0,
                    ),
                    amplitude: (
                        ((cell_w - 1.0) / 2.0 - CELL_MARGIN - max_radius).max(0.0),
                        ((cell_h - 1.0) / 2.0 - CELL_MARGIN - max_radius).max(0.0),
                    ),
                    periods,
                    phases,
                    base_radius,
                    colour,
                }
            })
            .collect();
        Ok(SyntheticScene { width, height, seed, discs })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::time::millis;

    fn scene(blobs: usize, seed: u64) -> SyntheticScene {
        SyntheticScene::builder().blobs(blobs).seed(seed).create().unwrap()
    }

    fn luminance(p: &[u8]) -> u32 {
        (77 * u32::from(p[0]) + 150 * u32::from(p[1]) + 29 * u32::from(p[2]) + 128) >> 8
    }

    #[test]
    fn defaults_are_the_seed_camera() {
        let s = scene(3, 0);
        assert_eq!((s.width(), s.height(), s.frame_len()), (640, 480, 640 * 480 * 3));
        let f = s.frame(0);
        assert_eq!((f.width, f.height, f.format), (640, 480, Image::FORMAT_RGB8));
        assert_eq!(f.image_data.len(), 640 * 480 * 3);
    }

    #[test]
    fn rendering_is_a_pure_function_of_seed_and_time() {
        let (a, b) = (scene(4, 9), scene(4, 9));
        assert_eq!(a.frame(millis(250)), b.frame(millis(250)));
        assert_ne!(a.frame(millis(250)).image_data, a.frame(millis(500)).image_data);
        assert_ne!(a.truth(0), scene(4, 10).truth(0));
    }

    #[test]
    fn render_into_matches_frame_and_rejects_wrong_buffers() {
        let s = scene(2, 3);
        let mut buf = vec![0u8; s.frame_len()];
        s.render_into(millis(40), &mut buf).unwrap();
        assert_eq!(&s.frame(millis(40)).image_data[..], &buf[..]);
        let mut short = vec![0u8; s.frame_len() - 1];
        assert_eq!(
            s.render_into(0, &mut short),
            Err(RenderError::WrongBufferLength {
                expected: s.frame_len(),
                actual: s.frame_len() - 1
            })
        );
    }

    #[test]
    fn discs_are_bright_and_background_is_dark() {
        let s = scene(3, 1);
        let t = millis(1234);
        let f = s.frame(t);
        let bright = f.image_data.chunks_exact(3).filter(|p| luminance(p) > 127).count();
        let truth_area: i64 = s.truth(t).iter().map(|b| b.size).sum();
        assert_eq!(bright as i64, truth_area);
        assert!(
            f.image_data.chunks_exact(3).all(|p| { luminance(p) <= 39 || luminance(p) >= 180 })
        );
        for b in s.truth(t) {
            let i = (b.y as usize * 640 + b.x as usize) * 3;
            assert!(luminance(&f.image_data[i..i + 3]) >= 180, "centre of {b:?} is not bright");
        }
    }

    #[test]
    fn discs_stay_inside_their_cells_over_time() {
        let s = scene(6, 5);
        for k in 0..200 {
            let t = millis(97 * k) - 3_000_000_000;
            for (i, disc) in s.discs.iter().enumerate() {
                let (cx, cy, r) = disc.at(t);
                assert!(r > 1.0);
                let (col, row) = ((i % 3) as f64, (i / 3) as f64);
                let (cw, ch) = (640.0 / 3.0, 480.0 / 2.0);
                assert!(cx - r >= col * cw + CELL_MARGIN - 1e-9, "disc {i} left of its cell");
                assert!(cx + r <= (col + 1.0) * cw - 1.0 - CELL_MARGIN + 1e-9);
                assert!(cy - r >= row * ch + CELL_MARGIN - 1e-9);
                assert!(cy + r <= (row + 1.0) * ch - 1.0 - CELL_MARGIN + 1e-9);
            }
        }
    }

    #[test]
    fn wall_clock_times_render() {
        let s = scene(3, 2);
        let t = 1_700_000_000_000_000_000;
        let truth = s.truth(t);
        assert_eq!(truth.len(), 3);
        assert!(truth.iter().all(|b| b.size > 0));
        assert_eq!(s.truth(i64::MIN).len(), 3);
        assert_eq!(s.truth(i64::MAX).len(), 3);
    }

    #[test]
    fn bad_settings_are_rejected() {
        let err = |b: SyntheticSceneBuilder| b.create().unwrap_err();
        assert!(matches!(
            err(SyntheticScene::builder().width(0)),
            SceneBuildError::UnsupportedSize { .. }
        ));
        assert!(matches!(
            err(SyntheticScene::builder().height(MAX_DIMENSION + 1)),
            SceneBuildError::UnsupportedSize { .. }
        ));
        assert!(matches!(
            err(SyntheticScene::builder().width(64).height(48).blobs(50)),
            SceneBuildError::TooManyBlobs { blobs: 50, .. }
        ));
        assert!(matches!(
            err(SyntheticScene::builder().blobs(usize::MAX)),
            SceneBuildError::TooManyBlobs { .. }
        ));
        let empty = SyntheticScene::builder().width(1).height(1).blobs(0).create().unwrap();
        assert!(empty.truth(0).is_empty());
        assert_eq!(empty.frame(0).image_data.len(), 3);
    }
}
