//! The `BlobDetection` unit (the seed's BlobDetector, tutorial 9.1): bright regions of
//! an image as a [`BlobSeq`].
//!
//! A pixel is *foreground* when its luminance is strictly above a threshold; blobs are
//! the connected components of foreground pixels. Components are labelled in one pass
//! over the image with a union-find over provisional labels, keeping only the previous
//! and current rows of labels, so time is linear in the pixel count (up to the
//! near-constant inverse Ackermann factor) and scratch memory is two rows plus one entry
//! per provisional label.

use esgm_core::library::{Blob, BlobSeq, Image};

/// Which neighbours make two foreground pixels part of one blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Connectivity {
    /// Left, right, up and down: pixels touching only at a corner are separate blobs.
    Four,
    /// The four plus the diagonals: pixels touching at a corner are one blob. The
    /// default, because a thin diagonal edge of one object should not split it.
    #[default]
    Eight,
}

/// The settings of a [`BlobDetector`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlobDetectionConfig {
    /// A pixel is foreground when its luminance (see [`luminance`]) is strictly above
    /// this, as in OpenCV's binary threshold; 255 finds nothing. Default 127.
    pub threshold: u8,
    /// Which pixels count as neighbours. Default [`Connectivity::Eight`].
    pub connectivity: Connectivity,
    /// Blobs with fewer pixels are dropped, as noise. Default 10.
    pub min_size: u64,
}

impl Default for BlobDetectionConfig {
    fn default() -> Self {
        Self { threshold: 127, connectivity: Connectivity::Eight, min_size: 10 }
    }
}

/// An image the detector cannot read. The image is left untouched; the caller skips
/// it (the unit yields no value for it).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DetectionError {
    /// A side is negative: the producer wrote a corrupt header; drop the image.
    #[error("image has a negative size: {width}×{height}")]
    NegativeSize {
        /// The width given.
        width: i64,
        /// The height given.
        height: i64,
    },
    /// The pixel format is neither [`Image::FORMAT_RGB8`] nor [`Image::FORMAT_MONO8`]:
    /// convert the image first.
    #[error("unknown image format {format}: expected RGB8 (0) or MONO8 (1)")]
    UnknownFormat {
        /// The format given.
        format: i64,
    },
    /// A side exceeds [`BlobDetector::MAX_SIDE`] or the image has more than
    /// [`BlobDetector::MAX_PIXELS`] pixels: scale it down.
    #[error("a {width}×{height} image is larger than the detector supports")]
    TooLarge {
        /// The width given.
        width: i64,
        /// The height given.
        height: i64,
    },
    /// The pixel data is not `width × height × bytes per pixel` long: the image is
    /// truncated or its header is wrong; drop it.
    #[error("image data is {actual} bytes, its size and format need {expected}")]
    DataLengthMismatch {
        /// The length the header implies.
        expected: usize,
        /// The length found.
        actual: usize,
    },
}

/// The luminance of an RGB pixel: ITU-R BT.601 weights (0.299, 0.587, 0.114) in 8-bit
/// fixed point, rounded. The weights sum to 256, so white maps to 255 exactly.
///
/// Note what this means for thresholds: saturated red is only 77 and saturated blue 29.
pub fn luminance([r, g, b]: [u8; 3]) -> u8 {
    ((77 * u32::from(r) + 150 * u32::from(g) + 29 * u32::from(b) + 128) >> 8) as u8
}

/// Running moments of one provisional label.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    sum_x: u64,
    sum_y: u64,
    count: u64,
}

impl Moments {
    fn add(&mut self, other: Moments) {
        self.sum_x += other.sum_x;
        self.sum_y += other.sum_y;
        self.count += other.count;
    }
}

/// Integer `numerator / denominator` rounded half up; `denominator` is non-zero.
fn round_div(numerator: u64, denominator: u64) -> i64 {
    ((2 * numerator + denominator) / (2 * denominator)) as i64
}

/// The blob detection unit: finds the blobs of an [`Image`], reusing its scratch space
/// from one image to the next.
#[derive(Debug, Clone, Default)]
pub struct BlobDetector {
    config: BlobDetectionConfig,
    /// Foreground flags of the current row.
    mask: Vec<bool>,
    /// Provisional labels of the previous and current rows; 0 is background.
    prev: Vec<u32>,
    cur: Vec<u32>,
    /// Union-find parents of provisional labels; index 0 is unused.
    parent: Vec<u32>,
    /// Moments of each provisional label, summed into its root at the end.
    moments: Vec<Moments>,
}

impl BlobDetector {
    /// The longest side accepted: far above any camera, and small enough that centroid
    /// sums cannot overflow.
    pub const MAX_SIDE: i64 = 1 << 24;
    /// The most pixels accepted: labels are `u32`, and 0 means background.
    pub const MAX_PIXELS: u64 = u32::MAX as u64 - 1;

    /// A detector with the given settings.
    pub fn new(config: BlobDetectionConfig) -> Self {
        Self { config, ..Self::default() }
    }

    /// The settings.
    pub fn config(&self) -> &BlobDetectionConfig {
        &self.config
    }

    /// The settings, to change between images.
    pub fn config_mut(&mut self) -> &mut BlobDetectionConfig {
        &mut self.config
    }

    /// The blobs of `image`, largest first (ties: topmost, then leftmost centroid),
    /// each with its centroid rounded to the nearest pixel (halves up) and its size in
    /// pixels; blobs smaller than `min_size` are left out.
    pub fn detect(&mut self, image: &Image) -> Result<BlobSeq, DetectionError> {
        self.detect_pixels(image.width, image.height, image.format, &image.image_data)
    }

    /// As [`detect`](Self::detect), from an image's fields, for callers that read
    /// them in place (an archived image in shared memory) rather than as an [`Image`].
    pub fn detect_pixels(
        &mut self,
        width: i64,
        height: i64,
        format: i64,
        data: &[u8],
    ) -> Result<BlobSeq, DetectionError> {
        let (w, h) = Self::check(width, height, format, data)?;
        if w == 0 || h == 0 {
            return Ok(BlobSeq { items: Vec::new() });
        }
        let eight = self.config.connectivity == Connectivity::Eight;
        let threshold = self.config.threshold;

        self.mask.clear();
        self.mask.resize(w, false);
        self.prev.clear();
        self.prev.resize(w, 0);
        self.cur.clear();
        self.cur.resize(w, 0);
        self.parent.clear();
        self.parent.push(0);
        self.moments.clear();
        self.moments.push(Moments::default());

        // `check` proved `data` is exactly `h` rows of `data.len() / h` bytes.
        for (y, row) in data.chunks_exact(data.len() / h).enumerate() {
            if format == Image::FORMAT_RGB8 {
                for (m, p) in self.mask.iter_mut().zip(row.chunks_exact(3)) {
                    *m = luminance([p[0], p[1], p[2]]) > threshold;
                }
            } else {
                for (m, &p) in self.mask.iter_mut().zip(row) {
                    *m = p > threshold;
                }
            }
            for x in 0..w {
                if !self.mask[x] {
                    self.cur[x] = 0;
                    continue;
                }
                let left = if x > 0 { self.cur[x - 1] } else { 0 };
                let up = self.prev[x];
                let (up_left, up_right) = if eight {
                    (
                        if x > 0 { self.prev[x - 1] } else { 0 },
                        if x + 1 < w { self.prev[x + 1] } else { 0 },
                    )
                } else {
                    (0, 0)
                };
                let mut label = 0;
                for neighbour in [left, up, up_left, up_right] {
                    if neighbour == 0 || neighbour == label {
                        continue;
                    }
                    label = if label == 0 { neighbour } else { self.union(label, neighbour) };
                }
                if label == 0 {
                    // Fits: at most MAX_PIXELS labels, checked above.
                    label = self.parent.len() as u32;
                    self.parent.push(label);
                    self.moments.push(Moments::default());
                }
                self.cur[x] = label;
                let m = &mut self.moments[label as usize];
                m.sum_x += x as u64;
                m.sum_y += y as u64;
                m.count += 1;
            }
            std::mem::swap(&mut self.prev, &mut self.cur);
        }

        // Fold every provisional label's moments into its component's root.
        for label in 1..self.parent.len() as u32 {
            let root = self.find(label);
            if root != label {
                let moments = self.moments[label as usize];
                self.moments[root as usize].add(moments);
            }
        }
        let min_size = self.config.min_size.max(1);
        let mut items: Vec<Blob> = (1..self.parent.len())
            .filter(|&label| self.parent[label] as usize == label)
            .map(|label| self.moments[label])
            .filter(|m| m.count >= min_size)
            .map(|m| Blob {
                x: round_div(m.sum_x, m.count),
                y: round_div(m.sum_y, m.count),
                size: m.count as i64,
            })
            .collect();
        items.sort_unstable_by(|a, b| b.size.cmp(&a.size).then(a.y.cmp(&b.y)).then(a.x.cmp(&b.x)));
        Ok(BlobSeq { items })
    }

    /// Validates an image header against its data; returns width and height.
    fn check(
        width: i64,
        height: i64,
        format: i64,
        data: &[u8],
    ) -> Result<(usize, usize), DetectionError> {
        if width < 0 || height < 0 {
            return Err(DetectionError::NegativeSize { width, height });
        }
        let bpp = Image::bytes_per_pixel(format).ok_or(DetectionError::UnknownFormat { format })?;
        let too_large = DetectionError::TooLarge { width, height };
        if width > Self::MAX_SIDE || height > Self::MAX_SIDE {
            return Err(too_large);
        }
        // Both sides are at most 2^24, so these products fit in u64.
        let pixels = width as u64 * height as u64;
        if pixels > Self::MAX_PIXELS {
            return Err(too_large);
        }
        let expected = usize::try_from(pixels * bpp as u64).map_err(|_| too_large)?;
        if data.len() != expected {
            return Err(DetectionError::DataLengthMismatch { expected, actual: data.len() });
        }
        Ok((width as usize, height as usize))
    }

    /// The root of `label`, halving paths on the way.
    fn find(&mut self, mut label: u32) -> u32 {
        while self.parent[label as usize] != label {
            let grandparent = self.parent[self.parent[label as usize] as usize];
            self.parent[label as usize] = grandparent;
            label = grandparent;
        }
        label
    }

    /// Merges the components of `a` and `b`; the smaller root survives, so roots are
    /// stable and the result is independent of merge order.
    fn union(&mut self, a: u32, b: u32) -> u32 {
        let (ra, rb) = (self.find(a), self.find(b));
        let (root, child) = if ra <= rb { (ra, rb) } else { (rb, ra) };
        self.parent[child as usize] = root;
        root
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A MONO8 image from rows of `#` (255) and `.` (0).
    fn mono(rows: &[&str]) -> Image {
        let height = rows.len() as i64;
        let width = rows.first().map_or(0, |r| r.len()) as i64;
        let data: Vec<u8> =
            rows.iter().flat_map(|r| r.bytes().map(|c| if c == b'#' { 255 } else { 0 })).collect();
        Image { width, height, format: Image::FORMAT_MONO8, image_data: data.into() }
    }

    fn detector(connectivity: Connectivity) -> BlobDetector {
        BlobDetector::new(BlobDetectionConfig { connectivity, min_size: 1, ..Default::default() })
    }

    fn blobs(connectivity: Connectivity, rows: &[&str]) -> Vec<Blob> {
        detector(connectivity).detect(&mono(rows)).unwrap().items
    }

    fn b(x: i64, y: i64, size: i64) -> Blob {
        Blob { x, y, size }
    }

    #[test]
    fn diagonal_neighbours_join_only_under_eight_connectivity() {
        let main_diagonal = ["#...", ".#..", "..#.", "...."];
        assert_eq!(blobs(Connectivity::Eight, &main_diagonal), [b(1, 1, 3)]);
        assert_eq!(blobs(Connectivity::Four, &main_diagonal), [b(0, 0, 1), b(1, 1, 1), b(2, 2, 1)]);
        // The up-right neighbour, which the scan order reaches last.
        let anti_diagonal = ["..#", ".#.", "#.."];
        assert_eq!(blobs(Connectivity::Eight, &anti_diagonal), [b(1, 1, 3)]);
        assert_eq!(blobs(Connectivity::Four, &anti_diagonal).len(), 3);
    }

    #[test]
    fn branches_that_meet_later_are_one_blob() {
        // Three arms labelled apart on the first row, joined on the last.
        let comb = ["#.#.#", "#.#.#", "#####"];
        assert_eq!(blobs(Connectivity::Four, &comb), [b(2, 1, 11)]);
        // A spiral: its equivalences chain through several unions.
        let spiral = ["#######", "#.....#", "#.###.#", "#.#.#.#", "#.#...#", "#.#####"];
        let found = blobs(Connectivity::Four, &spiral);
        assert_eq!(found.len(), 1);
        assert_eq!(
            found[0].size,
            spiral.iter().map(|r| r.matches('#').count() as i64).sum::<i64>()
        );
    }

    #[test]
    fn blobs_on_borders_and_corners_are_found() {
        let rows = ["##..##", "#....#", "......", "#.##.#", "##..##"];
        let found = blobs(Connectivity::Four, &rows);
        assert_eq!(found.len(), 5);
        assert_eq!(&found[..4], [b(0, 0, 3), b(5, 0, 3), b(0, 4, 3), b(5, 4, 3)]);
        assert_eq!(found[4], b(3, 3, 2)); // centroid x 2.5 rounds up
        assert_eq!(blobs(Connectivity::Four, &["#"]), [b(0, 0, 1)]);
        assert_eq!(blobs(Connectivity::Eight, &["#", "#", "#"]), [b(0, 1, 3)]);
    }

    #[test]
    fn all_dark_finds_nothing_and_all_bright_finds_one_blob() {
        let mut d = BlobDetector::default();
        let dark = Image {
            width: 640,
            height: 480,
            format: Image::FORMAT_RGB8,
            image_data: vec![0u8; 640 * 480 * 3].into(),
        };
        assert!(d.detect(&dark).unwrap().items.is_empty());
        let bright = Image { image_data: vec![255u8; 640 * 480 * 3].into(), ..dark };
        // Centroid (319.5, 239.5) rounds halves up.
        assert_eq!(d.detect(&bright).unwrap().items, [b(320, 240, 640 * 480)]);
        let empty = Image { width: 0, height: 0, image_data: Vec::new().into(), ..bright };
        assert!(d.detect(&empty).unwrap().items.is_empty());
        let no_rows = Image { width: 5, height: 0, ..empty };
        assert!(d.detect(&no_rows).unwrap().items.is_empty());
    }

    #[test]
    fn threshold_is_strict_and_on_luminance() {
        let pixels = |data: Vec<u8>| Image {
            width: data.len() as i64 / 3,
            height: 1,
            format: Image::FORMAT_RGB8,
            image_data: data.into(),
        };
        let mut d = detector(Connectivity::Four);
        // Pure red has luminance 77, pure green 149: only green is above 127.
        let found = d.detect(&pixels(vec![255, 0, 0, 0, 0, 0, 0, 255, 0])).unwrap().items;
        assert_eq!(found, [b(2, 0, 1)]);
        assert_eq!((luminance([255, 0, 0]), luminance([0, 255, 0])), (77, 149));
        assert_eq!((luminance([255, 255, 255]), luminance([0, 0, 255])), (255, 29));

        d.config_mut().threshold = 100;
        let grey = Image { width: 3, format: Image::FORMAT_MONO8, ..pixels(vec![100, 101, 99]) };
        assert_eq!(d.detect(&grey).unwrap().items, [b(1, 0, 1)]);
        d.config_mut().threshold = 255;
        assert!(d.detect(&mono(&["###"])).unwrap().items.is_empty());
    }

    #[test]
    fn small_blobs_are_dropped_and_the_rest_sorted_by_size() {
        let rows = ["#..##...", "...##..#", "......##", "###...##"];
        let mut d = detector(Connectivity::Four);
        assert_eq!(
            d.detect(&mono(&rows)).unwrap().items,
            [b(7, 2, 5), b(4, 1, 4), b(1, 3, 3), b(0, 0, 1)]
        );
        d.config_mut().min_size = 4;
        assert_eq!(d.detect(&mono(&rows)).unwrap().items, [b(7, 2, 5), b(4, 1, 4)]);
    }

    #[test]
    fn malformed_images_are_errors() {
        let mut d = BlobDetector::default();
        let ok = mono(&["##", "##"]);
        assert_eq!(
            d.detect(&Image { width: -2, ..ok.clone() }),
            Err(DetectionError::NegativeSize { width: -2, height: 2 })
        );
        assert_eq!(
            d.detect(&Image { format: 7, ..ok.clone() }),
            Err(DetectionError::UnknownFormat { format: 7 })
        );
        assert_eq!(
            d.detect(&Image { format: Image::FORMAT_RGB8, ..ok.clone() }),
            Err(DetectionError::DataLengthMismatch { expected: 12, actual: 4 })
        );
        assert_eq!(
            d.detect(&Image { width: 3, ..ok.clone() }),
            Err(DetectionError::DataLengthMismatch { expected: 6, actual: 4 })
        );
        assert!(matches!(
            d.detect(&Image { width: i64::MAX, ..ok.clone() }),
            Err(DetectionError::TooLarge { .. })
        ));
        assert!(matches!(
            d.detect(&Image { width: 1 << 20, height: 1 << 20, ..ok.clone() }),
            Err(DetectionError::TooLarge { .. })
        ));
        // The detector is still usable afterwards.
        d.config_mut().min_size = 1;
        assert_eq!(d.detect(&ok).unwrap().items, [b(1, 1, 4)]);
    }

    #[test]
    fn scratch_reuse_does_not_leak_between_images() {
        let mut reused = detector(Connectivity::Eight);
        let big = mono(&["#.#.#.#", ".#.#.#.", "#.#.#.#"]);
        let small = mono(&["#.", ".."]);
        reused.detect(&big).unwrap();
        assert_eq!(
            reused.detect(&small).unwrap(),
            detector(Connectivity::Eight).detect(&small).unwrap()
        );
        assert_eq!(
            reused.detect(&big).unwrap(),
            detector(Connectivity::Eight).detect(&big).unwrap()
        );
    }

    /// A plain flood fill: the obviously correct reference the union-find is checked
    /// against.
    fn reference(width: usize, height: usize, mask: &[bool], eight: bool) -> Vec<Blob> {
        let mut seen = vec![false; mask.len()];
        let mut out = Vec::new();
        for start in 0..mask.len() {
            if !mask[start] || seen[start] {
                continue;
            }
            seen[start] = true;
            let mut stack = vec![start];
            let (mut sx, mut sy, mut n) = (0u64, 0u64, 0u64);
            while let Some(i) = stack.pop() {
                let (x, y) = ((i % width) as i64, (i / width) as i64);
                sx += x as u64;
                sy += y as u64;
                n += 1;
                for (dx, dy) in
                    [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)]
                        .into_iter()
                        .take(if eight { 8 } else { 4 })
                {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width as i64 || ny >= height as i64 {
                        continue;
                    }
                    let j = ny as usize * width + nx as usize;
                    if mask[j] && !seen[j] {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
            out.push(Blob { x: round_div(sx, n), y: round_div(sy, n), size: n as i64 });
        }
        out.sort_unstable_by(|a, b| b.size.cmp(&a.size).then(a.y.cmp(&b.y)).then(a.x.cmp(&b.x)));
        out
    }

    proptest! {
        #[test]
        fn matches_a_flood_fill(
            (width, height, mask) in (1usize..24, 1usize..24).prop_flat_map(|(w, h)| {
                (Just(w), Just(h), proptest::collection::vec(any::<bool>(), w * h))
            }),
            eight in any::<bool>(),
        ) {
            let image = Image {
                width: width as i64,
                height: height as i64,
                format: Image::FORMAT_MONO8,
                image_data: mask.iter().map(|&m| if m { 200 } else { 10 }).collect::<Vec<u8>>().into(),
            };
            let connectivity = if eight { Connectivity::Eight } else { Connectivity::Four };
            let found = detector(connectivity).detect(&image).unwrap().items;
            prop_assert_eq!(found, reference(width, height, &mask, eight));
        }
    }
}
