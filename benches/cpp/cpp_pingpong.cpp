// esgm-bench's C++ ping-pong through esgm's C ABI (esgm.h): the rows cpp-small and
// cpp-image, beside connect-small and connect-image, which make the same hops through
// the Rust API (benches/src/scenarios/ipc_connect_echo.rs). This program mirrors that
// file step for step, so that the two rows differ only in the language and the ABI.
//
//   cpp_pingpong ping DOMAIN small|image spin|block PACED SAMPLES WARMUP GAP_NS TIMEOUT_S
//   cpp_pingpong pong DOMAIN small|image spin|block PACED TIMEOUT_S
//
// Both processes connect to the coordinator of DOMAIN (esgm-bench runs it on a thread
// of its own). ping creates the primitive trajectory `ping` (and, PACED = 1, `done`),
// then subscribes to `pong` (and `ready`) once pong has created them; pong subscribes
// to `ping` (and `done`) before it creates its own. Every trajectory keeps a cache of 4
// samples, every subscription a queue of 1024 (SubscribeOptions::default()). Each leg
// is `esgm_add` in one process until `esgm_subscription_recv` in the other returned the
// sample and the reader read it: the `x` of a RobotState, or a pixel at each end of a
// 640x480 RGB Image (checked against the frame's pattern) and whether those pixels are
// read in place in shared memory (`esgm_sample_octets_are_shared`, as the Rust reader
// asks `Octets::is_held`). The sequence number travels as the structure's valid time.
//
// Waits: `spin` polls `esgm_subscription_recv` with a timeout of 0 in a loop; `block`
// waits in it with a timeout of 20 ms, in a loop. Before each `block` hop ping spins
// for GAP_NS (esgm-bench's EVENT_GAP), so every receiver is asleep when it comes.
//
// Each structure is made before the timer starts: a RobotState, or an Image whose
// pixels are written once into a loan of the trajectory's shared memory
// (`esgm_trajectory_image_loan`), as a camera renders a frame. PACED (every image row):
// pong says on `ready` that its reply is made and it waits, ping says on `done` that it
// has read the reply and stopped its timer, before pong makes its next frame.
//
// Start-up: ping adds pings with sequence 0, ever less often (5 ms doubling to 200 ms),
// until one is answered, then waits 50 ms and forgets the answers. Stop: sequence -1,
// then `esgm_flush`, so the stop reaches pong before ping leaves.
//
// Output: ping prints `r NS` (half the round trip) and `w NS` (the time it took to make
// the structure) per measured hop, then `held N`; pong prints `note TEXT` lines for
// the report. Every wait gives up after TIMEOUT_S (exit 2, the reason on stderr).
#include "esgm.h"

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <string>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

constexpr int64_t kHello = 0;
constexpr int64_t kStop = -1;
// CACHE in ipc_connect_echo.rs.
constexpr size_t kCache = 4;
// SubscribeOptions::default()'s capacity.
constexpr size_t kQueue = 1024;
constexpr int64_t kWidth = 640;
constexpr int64_t kHeight = 480;
constexpr size_t kPixelBytes = 640 * 480 * 3;
// The longest a blocking receive waits between two looks at the clock (Patience's SLICE).
constexpr int64_t kSlice = 20 * ESGM_MILLISECOND;
// Polls between two looks at the clock while spinning.
constexpr uint32_t kPollsPerClockRead = 4096;
constexpr auto kHelloEvery = std::chrono::milliseconds(5);
constexpr auto kHelloEveryMax = std::chrono::milliseconds(200);
constexpr auto kHelloSettle = std::chrono::milliseconds(50);

const char* g_role = "cpp_pingpong";
esgm_t g_esgm{0};
std::chrono::seconds g_timeout{10};

// Leaves the domain (its services go now rather than when someone cleans up after a
// dead process) and exits 2 with `what` on stderr.
[[noreturn]] void fail(const std::string& what) {
    std::fprintf(stderr, "%s: %s\n", g_role, what.c_str());
    esgm_free(g_esgm);
    std::exit(2);
}

void check(esgm_status status, const std::string& what) {
    if (status == ESGM_OK) return;
    // Copied first: esgm_free may fail and overwrite it.
    std::string message = esgm_last_error_message();
    fail(what + ": " + esgm_status_name(status) + ": " + message);
}

uint8_t pattern(size_t index, uint8_t seed) {
    return static_cast<uint8_t>(static_cast<uint8_t>(index) + seed);
}

// Writes the frame's pattern into `out`, every byte once. The pattern repeats every
// 256 bytes, so one period is made and copied along: the byte-by-byte loop is not
// vectorised by g++ at -O2 and took 5-6 times the Rust writer's time (which LLVM
// vectorises), which would pace the image's hops differently (longer idle, deeper sleep).
void write_pattern(uint8_t* out, size_t len, uint8_t seed) {
    uint8_t period[256];
    for (size_t k = 0; k < sizeof period; ++k) period[k] = pattern(k, seed);
    size_t k = 0;
    for (; k + sizeof period <= len; k += sizeof period) std::memcpy(out + k, period, sizeof period);
    std::memcpy(out + k, period, len - k);
}

// Keeps a value read from being optimised away (Rust's black_box).
volatile uint64_t g_sink;

struct Patience {
    const char* what;
    Clock::time_point since = Clock::now();
    void check_time() const {
        if (Clock::now() - since > g_timeout) {
            fail(std::string("no ") + what + " within " + std::to_string(g_timeout.count()) +
                 " s: the other process hangs or lost the connection");
        }
    }
};

// A sample within `timeout_ns` (0: only one already there), or false.
bool received(esgm_subscription_t sub, int64_t timeout_ns, esgm_sample_t* out, const char* what) {
    const esgm_status s = esgm_subscription_recv(sub, timeout_ns, out);
    if (s == ESGM_OK) return true;
    if (s == ESGM_TIMEOUT) return false;
    check(s, std::string("receiving ") + what);
    return false;
}

int64_t valid_time(esgm_sample_t sample) {
    esgm_sample_info_t info;
    check(esgm_sample_info(sample, &info), "reading a sample's times");
    return info.valid_time;
}

// The next sample for which `accept` is true (others are freed), waiting as the row
// says: polling, or blocking a slice at a time.
template <typename Accept>
esgm_sample_t next_where(esgm_subscription_t sub, bool spin, const char* what, Accept accept) {
    Patience patience{what};
    esgm_sample_t sample{0};
    uint32_t polls = 0;
    for (;;) {
        if (received(sub, spin ? 0 : kSlice, &sample, what)) {
            if (accept(sample)) return sample;
            check(esgm_sample_free(sample), "freeing a sample");
            continue;
        }
        if (!spin || ++polls % kPollsPerClockRead == 0) patience.check_time();
    }
}

esgm_sample_t next(esgm_subscription_t sub, bool spin, const char* what) {
    return next_where(sub, spin, what, [](esgm_sample_t) { return true; });
}

// What a consumer reads (ipc_payload.rs's read_value): the `x` of a RobotState, or one
// pixel at each end of an Image, checked against the frame's pattern; `held` says
// whether the pixels are read in place in shared memory.
uint64_t read_value(esgm_sample_t sample, bool image, bool* held) {
    *held = false;
    if (!image) {
        double x = 0;
        check(esgm_sample_get_double(sample, "x", &x), "reading x");
        uint64_t bits;
        std::memcpy(&bits, &x, sizeof bits);
        return bits;
    }
    const uint8_t* pixels = nullptr;
    size_t len = 0;
    check(esgm_sample_get_octets(sample, "image_data", &pixels, &len), "reading image_data");
    if (len != kPixelBytes || pixels[len - 1] != pattern(len - 1, pixels[0])) {
        fail("the image's pixels are not the frame sent (" + std::to_string(len) + " bytes)");
    }
    check(esgm_sample_octets_are_shared(sample, "image_data", held), "asking where pixels are");
    return static_cast<uint64_t>(pixels[0]) + pixels[len - 1];
}

// The i-th structure for `trajectory`, as its producer makes it (ipc_connect_echo.rs's
// make_for): a RobotState, or an Image whose pixels are written once into a loan of the
// trajectory's shared memory. Its times are set by `stamped`.
esgm_structure_t make_for(esgm_trajectory_t trajectory, bool image, uint64_t i) {
    esgm_structure_t s{0};
    if (!image) {
        const double f = static_cast<double>(i);
        check(esgm_structure_new("robot", 0, 0, &s), "making a RobotState");
        check(esgm_structure_set_double(s, "x", f), "setting x");
        check(esgm_structure_set_double(s, "y", 0.5 * f), "setting y");
        check(esgm_structure_set_double(s, "dir", 90.0), "setting dir");
        return s;
    }
    esgm_image_loan_t loan{0};
    check(esgm_trajectory_image_loan(trajectory, kWidth, kHeight, ESGM_IMAGE_RGB8, &loan),
          "asking for an image loan");
    uint8_t* pixels = nullptr;
    size_t len = 0;
    check(esgm_image_loan_pixels(loan, &pixels, &len), "reading the loan's pixels");
    write_pattern(pixels, len, static_cast<uint8_t>(i));
    check(esgm_structure_new("camera", 0, 0, &s), "making an Image");
    check(esgm_structure_set_long(s, "width", kWidth), "setting width");
    check(esgm_structure_set_long(s, "height", kHeight), "setting height");
    check(esgm_structure_set_long(s, "format", ESGM_IMAGE_RGB8), "setting format");
    check(esgm_structure_set_image(s, "image_data", loan), "setting image_data");
    return s;
}

esgm_structure_t stamped(esgm_structure_t s, int64_t seq) {
    check(esgm_structure_set_times(s, seq, seq), "setting the times");
    return s;
}

// Adds `s` (which it takes) to `trajectory`, which this process writes: it must be
// admitted.
void add(esgm_trajectory_t trajectory, esgm_structure_t s, const char* name) {
    int32_t outcome = -1;
    check(esgm_add(trajectory, s, &outcome), std::string("adding to ") + name);
    if (outcome != ESGM_OUTCOME_ADDED) {
        fail(std::string(name) + ": a structure was not admitted (outcome " +
             std::to_string(outcome) + ")");
    }
}

void connect(const char* domain, const char* host) {
    check(esgm_connect_as(domain, host, &g_esgm),
          std::string(host) + ": connecting to the coordinator of " + domain);
}

// Creates primitive trajectory `name` of RobotState or Image, written by this process.
esgm_trajectory_t create(const char* name, bool image) {
    esgm_spec_t spec{0};
    check(esgm_spec_primitive(name, image ? "Image" : "RobotState", &spec), "a spec");
    check(esgm_spec_cache_count(spec, kCache), "the spec's cache");
    esgm_trajectory_t t{0};
    check(esgm_create_trajectory(g_esgm, spec, &t), std::string("creating ") + name);
    check(esgm_spec_free(spec), "freeing a spec");
    return t;
}

// Subscribes to trajectory `name` once the other process has created it.
esgm_subscription_t subscribe_when_created(const char* name) {
    Patience patience{name};
    esgm_trajectory_t t{0};
    for (;;) {
        const esgm_status s = esgm_get_entity_trajectory_structure(g_esgm, name, &t);
        if (s == ESGM_OK) break;
        if (s != ESGM_NO_SUCH_ENTITY_STRUCTURE) check(s, std::string("looking for ") + name);
        patience.check_time();
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    esgm_subscription_t sub{0};
    check(esgm_subscribe(t, kQueue, 0, &sub), std::string("subscribing to ") + name);
    check(esgm_trajectory_free(t), "freeing a trajectory handle");
    return sub;
}

// Frees every sample waiting on `sub`; returns the latest valid time among them, or
// `latest` if none.
int64_t drain(esgm_subscription_t sub, int64_t latest, const char* what) {
    esgm_sample_t s{0};
    while (received(sub, 0, &s, what)) {
        latest = std::max(latest, valid_time(s));
        check(esgm_sample_free(s), "freeing a sample");
    }
    return latest;
}

void leave(std::initializer_list<esgm_subscription_t> subs,
           std::initializer_list<esgm_trajectory_t> trajectories) {
    for (auto s : subs) check(esgm_unsubscribe(s), "unsubscribing");
    for (auto t : trajectories) check(esgm_trajectory_free(t), "freeing a trajectory handle");
    check(esgm_free(g_esgm), "leaving the domain");
    g_esgm = esgm_t{0};
}

int64_t ns_since(Clock::time_point start) {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count();
}

int ping(const char* domain, bool image, bool spin, bool paced, long samples, long warmup,
         int64_t gap_ns) {
    connect(domain, "bench-measuring");
    const esgm_trajectory_t ping_t = create("ping", image);
    // Images only (see the header).
    const esgm_trajectory_t done_t = paced ? create("done", false) : esgm_trajectory_t{0};
    // pong subscribes to ours before it creates its own: once its trajectories exist,
    // its subscriptions do too.
    const esgm_subscription_t pong = subscribe_when_created("pong");
    const esgm_subscription_t ready =
        paced ? subscribe_when_created("ready") : esgm_subscription_t{0};

    {
        Patience patience{"answer to the first ping"};
        auto every = std::chrono::duration_cast<std::chrono::nanoseconds>(kHelloEvery);
        for (;;) {
            add(ping_t, stamped(make_for(ping_t, image, 0), kHello), "ping");
            esgm_sample_t answer{0};
            if (received(pong, every.count(), &answer, "pong")) {
                check(esgm_sample_free(answer), "freeing a sample");
                break;
            }
            patience.check_time();
            every = std::min<std::chrono::nanoseconds>(every * 2, kHelloEveryMax);
        }
    }
    // Let pong answer the start-up pings still queued, and forget the answers, so that
    // the first measured ping finds it idle.
    std::this_thread::sleep_for(kHelloSettle);
    drain(pong, 0, "pong");
    // The latest ping pong said it is ready after (images only).
    int64_t ready_after = paced ? drain(ready, kHello - 1, "ready") : kHello - 1;

    std::vector<int64_t> one_way, write;
    one_way.reserve(static_cast<size_t>(samples));
    write.reserve(static_cast<size_t>(samples));
    long held = 0;
    for (long i = 1; i <= warmup + samples; ++i) {
        const int64_t seq = i;
        while (paced && ready_after < seq - 1) {
            const esgm_sample_t signal = next(ready, spin, "pong ready");
            ready_after = std::max(ready_after, valid_time(signal));
            check(esgm_sample_free(signal), "freeing a sample");
        }
        const auto making = Clock::now();
        const esgm_structure_t structure =
            stamped(make_for(ping_t, image, static_cast<uint64_t>(i)), seq);
        const int64_t made = ns_since(making);

        if (!spin) {
            // esgm-bench's EVENT_GAP, busy, so this core stays awake.
            const auto gap = Clock::now();
            while (ns_since(gap) < gap_ns) {
            }
        }
        const auto start = Clock::now();
        add(ping_t, structure, "ping");
        const esgm_sample_t back = next_where(
            pong, spin, "pong", [seq](esgm_sample_t s) { return valid_time(s) == seq; });
        bool in_place = false;
        g_sink = read_value(back, image, &in_place);
        const int64_t round_trip = ns_since(start);
        if (paced) {
            add(done_t, stamped(make_for(done_t, false, static_cast<uint64_t>(i)), seq), "done");
        }
        check(esgm_sample_free(back), "freeing a sample");

        if (i > warmup) {
            one_way.push_back(round_trip / 2);
            write.push_back(made);
            held += in_place ? 1 : 0;
        }
    }
    add(ping_t, stamped(make_for(ping_t, image, 0), kStop), "ping");
    // The stop reaches pong's replica before this process leaves the domain.
    check(esgm_flush(g_esgm, static_cast<int64_t>(g_timeout.count()) * ESGM_SECOND),
          "flushing the stop");

    for (size_t k = 0; k < one_way.size(); ++k) {
        std::printf("r %" PRId64 "\nw %" PRId64 "\n", one_way[k], write[k]);
    }
    std::printf("held %ld\n", held);
    std::fflush(stdout);
    if (paced) {
        leave({pong, ready}, {ping_t, done_t});
    } else {
        leave({pong}, {ping_t});
    }
    return 0;
}

int pong(const char* domain, bool image, bool spin, bool paced) {
    connect(domain, "bench-peer");
    // Subscribed before ours are created: see `ping`.
    const esgm_subscription_t ping_sub = subscribe_when_created("ping");
    const esgm_subscription_t done = paced ? subscribe_when_created("done") : esgm_subscription_t{0};
    const esgm_trajectory_t pong_t = create("pong", image);
    const esgm_trajectory_t ready_t = paced ? create("ready", false) : esgm_trajectory_t{0};

    long pings = 0, early = 0, held = 0;
    int64_t last = kHello;
    esgm_structure_t reply = make_for(pong_t, image, 0);
    for (;;) {
        // A ping already here came while the reply was being made.
        esgm_sample_t sample{0};
        const bool waiting = received(ping_sub, 0, &sample, "ping");
        if (paced) {
            add(ready_t, stamped(make_for(ready_t, false, static_cast<uint64_t>(pings)), last),
                "ready");
        }
        if (!waiting) sample = next(ping_sub, spin, "ping");
        const int64_t seq = valid_time(sample);
        if (seq == kStop) {
            check(esgm_sample_free(sample), "freeing a sample");
            break;
        }
        bool in_place = false;
        g_sink = read_value(sample, image, &in_place);
        check(esgm_sample_free(sample), "freeing a sample");
        add(pong_t, stamped(reply, seq), "pong");
        last = seq;
        if (seq == kHello) {
            // The Rust peer answers every start-up ping with one frame's clone; a
            // structure handle is taken by the add, so this one makes another.
            reply = make_for(pong_t, image, 0);
            continue;
        }
        if (paced) {
            // Make the next frame only once the reply has been read.
            int64_t read_up_to = kHello;
            while (read_up_to < seq) {
                const esgm_sample_t signal = next(done, spin, "done");
                read_up_to = std::max(read_up_to, valid_time(signal));
                check(esgm_sample_free(signal), "freeing a sample");
            }
        }
        ++pings;
        early += waiting ? 1 : 0;
        held += in_place ? 1 : 0;
        reply = make_for(pong_t, image, static_cast<uint64_t>(pings));
    }
    check(esgm_structure_free(reply), "freeing the last reply");

    if (early > 0) {
        std::printf("note %ld of %ld pings (warm-up included) reached the peer before its reply "
                    "was made (those hops include part of the peer's preparation)\n",
                    early, pings);
    }
    if (image) {
        std::printf("note the peer read %ld of %ld pings' pixels (warm-up included) in place in "
                    "shared memory (held), %ld copied onto its heap\n",
                    held, pings, pings - held);
    }
    std::fflush(stdout);
    if (paced) {
        leave({ping_sub, done}, {pong_t, ready_t});
    } else {
        leave({ping_sub}, {pong_t});
    }
    return 0;
}

bool parse_long(const char* text, long* out) {
    char* end = nullptr;
    *out = std::strtol(text, &end, 10);
    return end != text && *end == '\0';
}

}  // namespace

int main(int argc, char** argv) {
    const char* usage =
        "usage: cpp_pingpong ping DOMAIN small|image spin|block PACED SAMPLES WARMUP GAP_NS "
        "TIMEOUT_S\n       cpp_pingpong pong DOMAIN small|image spin|block PACED TIMEOUT_S\n";
    if (argc < 7) {
        std::fputs(usage, stderr);
        return 1;
    }
    const std::string role = argv[1], kind = argv[3], wait = argv[4], paced = argv[5];
    const char* domain = argv[2];
    if ((role != "ping" && role != "pong") || (kind != "small" && kind != "image") ||
        (wait != "spin" && wait != "block") || (paced != "0" && paced != "1")) {
        std::fputs(usage, stderr);
        return 1;
    }
    g_role = role == "ping" ? "cpp ping" : "cpp pong";
    const bool image = kind == "image", spin = wait == "spin", is_paced = paced == "1";
    long samples = 0, warmup = 0, gap_ns = 0, timeout_s = 0;
    if (role == "ping") {
        if (argc != 10 || !parse_long(argv[6], &samples) || !parse_long(argv[7], &warmup) ||
            !parse_long(argv[8], &gap_ns) || !parse_long(argv[9], &timeout_s) || samples < 1 ||
            warmup < 0 || gap_ns < 0 || timeout_s < 1) {
            std::fputs(usage, stderr);
            return 1;
        }
        g_timeout = std::chrono::seconds(timeout_s);
        return ping(domain, image, spin, is_paced, samples, warmup, gap_ns);
    }
    if (argc != 7 || !parse_long(argv[6], &timeout_s) || timeout_s < 1) {
        std::fputs(usage, stderr);
        return 1;
    }
    g_timeout = std::chrono::seconds(timeout_s);
    return pong(domain, image, spin, is_paced);
}
