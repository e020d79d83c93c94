//! A camera replaying a directory of PNG or JPEG files.

use std::path::{Path, PathBuf};

use esgm_core::Time;
use esgm_core::library::Image;
use esgm_core::value::Octets;

use crate::frame_source::{FrameSource, MAX_DIMENSION, RenderError, check_buffer};

/// Frames decoded from the PNG and JPEG files of a directory, replayed in file-name
/// order and cycled forever: frame `k` is shown for `frame_period` ns from `k ×
/// frame_period`, and time `n × frame_period` (for `n` files) shows the first again.
///
/// Every file is decoded when the directory is opened: a corrupt file is reported at
/// start-up rather than by a camera stalling mid-run, and each frame is afterwards a
/// shared buffer handed out without copying. The cost is memory: all frames are held
/// at once, as RGB8.
#[derive(Debug, Clone)]
pub struct ImageDirectory {
    frames: Vec<Image>,
    paths: Vec<PathBuf>,
    width: u32,
    height: u32,
    frame_period: Time,
}

/// A directory could not be opened as an [`ImageDirectory`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageDirectoryError {
    /// The directory could not be listed: check the path and its permissions.
    #[error("cannot list image directory {path}")]
    CannotReadDirectory {
        /// The directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The directory holds no `.png`, `.jpg` or `.jpeg` file: add some or choose another.
    #[error("no .png, .jpg or .jpeg file in {path}")]
    NoImages {
        /// The directory.
        path: PathBuf,
    },
    /// A file could not be read or decoded: fix or remove it.
    #[error("cannot decode image {path}")]
    UndecodableFile {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: image::ImageError,
    },
    /// A file's size differs from the first file's: a camera has one resolution, so
    /// scale the files to one size.
    #[error(
        "{path} is {width}×{height}, but the first image is {expected_width}×{expected_height}"
    )]
    MixedSizes {
        /// The file.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The first file's width.
        expected_width: u32,
        /// The first file's height.
        expected_height: u32,
    },
    /// A file is larger than [`MAX_DIMENSION`] on a side: scale it down.
    #[error("{path} is {width}×{height}, larger than {max} pixels on a side")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The largest side supported.
        max: u32,
    },
    /// The frame period is not positive: give each frame a duration above zero.
    #[error("frame period must be positive, got {frame_period} ns")]
    InvalidFramePeriod {
        /// The period given.
        frame_period: Time,
    },
}

/// True for the file names the directory replays.
fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["png", "jpg", "jpeg"].iter().any(|known| e.eq_ignore_ascii_case(known)))
}

impl ImageDirectory {
    /// Lists `dir`'s `.png`, `.jpg` and `.jpeg` files (any case; other files and
    /// subdirectories are ignored), sorts them by name, and decodes each to RGB8. The
    /// format is read from the file's content, not trusted from its name.
    pub fn open(dir: impl AsRef<Path>, frame_period: Time) -> Result<Self, ImageDirectoryError> {
        let dir = dir.as_ref();
        if frame_period <= 0 {
            return Err(ImageDirectoryError::InvalidFramePeriod { frame_period });
        }
        let cannot_read =
            |source| ImageDirectoryError::CannotReadDirectory { path: dir.to_path_buf(), source };
        let mut paths = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(cannot_read)? {
            let path = entry.map_err(cannot_read)?.path();
            if path.is_file() && is_image_file(&path) {
                paths.push(path);
            }
        }
        paths.sort();
        let mut frames = Vec::with_capacity(paths.len());
        let mut size = None;
        for path in &paths {
            let undecodable =
                |source| ImageDirectoryError::UndecodableFile { path: path.clone(), source };
            let rgb = image::ImageReader::open(path)
                .map_err(|e| undecodable(image::ImageError::IoError(e)))?
                .with_guessed_format()
                .map_err(|e| undecodable(image::ImageError::IoError(e)))?
                .decode()
                .map_err(undecodable)?
                .into_rgb8();
            let (width, height) = rgb.dimensions();
            if width > MAX_DIMENSION || height > MAX_DIMENSION {
                return Err(ImageDirectoryError::TooLarge {
                    path: path.clone(),
                    width,
                    height,
                    max: MAX_DIMENSION,
                });
            }
            let (expected_width, expected_height) = *size.get_or_insert((width, height));
            if (width, height) != (expected_width, expected_height) {
                return Err(ImageDirectoryError::MixedSizes {
                    path: path.clone(),
                    width,
                    height,
                    expected_width,
                    expected_height,
                });
            }
            frames.push(Image {
                width: i64::from(width),
                height: i64::from(height),
                format: Image::FORMAT_RGB8,
                image_data: Octets::from(rgb.into_raw()),
            });
        }
        let Some((width, height)) = size else {
            return Err(ImageDirectoryError::NoImages { path: dir.to_path_buf() });
        };
        Ok(Self { frames, paths, width, height, frame_period })
    }

    /// The number of frames, at least one.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// The files replayed, in replay order.
    pub fn paths(&self) -> &[PathBuf] {
        &self.paths
    }

    /// How long each frame is shown, in ns.
    pub fn frame_period(&self) -> Time {
        self.frame_period
    }

    /// The index of the frame shown at time `t`. Times before zero count backwards, so
    /// the replay is one seamless cycle over all times.
    pub fn index_at(&self, t: Time) -> usize {
        let count = self.frames.len() as i64;
        t.div_euclid(self.frame_period).rem_euclid(count) as usize
    }

    /// The frame at `index`, cycling: index `frame_count()` is frame 0 again. The
    /// pixels are shared, not copied.
    pub fn frame_at_index(&self, index: usize) -> Image {
        // `open` never builds an empty directory, so the modulus is non-zero.
        self.frames[index % self.frames.len()].clone()
    }
}

impl FrameSource for ImageDirectory {
    fn width(&self) -> u32 {
        self.width
    }

    fn height(&self) -> u32 {
        self.height
    }

    fn render_into(&self, t: Time, out: &mut [u8]) -> Result<(), RenderError> {
        check_buffer(self.frame_len(), out)?;
        out.copy_from_slice(&self.frames[self.index_at(t)].image_data);
        Ok(())
    }

    fn frame(&self, t: Time) -> Image {
        self.frame_at_index(self.index_at(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::time::millis;
    use image::{GrayImage, Luma, Rgb, RgbImage};

    /// A `w`×`h` image filled with `colour`.
    fn solid(w: u32, h: u32, colour: [u8; 3]) -> RgbImage {
        RgbImage::from_pixel(w, h, Rgb(colour))
    }

    #[test]
    fn replays_pngs_in_name_order_and_cycles() {
        let dir = tempfile::tempdir().unwrap();
        solid(4, 3, [10, 20, 30]).save(dir.path().join("b.png")).unwrap();
        solid(4, 3, [200, 0, 0]).save(dir.path().join("a.PNG")).unwrap();
        std::fs::write(dir.path().join("notes.txt"), "not an image").unwrap();
        std::fs::create_dir(dir.path().join("sub.png")).unwrap();

        let d = ImageDirectory::open(dir.path(), millis(100)).unwrap();
        assert_eq!(d.frame_count(), 2);
        assert_eq!((d.width(), d.height(), d.frame_len()), (4, 3, 36));
        let names: Vec<_> = d.paths().iter().map(|p| p.file_name().unwrap()).collect();
        assert_eq!(names, ["a.PNG", "b.png"]);

        let first = d.frame(0);
        assert_eq!((first.width, first.height, first.format), (4, 3, Image::FORMAT_RGB8));
        assert_eq!(&first.image_data[..3], &[200, 0, 0]);
        assert_eq!(&d.frame(millis(150)).image_data[..3], &[10, 20, 30]);
        assert_eq!(d.index_at(millis(200)), 0);
        assert_eq!(d.index_at(millis(-1)), 1);
        assert_eq!(d.frame_at_index(3), d.frame_at_index(1));
        assert!(d.frame(0).image_data.ptr_eq(&d.frame(millis(200)).image_data));

        let mut buf = vec![0u8; d.frame_len()];
        d.render_into(millis(100), &mut buf).unwrap();
        assert_eq!(&buf[..3], &[10, 20, 30]);
        assert!(d.render_into(0, &mut [0u8; 5]).is_err());
    }

    #[test]
    fn converts_grey_pngs_and_jpegs_to_rgb8() {
        let dir = tempfile::tempdir().unwrap();
        GrayImage::from_pixel(8, 8, Luma([77])).save(dir.path().join("0.png")).unwrap();
        solid(8, 8, [0, 255, 0]).save(dir.path().join("1.jpg")).unwrap();
        let d = ImageDirectory::open(dir.path(), 1).unwrap();
        assert_eq!(&d.frame_at_index(0).image_data[..6], &[77, 77, 77, 77, 77, 77]);
        let jpeg = d.frame_at_index(1);
        assert_eq!(jpeg.image_data.len(), 8 * 8 * 3);
        // JPEG is lossy: close to pure green is all one can ask.
        let p = &jpeg.image_data[..3];
        assert!(p[0] < 30 && p[1] > 225 && p[2] < 30, "{p:?}");
    }

    #[test]
    fn reports_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let open = |p: &Path| ImageDirectory::open(p, millis(100)).unwrap_err();

        assert!(matches!(open(dir.path()), ImageDirectoryError::NoImages { .. }));
        assert!(matches!(
            open(&dir.path().join("missing")),
            ImageDirectoryError::CannotReadDirectory { .. }
        ));
        assert!(matches!(
            ImageDirectory::open(dir.path(), 0).unwrap_err(),
            ImageDirectoryError::InvalidFramePeriod { frame_period: 0 }
        ));

        solid(4, 4, [1, 2, 3]).save(dir.path().join("a.png")).unwrap();
        solid(5, 4, [1, 2, 3]).save(dir.path().join("b.png")).unwrap();
        assert!(matches!(
            open(dir.path()),
            ImageDirectoryError::MixedSizes { width: 5, expected_width: 4, .. }
        ));

        std::fs::remove_file(dir.path().join("b.png")).unwrap();
        std::fs::write(dir.path().join("c.jpg"), b"definitely not a jpeg").unwrap();
        let err = open(dir.path());
        assert!(matches!(err, ImageDirectoryError::UndecodableFile { .. }), "{err:?}");
        assert!(err.to_string().contains("c.jpg"));
    }
}
