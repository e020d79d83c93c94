// The seed's DrivingDirection unit (chapter 9.2) in C++: from the robot's state and
// the current blob, the heading and speed to approach the blob, computed only once the
// robot state is at least as new as the blob ("unless we want to start chasing old
// objects or make the same turn twice"). A class with compute and compute_at, so a
// generated trajectory can use it as a temporal function too.
//
// A system file declares it (tutorial_cpp.toml):
//   [[unit]]
//   name = "DrivingDirection"
//   program = "driving_direction_unit"   # found on PATH
#include "driving_direction.hpp"

#include <esgm/esgm.hpp>

#include <iostream>
#include <memory>
#include <string>

namespace {

class DrivingDirectionUnit : public esgm::CompUnit {
public:
    explicit DrivingDirectionUnit(tutorial::DirectionConfig config) : config_(config) {}

    // input[0] is the robot state and input[1] the current blob.
    std::optional<esgm::Structure> compute(const esgm::Inputs& inputs, esgm::Time qtime) override {
        check(inputs);
        const esgm::Sample& robot_state = inputs[0];
        const esgm::Sample& blob = inputs[1];
        if (robot_state.valid_time() < blob.valid_time()) {
            return std::nullopt;  // the seed's ValueNotAvailable
        }
        const auto dir = tutorial::compute_direction(
            config_, robot_state.as<tutorial::RobotState>(), blob.as<tutorial::Blob>());
        return esgm::Entity<tutorial::DrivingDirection>::to_structure(
            dir, "driving_dir", robot_state.valid_time(), qtime);
    }

    std::optional<esgm::Structure> compute_at(const esgm::Inputs& inputs, esgm::Time t) override {
        check(inputs);
        const auto dir = tutorial::compute_direction(
            config_, inputs[0].as<tutorial::RobotState>(), inputs[1].as<tutorial::Blob>());
        const esgm::Time created = std::max(inputs[0].create_time(), inputs[1].create_time());
        return esgm::Entity<tutorial::DrivingDirection>::to_structure(dir, "driving_dir", t, created);
    }

private:
    static void check(const esgm::Inputs& inputs) {
        if (inputs.size() != 2) {
            throw esgm::InvalidType("DrivingDirection takes 2 inputs (robot state, blob), got " +
                                    std::to_string(inputs.size()));
        }
    }
    tutorial::DirectionConfig config_;
};

}  // namespace

int main(int argc, char** argv) {
    try {
        tutorial::DirectionConfig config;
        for (int i = 1; i + 1 < argc; i += 2) {
            const std::string flag = argv[i];
            const double value = std::stod(argv[i + 1]);
            if (flag == "--image-width") config.image_width = value;
            else if (flag == "--fov") config.horizontal_fov_deg = value;
            else if (flag == "--max-speed") config.max_speed = value;
            else if (flag == "--stop-size") config.stop_size = value;
            else throw std::invalid_argument("unknown option `" + flag + "`");
        }
        if (argc % 2 == 0) {
            throw std::invalid_argument(std::string("`") + argv[argc - 1] + "` needs a value");
        }
        esgm::Esgm::init_logging();
        auto esgm = esgm::Esgm::connect_from_env();
        esgm.add_comp_unit(esgm::Esgm::declared_name("DrivingDirection"), "DrivingDirection",
                           {"RobotState", "Blob"}, std::make_shared<DrivingDirectionUnit>(config));
        esgm.serve();
        return 0;
    } catch (const std::exception& e) {
        std::cerr << "driving_direction_unit: " << e.what() << "\n";
        return 1;
    }
}
