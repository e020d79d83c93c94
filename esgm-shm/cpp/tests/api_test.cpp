// esgm's C++17 wrapper, tested as a C++ program uses it: typed structs, exceptions
// carrying the IDL's errors, range-for subscriptions, lambdas and classes as units and
// sensors, images written into loans and read through spans, every trajectory kind.
// Run by esgm-shm/c/tests/programs.rs, built with g++ and clang++ (-Wall -Wextra
// -Wpedantic -Werror):
//
//   cpp_api_test in-process | shm DOMAIN
//   cpp_api_test scene SEED BLOBS TIME    (prints the C++ camera's frame checksum)
#include "../examples/blob_detection.hpp"
#include "../examples/driving_direction.hpp"
#include "../examples/synthetic_scene.hpp"

#include <esgm/esgm.hpp>

#include <atomic>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

namespace {

int failures = 0;
std::string runtime;

#define CHECK(cond)                                                                     \
    do {                                                                                \
        if (!(cond)) {                                                                  \
            std::cerr << __FILE__ << ":" << __LINE__ << " [" << runtime                  \
                      << "] check failed: " #cond "\n";                                 \
            failures++;                                                                 \
        }                                                                               \
    } while (0)

// `expr` must throw E, whose message contains `text`.
#define THROWS(expr, E, text)                                                           \
    do {                                                                                \
        try {                                                                           \
            (void)(expr);                                                               \
            std::cerr << __FILE__ << ":" << __LINE__ << " [" << runtime                  \
                      << "] did not throw " #E ": " #expr "\n";                         \
            failures++;                                                                 \
        } catch (const E& e_) {                                                         \
            if (std::string(e_.what()).find(text) == std::string::npos) {               \
                std::cerr << __FILE__ << ":" << __LINE__ << " [" << runtime              \
                          << "] message \"" << e_.what() << "\" lacks \"" << text << "\"\n"; \
                failures++;                                                             \
            }                                                                           \
        }                                                                               \
    } while (0)

struct Detection {
    std::string label;
    double score;
    std::vector<tutorial::Blob> boxes;
    tutorial::Blob best;
    std::vector<std::int64_t> ids;
    bool confirmed;
};

struct NotARobotState {
    std::int64_t x;
};

}  // namespace

ESGM_ENTITY(Detection, "Detection", label, score, boxes, best, ids, confirmed)
ESGM_ENTITY(NotARobotState, "RobotState", x)

namespace {

using namespace std::chrono_literals;

void typed_structures(esgm::Esgm& e) {
    e.create_type<Detection>();
    e.create_type<Detection>();  // registering it again keeps it
    e.create_type<tutorial::RobotState>();  // as esgm's library has it
    THROWS(e.create_type<NotARobotState>(), esgm::EntityStructureTypeAlreadyExists, "RobotState");
    esgm::Type t = e.get_entity_structure_type("Detection");
    CHECK(t.attributes().size() == 6);
    CHECK(t.attributes()[2].sort == esgm::Sort::EntityFrameSeq);
    CHECK(t.attributes()[2].element_type == "Blob");

    auto detections = e.create_primitive_entity_trajectory_structure("cpp_detections", "Detection");
    Detection d{"cup", 0.9, {{1, 2, 30}, {4, 5, 60}}, {7, 8, 90}, {3, 1, 4}, true};
    CHECK(detections.add_blocking(d, "det", esgm::seconds(1)) == esgm::Outcome::Added);
    esgm::Sample s = detections.get_latest();
    Detection back = s.as<Detection>();
    CHECK(back.label == "cup" && back.score == 0.9 && back.confirmed);
    CHECK(back.boxes.size() == 2 && back.boxes[1].size == 60);
    CHECK(back.best.x == 7 && back.ids.size() == 3 && back.ids[2] == 4);
    CHECK(s.get<std::string_view>("label") == "cup");
    CHECK(s.get<double>(1) == 0.9);  // by index
    CHECK(s.frames("boxes").size() == 2);
    CHECK(s.frame("boxes", 0).get<std::int64_t>("size") == 30);
    CHECK(s.get<esgm::Span<const std::int64_t>>("ids")[0] == 3);
    CHECK(s.name() == "det" && s.valid_time() == esgm::seconds(1));
    THROWS(s.get<double>("label"), esgm::InvalidType, "label");
    THROWS(s.get<double>("labels"), esgm::NoSuchAttribute, "it has label, score");
    THROWS(s.get<double>(17), esgm::OutOfRange, "no index 17");
    // A structure of the wrong shape is refused with the attribute named.
    THROWS(detections.add_blocking(esgm::Structure("det", 2).set("label", 5)), esgm::InvalidType,
           "label");
    e.destroy_entity_trajectory_structure("cpp_detections");
}

void queries_and_errors(esgm::Esgm& e) {
    auto t = e.create_primitive_entity_trajectory_structure("cpp_odo", "RobotState");
    THROWS(e.create_primitive_entity_trajectory_structure("cpp_odo", "RobotState"),
           esgm::EntityStructureAlreadyExists, "cpp_odo");
    THROWS(e.get_entity_trajectory_structure("cpp_od"), esgm::NoSuchEntityStructure,
           "did you mean `cpp_odo`");
    THROWS(t.get_latest(), esgm::ValueNotAvailable, "cpp_odo");
    for (int i = 1; i <= 5; i++) {
        t.add(tutorial::RobotState{double(i), 0, 0}, "robot1", esgm::seconds(i));
    }
    CHECK(t.get_latest().as<tutorial::RobotState>().x == 5);
    CHECK(t.get_nth_latest(2).as<tutorial::RobotState>().x == 3);
    CHECK(t.get_at(esgm::seconds(2)).get<double>("x") == 2);
    CHECK(t.get_closest_at_or_before(esgm::seconds(2) + 5).get<double>("x") == 2);
    CHECK(t.get_between(esgm::seconds(2), esgm::seconds(4)).size() == 3);
    CHECK(t.get_at_approximating(esgm::milliseconds(2500), esgm::Approximation::Linear)
              .get<double>("x") == 2.5);
    CHECK(t.get_at_approximating(esgm::milliseconds(2900), esgm::MOST_RECENT_VALUE_APPROXIMATION)
              .get<double>("x") == 2);
    auto fallback = esgm::Structure().set("x", 42.0).set("y", 0.0).set("dir", 0.0);
    CHECK(t.get_at_approximating(esgm::seconds(100), fallback).get<double>("x") == 42);
    CHECK(t.start_time() == esgm::seconds(1) && t.end_time() == esgm::seconds(5));
    CHECK(t.type().name() == "RobotState");
    CHECK(t.stats().added == 5);
    CHECK(t.policy_json().find("cache") != std::string::npos);
    esgm::Trajectory copy = t;  // another handle on the same trajectory
    CHECK(copy.get_latest().get<double>("x") == 5);
    t.create_at_now_blocking("robot2", esgm::Structure().set("x", 9.0).set("y", 0.0).set("dir", 0.0));
    CHECK(t.get_latest().name() == "robot2");
    t.reset_blocking();
    THROWS(t.get_latest(), esgm::ValueNotAvailable, "");
    e.destroy_entity_trajectory_structure("cpp_odo");
    THROWS(copy.get_latest(), esgm::NoSuchEntityStructure, "cpp_odo");
}

void policies_and_subscriptions(esgm::Esgm& e) {
    auto t = e.create_trajectory(esgm::Spec::primitive("cpp_pol", "RobotState")
                                     .order(esgm::Order::StrictMonotone)
                                     .cache(3)
                                     .filter("x > 0.0"));
    THROWS(e.create_trajectory(esgm::Spec::primitive("cpp_bad", "RobotState").filter("speed > 0")),
           esgm::IllegalPolicy, "speed");
    auto sub = t.subscribe();
    auto violations = t.subscribe_violations();
    t.add(tutorial::RobotState{1, 0, 0}, "r", esgm::seconds(1));
    THROWS(t.add_blocking(tutorial::RobotState{-1, 0, 0}, "r", esgm::seconds(2)),
           esgm::PolicyViolation, "filter");
    THROWS(t.add_blocking(tutorial::RobotState{1, 0, 0}, "r", 5), esgm::PolicyViolation, "order");
    t.add(tutorial::RobotState{3, 0, 0}, "r", esgm::seconds(3));
    int n = 0;
    for (const esgm::Sample& s : sub) {  // range-for waits for each sample
        n++;
        if (s.get<double>("x") == 3) break;
    }
    CHECK(n == 2);
    CHECK(!sub.recv(10ms).has_value());
    auto v = violations.recv(5s);
    CHECK(v && v->constraint == "filter" && v->trajectory == "cpp_pol");
    v = violations.recv(5s);
    CHECK(v && v->constraint == "order");
    // A loop over a subscription ends when its trajectory is destroyed.
    auto ending = t.subscribe();
    e.destroy_entity_trajectory_structure("cpp_pol");
    int after = 0;
    for (const esgm::Sample& s : ending) {
        (void)s;
        after++;
    }
    CHECK(after == 0);
}

class Doubler : public esgm::CompUnit {
public:
    std::atomic<int> calls{0};
    std::optional<esgm::Structure> compute(const esgm::Inputs& in, esgm::Time q) override {
        calls++;
        auto r = in.at(0).as<tutorial::RobotState>();
        if (r.x < 0) return std::nullopt;
        if (r.x == 13) throw std::runtime_error("thirteen is unlucky");
        if (r.x == 14) throw esgm::ValueNotAvailable();
        r.x *= 2;
        return esgm::Entity<tutorial::RobotState>::to_structure(r, "d", in[0].valid_time(), q);
    }
};

void units_sensors_operators(esgm::Esgm& e) {
    auto doubler = std::make_shared<Doubler>();
    e.add_comp_unit("CppDoubler", "RobotState", {"RobotState"}, doubler);
    THROWS(e.add_comp_unit("CppDoubler", "RobotState", {"RobotState"}, doubler),
           esgm::CompUnitAlreadyExists, "CppDoubler");
    // A lambda as a unit: the sum of two inputs' x.
    e.add_comp_unit("CppSum", "RobotState", {"RobotState", "RobotState"},
                    [](const esgm::Inputs& in, esgm::Time q) {
                        const double x = in[0].get<double>("x") + in[1].get<double>("x");
                        return esgm::Structure("sum", in[1].valid_time(), q)
                            .set("x", x).set("y", 0.0).set("dir", 0.0);
                    });
    auto a = e.create_primitive_entity_trajectory_structure("cpp_a", "RobotState");
    auto b = e.create_primitive_entity_trajectory_structure("cpp_b", "RobotState");
    auto doubled = e.create_computed_entity_trajectory_structure("cpp_doubled", "CppDoubler", {"cpp_a"});
    auto sum = e.create_computed_entity_trajectory_structure("cpp_sum", "CppSum", {"cpp_a", "cpp_b"});
    auto doubled_sub = doubled.subscribe();
    auto sum_sub = sum.subscribe();
    for (double x : {3.0, -1.0, 13.0, 14.0, 5.0}) {
        a.add(tutorial::RobotState{x, 0, 0}, "a", esgm::seconds(static_cast<std::int64_t>(x + 20)));
    }
    b.add(tutorial::RobotState{100, 0, 0}, "b", esgm::seconds(40));
    CHECK(doubled_sub.recv(10s)->get<double>("x") == 6);
    CHECK(doubled_sub.recv(10s)->get<double>("x") == 10);
    CHECK(sum_sub.recv(10s)->get<double>("x") == 105);
    e.flush(10s);
    CHECK(doubler->calls == 5);
    CHECK(e.stats_json().find("thirteen is unlucky") != std::string::npos ||
          e.stats_json().find("fail") != std::string::npos);

    // Every operator kind.
    auto sync = e.create_trajectory(esgm::Spec::sync("cpp_sync", {"cpp_a", "cpp_b"}, esgm::milliseconds(10)));
    auto merge = e.create_trajectory(esgm::Spec::merge("cpp_merge", {"cpp_a", "cpp_b"}));
    auto gen = e.create_trajectory(
        esgm::Spec::generated("cpp_gen", {"cpp_a:linear"}, esgm::milliseconds(100)).lag(0));
    auto merged = merge.subscribe();
    a.add(tutorial::RobotState{7, 0, 0}, "a", esgm::seconds(50));
    CHECK(merged.recv(10s).has_value());
    (void)sync;
    (void)gen;

    // A sensor: a lambda rendering the tutorial's scene into loans of the trajectory.
    const tutorial::SyntheticScene scene(160, 120, 2, 7);
    e.add_sensor_interface("cpp_camera", "Image", [scene](esgm::Time q, esgm::SensorContext& ctx) {
        esgm::ImageLoan frame = ctx.image_loan(scene.width(), scene.height());
        auto px = frame.pixels();
        scene.render_into(q, px.data(), px.size());
        return esgm::Structure("image", q)
            .set("width", std::int64_t{160}).set("height", std::int64_t{120})
            .set("format", std::int64_t{0}).set_image("image_data", std::move(frame));
    });
    THROWS(e.create_entity_trajectory_structure("cpp_frames", "cpp_cam", 0, 0, esgm::milliseconds(50), 0, 3),
           esgm::NoSuchSensor, "cpp_cam");
    auto frames = e.create_entity_trajectory_structure("cpp_frames", "cpp_camera", 0, 0,
                                                       esgm::milliseconds(50), 0, 3);
    auto frame_sub = frames.subscribe();
    auto frame = frame_sub.recv(10s);
    CHECK(frame.has_value());
    if (frame) {
        esgm::ImageView image = frame->image();
        CHECK(image.width == 160 && image.pixels.size() == 160 * 120 * 3);
        auto blobs = tutorial::detect_blobs(image.pixels, image.width, image.height);
        CHECK(blobs.size() == 2);
        // What the reader reads is what the scene rendered for that time.
        std::vector<std::uint8_t> expected(scene.frame_len());
        scene.render_into(frame->valid_time(), expected.data(), expected.size());
        CHECK(std::equal(expected.begin(), expected.end(), image.pixels.begin()));
    }
    for (const char* name : {"cpp_frames", "cpp_gen", "cpp_merge", "cpp_sync", "cpp_sum",
                             "cpp_doubled", "cpp_b", "cpp_a"}) {
        e.destroy_entity_trajectory_structure(name);
    }
    e.remove_sensor_interface("cpp_camera");
    THROWS(e.remove_sensor_interface("cpp_camera"), esgm::NoSuchSensor, "cpp_camera");
}

void images_in_place(esgm::Esgm& e, bool shared) {
    auto images = e.create_trajectory(esgm::Spec::primitive("cpp_images", "Image").cache(4));
    esgm::ImageLoan loan = images.image_loan(640, 480);
    CHECK(loan.shared() == shared);
    auto px = loan.pixels();
    for (std::size_t i = 0; i < px.size(); i++) px[i] = static_cast<std::uint8_t>(i % 249);
    images.add_blocking(esgm::Structure("camera", 1).set("width", 640).set("height", 480)
                            .set("format", 0).set_image("image_data", std::move(loan)));
    esgm::Sample s = images.get_latest();
    esgm::ImageView view = s.image();
    CHECK(view.shared == shared);
    CHECK(view.pixels.size() == 640 * 480 * 3);
    CHECK(view.pixels[1000] == 1000 % 249);
    THROWS(images.image_loan(0, 480), esgm::InvalidArgument, "0 × 480");
    e.destroy_entity_trajectory_structure("cpp_images");
    CHECK(view.pixels[px.size() - 1] == (px.size() - 1) % 249);  // the sample holds them
}

int semantics(esgm::Esgm& e, bool shared) {
    typed_structures(e);
    queries_and_errors(e);
    policies_and_subscriptions(e);
    units_sensors_operators(e);
    images_in_place(e, shared);
    CHECK(e.ping());
    e.set_log_level(esgm::LogLevel::Warn);
    e.flush(5s);
    CHECK(!e.memory_stats_json().empty());
    CHECK(e.trajectories_json().front() == '[');
    return failures;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::cerr << "usage: cpp_api_test in-process | shm DOMAIN | scene SEED BLOBS TIME\n";
        return 2;
    }
    runtime = argv[1];
    try {
        if (runtime == "scene" && argc == 5) {
            const tutorial::SyntheticScene scene(640, 480, std::stoul(argv[3]), std::stoull(argv[2]));
            std::vector<std::uint8_t> frame(scene.frame_len());
            scene.render_into(std::stoll(argv[4]), frame.data(), frame.size());
            std::uint64_t hash = 1469598103934665603ULL;  // FNV-1a
            for (std::uint8_t b : frame) hash = (hash ^ b) * 1099511628211ULL;
            std::cout << hash << "\n";
            for (const auto& b : scene.truth(std::stoll(argv[4])))
                std::cout << b.x << " " << b.y << " " << b.size << "\n";
            return 0;
        }
        int result = 0;
        if (runtime == "in-process") {
            auto e = esgm::Esgm::in_process();
            THROWS(e.serve(), esgm::OperationNotSupported, "in-process");
            result = semantics(e, false);
        } else if (runtime == "shm" && argc == 3) {
            auto e = esgm::Esgm::connect(argv[2]);
            result = semantics(e, true);
        } else {
            std::cerr << "unknown mode " << runtime << "\n";
            return 2;
        }
        std::cout << "cpp_api_test " << runtime << ": "
                  << (result == 0 ? "every check held" : std::to_string(result) + " checks failed")
                  << "\n";
        return result == 0 ? 0 : 1;
    } catch (const esgm::Error& e) {
        std::cerr << "cpp_api_test " << runtime << ": uncaught " << e.status_name() << ": "
                  << e.what() << "\n";
        return 1;
    }
}
