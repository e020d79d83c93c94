//! [`ComputeDirection`] as an esgm computational unit: `RobotState`, `Blob` →
//! `DrivingDirection` (the seed's `DrivingDirectionCU`).

use esgm_core::esgm::{Stamped, TypedUnit};
use esgm_core::library::{Blob, DrivingDirection, RobotState};
use esgm_core::{ComputeError, Entity, InputType, Time};

use crate::driving_direction::{
    ComputeDirection, DrivingDirectionConfig, DrivingDirectionConfigError,
};

/// The `DrivingDirection` unit: where to drive to approach the current blob.
///
/// Inputs are the robot state then the current blob, the order of the seed's
/// `driving_direction` trajectory (`robot_state`, `current_blob`). It applies the seed's
/// synchronization rule ([`crate::inputs_synchronized`]): a direction is computed only
/// when the robot state is at least as new as the blob, otherwise there is no value. The
/// output is valid when the robot state is (the pose it steers from) and created at the
/// query time.
#[derive(Debug, Clone, Copy, Default)]
pub struct DrivingDirectionUnit {
    unit: ComputeDirection,
}

impl DrivingDirectionUnit {
    /// The name the tutorial registers it under.
    pub const NAME: &'static str = "DrivingDirection";
    /// The type of its output.
    pub const OUTPUT_TYPE: &'static str = DrivingDirection::TYPE_NAME;
    /// The name of every structure it produces (the seed's `"driving_dir"`).
    pub const STRUCTURE_NAME: &'static str = "driving_dir";

    /// A unit with checked settings (match `image_width` to the camera).
    pub fn new(config: DrivingDirectionConfig) -> Result<Self, DrivingDirectionConfigError> {
        Ok(Self { unit: ComputeDirection::new(config)? })
    }

    /// The computation, e.g. to work out the bearing of a blob.
    pub fn computation(&self) -> &ComputeDirection {
        &self.unit
    }

    /// Its input types, for `add_comp_unit`: a `RobotState` then a `Blob`
    /// ([`TypedUnit::Inputs`]).
    pub fn input_types() -> Vec<InputType> {
        <Self as TypedUnit>::input_types()
    }
}

impl TypedUnit for DrivingDirectionUnit {
    const NAME: &'static str = "DrivingDirection";
    type Inputs = (Stamped<RobotState>, Stamped<Blob>);
    type Output = DrivingDirection;

    fn compute(
        &self,
        (robot, blob): Self::Inputs,
        qtime: Time,
    ) -> Result<Stamped<DrivingDirection>, ComputeError> {
        let direction = self
            .unit
            .compute_synchronized(&robot.value, robot.valid_time, &blob.value, blob.valid_time)
            .ok_or(ComputeError::ValueNotAvailable)?;
        Ok(Stamped::new(Self::STRUCTURE_NAME, robot.valid_time, qtime, direction))
    }

    /// The temporal function (E6): the direction at `t` from the robot state and the
    /// blob as their generators give them at `t` (interpolated, most recent, …), so a
    /// stream sampled at a fixed period steers from values that hold at one instant.
    /// The synchronization rule does not apply: both inputs are valid at `t`.
    fn compute_at(
        &self,
        (robot, blob): Self::Inputs,
        t: Time,
    ) -> Result<Stamped<DrivingDirection>, ComputeError> {
        let created = robot.create_time.max(blob.create_time);
        Ok(Stamped::new(
            Self::STRUCTURE_NAME,
            t,
            created,
            self.unit.compute(&robot.value, &blob.value),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unit_test_support::sample;

    const ROBOT: RobotState = RobotState { x: 1.0, y: 2.0, dir: 90.0 };
    const RIGHT_BLOB: Blob = Blob { x: 479, y: 240, size: 100 };

    #[test]
    fn steers_from_the_robot_state_once_it_is_as_new_as_the_blob() {
        let unit = DrivingDirectionUnit::default();
        let es =
            unit.compute_samples(&[sample(&ROBOT, 500), sample(&RIGHT_BLOB, 500)], 510).unwrap();
        assert_eq!((es.name.as_str(), es.valid_time, es.create_time), ("driving_dir", 500, 510));
        let direction = DrivingDirection::from_structure(&es).unwrap();
        assert_eq!(direction, ComputeDirection::default().compute(&ROBOT, &RIGHT_BLOB));
        assert!(direction.dir < ROBOT.dir, "a blob right of centre turns right: {direction:?}");
    }

    #[test]
    fn the_temporal_function_steers_from_both_values_at_its_time() {
        let unit = DrivingDirectionUnit::default();
        let es =
            unit.compute_samples_at(&[sample(&ROBOT, 499), sample(&RIGHT_BLOB, 500)], 450).unwrap();
        assert_eq!((es.valid_time, es.create_time), (450, 500));
        let direction = DrivingDirection::from_structure(&es).unwrap();
        assert_eq!(direction, ComputeDirection::default().compute(&ROBOT, &RIGHT_BLOB));
    }

    #[test]
    fn a_robot_state_older_than_the_blob_is_no_value() {
        let unit = DrivingDirectionUnit::default();
        assert_eq!(
            unit.compute_samples(&[sample(&ROBOT, 499), sample(&RIGHT_BLOB, 500)], 510),
            Err(ComputeError::ValueNotAvailable)
        );
    }

    #[test]
    fn swapped_or_missing_inputs_fail() {
        let unit = DrivingDirectionUnit::default();
        let Err(ComputeError::Failed { reason }) =
            unit.compute_samples(&[sample(&RIGHT_BLOB, 1), sample(&ROBOT, 1)], 2)
        else {
            panic!("swapped inputs were accepted");
        };
        assert!(reason.starts_with("input 0 of DrivingDirection is not a readable `RobotState`"));
        assert_eq!(
            unit.compute_samples(&[sample(&ROBOT, 1)], 2),
            Err(ComputeError::Failed { reason: "DrivingDirection takes 2 input(s), got 1".into() })
        );
    }

    #[test]
    fn bad_settings_are_rejected() {
        let config = DrivingDirectionConfig { image_width: 0, ..Default::default() };
        assert_eq!(
            DrivingDirectionUnit::new(config).unwrap_err(),
            DrivingDirectionConfigError::ZeroImageWidth
        );
    }
}
