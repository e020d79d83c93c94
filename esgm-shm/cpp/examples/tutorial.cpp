// The seed's tutorial main program (esgm_tutorial.cc, chapters 6-10), in C++ on esgm,
// step by step as the seed writes it: retrieve the ESGM, create the entity structure
// types, a primitive trajectory for the robot states, register the camera sensor and
// sample it, register the blob detection, blob selection and driving direction units
// and compute their trajectories, push robot states from a thread, then query the
// driving direction (latest, between, approximated) and subscribe to it.
//
//   tutorial                 the ESGM in this process
//   tutorial --domain lab    the system of `esgm up --domain lab` (as separate processes)
//
// Where the seed used CORBA servants and wrappers, esgm takes C++ lambdas and classes,
// and typed structs (ESGM_ENTITY). The units compute for real: blobs are found in the
// camera's synthetic scene and the robot steers towards the first one.
#include "blob_detection.hpp"
#include "driving_direction.hpp"
#include "synthetic_scene.hpp"

#include <esgm/esgm.hpp>

#include <atomic>
#include <chrono>
#include <iostream>
#include <string>
#include <thread>

using esgm::Time;
using esgm::TIMEUNITS_PER_MILLI_SECOND;
using esgm::TIMEUNITS_PER_SECOND;
using std::cout;
using std::endl;
using std::flush;

struct BlobSeq {
    std::vector<tutorial::Blob> items;
};
ESGM_ENTITY(BlobSeq, "BlobSeq", items)

/** The sensor interface to the camera (seed 8.2). */
class CameraSensorInterface : public esgm::SensorInterface {
public:
    esgm::Structure get_current_value(Time qtime, esgm::SensorContext& context) override {
        esgm::ImageLoan img_data = context.image_loan(scene_.width(), scene_.height());
        esgm::Span<std::uint8_t> pixels = img_data.pixels();
        scene_.render_into(qtime, pixels.data(), pixels.size());
        Time now = qtime;
        return esgm::Structure("image", now)
            .set("width", std::int64_t{scene_.width()})
            .set("height", std::int64_t{scene_.height()})
            .set("format", std::int64_t{0})
            .set_image("image_data", std::move(img_data));
    }

private:
    tutorial::SyntheticScene scene_{640, 480, 3, 0};
};

/** The blob detection computational unit (seed 9.1). */
class BlobDetectionCU : public esgm::CompUnit {
public:
    std::optional<esgm::Structure> compute(const esgm::Inputs& inputs, Time qtime) override {
        if (inputs.size() == 1) {
            Time now = qtime;
            esgm::ImageView image = inputs[0].image();  // read in place, not copied
            BlobSeq blobs{tutorial::detect_blobs(image.pixels, image.width, image.height)};
            return esgm::Entity<BlobSeq>::to_structure(blobs, "blobs", inputs[0].valid_time(), now);
        }
        throw esgm::ValueNotAvailable();
    }
};

/** The blob selection computational unit: the largest blob is the object of interest. */
class BlobSelectionCU : public esgm::CompUnit {
public:
    std::optional<esgm::Structure> compute(const esgm::Inputs& inputs, Time qtime) override {
        if (inputs.size() == 1) {
            BlobSeq blobs = inputs[0].as<BlobSeq>();
            if (!blobs.items.empty()) {
                tutorial::Blob best = blobs.items[0];
                for (const tutorial::Blob& b : blobs.items) {
                    if (b.size > best.size) best = b;
                }
                return esgm::Entity<tutorial::Blob>::to_structure(best, "blob",
                                                                  inputs[0].valid_time(), qtime);
            }
        }
        throw esgm::ValueNotAvailable();
    }
};

/** The driving direction computational unit (seed 9.2). */
class DrivingDirectionCU : public esgm::CompUnit {
public:
    std::optional<esgm::Structure> compute(const esgm::Inputs& inputs, Time qtime) override {
        // input[0] is the robot state and input[1] the current blob
        if (inputs.size() == 2 && inputs[0].valid_time() >= inputs[1].valid_time()) {
            auto robot_state = inputs[0].as<tutorial::RobotState>();
            auto blob = inputs[1].as<tutorial::Blob>();
            // Compute driving direction
            auto driving_dir = tutorial::compute_direction({}, robot_state, blob);
            return esgm::Entity<tutorial::DrivingDirection>::to_structure(
                driving_dir, "driving_dir", inputs[0].valid_time(), qtime);
        }
        throw esgm::ValueNotAvailable();
    }
};

/** Joins a thread when it goes, so an exception on the way out cannot terminate. */
struct Joined {
    std::atomic<bool>& finished;
    std::thread thread;
    ~Joined() {
        finished = true;
        if (thread.joinable()) thread.join();
    }
};

/** The robot sensor thread: a new robot state every 100 ms (seed 8.1). */
void thread_main(esgm::Trajectory robot_state_ets, std::atomic<bool>& finished) {
    cout << "started robot sensor thread" << endl;
    double dir = 0;
    while (!finished) {
        try {
            robot_state_ets.create_at_now("robot1", esgm::Entity<tutorial::RobotState>::to_frame(
                                                        tutorial::RobotState{1, 2, dir}));
            dir = dir + 1 >= 360 ? 0 : dir + 1;
        } catch (const esgm::Error& e) {
            cout << "caught esgm::Error " << e.what() << endl;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    cout << "killed robot sensor thread" << endl;
}

std::string show(const esgm::Sample& s) {
    auto d = s.as<tutorial::DrivingDirection>();
    return "valid at " + std::to_string(s.valid_time()) + ": dir " + std::to_string(d.dir) +
           " speed " + std::to_string(d.speed);
}

int main(int argc, char* argv[]) {
    std::string domain;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (std::string(argv[i]) == "--domain") domain = argv[i + 1];
    }
    try {
        // Retrieve the ESGM (seed 6.3)
        cout << "retrieving the ESGM " << (domain.empty() ? "(in this process)" : domain)
             << "... " << flush;
        esgm::Esgm esgm = domain.empty() ? esgm::Esgm::in_process() : esgm::Esgm::connect(domain);
        cout << "done" << endl;

        // Create the entity structure types (seed 7.3); esgm's library has the
        // tutorial's types already, as the seed's wrappers define them.
        std::string blob_type_name("Blob");
        std::string image_type_name("Image");
        std::string blob_seq_type_name("BlobSeq");
        std::string robot_state_type_name("RobotState");
        std::string driving_direction_type_name("DrivingDirection");
        esgm::Type blob_type("Blob");
        blob_type.attr("x", esgm::Sort::Long).attr("y", esgm::Sort::Long).attr("size", esgm::Sort::Long);
        try {
            esgm.create_entity_structure_type(blob_type_name, blob_type);
        } catch (const esgm::EntityStructureTypeAlreadyExists&) {
            cout << "the type Blob is in esgm's library already" << endl;
        }
        esgm.create_type<tutorial::RobotState>();
        esgm.create_type<tutorial::DrivingDirection>();
        esgm.create_type<BlobSeq>();

        // Create a primitive entity trajectory structure for the robot sensor (seed 8.1)
        esgm::Trajectory robot_state =
            esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState");

        // Register the camera sensor (seed 8.2)
        cout << "add the camera sensor interface... " << flush;
        esgm.add_sensor_interface("camera", image_type_name,
                                  std::make_shared<CameraSensorInterface>());
        cout << "done" << endl;

        // Create an entity trajectory structure called images which samples the camera
        // sensor every second forever with any delay, and stores the last 5 images
        cout << "create images entity trajectory structure... " << flush;
        esgm::Trajectory images = esgm.create_entity_trajectory_structure(
            "images", "camera", 0, 0, 1 * TIMEUNITS_PER_SECOND, 0, 5);
        cout << "done" << endl;

        // Register the blob detection comp unit (seed 9.1)
        cout << "add the blob detection comp unit... " << flush;
        esgm.add_comp_unit("BlobDetection", blob_seq_type_name, {ESGM_ANY_STRUCTURE},
                           std::make_shared<BlobDetectionCU>());
        cout << "done" << endl;

        // Create a computed entity trajectory structure called blobs which extracts
        // blobs from each image from the camera sensor
        cout << "create blobs entity trajectory structure... " << flush;
        esgm::Trajectory blobs =
            esgm.create_computed_entity_trajectory_structure("blobs", "BlobDetection", {"images"});
        cout << "done" << endl;

        // Register the blob selection comp unit
        cout << "add the blob selection comp unit... " << flush;
        esgm.add_comp_unit("BlobSelection", blob_type_name, {ESGM_ANY_STRUCTURE},
                           std::make_shared<BlobSelectionCU>());
        cout << "done" << endl;

        // Create a computed entity trajectory structure called current_blob which
        // selects one of the input blobs
        cout << "create current blob entity trajectory structure... " << flush;
        esgm::Trajectory current_blob = esgm.create_computed_entity_trajectory_structure(
            "current_blob", "BlobSelection", {"blobs"});
        cout << "done" << endl;

        // Register the driving direction comp unit (seed 9.2)
        cout << "add the driving direction comp unit... " << flush;
        esgm.add_comp_unit("DrivingDirection", driving_direction_type_name,
                           {ESGM_ANY_STRUCTURE, ESGM_ANY_STRUCTURE},
                           std::make_shared<DrivingDirectionCU>());
        cout << "done" << endl;

        // Create a computed entity trajectory structure called driving_direction which
        // computes the driving direction to the blob
        cout << "create driving direction entity trajectory structure... " << flush;
        esgm::Trajectory driving_direction = esgm.create_computed_entity_trajectory_structure(
            "driving_direction", "DrivingDirection", {"robot_state", "current_blob"});
        cout << "done" << endl;

        // Create a thread which pushes the robot's state every 100 ms
        cout << "create robot sensor thread... " << flush;
        std::atomic<bool> finished{false};
        Joined robot{finished, std::thread(thread_main, robot_state, std::ref(finished))};
        cout << "done" << endl;

        // Run for a while to get things started
        cout << "run for a while... " << endl;
        std::this_thread::sleep_for(std::chrono::seconds(3));
        cout << "...finished running" << endl;

        // Retrieve the driving direction entity trajectory structure (seed 10.1)
        cout << "get driving direction entity trajectory structure... " << flush;
        esgm::Trajectory driving_dir = esgm.get_entity_trajectory_structure("driving_direction");
        cout << "done" << endl;

        // Get the latest value (seed 10.2)
        cout << "get current driving direction... " << flush;
        esgm::Sample latest = driving_dir.get_latest();
        cout << show(latest) << endl;

        // Get all entity structures between t1 and t2
        Time t1 = latest.valid_time() - 5 * TIMEUNITS_PER_SECOND;
        Time t2 = latest.valid_time() - 1 * TIMEUNITS_PER_SECOND;
        cout << "get the driving direction between " << t1 << " and " << t2 << "... " << flush;
        std::vector<esgm::Sample> interval = driving_dir.get_between(t1, t2);
        cout << interval.size() << " structures" << endl;

        // Approximate the value at time-point t
        Time t = latest.valid_time() - 100 * TIMEUNITS_PER_MILLI_SECOND;
        cout << "get the driving direction at " << t << "... " << flush;
        esgm::Sample at_t = driving_dir.get_at_approximating(t, esgm::MOST_RECENT_VALUE_APPROXIMATION);
        cout << show(at_t) << endl;

        // Subscribe to the current driving direction (seed 10.3): the callback runs on
        // a thread of its own for every new structure
        cout << "subscribe to the driving direction... " << flush;
        esgm::Subscription sub_proxy = driving_dir.subscribe();
        std::atomic<int> got{0};
        Joined callback{finished, std::thread([&] {
            while (!finished) {
                if (auto s = sub_proxy.recv(std::chrono::milliseconds(100))) {
                    cout << "got sample driving_dir = " << show(*s) << endl;
                    got++;
                }
            }
        })};
        cout << "done" << endl;

        // Run for a while, this should generate some callbacks
        cout << "run for a while... " << endl;
        std::this_thread::sleep_for(std::chrono::seconds(2));
        cout << "...finished running" << endl;

        // Notify the threads that the application is finished and wait for them
        finished = true;
        cout << "wait for robot sensor thread to finish... " << flush;
        robot.thread.join();
        callback.thread.join();
        cout << "done" << endl;
        cout << "tutorial: " << got << " driving directions received, "
             << images.stats().added << " images, " << blobs.stats().added << " blob sets, "
             << current_blob.stats().added << " current blobs" << endl;
        return got > 0 ? 0 : 1;
    } catch (const esgm::Error& e) {
        cout << "caught esgm::Error " << e.status_name() << ": " << e.what() << endl;
    } catch (const std::exception& e) {
        cout << "caught std::exception " << e.what() << endl;
    } catch (...) {
        cout << "caught unknown exception" << endl;
    }
    return 1;
}
