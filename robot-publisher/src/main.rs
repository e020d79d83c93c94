//! `robot-publisher`: for now, drives the simulated robot for one second toward a fixed
//! driving direction and prints its state every 100 ms, the seed's publishing period.
//!
//! Publishing into an esgm runtime comes with the runtime traits; the motion is the
//! library's.

use std::process::ExitCode;

use esgm_core::library::{DrivingDirection, RobotState};
use esgm_core::time::millis;
use robot_publisher::{Kinematics, KinematicsConfig};

fn main() -> ExitCode {
    let start = RobotState { x: 1.0, y: 2.0, dir: 3.0 };
    let mut robot = match Kinematics::new(start, KinematicsConfig::default()) {
        Ok(robot) => robot,
        Err(err) => {
            eprintln!("robot-publisher: {err}");
            return ExitCode::FAILURE;
        }
    };
    let command = DrivingDirection { dir: 45.0, speed: 0.5 };
    let period = millis(100);
    println!("t_ms x y dir (command: dir {} speed {})", command.dir, command.speed);
    println!("0 {:.4} {:.4} {:.2}", start.x, start.y, start.dir);
    for k in 1..=10 {
        let s = robot.step(period, &command);
        println!("{} {:.4} {:.4} {:.2}", k * 100, s.x, s.y, s.dir);
    }
    ExitCode::SUCCESS
}
