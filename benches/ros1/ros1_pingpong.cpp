// esgm-bench's ROS 1 peer: a roscpp publisher/subscriber ping-pong between two
// processes, the baseline rows ros1-small and ros1-image.
//
//   ros1_pingpong pong <topic-prefix> <spin|block>
//   ros1_pingpong ping <topic-prefix> <spin|block> <bytes> <samples> <warmup>
//   ros1_pingpong reader <topic-prefix> block
//   ros1_pingpong writer <topic-prefix> block <bytes> <samples> <readers>
//
// Both processes talk through a rosmaster (ROS_MASTER_URI) over TCPROS on loopback,
// with TCP_NODELAY. A message is a std_msgs/UInt8MultiArray carrying <bytes> bytes
// (the size of the structure esgm sends; the sequence number in its first 8 bytes).
// The pong process answers each ping with the message it received. The ping process
// prints one line `r <ns>` per measured hop: half the round trip, timed on its
// monotonic clock, from just before publish() (the message is filled before) until
// the answer's callback has run and read the last byte. `spin` polls the callback
// queue without sleeping; `block` waits on it. Every wait has a deadline (exit 2).
//
// The fan-out rows (ros1-fanout-K, beside esgm's fanout-K): one `writer` publishes a
// message every 2 ms on <prefix>/tf once <readers> `reader` processes are connected,
// stamped with the system clock (CLOCK_REALTIME, as esgm-bench's SystemClock) in bytes
// 8..16. Each reader prints `h <seq> <ns>` per message: the time from that stamp until
// its callback ran. esgm-bench takes, per message, the last reader's figure.
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_msgs/UInt8MultiArray.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>

namespace {

constexpr uint64_t kStop = UINT64_MAX;
constexpr uint64_t kHello = 0;
constexpr double kDeadlineSeconds = 20.0;

uint64_t seq_of(const std::vector<uint8_t>& data) {
    uint64_t seq = 0;
    if (data.size() >= sizeof seq) std::memcpy(&seq, data.data(), sizeof seq);
    return seq;
}

struct Inbox {
    uint64_t last_seq = kHello;
    bool got = false;
    uint8_t last_byte = 0;
    std_msgs::UInt8MultiArray::ConstPtr msg;
    void on(const std_msgs::UInt8MultiArray::ConstPtr& m) {
        last_seq = seq_of(m->data);
        last_byte = m->data.empty() ? 0 : m->data.back();
        msg = m;
        got = true;
    }
};

// Runs callbacks until the inbox got a message (returns true) or the deadline passed.
bool wait_for(Inbox& inbox, bool spin, double seconds) {
    auto* queue = ros::getGlobalCallbackQueue();
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
    uint32_t polls = 0;
    while (!inbox.got) {
        if (!ros::ok()) return false;
        if (spin) {
            queue->callAvailable(ros::WallDuration(0));
            if (++polls % 4096 == 0 && ros::WallTime::now() > deadline) return false;
        } else {
            queue->callAvailable(ros::WallDuration(0.02));
            if (ros::WallTime::now() > deadline) return false;
        }
    }
    return true;
}

int pong(const std::string& prefix, bool spin) {
    ros::NodeHandle nh;
    Inbox inbox;
    ros::Publisher pub = nh.advertise<std_msgs::UInt8MultiArray>(prefix + "/pong", 4);
    ros::Subscriber sub = nh.subscribe(prefix + "/ping", 4, &Inbox::on, &inbox,
                                       ros::TransportHints().tcpNoDelay());
    for (;;) {
        inbox.got = false;
        if (!wait_for(inbox, spin, 60.0)) {
            std::fprintf(stderr, "pong: no ping within 60 s\n");
            return 2;
        }
        if (inbox.last_seq == kStop) return 0;
        pub.publish(*inbox.msg);
    }
}

int ping(const std::string& prefix, bool spin, size_t bytes, long samples, long warmup) {
    ros::NodeHandle nh;
    Inbox inbox;
    ros::Publisher pub = nh.advertise<std_msgs::UInt8MultiArray>(prefix + "/ping", 4);
    ros::Subscriber sub = nh.subscribe(prefix + "/pong", 4, &Inbox::on, &inbox,
                                       ros::TransportHints().tcpNoDelay());
    std_msgs::UInt8MultiArray msg;
    msg.data.assign(bytes < 8 ? 8 : bytes, 0);
    auto set_seq = [&](uint64_t seq) {
        std::memcpy(msg.data.data(), &seq, sizeof seq);
        msg.data.back() = static_cast<uint8_t>(seq);
    };
    // Connect: ping with the hello until the pong process answers.
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(kDeadlineSeconds);
    for (;;) {
        set_seq(kHello);
        inbox.got = false;
        pub.publish(msg);
        if (wait_for(inbox, false, 0.05)) break;
        if (ros::WallTime::now() > deadline) {
            std::fprintf(stderr, "ping: the pong process never answered\n");
            return 2;
        }
    }
    ros::WallDuration(0.1).sleep();
    ros::getGlobalCallbackQueue()->callAvailable(ros::WallDuration(0));
    for (long i = 1; i <= warmup + samples; ++i) {
        const uint64_t seq = static_cast<uint64_t>(i);
        set_seq(seq);
        if (!spin) ros::WallDuration(50e-6).sleep();  // as esgm-bench's event gap
        const auto start = std::chrono::steady_clock::now();
        pub.publish(msg);
        do {
            inbox.got = false;
            if (!wait_for(inbox, spin, kDeadlineSeconds)) {
                std::fprintf(stderr, "ping: no answer to %lu\n", static_cast<unsigned long>(seq));
                return 2;
            }
        } while (inbox.last_seq != seq);
        const auto rtt = std::chrono::steady_clock::now() - start;
        if (inbox.last_byte != static_cast<uint8_t>(seq)) {
            std::fprintf(stderr, "ping: answer %lu has the wrong last byte\n",
                         static_cast<unsigned long>(seq));
            return 2;
        }
        if (i > warmup) {
            const long long ns = std::chrono::duration_cast<std::chrono::nanoseconds>(rtt).count();
            std::printf("r %lld\n", ns / 2);
        }
    }
    set_seq(kStop);
    pub.publish(msg);
    ros::WallDuration(0.2).sleep();
    return 0;
}

int64_t realtime_ns() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

struct FanoutReader {
    void on(const std_msgs::UInt8MultiArray::ConstPtr& m) {
        const int64_t now = realtime_ns();
        const uint64_t seq = seq_of(m->data);
        if (seq == kStop) {
            stopped = true;
            return;
        }
        int64_t sent = 0;
        if (m->data.size() >= 16) std::memcpy(&sent, m->data.data() + 8, sizeof sent);
        std::printf("h %llu %lld\n", static_cast<unsigned long long>(seq),
                    static_cast<long long>(now - sent));
    }
    bool stopped = false;
};

int fanout_reader(const std::string& prefix) {
    ros::NodeHandle nh;
    FanoutReader reader;
    ros::Subscriber sub = nh.subscribe(prefix + "/tf", 16, &FanoutReader::on, &reader,
                                       ros::TransportHints().tcpNoDelay());
    auto* queue = ros::getGlobalCallbackQueue();
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(300.0);
    while (!reader.stopped) {
        if (!ros::ok() || ros::WallTime::now() > deadline) {
            std::fprintf(stderr, "reader: no end within 300 s\n");
            return 2;
        }
        queue->callAvailable(ros::WallDuration(0.05));
    }
    std::fflush(stdout);
    return 0;
}

int fanout_writer(const std::string& prefix, size_t bytes, long samples, uint32_t readers) {
    ros::NodeHandle nh;
    ros::Publisher pub = nh.advertise<std_msgs::UInt8MultiArray>(prefix + "/tf", 16);
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(120.0);
    while (pub.getNumSubscribers() < readers) {
        if (!ros::ok() || ros::WallTime::now() > deadline) {
            std::fprintf(stderr, "writer: %u of %u readers connected within 120 s\n",
                         pub.getNumSubscribers(), readers);
            return 2;
        }
        ros::WallDuration(0.01).sleep();
    }
    // Every reader connected: let their TCPROS links settle, as esgm's row does.
    ros::WallDuration(0.5).sleep();
    std_msgs::UInt8MultiArray msg;
    msg.data.assign(bytes < 16 ? 16 : bytes, 0);
    for (long i = 0; i < samples; ++i) {
        const uint64_t seq = static_cast<uint64_t>(i);
        std::memcpy(msg.data.data(), &seq, sizeof seq);
        const int64_t now = realtime_ns();
        std::memcpy(msg.data.data() + 8, &now, sizeof now);
        pub.publish(msg);
        ros::WallDuration(0.002).sleep();
    }
    ros::WallDuration(0.5).sleep();
    std::memcpy(msg.data.data(), &kStop, sizeof kStop);
    pub.publish(msg);
    ros::WallDuration(0.5).sleep();
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 4) {
        std::fprintf(stderr, "usage: ros1_pingpong ping|pong PREFIX spin|block [BYTES SAMPLES WARMUP]\n");
        return 1;
    }
    const std::string role = argv[1], prefix = argv[2];
    const bool spin = std::string(argv[3]) == "spin";
    ros::init(argc, argv, "esgm_bench_" + role, ros::init_options::AnonymousName |
                                                     ros::init_options::NoSigintHandler);
    if (role == "pong") return pong(prefix, spin);
    if (role == "reader") return fanout_reader(prefix);
    if (role == "writer" && argc >= 7) {
        return fanout_writer(prefix, std::stoul(argv[4]), std::stol(argv[5]),
                             static_cast<uint32_t>(std::stoul(argv[6])));
    }
    if (role == "ping" && argc >= 7) {
        return ping(prefix, spin, std::stoul(argv[4]), std::stol(argv[5]), std::stol(argv[6]));
    }
    std::fprintf(stderr, "bad arguments\n");
    return 1;
}
