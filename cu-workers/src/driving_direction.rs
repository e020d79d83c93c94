//! The `DrivingDirection` unit (the seed's ComputeDirection, tutorial 9.2): where to
//! drive, and how fast, to take a closer look at the current blob.
//!
//! # Conventions
//! - **Headings** ([`RobotState::dir`], [`DrivingDirection::dir`]) are degrees,
//!   counter-clockwise positive, as mathematical angles in the robot's x-y plane:
//!   0° faces +x, 90° faces +y. Output headings are normalised to `[0, 360)`.
//! - **The camera** looks along the robot's heading. Image column 0 is at the left
//!   edge and columns grow to the right; the horizontal field of view spans the image
//!   width evenly (`fov / width` degrees a column), so column `c`'s centre is
//!   `(c + 0.5) × fov / width − fov / 2` degrees right of the optical axis. This linear
//!   mapping matches a pinhole camera at the centre and the edges and is off by at most
//!   about 1° in between for a 60° lens: plenty for steering.
//! - **Bearing** of a blob is therefore positive (counter-clockwise) for a blob left of
//!   the image centre and negative for one right of it: a blob right of centre
//!   *decreases* the desired heading (the robot turns right, clockwise).
//! - **Speed** falls linearly with the blob's size, the cue that the object is close:
//!   `max_speed × (1 − size / stop_size)`, clamped to `[0, max_speed]`, so the robot stops
//!   once the blob covers `stop_size` pixels.

use esgm_core::Time;
use esgm_core::library::{Blob, DrivingDirection, RobotState};

/// The settings of [`ComputeDirection`]; [`ComputeDirection::new`] checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrivingDirectionConfig {
    /// Width in pixels of the images the blobs were found in. Default 640, the seed's
    /// camera.
    pub image_width: u32,
    /// Horizontal field of view of the camera in degrees, in `(0, 360)`. Default 60.
    pub horizontal_fov_deg: f64,
    /// Speed when the blob is tiny (far away), in the robot's units a second; finite and
    /// at least zero. Default 1.
    pub max_speed: f64,
    /// Blob size in pixels at which the robot stops, close enough to look; finite and
    /// positive. Default 20 000 (about a 160-pixel-wide disc in a 640×480 image).
    pub stop_size: f64,
}

impl Default for DrivingDirectionConfig {
    fn default() -> Self {
        Self { image_width: 640, horizontal_fov_deg: 60.0, max_speed: 1.0, stop_size: 20_000.0 }
    }
}

/// A [`DrivingDirectionConfig`] setting is out of range: fix that setting.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DrivingDirectionConfigError {
    /// The image width is zero: give the camera's width in pixels.
    #[error("image width must be positive")]
    ZeroImageWidth,
    /// The field of view is not a finite angle in `(0, 360)` degrees.
    #[error("horizontal field of view must be in (0, 360) degrees, got {0}")]
    InvalidFieldOfView(f64),
    /// The maximum speed is negative or not finite.
    #[error("max speed must be finite and at least 0, got {0}")]
    InvalidMaxSpeed(f64),
    /// The stop size is not a finite positive number of pixels.
    #[error("stop size must be finite and positive, got {0}")]
    InvalidStopSize(f64),
}

/// The seed's input synchronization rule for this unit: compute only when the robot
/// state is at least as new as the blob (`robot_valid_time >= blob_valid_time`).
///
/// Robot states arrive every 100 ms and blobs less often. Acting on a new blob with a
/// robot state from before it would steer by where the robot *was* when the blob was
/// seen; waiting for the next robot state delays the reaction by at most one robot
/// period. Once satisfied, the rule stays satisfied as robot states keep coming, so the
/// direction is recomputed with each new state (chasing the blob's last known position).
///
/// The seed's prose says "when the robot state is older than the current blob", but its
/// code, `inputs[0].vtime >= inputs[1].vtime` with the robot state as input 0, and its
/// rationale both say the opposite; esgm follows the code.
pub fn inputs_synchronized(robot_valid_time: Time, blob_valid_time: Time) -> bool {
    robot_valid_time >= blob_valid_time
}

/// `degrees` normalised to `[0, 360)`.
fn normalize_degrees(degrees: f64) -> f64 {
    let d = degrees.rem_euclid(360.0);
    // rem_euclid can round up to exactly 360 for tiny negative inputs.
    if d >= 360.0 { 0.0 } else { d }
}

/// The driving direction unit: robot state and current blob to desired heading and
/// speed, with the conventions of the [module](self).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ComputeDirection {
    config: DrivingDirectionConfig,
}

impl ComputeDirection {
    /// A unit with checked settings.
    pub fn new(config: DrivingDirectionConfig) -> Result<Self, DrivingDirectionConfigError> {
        use DrivingDirectionConfigError as E;
        let DrivingDirectionConfig { image_width, horizontal_fov_deg, max_speed, stop_size } =
            config;
        if image_width == 0 {
            return Err(E::ZeroImageWidth);
        }
        if !(horizontal_fov_deg > 0.0 && horizontal_fov_deg < 360.0) {
            return Err(E::InvalidFieldOfView(horizontal_fov_deg));
        }
        if !(max_speed.is_finite() && max_speed >= 0.0) {
            return Err(E::InvalidMaxSpeed(max_speed));
        }
        if !(stop_size.is_finite() && stop_size > 0.0) {
            return Err(E::InvalidStopSize(stop_size));
        }
        Ok(Self { config })
    }

    /// The settings.
    pub fn config(&self) -> &DrivingDirectionConfig {
        &self.config
    }

    /// The bearing in degrees of image column `x` from the optical axis, positive to
    /// the left (counter-clockwise). Columns outside the image, which no detector
    /// reports, are clamped to the edge of the field of view.
    pub fn bearing(&self, x: i64) -> f64 {
        let width = f64::from(self.config.image_width);
        let fov = self.config.horizontal_fov_deg;
        let right_of_axis = (x as f64 + 0.5 - width / 2.0) * fov / width;
        (-right_of_axis).clamp(-fov / 2.0, fov / 2.0)
    }

    /// The speed for a blob of `size` pixels: full speed for an empty blob, falling
    /// linearly to zero at `stop_size`.
    pub fn speed(&self, size: i64) -> f64 {
        let closeness = (size as f64 / self.config.stop_size).clamp(0.0, 1.0);
        self.config.max_speed * (1.0 - closeness)
    }

    /// The desired heading (robot heading plus the blob's bearing, in `[0, 360)`) and
    /// speed. A non-finite robot heading gives a non-finite desired heading.
    pub fn compute(&self, robot: &RobotState, blob: &Blob) -> DrivingDirection {
        DrivingDirection {
            dir: normalize_degrees(robot.dir + self.bearing(blob.x)),
            speed: self.speed(blob.size),
        }
    }

    /// [`compute`](Self::compute) under the seed's synchronization rule
    /// ([`inputs_synchronized`]): `None` (the seed's `ValueNotAvailable`) while the
    /// robot state is older than the blob.
    pub fn compute_synchronized(
        &self,
        robot: &RobotState,
        robot_valid_time: Time,
        blob: &Blob,
        blob_valid_time: Time,
    ) -> Option<DrivingDirection> {
        inputs_synchronized(robot_valid_time, blob_valid_time).then(|| self.compute(robot, blob))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::time::millis;

    fn robot(dir: f64) -> RobotState {
        RobotState { x: 3.0, y: -2.0, dir }
    }

    fn blob(x: i64, size: i64) -> Blob {
        Blob { x, y: 240, size }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn bearings_follow_the_documented_sign() {
        let unit = ComputeDirection::default();
        // 60° over 640 columns: 0.09375° a column, exact in binary.
        // Column 479's centre is 159.5 columns right of the axis at 320.
        assert!(close(unit.bearing(479), -14.953125));
        assert!(close(unit.bearing(160), 14.953125));
        // Columns 319 and 320 straddle the axis.
        assert!(close(unit.bearing(319), 0.046875));
        assert!(close(unit.bearing(320), -0.046875));
        // The edge columns are half a column inside the field of view.
        assert!(close(unit.bearing(0), 29.953125));
        assert!(close(unit.bearing(639), -29.953125));
        assert!(close(unit.bearing(-10_000), 30.0));
        assert!(close(unit.bearing(i64::MAX), -30.0));
    }

    #[test]
    fn blob_right_of_centre_decreases_the_heading() {
        let unit = ComputeDirection::default();
        let right = unit.compute(&robot(90.0), &blob(479, 100));
        assert!(close(right.dir, 90.0 - 14.953125), "{right:?}");
        let left = unit.compute(&robot(90.0), &blob(160, 100));
        assert!(close(left.dir, 90.0 + 14.953125), "{left:?}");
    }

    #[test]
    fn headings_wrap_into_0_to_360() {
        let unit = ComputeDirection::default();
        assert!(close(unit.compute(&robot(5.0), &blob(479, 0)).dir, 350.046875));
        assert!(close(unit.compute(&robot(355.0), &blob(160, 0)).dir, 9.953125));
        assert!(close(unit.compute(&robot(-90.0), &blob(479, 0)).dir, 255.046875));
        assert!(close(unit.compute(&robot(720.0 + 30.0), &blob(479, 0)).dir, 15.046875));
        assert_eq!(normalize_degrees(-1e-20), 0.0);
        assert!(unit.compute(&robot(f64::NAN), &blob(0, 0)).dir.is_nan());
    }

    #[test]
    fn larger_blobs_are_approached_slower() {
        let unit = ComputeDirection::new(DrivingDirectionConfig {
            max_speed: 2.0,
            stop_size: 10_000.0,
            ..Default::default()
        })
        .unwrap();
        let speed = |size| unit.compute(&robot(0.0), &blob(320, size)).speed;
        assert_eq!(speed(0), 2.0);
        assert_eq!(speed(2_500), 1.5);
        assert_eq!(speed(5_000), 1.0);
        assert_eq!(speed(10_000), 0.0);
        assert_eq!(speed(50_000), 0.0);
        assert_eq!(speed(-5), 2.0);
        let sizes = [0, 10, 100, 1_000, 5_000, 9_999];
        assert!(sizes.windows(2).all(|w| speed(w[0]) > speed(w[1])));
    }

    #[test]
    fn a_wider_field_of_view_turns_more_for_the_same_pixel() {
        let narrow = ComputeDirection::default();
        let wide = ComputeDirection::new(DrivingDirectionConfig {
            horizontal_fov_deg: 120.0,
            ..Default::default()
        })
        .unwrap();
        assert!(close(wide.bearing(479), 2.0 * narrow.bearing(479)));
    }

    #[test]
    fn computes_only_once_the_robot_state_is_as_new_as_the_blob() {
        assert!(inputs_synchronized(millis(200), millis(150)));
        assert!(inputs_synchronized(millis(150), millis(150)));
        assert!(!inputs_synchronized(millis(100), millis(150)));

        let unit = ComputeDirection::default();
        let b = blob(320, 0);
        assert_eq!(unit.compute_synchronized(&robot(10.0), millis(100), &b, millis(150)), None);
        assert_eq!(
            unit.compute_synchronized(&robot(10.0), millis(200), &b, millis(150)),
            Some(unit.compute(&robot(10.0), &b))
        );
    }

    #[test]
    fn bad_settings_are_rejected() {
        let new = |c| ComputeDirection::new(c).unwrap_err();
        let d = DrivingDirectionConfig::default();
        use DrivingDirectionConfigError as E;
        assert_eq!(new(DrivingDirectionConfig { image_width: 0, ..d }), E::ZeroImageWidth);
        for fov in [0.0, -1.0, 360.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                new(DrivingDirectionConfig { horizontal_fov_deg: fov, ..d }),
                E::InvalidFieldOfView(_)
            ));
        }
        for speed in [-0.1, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                new(DrivingDirectionConfig { max_speed: speed, ..d }),
                E::InvalidMaxSpeed(_)
            ));
        }
        for size in [0.0, -3.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                new(DrivingDirectionConfig { stop_size: size, ..d }),
                E::InvalidStopSize(_)
            ));
        }
        assert_eq!(ComputeDirection::new(d).unwrap(), ComputeDirection::default());
    }
}
