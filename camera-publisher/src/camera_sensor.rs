//! The camera as an esgm pull sensor (the seed's `CameraSensorInterface`, tutorial
//! 8.2): any [`FrameSource`] behind [`SensorInterface`].
//!
//! The adapter only names esgm-core's traits, so the same value registers with the
//! in-process runtime or, later, with a shared-memory worker process.

use esgm_core::library::Image;
use esgm_core::{Entity, EntityStructure, OctetsAllocator, SensorError, SensorInterface, Time};

use crate::frame_source::FrameSource;

/// A camera that esgm samples: each call renders the frame at the query time.
///
/// ```
/// use std::sync::Arc;
/// use camera_publisher::{CameraSensor, SyntheticScene};
/// use esgm_core::{Esgm, InProcessEsgm, SensorInterface};
///
/// let scene = SyntheticScene::builder().width(64).height(48).blobs(1).create()?;
/// let camera = CameraSensor::new(scene);
/// let image = camera.get_current_value(1_000)?;
/// assert_eq!((image.name.as_str(), image.valid_time, image.create_time), ("image", 1_000, 1_000));
///
/// let esgm = InProcessEsgm::default();
/// esgm.add_sensor_interface("camera", CameraSensor::<SyntheticScene>::TYPE_NAME, Arc::new(camera))?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct CameraSensor<S> {
    source: S,
}

impl<S: FrameSource> CameraSensor<S> {
    /// The type of the structures it produces, to register it under.
    pub const TYPE_NAME: &'static str = Image::TYPE_NAME;
    /// The name of every structure it produces (the seed's `"image"`).
    pub const STRUCTURE_NAME: &'static str = "image";

    /// A sensor over `source`.
    pub fn new(source: S) -> Self {
        Self { source }
    }

    /// The frame source, e.g. a scene's ground truth.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// The frame at `qtime` as an `Image` structure valid and created at `qtime`.
    ///
    /// The seed stamps both times with the query time, which stands for "now"; a
    /// synthetic scene is a function of time, so the frame is the one at exactly that
    /// time and the stamp is exact.
    pub fn image_at(&self, qtime: Time) -> EntityStructure {
        self.source.frame(qtime).to_structure(Self::STRUCTURE_NAME, qtime, qtime)
    }
}

impl<S: FrameSource + Send + Sync> SensorInterface for CameraSensor<S> {
    fn get_current_value(&self, qtime: Time) -> Result<EntityStructure, SensorError> {
        Ok(self.image_at(qtime))
    }

    /// Renders the frame straight into the trajectory's own image buffer — a loan of
    /// its shared memory when the trajectory is published to other processes — so the
    /// frame is written once, where every reader reads it.
    fn get_current_value_with(
        &self,
        qtime: Time,
        images: &dyn OctetsAllocator,
    ) -> Result<EntityStructure, SensorError> {
        let (width, height) = (i64::from(self.source.width()), i64::from(self.source.height()));
        let Some(mut buffer) = images.image(width, height, Image::FORMAT_RGB8) else {
            return self.get_current_value(qtime);
        };
        self.source
            .render_into(qtime, buffer.pixels_mut())
            .map_err(|e| SensorError::Failed { reason: e.to_string() })?;
        let image =
            Image { width, height, format: Image::FORMAT_RGB8, image_data: buffer.into_octets() };
        Ok(image.to_structure(Self::STRUCTURE_NAME, qtime, qtime))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SyntheticScene;

    #[test]
    fn renders_the_frame_at_the_query_time() {
        let scene =
            SyntheticScene::builder().width(32).height(24).blobs(1).seed(3).create().unwrap();
        let expected = scene.frame(7_000);
        let camera = CameraSensor::new(scene);
        let es = camera.get_current_value(7_000).unwrap();
        assert_eq!(es.name, "image");
        assert_eq!((es.valid_time, es.create_time), (7_000, 7_000));
        assert_eq!(Image::from_structure(&es).unwrap(), expected);
    }

    #[test]
    fn renders_into_the_trajectorys_buffer_the_same_frame() {
        let scene =
            SyntheticScene::builder().width(32).height(24).blobs(2).seed(5).create().unwrap();
        let expected = scene.frame(9_000);
        let camera = CameraSensor::new(scene);
        let es = camera.get_current_value_with(9_000, &esgm_core::HeapAllocator).unwrap();
        assert_eq!(Image::from_structure(&es).unwrap(), expected);
    }
}
