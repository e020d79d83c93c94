// esgm-bench's ROS 1 peer of the Autoware reference system (refsys-ros1): one node of
// the topology per process, on roscpp, as a ROS 1 user deploys nodes.
//
//   refsys_node NODE CRUNCH DIR KIND ARGS...
//   refsys_node --crunch-time CRUNCH        (prints one crunch's median time here in ns,
//                                            and its result)
//     KIND ARGS: sensor PERIOD_NS
//                transform INPUT OUTPUT [HOT_ROOT]   (HOT_ROOT: this is the hot path's sink)
//                fusion INPUT0 INPUT1
//                cyclic PERIOD_NS INPUT...
//                intersection INPUT0 OUTPUT0 INPUT1 OUTPUT1
//                command INPUT
//
// The node's kind, topics and period come from esgm-bench (benches/src/refsys/
// topology.rs renders them, benches/src/refsys/ros1.rs starts this program), so the
// graph is written down once. What a node does with its messages is a line-by-line port
// of benches/src/refsys/node.rs (itself upstream's nodes/rclcpp/*.hpp without the
// transport), on Message4kb byte for byte as benches/src/refsys/message.rs, with
// upstream's number cruncher; the report it writes is report.rs's text. Change one, change
// the other.
//
// Transport, as a ROS 1 user would write upstream's nodes:
// - every topic carries a std_msgs/UInt8MultiArray of the message's 4,096 bytes (ROS 1
//   cannot build upstream's reference_interfaces/Message4kb without catkin's message
//   generation; UInt8MultiArray is a plain type every ROS 1 install has, and adds only
//   its 12-byte layout and length header on the wire);
// - upstream's history depth 1 is a queue of 1 on every publisher and subscriber (roscpp
//   drops the oldest message when one is full); TCPROS with TCP_NODELAY, as
//   ros1_pingpong;
// - sensors and the behavior planner are ros::WallTimers with upstream's periods,
//   created so they first fire at START;
// - callbacks (subscriptions and the timer) run on one thread, a ros::AsyncSpinner(1),
//   as upstream's single-threaded executor runs a node's callbacks.
//
// On standard input and output it speaks esgm-bench's protocol (benches/src/refsys/
// processes.rs): it prints `ready` once its publishers and subscribers exist and every
// subscriber is connected to its topic's publisher; reads `go START UNTIL` (ns,
// CLOCK_REALTIME); produces from START to UNTIL; at UNTIL + 500 ms stops its callbacks,
// writes DIR/NODE.txt, prints `note ...` lines for anything it could not handle and
// `done`; then leaves on `exit` or the end of its input. Every wait has a deadline; a
// failure prints one line on stderr and exits with 2 (bad arguments: 1).
#include <ros/ros.h>
#include <std_msgs/UInt8MultiArray.h>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace {

// ---------------------------------------------------------------------------------------
// Message4kb (message.rs): an 8-byte count, 63 stats of 64 bytes {u64 timestamp,
// u32 sequence, u32 dropped, 48-byte NUL-terminated name}, 56 bytes of data; little endian.

constexpr size_t kMessageLen = 4096;
constexpr size_t kStatsCapacity = 63;
constexpr size_t kStatsLen = 64;
constexpr size_t kNameLen = 48;
constexpr size_t kStatsAt = 8;
constexpr size_t kDataAt = kStatsAt + kStatsCapacity * kStatsLen;
static_assert(kDataAt + 56 == kMessageLen, "Message4kb is 4,096 bytes");

uint64_t get_u64(const uint8_t* p) {
    uint64_t v = 0;
    for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
    return v;
}

uint32_t get_u32(const uint8_t* p) {
    uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
    return v;
}

void put_u64(uint8_t* p, uint64_t v) {
    for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

void put_u32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

// One hop of a trace.
struct Hop {
    uint64_t timestamp = 0;
    uint32_t sequence = 0;
};

// The name in a stats entry, up to its NUL.
std::string_view name_of(const uint8_t* entry) {
    const char* name = reinterpret_cast<const char*>(entry + 16);
    size_t len = 0;
    while (len < kNameLen && name[len] != '\0') ++len;
    return std::string_view(name, len);
}

// A received message's bytes, checked to be a Message4kb (see `view_of`).
class View {
public:
    explicit View(const uint8_t* bytes) : b_(bytes) {}
    uint64_t count() const { return get_u64(b_); }
    const uint8_t* entry(size_t i) const { return b_ + kStatsAt + i * kStatsLen; }

    // The last hop's sequence number (its publisher's), 0 for an empty trace.
    uint32_t sequence() const {
        const uint64_t n = count();
        return n == 0 ? 0 : get_u32(entry(n - 1) + 8);
    }

    // The hop of `node`, if the trace has it.
    std::optional<Hop> hop(std::string_view node) const {
        for (size_t i = 0; i < count(); ++i) {
            if (name_of(entry(i)) == node) {
                return Hop{get_u64(entry(i)), get_u32(entry(i) + 8)};
            }
        }
        return std::nullopt;
    }

private:
    const uint8_t* b_;
};

using Input = std_msgs::UInt8MultiArray::ConstPtr;

// The message in `m`, or nothing if its bytes are not a Message4kb (message.rs's
// `from_bytes`: 4,096 bytes, at most 63 stats).
std::optional<View> view_of(const Input& m) {
    if (!m || m->data.size() != kMessageLen) return std::nullopt;
    View v(m->data.data());
    if (v.count() > kStatsCapacity) return std::nullopt;
    return v;
}

// A message being made.
class Message {
public:
    Message() : bytes_(kMessageLen, 0) {}

    // Adds the entries of `source`'s trace whose node is not in this one yet, as many as
    // fit (upstream's merge_history_into_sample).
    void merge_history(const View& source) {
        for (size_t i = 0; i < source.count(); ++i) {
            const uint64_t n = count();
            if (n >= kStatsCapacity) return;
            const uint8_t* e = source.entry(i);
            bool there = false;
            for (size_t k = 0; k < n && !there; ++k) there = name_of(entry(k)) == name_of(e);
            if (there) continue;
            std::memcpy(entry(n), e, kStatsLen);
            put_u64(bytes_.data(), n + 1);
        }
    }

    // Appends `node`'s own entry, unless the trace is full (upstream's set_sample).
    void push_hop(const std::string& node, uint32_t sequence, uint32_t dropped,
                  uint64_t timestamp) {
        const uint64_t n = count();
        if (n >= kStatsCapacity) return;
        uint8_t* e = entry(n);
        std::memset(e, 0, kStatsLen);
        put_u64(e, timestamp);
        put_u32(e + 8, sequence);
        put_u32(e + 12, dropped);
        std::memcpy(e + 16, node.data(), std::min(node.size(), kNameLen - 1));
        put_u64(bytes_.data(), n + 1);
    }

    // Writes the work's result into the data (so no compiler drops the work).
    void set_result(int64_t result) {
        put_u64(bytes_.data() + kDataAt, static_cast<uint64_t>(result));
    }

    // Its bytes, moved out.
    std::vector<uint8_t> take() { return std::move(bytes_); }

private:
    uint64_t count() const { return get_u64(bytes_.data()); }
    uint8_t* entry(size_t i) { return bytes_.data() + kStatsAt + i * kStatsLen; }
    std::vector<uint8_t> bytes_;
};

// The samples missed on an input whose last sequence number was `last` and whose new
// message carries `current`; updates `last` (get_missed_samples_and_update_seq_nr).
uint32_t missed(uint32_t& last, uint32_t current) {
    const uint32_t gap = current > last ? current - last - 1 : 0;
    last = current;
    return gap;
}

// ---------------------------------------------------------------------------------------
// The number cruncher (cruncher.rs, upstream's number_cruncher.hpp with its `escape`).

// Whether `n` divides `i`, as rustc's LLVM compiles `i % n == 0` on x86-64: a 32-bit
// division when both fit, a 64-bit one otherwise. g++ always emits the 64-bit one, which
// took 4.0 ms a crunch to 4096 here against 2.3 ms for this and for esgm-bench's Rust
// build: written out, every system's nodes do the same work at the same cost.
inline bool divides(uint64_t n, uint64_t i) {
    if (((i | n) >> 32) == 0) return static_cast<uint32_t>(i) % static_cast<uint32_t>(n) == 0;
    return i % n == 0;
}

int64_t number_cruncher(uint64_t maximum) {
    const uint64_t initial = 2;
    if (maximum <= initial) return 2;
    int64_t primes = 0;
    for (uint64_t i = initial; i <= maximum; ++i) {
        bool is_prime = true;
        for (uint64_t n = initial; n < i; ++n) {
            if (divides(n, i)) {
                is_prime = false;
                break;
            }
        }
        asm volatile("" : : "g"(is_prime) : "memory");
        if (is_prime) ++primes;
    }
    return primes;
}

// Now on the system clock (CLOCK_REALTIME), ns: every process stamps one timeline.
uint64_t now_ns() {
    timespec ts{};
    if (clock_gettime(CLOCK_REALTIME, &ts) != 0) return 0;
    return static_cast<uint64_t>(ts.tv_sec) * 1000000000ULL + static_cast<uint64_t>(ts.tv_nsec);
}

// Sleeps until `ns` on the system clock (never wakes early).
void sleep_until(uint64_t ns) {
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(ns / 1000000000ULL);
    ts.tv_nsec = static_cast<long>(ns % 1000000000ULL);
    while (clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
}

// ---------------------------------------------------------------------------------------
// The report (report.rs).

struct HotPathRecord {
    uint32_t root_sequence;
    uint64_t root_timestamp;
    uint64_t sink_timestamp;
};

struct Received {
    std::string topic;
    uint64_t received;
    uint64_t missed;
};

struct Report {
    explicit Report(std::string name) : node(std::move(name)) {}

    std::string node;
    std::vector<std::pair<std::string, uint64_t>> published;
    std::vector<Received> received;
    std::vector<HotPathRecord> hot_path;
    std::vector<uint64_t> planner_fired;

    // Another report of the same node (an intersection's second connection) folded in.
    void merge(const Report& other) {
        published.insert(published.end(), other.published.begin(), other.published.end());
        received.insert(received.end(), other.received.begin(), other.received.end());
        hot_path.insert(hot_path.end(), other.hot_path.begin(), other.hot_path.end());
        planner_fired.insert(planner_fired.end(), other.planner_fired.begin(),
                             other.planner_fired.end());
    }

    std::string text() const {
        std::ostringstream s;
        s << "node " << node << "\n";
        for (const auto& [t, n] : published) s << "published " << t << " " << n << "\n";
        for (const auto& r : received) {
            s << "received " << r.topic << " " << r.received << " " << r.missed << "\n";
        }
        for (const auto& h : hot_path) {
            s << "hot " << h.root_sequence << " " << h.root_timestamp << " " << h.sink_timestamp
              << "\n";
        }
        for (uint64_t t : planner_fired) s << "fired " << t << "\n";
        return s.str();
    }
};

// ---------------------------------------------------------------------------------------
// Each kind's logic (node.rs).

class Sensor {
public:
    explicit Sensor(std::string name) : name_(std::move(name)) {}

    Message fire() {
        Message m;
        m.push_hop(name_, sequence_, 0, now_ns());
        ++sequence_;
        return m;
    }

    Report report() const {
        Report r(name_);
        r.published.emplace_back(name_, sequence_);
        return r;
    }

private:
    std::string name_;
    uint32_t sequence_ = 0;
};

class Transform {
public:
    // `hot_root` non-empty: this is the hot path's sink, recording that root's hop.
    Transform(std::string name, std::string input, std::string output, uint64_t crunch,
              std::string hot_root)
        : name_(std::move(name)),
          input_(std::move(input)),
          output_(std::move(output)),
          crunch_(crunch),
          hot_root_(std::move(hot_root)) {}

    Message on_input(const View& input) {
        const uint64_t timestamp = now_ns();
        const int64_t result = number_cruncher(crunch_);
        Message out;
        out.merge_history(input);
        const uint32_t dropped = missed(last_input_, input.sequence());
        ++received_;
        dropped_ += dropped;
        out.push_hop(name_, sequence_, dropped, timestamp);
        out.set_result(result);
        ++sequence_;
        if (!hot_root_.empty()) {
            if (auto root = input.hop(hot_root_)) {
                hot_path_.push_back({root->sequence, root->timestamp, timestamp});
            }
        }
        return out;
    }

    Report report() const {
        Report r(name_);
        r.published.emplace_back(output_, sequence_);
        r.received.push_back({input_, received_, dropped_});
        r.hot_path = hot_path_;
        return r;
    }

private:
    std::string name_, input_, output_;
    uint64_t crunch_;
    std::string hot_root_;
    uint32_t sequence_ = 0;
    uint32_t last_input_ = 0;
    uint64_t received_ = 0;
    uint64_t dropped_ = 0;
    std::vector<HotPathRecord> hot_path_;
};

class Fusion {
public:
    Fusion(std::string name, std::string input0, std::string input1, uint64_t crunch)
        : name_(std::move(name)), inputs_{std::move(input0), std::move(input1)}, crunch_(crunch) {}

    // Takes a message of input `index` (its bytes checked); the output once both have one.
    std::optional<Message> on_input(size_t index, const Input& input) {
        const uint64_t timestamp = now_ns();
        ++received_[index];
        cache_[index] = input;
        if (!cache_[0] || !cache_[1]) return std::nullopt;
        const int64_t result = number_cruncher(crunch_);
        const View a(cache_[0]->data.data()), b(cache_[1]->data.data());
        const uint32_t gaps[2] = {missed(last_input_[0], a.sequence()),
                                  missed(last_input_[1], b.sequence())};
        Message out;
        out.merge_history(a);
        out.merge_history(b);
        out.push_hop(name_, sequence_, gaps[0] + gaps[1], timestamp);
        out.set_result(result);
        dropped_[0] += gaps[0];
        dropped_[1] += gaps[1];
        ++sequence_;
        cache_[0].reset();
        cache_[1].reset();
        return out;
    }

    Report report() const {
        Report r(name_);
        r.published.emplace_back(name_, sequence_);
        for (size_t i = 0; i < 2; ++i) {
            r.received.push_back({inputs_[i], received_[i], dropped_[i]});
        }
        return r;
    }

private:
    std::string name_;
    std::string inputs_[2];
    uint64_t crunch_;
    Input cache_[2];
    uint32_t last_input_[2] = {0, 0};
    uint64_t received_[2] = {0, 0};
    uint64_t dropped_[2] = {0, 0};
    uint32_t sequence_ = 0;
};

class Cyclic {
public:
    Cyclic(std::string name, std::vector<std::string> inputs, uint64_t crunch)
        : name_(std::move(name)),
          inputs_(std::move(inputs)),
          crunch_(crunch),
          cache_(inputs_.size()),
          last_input_(inputs_.size(), 0),
          received_(inputs_.size(), 0),
          dropped_(inputs_.size(), 0) {}

    // Keeps the latest message of input `index` (its bytes checked).
    void on_input(size_t index, const Input& input) {
        ++received_[index];
        cache_[index] = input;
    }

    Message on_timer() {
        const uint64_t timestamp = now_ns();
        fired_.push_back(timestamp);
        const int64_t result = number_cruncher(crunch_);
        Message out;
        uint32_t dropped = 0;
        for (size_t i = 0; i < cache_.size(); ++i) {
            if (!cache_[i]) continue;
            const View m(cache_[i]->data.data());
            const uint32_t gap = missed(last_input_[i], m.sequence());
            dropped_[i] += gap;
            dropped += gap;
            out.merge_history(m);
            cache_[i].reset();
        }
        out.push_hop(name_, sequence_, dropped, timestamp);
        out.set_result(result);
        ++sequence_;
        return out;
    }

    Report report() const {
        Report r(name_);
        r.published.emplace_back(name_, sequence_);
        for (size_t i = 0; i < inputs_.size(); ++i) {
            r.received.push_back({inputs_[i], received_[i], dropped_[i]});
        }
        r.planner_fired = fired_;
        return r;
    }

private:
    std::string name_;
    std::vector<std::string> inputs_;
    uint64_t crunch_;
    std::vector<Input> cache_;
    std::vector<uint32_t> last_input_;
    std::vector<uint64_t> received_;
    std::vector<uint64_t> dropped_;
    uint32_t sequence_ = 0;
    std::vector<uint64_t> fired_;
};

class Command {
public:
    Command(std::string name, std::string input)
        : name_(std::move(name)), input_(std::move(input)) {}

    void on_input(const View& input) {
        ++received_;
        dropped_ += missed(last_input_, input.sequence());
    }

    Report report() const {
        Report r(name_);
        r.received.push_back({input_, received_, dropped_});
        return r;
    }

private:
    std::string name_, input_;
    uint32_t last_input_ = 0;
    uint64_t received_ = 0;
    uint64_t dropped_ = 0;
};

// ---------------------------------------------------------------------------------------
// The node on roscpp.

constexpr double kMasterPatience = 60.0;     // for the rosmaster esgm-bench starts with us
constexpr double kConnectPatience = 60.0;    // for every input's publisher to connect
constexpr double kMasterRetry = 10.0;        // per call to the master after that
constexpr uint64_t kDrainNs = 500000000ULL;  // esgm's DRAIN: in-flight messages land
constexpr uint64_t kDayNs = 86400ULL * 1000000000ULL;
constexpr uint32_t kDepth = 1;               // upstream's history depth

// When the topology runs (set from `go`): sensors and the planner publish only inside it.
struct Window {
    std::atomic<uint64_t> start{0}, until{0};
    bool open(uint64_t t) const {
        const uint64_t s = start.load();
        return s > 0 && t >= s && t < until.load();
    }
};

// A subscription, and what arrived on it that was not a Message4kb.
struct Inlet {
    std::string topic;
    ros::Subscriber subscriber;
    uint64_t invalid = 0;  // touched only on the spinner's thread, read after it stopped
};

// Everything one node holds: its ports, its logic (behind `report`), its timer.
struct Node {
    std::string name;
    ros::NodeHandle nh;
    Window window;
    std::vector<ros::Publisher> publishers;
    std::vector<std::unique_ptr<Inlet>> inlets;
    std::function<Report()> report;
    // A sensor's or the planner's timer: its period and what it does each tick.
    uint64_t period_ns = 0;
    std::function<void()> tick;
    ros::WallTimer timer;
};

[[noreturn]] void fail(const std::string& what) {
    std::fprintf(stderr, "refsys_node: %s\n", what.c_str());
    std::fflush(stderr);
    std::_Exit(2);
}

void publish(ros::Publisher& pub, Message m) {
    std_msgs::UInt8MultiArray out;
    out.data = m.take();
    pub.publish(out);
}

ros::Publisher advertise(Node& node, const std::string& topic) {
    ros::Publisher pub = node.nh.advertise<std_msgs::UInt8MultiArray>(topic, kDepth);
    if (!pub) fail("cannot advertise " + topic);
    node.publishers.push_back(pub);
    return pub;
}

// Subscribes to `topic`; `on` gets each message whose bytes are a Message4kb.
void subscribe(Node& node, const std::string& topic, std::function<void(const Input&)> on) {
    node.inlets.push_back(std::make_unique<Inlet>());
    Inlet* inlet = node.inlets.back().get();
    inlet->topic = topic;
    ros::SubscribeOptions ops;
    ops.init<std_msgs::UInt8MultiArray>(topic, kDepth, [inlet, on](const Input& m) {
        if (!view_of(m)) {
            ++inlet->invalid;
            return;
        }
        on(m);
    });
    ops.transport_hints = ros::TransportHints().tcpNoDelay();
    inlet->subscriber = node.nh.subscribe(ops);
    if (!inlet->subscriber) fail("cannot subscribe to " + topic);
}

uint64_t parse_u64(const char* s, const char* what) {
    errno = 0;
    char* end = nullptr;
    const unsigned long long v = std::strtoull(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0' || s[0] == '-') {
        std::fprintf(stderr, "refsys_node: %s `%s` is not a number\n", what, s);
        std::exit(1);
    }
    return v;
}

// Builds the node `args` describe (KIND ARGS...; see the header).
void build(Node& node, uint64_t crunch, const std::vector<std::string>& args) {
    const std::string& kind = args.empty() ? std::string() : args[0];
    const size_t n = args.size();
    auto usage = [&]() {
        std::fprintf(stderr, "refsys_node: bad arguments for a `%s` node\n", kind.c_str());
        std::exit(1);
    };
    if (kind == "sensor") {
        if (n != 2) usage();
        node.period_ns = parse_u64(args[1].c_str(), "the period");
        auto sensor = std::make_shared<Sensor>(node.name);
        ros::Publisher pub = advertise(node, node.name);
        node.tick = [sensor, pub]() mutable { publish(pub, sensor->fire()); };
        node.report = [sensor]() { return sensor->report(); };
    } else if (kind == "transform") {
        if (n != 3 && n != 4) usage();
        auto t = std::make_shared<Transform>(node.name, args[1], args[2], crunch,
                                             n == 4 ? args[3] : std::string());
        ros::Publisher pub = advertise(node, args[2]);
        subscribe(node, args[1], [t, pub](const Input& m) mutable {
            publish(pub, t->on_input(View(m->data.data())));
        });
        node.report = [t]() { return t->report(); };
    } else if (kind == "intersection") {
        if (n != 5) usage();
        std::vector<std::shared_ptr<Transform>> both;
        for (size_t c = 0; c < 2; ++c) {
            const std::string& input = args[1 + 2 * c];
            const std::string& output = args[2 + 2 * c];
            auto t = std::make_shared<Transform>(node.name, input, output, crunch, "");
            ros::Publisher pub = advertise(node, output);
            subscribe(node, input, [t, pub](const Input& m) mutable {
                publish(pub, t->on_input(View(m->data.data())));
            });
            both.push_back(t);
        }
        node.report = [both]() {
            Report r = both[0]->report();
            r.merge(both[1]->report());
            return r;
        };
    } else if (kind == "fusion") {
        if (n != 3) usage();
        auto f = std::make_shared<Fusion>(node.name, args[1], args[2], crunch);
        ros::Publisher pub = advertise(node, node.name);
        for (size_t i = 0; i < 2; ++i) {
            subscribe(node, args[1 + i], [f, pub, i](const Input& m) mutable {
                if (auto out = f->on_input(i, m)) publish(pub, std::move(*out));
            });
        }
        node.report = [f]() { return f->report(); };
    } else if (kind == "cyclic") {
        if (n < 3) usage();
        node.period_ns = parse_u64(args[1].c_str(), "the period");
        const std::vector<std::string> inputs(args.begin() + 2, args.end());
        auto c = std::make_shared<Cyclic>(node.name, inputs, crunch);
        ros::Publisher pub = advertise(node, node.name);
        for (size_t i = 0; i < inputs.size(); ++i) {
            subscribe(node, inputs[i], [c, i](const Input& m) { c->on_input(i, m); });
        }
        node.tick = [c, pub]() mutable { publish(pub, c->on_timer()); };
        node.report = [c]() { return c->report(); };
    } else if (kind == "command") {
        if (n != 2) usage();
        auto c = std::make_shared<Command>(node.name, args[1]);
        subscribe(node, args[1], [c](const Input& m) { c->on_input(View(m->data.data())); });
        node.report = [c]() { return c->report(); };
    } else {
        std::fprintf(stderr, "refsys_node: no node kind `%s`\n", kind.c_str());
        std::exit(1);
    }
    if (node.tick && node.period_ns == 0) usage();
}

// Waits for the rosmaster (esgm-bench starts it with the nodes): a deadline, not roscpp's
// endless retry.
void wait_for_master() {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(kMasterPatience);
    while (!ros::master::check()) {
        if (ros::WallTime::now() > deadline) {
            fail("no rosmaster at " + ros::master::getURI() + " within 60 s");
        }
        ros::WallDuration(0.05).sleep();
    }
}

// Waits until every input's publisher is connected, so the run does not start with a
// topic nobody delivers yet.
void wait_for_connections(const Node& node) {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(kConnectPatience);
    for (const auto& inlet : node.inlets) {
        while (inlet->subscriber.getNumPublishers() == 0) {
            if (!ros::ok() || ros::WallTime::now() > deadline) {
                fail("no publisher of " + inlet->topic + " connected within 60 s");
            }
            ros::WallDuration(0.01).sleep();
        }
    }
}

// One line of standard input; false at its end.
bool read_line(std::string& line) {
    return static_cast<bool>(std::getline(std::cin, line));
}

// One line to esgm-bench; if it cannot be told, the run is over.
void say(const std::string& line) {
    if (std::printf("%s\n", line.c_str()) < 0 || std::fflush(stdout) != 0) {
        fail("cannot write to esgm-bench: " + std::string(std::strerror(errno)));
    }
}

void write_report(const std::string& dir, const Report& r) {
    const std::string path = dir + "/" + r.node + ".txt";
    const std::string text = r.text();
    FILE* f = std::fopen(path.c_str(), "w");
    if (f == nullptr) fail("cannot write " + path + ": " + std::strerror(errno));
    const bool written = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    if (std::fclose(f) != 0 || !written) fail("cannot write " + path + ": " + std::strerror(errno));
}

// `--crunch-time LIMIT`: the median time of 21 crunches to LIMIT in this build, in ns (the
// nodes' work here, which esgm-bench prints beside its own build's), and their result
// (which esgm-bench checks against its own cruncher's).
int crunch_time(const char* limit) {
    const uint64_t maximum = parse_u64(limit, "the crunch limit");
    std::vector<uint64_t> times;
    int64_t result = 0;
    for (int i = 0; i < 21; ++i) {
        const uint64_t start = now_ns();
        result = number_cruncher(maximum);
        times.push_back(now_ns() - start);
    }
    std::sort(times.begin(), times.end());
    std::printf("%llu %lld\n", static_cast<unsigned long long>(times[times.size() / 2]),
                static_cast<long long>(result));
    return std::fflush(stdout) == 0 ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc == 3 && std::string(argv[1]) == "--crunch-time") return crunch_time(argv[2]);
    if (argc < 2) {
        std::fprintf(stderr, "usage: refsys_node NODE CRUNCH DIR KIND ARGS...\n");
        return 1;
    }
    // The node's ROS name is its topology name (unique under esgm-bench's private master).
    const std::string name = argv[1];
    try {
        ros::init(argc, argv, name, ros::init_options::NoSigintHandler);
    } catch (const ros::InvalidNameException& e) {
        std::fprintf(stderr, "refsys_node: `%s` is not a ROS node name: %s\n", name.c_str(),
                     e.what());
        return 1;
    }
    // ros::init took its remappings (none from esgm-bench) out of argv.
    if (argc < 5) {
        std::fprintf(stderr, "usage: refsys_node NODE CRUNCH DIR KIND ARGS...\n");
        return 1;
    }
    const uint64_t crunch = parse_u64(argv[2], "the crunch limit");
    const std::string dir = argv[3];
    const std::vector<std::string> args(argv + 4, argv + argc);

    // Every call to the master gives up after kMasterRetry instead of retrying for ever.
    ros::master::setRetryTimeout(ros::WallDuration(kMasterRetry));
    wait_for_master();
    Node node;  // its NodeHandle starts the node, which registers with the master
    node.name = name;
    build(node, crunch, args);

    ros::AsyncSpinner spinner(1);
    spinner.start();
    wait_for_connections(node);
    say("ready");

    std::string line;
    if (!read_line(line)) return 0;  // esgm-bench went away before the run
    std::istringstream go(line);
    std::string word;
    unsigned long long start = 0, until = 0;
    if (!(go >> word >> start >> until) || word != "go" || start == 0 || until <= start) {
        fail("expected `go START UNTIL`, got `" + line + "`");
    }
    // A window past a day from now is no run esgm-bench makes: refuse it, not sleep on it.
    if (until > now_ns() + kDayNs) fail("a run until " + std::to_string(until) + " is too far");
    node.window.until = until;
    node.window.start = start;

    if (node.tick) {
        // A timer fires first one period after it is made: make it a period before START,
        // so it ticks at START, START + period, ... (a drift-free schedule in roscpp).
        if (start > node.period_ns) sleep_until(start - node.period_ns);
        Window* window = &node.window;
        std::function<void()> tick = node.tick;
        ros::WallDuration period;
        period.fromNSec(static_cast<int64_t>(node.period_ns));
        node.timer = node.nh.createWallTimer(
            period,
            [window, tick](const ros::WallTimerEvent&) {
                if (window->open(now_ns())) tick();
            },
            false, true);
        if (!node.timer) fail("cannot make the timer");
    }

    sleep_until(until + kDrainNs);
    if (node.timer) node.timer.stop();
    spinner.stop();  // joins the callback thread: the logic is ours to read from here
    write_report(dir, node.report());
    for (const auto& inlet : node.inlets) {
        if (inlet->invalid > 0) {
            say("note " + std::to_string(inlet->invalid) + " messages on " + inlet->topic +
                " were not a Message4kb (ignored)");
        }
    }
    say("done");

    // `exit`, or the end of the input: either way, leave.
    read_line(line);
    node.timer = ros::WallTimer();
    node.inlets.clear();
    node.publishers.clear();
    ros::shutdown();
    return 0;
}
