// The tutorial's camera (seed chapter 8.2) as a C++ sensor: esgm pulls it at every
// sample time of every trajectory sampled from it, and it renders the synthetic scene
// straight into a loan of that trajectory's shared memory, so the frame is written
// once, where every reader in every process reads it (the image copies stay 0).
//
// A system file declares it (tutorial_cpp.toml):
//   [[sensor]]
//   name = "camera"
//   program = "tutorial_camera"          # found on PATH
//   args = ["--seed", "0", "--blobs", "3"]
// and `esgm up` starts, supervises and restarts it, passing the domain and the name
// in the environment.
#include "synthetic_scene.hpp"

#include <esgm/esgm.hpp>

#include <cstdlib>
#include <iostream>
#include <string>

namespace {

struct Options {
    std::uint64_t seed = 0;
    std::size_t blobs = 3;
    std::uint32_t width = 640;
    std::uint32_t height = 480;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; i++) {
        const std::string flag = argv[i];
        if (i + 1 >= argc) {
            throw std::invalid_argument("`" + flag + "` needs a value");
        }
        const std::string value = argv[++i];
        std::size_t used = 0;
        const unsigned long long n = std::stoull(value, &used);
        if (used != value.size()) {
            throw std::invalid_argument("`" + flag + " " + value + "` is not a whole number");
        }
        if (flag == "--seed") {
            o.seed = n;
        } else if (flag == "--blobs") {
            o.blobs = static_cast<std::size_t>(n);
        } else if (flag == "--width") {
            o.width = static_cast<std::uint32_t>(n);
        } else if (flag == "--height") {
            o.height = static_cast<std::uint32_t>(n);
        } else {
            throw std::invalid_argument("unknown option `" + flag +
                                        "`; usage: tutorial_camera [--seed N] [--blobs N] "
                                        "[--width W] [--height H]");
        }
    }
    return o;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const Options o = parse(argc, argv);
        const tutorial::SyntheticScene scene(o.width, o.height, o.blobs, o.seed);
        esgm::Esgm::init_logging();
        auto esgm = esgm::Esgm::connect_from_env();
        const std::string name = esgm::Esgm::declared_name("camera");
        esgm.add_sensor_interface(name, "Image", [scene](esgm::Time qtime,
                                                         esgm::SensorContext& context) {
            esgm::ImageLoan frame = context.image_loan(scene.width(), scene.height());
            esgm::Span<std::uint8_t> pixels = frame.pixels();
            scene.render_into(qtime, pixels.data(), pixels.size());
            return esgm::Structure("image", qtime)
                .set("width", std::int64_t{scene.width()})
                .set("height", std::int64_t{scene.height()})
                .set("format", std::int64_t{0})
                .set_image("image_data", std::move(frame));
        });
        std::cerr << "tutorial_camera: serving `" << name << "` (" << o.width << "x" << o.height
                  << ", " << o.blobs << " blobs, seed " << o.seed << ")\n";
        esgm.serve();
        return 0;
    } catch (const std::exception& e) {
        std::cerr << "tutorial_camera: " << e.what() << "\n";
        return 1;
    }
}
