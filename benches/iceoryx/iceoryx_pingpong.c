/* esgm-bench's classic-iceoryx peer: a publish-subscribe ping-pong between two C
 * processes on iceoryx 2.0's C binding (Debian's libiceoryx-binding-c-dev), the rows
 * iceoryx-c-small and iceoryx-c-image, beside cpp-small and cpp-image (esgm from C++).
 *
 *   iceoryx_pingpong ping INSTANCE spin|block BYTES PACED SAMPLES WARMUP GAP_NS TIMEOUT_S
 *   iceoryx_pingpong pong INSTANCE spin|block BYTES PACED TIMEOUT_S
 *
 * Both talk through a RouDi (iox-roudi) that esgm-bench starts for the pair. Each
 * message is one chunk: BYTES of payload (the small structure's encoded size, or the
 * image's 921,600 bytes of pixels) after an 8-byte user header holding the sequence
 * number. The writer loans the chunk from its publisher and writes the payload in
 * place (the pattern esgm's rows write, byte k = k + seed), before the timer; the
 * reader takes the chunk and reads the byte at each end in place, checking one against
 * the other, then releases it. pong answers each ping with a chunk it loaned and wrote
 * before the ping came.
 *
 * ping prints `r NS` per measured hop: half the round trip, on its monotonic clock,
 * from just before publish until the answer is taken and read. Waits: `spin` polls iox_sub_take_chunk in a loop;
 * `block` waits in a WaitSet on the subscriber's HAS_DATA state (20 ms slices), after a
 * busy gap of GAP_NS (esgm-bench's EVENT_GAP) before each hop. PACED = 1 (the image
 * rows, as esgm's): pong says on `ready` that its reply is written and it waits, ping
 * says on `done` that it has read the reply, before pong writes its next one.
 *
 * Start-up: ping publishes sequence 0, ever less often, until one is answered (a chunk
 * published before RouDi connected the pair is lost), waits 50 ms and forgets the
 * answers. Stop: sequence -1, which pong echoes before it exits. Every wait gives up
 * after TIMEOUT_S (exit 2, the reason on stderr). */
#define _POSIX_C_SOURCE 200809L

#include "iceoryx_binding_c/chunk.h"
#include "iceoryx_binding_c/log.h"
#include "iceoryx_binding_c/publisher.h"
#include "iceoryx_binding_c/runtime.h"
#include "iceoryx_binding_c/subscriber.h"
#include "iceoryx_binding_c/types.h"
#include "iceoryx_binding_c/wait_set.h"

#include <inttypes.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define HELLO INT64_C(0)
#define STOP INT64_C(-1)
#define SERVICE "esgm-bench"
/* What a subscriber queues (the startup pings may pile up a few). */
#define QUEUE 16
#define SLICE_NS INT64_C(20000000)
#define POLLS_PER_CLOCK_READ 4096u

static const char* g_role = "iceoryx";
static int64_t g_timeout_ns = INT64_C(10000000000);
static volatile uint64_t g_sink;

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * INT64_C(1000000000) + ts.tv_nsec;
}

static void fail(const char* what) {
    fprintf(stderr, "%s: %s\n", g_role, what);
    exit(2);
}

static uint8_t pattern(size_t index, uint8_t seed) {
    return (uint8_t)((uint8_t)index + seed);
}

/* One end of a topic: a publisher, or a subscriber with the WaitSet it blocks in. */
typedef struct {
    iox_pub_storage_t storage;
    iox_pub_t port;
    uint32_t bytes;
} Writer;

typedef struct {
    iox_sub_storage_t storage;
    iox_sub_t port;
    iox_ws_storage_t ws_storage;
    iox_ws_t ws;
    const char* name;
} Reader;

static void writer_init(Writer* w, const char* instance, const char* event, uint32_t bytes) {
    iox_pub_options_t options;
    iox_pub_options_init(&options);
    options.historyCapacity = 0;
    w->port = iox_pub_init(&w->storage, SERVICE, instance, event, &options);
    w->bytes = bytes;
}

static void reader_init(Reader* r, const char* instance, const char* event) {
    iox_sub_options_t options;
    iox_sub_options_init(&options);
    options.queueCapacity = QUEUE;
    options.historyRequest = 0;
    options.queueFullPolicy = QueueFullPolicy_DISCARD_OLDEST_DATA;
    r->port = iox_sub_init(&r->storage, SERVICE, instance, event, &options);
    r->ws = iox_ws_init(&r->ws_storage);
    r->name = event;
    if (iox_ws_attach_subscriber_state(r->ws, r->port, SubscriberState_HAS_DATA, 0, NULL) !=
        WaitSetResult_SUCCESS) {
        fail("cannot attach a subscriber to its WaitSet");
    }
}

static void reader_deinit(Reader* r) {
    iox_ws_detach_subscriber_state(r->ws, r->port, SubscriberState_HAS_DATA);
    iox_ws_deinit(r->ws);
    iox_sub_deinit(r->port);
}

static int64_t seq_of(const void* payload) {
    const void* header =
        iox_chunk_header_to_user_header_const(iox_chunk_header_from_user_payload_const(payload));
    int64_t seq;
    memcpy(&seq, header, sizeof seq);
    return seq;
}

/* A chunk loaned from `w`, its payload written (seed `seed`), its header `seq`. */
static void* written(Writer* w, int64_t seq, uint8_t seed) {
    void* payload = NULL;
    enum iox_AllocationResult result = iox_pub_loan_aligned_chunk_with_user_header(
        w->port, &payload, w->bytes, 8, sizeof(int64_t), 8);
    if (result != AllocationResult_SUCCESS) {
        fprintf(stderr, "%s: loaning a chunk of %u bytes failed (%d)\n", g_role, w->bytes,
                (int)result);
        exit(2);
    }
    /* Every byte once: one period of the pattern (256 bytes) copied along, as
     * cpp_pingpong.cpp writes its frames (a byte loop is not vectorised at -O2). */
    uint8_t period[256];
    for (size_t k = 0; k < sizeof period; ++k) period[k] = pattern(k, seed);
    uint8_t* const bytes = payload;
    size_t k = 0;
    for (; k + sizeof period <= w->bytes; k += sizeof period) memcpy(bytes + k, period, sizeof period);
    memcpy(bytes + k, period, w->bytes - k);
    memcpy(iox_chunk_header_to_user_header(iox_chunk_header_from_user_payload(payload)), &seq,
           sizeof seq);
    return payload;
}

static void set_seq(void* payload, int64_t seq) {
    memcpy(iox_chunk_header_to_user_header(iox_chunk_header_from_user_payload(payload)), &seq,
           sizeof seq);
}

/* Reads the byte at each end, checks one against the other. */
static uint64_t read_value(const void* payload, uint32_t bytes) {
    const uint8_t* p = payload;
    if (p[bytes - 1] != pattern(bytes - 1, p[0])) fail("a payload is not what was sent");
    return (uint64_t)p[0] + p[bytes - 1];
}

/* A chunk within `timeout_ns` (0: only one already there), or NULL. */
static const void* take(Reader* r, bool spin, int64_t timeout_ns) {
    const void* payload = NULL;
    if (iox_sub_take_chunk(r->port, &payload) == ChunkReceiveResult_SUCCESS) return payload;
    if (spin || timeout_ns == 0) return NULL;
    struct timespec slice = {.tv_sec = (time_t)(timeout_ns / INT64_C(1000000000)),
                             .tv_nsec = (long)(timeout_ns % INT64_C(1000000000))};
    iox_notification_info_t infos[1];
    uint64_t missed = 0;
    iox_ws_timed_wait(r->ws, slice, infos, 1, &missed);
    if (iox_sub_take_chunk(r->port, &payload) == ChunkReceiveResult_SUCCESS) return payload;
    return NULL;
}

/* The next chunk, polling or blocking a slice at a time, until the timeout. */
static const void* next(Reader* r, bool spin) {
    const int64_t since = now_ns();
    uint32_t polls = 0;
    for (;;) {
        const void* payload = take(r, spin, SLICE_NS);
        if (payload) return payload;
        if ((!spin || ++polls % POLLS_PER_CLOCK_READ == 0) && now_ns() - since > g_timeout_ns) {
            fprintf(stderr, "%s: no %s within %" PRId64 " s\n", g_role, r->name,
                    g_timeout_ns / INT64_C(1000000000));
            exit(2);
        }
    }
}

/* Releases every chunk waiting on `r`; returns the latest sequence among them, or
 * `latest`. */
static int64_t drain(Reader* r, int64_t latest) {
    const void* payload;
    while ((payload = take(r, true, 0)) != NULL) {
        const int64_t seq = seq_of(payload);
        if (seq > latest) latest = seq;
        iox_sub_release_chunk(r->port, payload);
    }
    return latest;
}

static void spin_for(int64_t ns) {
    const int64_t start = now_ns();
    while (now_ns() - start < ns) {
    }
}

static int ping(const char* instance, bool spin, uint32_t bytes, bool paced, long samples,
                long warmup, int64_t gap_ns) {
    iox_runtime_init("esgm_bench_ping");
    Writer ping_w, done_w;
    Reader pong_r, ready_r;
    writer_init(&ping_w, instance, "ping", bytes);
    reader_init(&pong_r, instance, "pong");
    if (paced) {
        writer_init(&done_w, instance, "done", 8);
        reader_init(&ready_r, instance, "ready");
    }

    const int64_t started = now_ns();
    int64_t every = INT64_C(5000000);
    for (;;) {
        iox_pub_publish_chunk(ping_w.port, written(&ping_w, HELLO, 0));
        const int64_t sent = now_ns();
        const void* answer = NULL;
        while (!answer && now_ns() - sent < every) answer = take(&pong_r, false, SLICE_NS / 4);
        if (answer) {
            iox_sub_release_chunk(pong_r.port, answer);
            break;
        }
        if (now_ns() - started > g_timeout_ns) fail("the pong process never answered");
        every = every * 2 > INT64_C(200000000) ? INT64_C(200000000) : every * 2;
    }
    const struct timespec settle = {.tv_sec = 0, .tv_nsec = 50000000};
    nanosleep(&settle, NULL);
    drain(&pong_r, HELLO);
    int64_t ready_after = paced ? drain(&ready_r, HELLO - 1) : HELLO - 1;

    int64_t* one_way = calloc((size_t)samples, sizeof(int64_t));
    if (!one_way) fail("out of memory");
    for (long i = 1; i <= warmup + samples; ++i) {
        const int64_t seq = i;
        while (paced && ready_after < seq - 1) {
            const void* signal = next(&ready_r, spin);
            const int64_t s = seq_of(signal);
            if (s > ready_after) ready_after = s;
            iox_sub_release_chunk(ready_r.port, signal);
        }
        void* chunk = written(&ping_w, seq, (uint8_t)i);
        if (!spin) spin_for(gap_ns);

        const int64_t start = now_ns();
        iox_pub_publish_chunk(ping_w.port, chunk);
        const void* back;
        for (;;) {
            back = next(&pong_r, spin);
            if (seq_of(back) == seq) break;
            iox_sub_release_chunk(pong_r.port, back);
        }
        g_sink = read_value(back, bytes);
        const int64_t round_trip = now_ns() - start;
        if (paced) iox_pub_publish_chunk(done_w.port, written(&done_w, seq, 0));
        iox_sub_release_chunk(pong_r.port, back);
        if (i > warmup) one_way[i - warmup - 1] = round_trip / 2;
    }
    /* Stop, until pong echoes it. */
    iox_pub_publish_chunk(ping_w.port, written(&ping_w, STOP, 0));
    for (;;) {
        const void* back = next(&pong_r, spin);
        const int64_t s = seq_of(back);
        iox_sub_release_chunk(pong_r.port, back);
        if (s == STOP) break;
    }
    for (long k = 0; k < samples; ++k) printf("r %" PRId64 "\n", one_way[k]);
    fflush(stdout);
    free(one_way);

    if (paced) {
        reader_deinit(&ready_r);
        iox_pub_deinit(done_w.port);
    }
    reader_deinit(&pong_r);
    iox_pub_deinit(ping_w.port);
    iox_runtime_shutdown();
    return 0;
}

static int pong(const char* instance, bool spin, uint32_t bytes, bool paced) {
    iox_runtime_init("esgm_bench_pong");
    Writer pong_w, ready_w;
    Reader ping_r, done_r;
    reader_init(&ping_r, instance, "ping");
    writer_init(&pong_w, instance, "pong", bytes);
    if (paced) {
        reader_init(&done_r, instance, "done");
        writer_init(&ready_w, instance, "ready", 8);
    }

    long pings = 0;
    int64_t last = HELLO;
    void* reply = written(&pong_w, HELLO, 0);
    for (;;) {
        /* A ping already here came while the reply was being written. */
        const void* chunk = take(&ping_r, true, 0);
        if (paced) iox_pub_publish_chunk(ready_w.port, written(&ready_w, last, 0));
        if (!chunk) chunk = next(&ping_r, spin);
        const int64_t seq = seq_of(chunk);
        if (seq != STOP) g_sink = read_value(chunk, bytes);
        iox_sub_release_chunk(ping_r.port, chunk);
        set_seq(reply, seq);
        iox_pub_publish_chunk(pong_w.port, reply);
        if (seq == STOP) break;
        last = seq;
        if (seq == HELLO) {
            reply = written(&pong_w, HELLO, 0);
            continue;
        }
        if (paced) {
            /* Write the next reply only once this one has been read. */
            int64_t read_up_to = HELLO;
            while (read_up_to < seq) {
                const void* signal = next(&done_r, spin);
                const int64_t s = seq_of(signal);
                if (s > read_up_to) read_up_to = s;
                iox_sub_release_chunk(done_r.port, signal);
            }
        }
        ++pings;
        reply = written(&pong_w, HELLO, (uint8_t)pings);
    }
    if (paced) {
        iox_pub_deinit(ready_w.port);
        reader_deinit(&done_r);
    }
    iox_pub_deinit(pong_w.port);
    reader_deinit(&ping_r);
    iox_runtime_shutdown();
    return 0;
}

static bool parse_long(const char* text, long* out) {
    char* end = NULL;
    *out = strtol(text, &end, 10);
    return end != text && *end == '\0';
}

int main(int argc, char** argv) {
    static const char usage[] =
        "usage: iceoryx_pingpong ping INSTANCE spin|block BYTES PACED SAMPLES WARMUP GAP_NS "
        "TIMEOUT_S\n       iceoryx_pingpong pong INSTANCE spin|block BYTES PACED TIMEOUT_S\n";
    if (argc < 7) {
        fputs(usage, stderr);
        return 1;
    }
    const char* role = argv[1];
    const char* instance = argv[2];
    const bool spin = strcmp(argv[3], "spin") == 0;
    long bytes = 0, paced = 0, samples = 0, warmup = 0, gap_ns = 0, timeout_s = 0;
    if ((!spin && strcmp(argv[3], "block") != 0) || !parse_long(argv[4], &bytes) || bytes < 1 ||
        bytes > (1L << 24) || !parse_long(argv[5], &paced) || (paced != 0 && paced != 1)) {
        fputs(usage, stderr);
        return 1;
    }
    iox_set_loglevel(Iceoryx_LogLevel_Error);
    if (strcmp(role, "ping") == 0 && argc == 10 && parse_long(argv[6], &samples) &&
        parse_long(argv[7], &warmup) && parse_long(argv[8], &gap_ns) &&
        parse_long(argv[9], &timeout_s) && samples > 0 && warmup >= 0 && gap_ns >= 0 &&
        timeout_s > 0) {
        g_role = "iceoryx ping";
        g_timeout_ns = (int64_t)timeout_s * INT64_C(1000000000);
        return ping(instance, spin, (uint32_t)bytes, paced == 1, samples, warmup, gap_ns);
    }
    if (strcmp(role, "pong") == 0 && argc == 7 && parse_long(argv[6], &timeout_s) &&
        timeout_s > 0) {
        g_role = "iceoryx pong";
        g_timeout_ns = (int64_t)timeout_s * INT64_C(1000000000);
        return pong(instance, spin, (uint32_t)bytes, paced == 1);
    }
    fputs(usage, stderr);
    return 1;
}
