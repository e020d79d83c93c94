// The seed's ComputeDirection (chapter 9.2) in C++: steer towards the current blob,
// slower as it grows, once the robot state is at least as new as the blob. The same
// arithmetic as cu-workers' Rust DrivingDirection.
#ifndef ESGM_EXAMPLES_DRIVING_DIRECTION_HPP
#define ESGM_EXAMPLES_DRIVING_DIRECTION_HPP

#include <esgm/esgm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace tutorial {

struct Blob {
    std::int64_t x, y, size;
};
struct RobotState {
    double x, y, dir;
};
struct DrivingDirection {
    double dir, speed;
};

struct DirectionConfig {
    double image_width = 640;
    double horizontal_fov_deg = 60;
    double max_speed = 1;
    double stop_size = 20000;
};

/// The heading towards `blob`, relative to the camera's axis (left positive).
inline double bearing(const DirectionConfig& c, std::int64_t x) {
    const double right_of_axis =
        (static_cast<double>(x) + 0.5 - c.image_width / 2.0) * c.horizontal_fov_deg / c.image_width;
    return std::clamp(-right_of_axis, -c.horizontal_fov_deg / 2.0, c.horizontal_fov_deg / 2.0);
}

inline DrivingDirection compute_direction(const DirectionConfig& c, const RobotState& robot,
                                          const Blob& blob) {
    double dir = std::fmod(robot.dir + bearing(c, blob.x), 360.0);
    if (dir < 0) {
        dir += 360.0;
    }
    if (dir >= 360.0) {
        dir = 0.0;
    }
    const double closeness = std::clamp(static_cast<double>(blob.size) / c.stop_size, 0.0, 1.0);
    return {dir, c.max_speed * (1.0 - closeness)};
}

}  // namespace tutorial

ESGM_ENTITY(tutorial::Blob, "Blob", x, y, size)
ESGM_ENTITY(tutorial::RobotState, "RobotState", x, y, dir)
ESGM_ENTITY(tutorial::DrivingDirection, "DrivingDirection", dir, speed)

#endif
