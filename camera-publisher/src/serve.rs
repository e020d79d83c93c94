//! The camera as a process of an esgm system: its command line ([`CameraArgs`]), the
//! frames it describes ([`CameraSource`]), registering it with any runtime
//! ([`serve`]) and the whole worker ([`run`]: connect, serve, leave with the system).
//!
//! The `camera-publisher` binary and `esgm worker camera` (which the coordinator and
//! `esgm demo` start) are both this code: a camera declared in a configuration file
//! behaves the same whichever of the two runs it.
//!
//! This module is the body of those binaries, so it reports like one: [`anyhow`]
//! errors with the context a user needs, printed as one line by the caller's `main`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use esgm_core::library::Image;
use esgm_core::{Esgm, Time};
use esgm_shm::ShmEsgm;
use esgm_shm::attach::serve_while_system_lives;

use crate::camera_sensor::CameraSensor;
use crate::frame_source::{FrameSource, RenderError};
use crate::image_directory::ImageDirectory;
use crate::scene::SyntheticScene;

/// How long a stopped system's coordinator may stay gone before a serving camera
/// leaves (a slow or crashed coordinator is waited for: see
/// [`esgm_shm::attach`]).
pub const COORDINATOR_PATIENCE: Duration = Duration::from_millis(500);

/// The name a camera serving sensor `sensor` goes by in the registry and in logs
/// (`camera-<sensor>`), unless its supervisor names it.
pub fn process_name(sensor: &str) -> String {
    format!("camera-{sensor}")
}

/// A camera's settings, as command-line arguments (`camera-publisher …`,
/// `esgm worker camera …`).
#[derive(Debug, Clone, PartialEq, Eq, clap::Parser)]
pub struct CameraArgs {
    /// Sensor name the camera registers under.
    #[arg(long, default_value = "camera")]
    pub name: String,
    /// Scene seed (the same seed gives the same scene in every process).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Number of moving blobs.
    #[arg(long, default_value_t = 3)]
    pub blobs: usize,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Serve the PNG/JPEG frames of this directory instead of a synthetic scene.
    #[arg(long, conflicts_with_all = ["seed", "blobs", "width", "height"])]
    pub dir: Option<PathBuf>,
    /// With --dir: how long each frame is shown (`100ms`, `1s`).
    #[arg(long, default_value = "100ms", value_parser = humantime::parse_duration)]
    pub frame_period: Duration,
}

impl CameraArgs {
    /// This process's name in the registry: the supervisor's name for it
    /// ([`esgm_shm::WORKER_ENV`]), or [`process_name`] of the sensor when run by hand.
    pub fn process_name(&self) -> String {
        std::env::var(esgm_shm::WORKER_ENV).unwrap_or_else(|_| process_name(&self.name))
    }

    /// The frames these settings describe: the directory's, or the synthetic scene's.
    pub fn source(&self) -> anyhow::Result<CameraSource> {
        match &self.dir {
            Some(dir) => {
                let period = Time::try_from(self.frame_period.as_nanos())
                    .context("--frame-period is too long")?;
                let frames = ImageDirectory::open(dir, period)
                    .with_context(|| format!("cannot serve the frames of {}", dir.display()))?;
                Ok(CameraSource::Directory(frames))
            }
            None => {
                let scene = SyntheticScene::builder()
                    .width(self.width)
                    .height(self.height)
                    .blobs(self.blobs)
                    .seed(self.seed)
                    .create()
                    .context("cannot build the synthetic scene")?;
                Ok(CameraSource::Scene(scene))
            }
        }
    }
}

/// The frames of a camera, chosen on its command line.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum CameraSource {
    /// Moving blobs, rendered for each time.
    Scene(SyntheticScene),
    /// Files of a directory, cycled through by time.
    Directory(ImageDirectory),
}

impl CameraSource {
    /// The source as the trait object every caller of it needs.
    fn inner(&self) -> &dyn FrameSource {
        match self {
            Self::Scene(scene) => scene,
            Self::Directory(frames) => frames,
        }
    }
}

impl FrameSource for CameraSource {
    fn width(&self) -> u32 {
        self.inner().width()
    }

    fn height(&self) -> u32 {
        self.inner().height()
    }

    fn render_into(&self, t: Time, out: &mut [u8]) -> Result<(), RenderError> {
        self.inner().render_into(t, out)
    }

    fn frame(&self, t: Time) -> Image {
        self.inner().frame(t)
    }
}

/// Registers the camera `args` describes with `esgm` as the pull sensor `args.name`,
/// on any runtime: in process, or a shared-memory connection (whose coordinator then
/// samples it from every process).
///
/// ```
/// use camera_publisher::serve::{CameraArgs, serve};
/// use clap::Parser;
/// use esgm_core::{Esgm, InProcessEsgm};
///
/// let args = CameraArgs::parse_from(["camera", "--name", "cam", "--width", "64", "--height", "48"]);
/// let esgm = InProcessEsgm::default();
/// serve(&esgm, &args)?;
/// assert_eq!(esgm.sensors()?, vec![("cam".to_owned(), "Image".to_owned())]);
/// # Ok::<(), anyhow::Error>(())
/// ```
pub fn serve<E: Esgm>(esgm: &E, args: &CameraArgs) -> anyhow::Result<()> {
    register(esgm, &args.name, args.source()?)
}

fn register<E: Esgm>(esgm: &E, name: &str, source: CameraSource) -> anyhow::Result<()> {
    let camera = Arc::new(CameraSensor::new(source));
    esgm.add_sensor_interface(name, CameraSensor::<CameraSource>::TYPE_NAME, camera)
        .with_context(|| format!("cannot register the camera `{name}`"))
}

/// The camera process: checks its settings, connects to the system of `domain`,
/// serves the camera, and returns once the system was stopped (its coordinator gone
/// for [`COORDINATOR_PATIENCE`] and its registry no longer kept). A slow or crashed
/// coordinator is waited for: the camera keeps serving its readers meanwhile.
pub fn run(domain: &str, args: &CameraArgs) -> anyhow::Result<()> {
    let source = args.source()?;
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(args.process_name())
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    register(&esgm, &args.name, source)?;
    tracing::info!(sensor = %args.name, "serving");
    serve_while_system_lives(&esgm, None, COORDINATOR_PATIENCE);
    tracing::info!(sensor = %args.name, "the system was stopped; leaving");
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use clap::Parser;

    fn parse(args: &[&str]) -> Result<CameraArgs, clap::Error> {
        CameraArgs::try_parse_from(std::iter::once("camera").chain(args.iter().copied()))
    }

    #[test]
    fn defaults_are_the_tutorials_camera() {
        let args = parse(&[]).unwrap();
        assert_eq!(
            (args.name.as_str(), args.width, args.height, args.blobs),
            ("camera", 640, 480, 3)
        );
        assert_eq!(args.frame_period, Duration::from_millis(100));
        assert!(matches!(args.source().unwrap(), CameraSource::Scene(_)));
    }

    #[test]
    fn a_directory_excludes_scene_settings() {
        assert!(parse(&["--dir", "frames", "--frame-period", "1s"]).is_ok());
        assert!(parse(&["--dir", "frames", "--seed", "3"]).is_err());
        assert!(parse(&["--frame-period", "soon"]).is_err());
    }

    #[test]
    fn a_scene_renders_as_its_source_does() {
        let args = parse(&["--width", "64", "--height", "48", "--seed", "9"]).unwrap();
        let source = args.source().unwrap();
        let scene = SyntheticScene::builder().width(64).height(48).seed(9).create().unwrap();
        let mut pixels = vec![0; source.frame_len()];
        source.render_into(5_000, &mut pixels).unwrap();
        assert_eq!(&pixels[..], &scene.frame(5_000).image_data[..]);
    }

    #[test]
    fn errors_name_what_was_wrong() {
        let too_wide = parse(&["--width", "0"]).unwrap().source().unwrap_err();
        assert!(format!("{too_wide:#}").starts_with("cannot build the synthetic scene"));
        let missing = parse(&["--dir", "/no/such/dir"]).unwrap().source().unwrap_err();
        assert!(format!("{missing:#}").contains("/no/such/dir"), "{missing:#}");
    }
}
