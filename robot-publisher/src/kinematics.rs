//! A unicycle model of a ground robot: a planar position and a heading, driven by a
//! desired heading and speed.
//!
//! # Conventions
//! Headings are degrees, counter-clockwise positive, 0° facing +x and 90° facing +y,
//! normalised to `[0, 360)`; moving at heading θ changes the position by
//! `(cos θ, sin θ)` per unit of distance. These are the conventions of cu-workers'
//! `ComputeDirection`, whose output this model follows. Speeds are position units a
//! second.

use esgm_core::Time;
use esgm_core::library::{DrivingDirection, RobotState};
use esgm_core::time::TIMEUNITS_PER_SECOND;

/// The limits of a [`Kinematics`] model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicsConfig {
    /// The fastest the robot turns, in degrees a second; finite and at least zero
    /// (zero: it cannot turn). Default 90.
    pub max_turn_rate_deg_per_s: f64,
    /// The fastest the robot drives; commands above it are capped. Finite and at least
    /// zero. Default 1.
    pub max_speed: f64,
}

impl Default for KinematicsConfig {
    fn default() -> Self {
        Self { max_turn_rate_deg_per_s: 90.0, max_speed: 1.0 }
    }
}

/// A [`Kinematics`] model could not be built: fix the named setting.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KinematicsError {
    /// The turn rate is negative or not finite.
    #[error("max turn rate must be finite and at least 0 °/s, got {0}")]
    InvalidTurnRate(f64),
    /// The maximum speed is negative or not finite.
    #[error("max speed must be finite and at least 0, got {0}")]
    InvalidMaxSpeed(f64),
    /// The initial state has a non-finite coordinate or heading.
    #[error("initial state must be finite, got {0:?}")]
    InvalidInitialState(RobotState),
}

/// `degrees` normalised to `[0, 360)`.
fn normalize_degrees(degrees: f64) -> f64 {
    let d = degrees.rem_euclid(360.0);
    // rem_euclid can round up to exactly 360 for tiny negative inputs.
    if d >= 360.0 { 0.0 } else { d }
}

/// The signed turn from heading `from` to heading `to` the short way round, in
/// `(-180, 180]` degrees: positive is counter-clockwise. Exactly opposite headings turn
/// counter-clockwise.
fn shortest_turn(from: f64, to: f64) -> f64 {
    let d = normalize_degrees(to - from);
    if d > 180.0 { d - 360.0 } else { d }
}

/// A simulated robot: its state, advanced by [`step`](Self::step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    state: RobotState,
    config: KinematicsConfig,
}

impl Default for Kinematics {
    /// The seed's robot, which reports `(1, 2, 3)`: at (1, 2) heading 3°, with the
    /// default limits.
    fn default() -> Self {
        Self { state: RobotState { x: 1.0, y: 2.0, dir: 3.0 }, config: KinematicsConfig::default() }
    }
}

impl Kinematics {
    /// A robot at `initial` (its heading normalised to `[0, 360)`) with the given limits.
    pub fn new(initial: RobotState, config: KinematicsConfig) -> Result<Self, KinematicsError> {
        let KinematicsConfig { max_turn_rate_deg_per_s: rate, max_speed } = config;
        if !(rate.is_finite() && rate >= 0.0) {
            return Err(KinematicsError::InvalidTurnRate(rate));
        }
        if !(max_speed.is_finite() && max_speed >= 0.0) {
            return Err(KinematicsError::InvalidMaxSpeed(max_speed));
        }
        if ![initial.x, initial.y, initial.dir].iter().all(|v| v.is_finite()) {
            return Err(KinematicsError::InvalidInitialState(initial));
        }
        let state = RobotState { dir: normalize_degrees(initial.dir), ..initial };
        Ok(Self { state, config })
    }

    /// The limits.
    pub fn config(&self) -> &KinematicsConfig {
        &self.config
    }

    /// The current state.
    pub fn state(&self) -> RobotState {
        self.state
    }

    /// Advances the robot by `dt_ns` nanoseconds under `command` and returns the new
    /// state.
    ///
    /// The robot turns toward `command.dir` the short way round at up to the maximum
    /// turn rate and, once there, holds it; meanwhile it drives at `command.speed`
    /// capped to `[0, max_speed]` (it does not reverse). A command with a non-finite
    /// heading or speed stops the robot where it is, and a step of zero or negative
    /// length changes nothing: bad input never makes the state non-finite.
    pub fn step(&mut self, dt_ns: Time, command: &DrivingDirection) -> RobotState {
        if dt_ns <= 0 || !command.dir.is_finite() || !command.speed.is_finite() {
            return self.state;
        }
        let dt = dt_ns as f64 / TIMEUNITS_PER_SECOND as f64;
        let speed = command.speed.clamp(0.0, self.config.max_speed);
        let rate = self.config.max_turn_rate_deg_per_s;
        let wanted = shortest_turn(self.state.dir, command.dir);
        let turn = wanted.clamp(-rate * dt, rate * dt);
        // Turning at the full rate for `turn_time`, then straight for the rest.
        let turn_time = if turn == 0.0 { 0.0 } else { (turn.abs() / rate).min(dt) };

        let start = self.state.dir.to_radians();
        let end = start + turn.to_radians();
        let arc = speed * turn_time;
        let (mut x, mut y) = (self.state.x, self.state.y);
        // With no turn there is no arc (and its radius would divide by zero).
        if turn != 0.0 {
            // Radius of the arc, signed with the turn: speed / angular rate.
            let radius = arc / turn.to_radians();
            x += radius * (end.sin() - start.sin());
            y += radius * (start.cos() - end.cos());
        }
        let straight = speed * (dt - turn_time);
        x += straight * end.cos();
        y += straight * end.sin();
        self.state = RobotState { x, y, dir: normalize_degrees(self.state.dir + turn) };
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::time::{millis, secs};
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    fn robot(x: f64, y: f64, dir: f64) -> Kinematics {
        Kinematics::new(RobotState { x, y, dir }, KinematicsConfig::default()).unwrap()
    }

    fn cmd(dir: f64, speed: f64) -> DrivingDirection {
        DrivingDirection { dir, speed }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn drives_straight_along_the_heading() {
        let mut r = robot(1.0, 2.0, 0.0);
        assert_eq!(r.step(secs(2), &cmd(0.0, 0.5)), RobotState { x: 2.0, y: 2.0, dir: 0.0 });
        let mut r = robot(0.0, 0.0, 90.0);
        let s = r.step(secs(1), &cmd(90.0, 1.0));
        assert!(close(s.x, 0.0) && close(s.y, 1.0) && s.dir == 90.0, "{s:?}");
    }

    #[test]
    fn turns_at_the_bounded_rate() {
        let mut r = robot(0.0, 0.0, 0.0);
        assert_eq!(r.step(millis(500), &cmd(90.0, 0.0)).dir, 45.0);
        assert_eq!(r.step(millis(500), &cmd(90.0, 0.0)).dir, 90.0);
        // Already there: no overshoot.
        assert_eq!(r.step(millis(500), &cmd(90.0, 0.0)).dir, 90.0);
    }

    #[test]
    fn turns_the_short_way_round() {
        let mut r = robot(0.0, 0.0, 350.0);
        assert_eq!(r.step(secs(1), &cmd(10.0, 0.0)).dir, 10.0);
        let mut r = robot(0.0, 0.0, 10.0);
        assert!(close(r.step(millis(100), &cmd(340.0, 0.0)).dir, 1.0));
        assert!(close(r.step(millis(100), &cmd(340.0, 0.0)).dir, 352.0));
        // Opposite: counter-clockwise, as documented.
        let mut r = robot(0.0, 0.0, 0.0);
        assert!(close(r.step(millis(100), &cmd(180.0, 0.0)).dir, 9.0));
        let mut r = robot(0.0, 0.0, 0.0);
        assert!(close(r.step(millis(100), &cmd(-90.0, 0.0)).dir, 351.0));
    }

    #[test]
    fn converges_to_the_commanded_heading_and_stays() {
        let mut r = robot(0.0, 0.0, 200.0);
        let target = 30.0; // 190° counter-clockwise or 170° clockwise: clockwise.
        let mut previous_error = 180.0;
        for _ in 0..40 {
            let s = r.step(millis(100), &cmd(target, 0.3));
            let error = shortest_turn(s.dir, target).abs();
            assert!(error <= previous_error, "heading error grew: {error} > {previous_error}");
            previous_error = error;
        }
        assert_eq!(r.state().dir, target);
        let before = r.state();
        let after = r.step(secs(1), &cmd(target, 0.3));
        assert!(close(after.x - before.x, 0.3 * 30f64.to_radians().cos()));
        assert!(close(after.y - before.y, 0.3 * 30f64.to_radians().sin()));
    }

    #[test]
    fn a_full_rate_quarter_turn_drives_a_quarter_circle() {
        // 90 °/s for 1 s at π/2 units/s: a quarter circle of radius 1, to the left.
        let config = KinematicsConfig { max_speed: 10.0, ..Default::default() };
        let mut r = Kinematics::new(RobotState { x: 0.0, y: 0.0, dir: 0.0 }, config).unwrap();
        let left = r.step(secs(1), &cmd(90.0, FRAC_PI_2));
        assert!(close(left.x, 1.0) && close(left.y, 1.0) && left.dir == 90.0, "{left:?}");
        // Back to 0°, clockwise: the mirror image, centred at (2, 1).
        let right = r.step(secs(1), &cmd(0.0, FRAC_PI_2));
        assert!(close(right.x, 2.0) && close(right.y, 2.0) && right.dir == 0.0, "{right:?}");
        // Capped at the default max speed 1: the same turn on a radius of 2/π.
        let mut slow = robot(0.0, 0.0, 0.0);
        let capped = slow.step(secs(1), &cmd(90.0, FRAC_PI_2));
        let radius = 2.0 / std::f64::consts::PI;
        assert!(close(capped.x, radius) && close(capped.y, radius), "{capped:?}");
    }

    #[test]
    fn speed_is_capped_and_never_negative() {
        let mut r = robot(0.0, 0.0, 0.0);
        assert_eq!(r.step(secs(1), &cmd(0.0, 5.0)).x, 1.0);
        assert_eq!(r.step(secs(1), &cmd(0.0, -5.0)).x, 1.0);
    }

    #[test]
    fn bad_commands_and_steps_change_nothing() {
        let mut r = robot(1.0, 1.0, 45.0);
        let start = r.state();
        assert_eq!(r.step(secs(1), &cmd(f64::NAN, 1.0)), start);
        assert_eq!(r.step(secs(1), &cmd(10.0, f64::INFINITY)), start);
        assert_eq!(r.step(0, &cmd(10.0, 1.0)), start);
        assert_eq!(r.step(-5, &cmd(10.0, 1.0)), start);
        let far = r.step(Time::MAX, &cmd(10.0, 1.0));
        assert!(far.x.is_finite() && far.y.is_finite() && far.dir == 10.0, "{far:?}");
    }

    #[test]
    fn bad_settings_are_rejected() {
        let at = |dir| RobotState { x: 0.0, y: 0.0, dir };
        let with =
            |rate, speed| KinematicsConfig { max_turn_rate_deg_per_s: rate, max_speed: speed };
        assert!(matches!(
            Kinematics::new(at(0.0), with(-1.0, 1.0)),
            Err(KinematicsError::InvalidTurnRate(_))
        ));
        assert!(matches!(
            Kinematics::new(at(0.0), with(1.0, f64::NAN)),
            Err(KinematicsError::InvalidMaxSpeed(_))
        ));
        assert!(matches!(
            Kinematics::new(at(f64::INFINITY), KinematicsConfig::default()),
            Err(KinematicsError::InvalidInitialState(_))
        ));
        assert_eq!(
            Kinematics::new(at(-90.0), KinematicsConfig::default()).unwrap().state().dir,
            270.0
        );
        // A robot that cannot turn still drives.
        let mut stiff = Kinematics::new(at(0.0), with(0.0, 1.0)).unwrap();
        assert_eq!(stiff.step(secs(1), &cmd(90.0, 1.0)), RobotState { x: 1.0, y: 0.0, dir: 0.0 });
    }

    proptest! {
        #[test]
        fn splitting_a_step_does_not_change_the_path(
            dir in 0.0f64..360.0,
            target in -720.0f64..720.0,
            speed in 0.0f64..1.0,
            total_ms in 1i64..5_000,
            split in 0.0f64..1.0,
        ) {
            let first = (total_ms as f64 * split) as i64;
            let mut one = robot(0.0, 0.0, dir);
            let mut two = one;
            let c = cmd(target, speed);
            let a = one.step(millis(total_ms), &c);
            two.step(millis(first), &c);
            let b = two.step(millis(total_ms - first), &c);
            prop_assert!((a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9, "{a:?} vs {b:?}");
            prop_assert!(shortest_turn(a.dir, b.dir).abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }
}
