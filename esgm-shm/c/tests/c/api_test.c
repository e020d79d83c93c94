/*
 * esgm's C ABI, tested as a C program uses it (SPEC L3): every operation of the
 * seed's esgm.idl and entity_trajectory_structure.idl, on both runtimes, and every
 * error path a C program can hit. Run by esgm-shm/c/tests/c_programs.rs (plain and
 * under AddressSanitizer and UndefinedBehaviorSanitizer):
 *
 *   api_test in-process              the semantics in one process
 *   api_test shm DOMAIN              the same semantics through a coordinator
 *   api_test killed-writer DOMAIN    a sample held after its writer was killed
 *   api_test writer DOMAIN NAME      (the killed writer: adds an image, then waits)
 *   api_test down DOMAIN             handles used after the domain went down
 *
 * Exit status 0 when every check held; each failed check prints its line.
 */
#define _POSIX_C_SOURCE 200809L
#include <esgm.h>

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>
#include <sys/wait.h>
#include <unistd.h>

static int failures = 0;
static const char *runtime = "";

#define CHECK(cond)                                                                  \
    do {                                                                             \
        if (!(cond)) {                                                               \
            fprintf(stderr, "%s:%d [%s] check failed: %s\n", __FILE__, __LINE__,     \
                    runtime, #cond);                                                 \
            failures++;                                                              \
        }                                                                            \
    } while (0)

/* A call that must succeed. */
#define OK(call)                                                                     \
    do {                                                                             \
        enum esgm_status s_ = (call);                                                \
        if (s_ != ESGM_OK) {                                                         \
            fprintf(stderr, "%s:%d [%s] %s returned %s: %s\n", __FILE__, __LINE__,   \
                    runtime, #call, esgm_status_name(s_), esgm_last_error_message()); \
            failures++;                                                              \
        }                                                                            \
    } while (0)

/* A call that must fail with `status`, its message containing `text`. */
#define FAILS(call, status, text)                                                    \
    do {                                                                             \
        enum esgm_status s_ = (call);                                                \
        if (s_ != (status)) {                                                        \
            fprintf(stderr, "%s:%d [%s] %s returned %s, expected %s (%s)\n",         \
                    __FILE__, __LINE__, runtime, #call, esgm_status_name(s_),        \
                    esgm_status_name(status), esgm_last_error_message());            \
            failures++;                                                              \
        } else if (strstr(esgm_last_error_message(), (text)) == NULL) {              \
            fprintf(stderr, "%s:%d [%s] %s: message \"%s\" lacks \"%s\"\n", __FILE__, \
                    __LINE__, runtime, #call, esgm_last_error_message(), (text));    \
            failures++;                                                              \
        }                                                                            \
    } while (0)

static int str_is(struct esgm_str_t s, const char *text) {
    return s.len == strlen(text) && memcmp(s.ptr, text, s.len) == 0;
}

/* A RobotState structure, ready to add. */
static esgm_structure_t robot_state(int64_t valid_time, double x) {
    esgm_structure_t s = {0};
    OK(esgm_structure_new("robot1", valid_time, valid_time, &s));
    OK(esgm_structure_set_double(s, "x", x));
    OK(esgm_structure_set_double(s, "y", 2.0 * x));
    OK(esgm_structure_set_double(s, "dir", 90.0));
    return s;
}

static double x_of(esgm_sample_t sample) {
    double x = -1;
    OK(esgm_sample_get_double(sample, "x", &x));
    return x;
}

/* E1: types made from attributes and sorts, read back, destroyed. */
static void types(esgm_t e) {
    esgm_type_t t = {0};
    OK(esgm_type_new("Detection", &t));
    OK(esgm_type_add_attribute(t, "label", ESGM_SORT_STRING, NULL));
    OK(esgm_type_add_attribute(t, "score", ESGM_SORT_DOUBLE, NULL));
    OK(esgm_type_add_attribute(t, "boxes", ESGM_SORT_ENTITY_FRAME_SEQ, "Blob"));
    OK(esgm_type_add_attribute(t, "best", ESGM_SORT_ENTITY_FRAME, "Blob"));
    OK(esgm_type_add_attribute(t, "where", ESGM_SORT_POSITION_ALTITUDE_ROTATION, NULL));
    FAILS(esgm_type_add_attribute(t, "score", ESGM_SORT_LONG, NULL), ESGM_INVALID_TYPE,
          "`score` already");
    FAILS(esgm_type_add_attribute(t, "frame", ESGM_SORT_ENTITY_FRAME, NULL),
          ESGM_INVALID_TYPE, "element");
    FAILS(esgm_type_add_attribute(t, "n", 999, NULL), ESGM_INVALID_ARGUMENT, "not a sort");
    FAILS(esgm_type_add_attribute(t, "n", ESGM_SORT_LONG, "Blob"), ESGM_INVALID_TYPE,
          "no element type");
    OK(esgm_create_type(e, t));
    FAILS(esgm_create_entity_structure_type(e, "Blob", t),
          ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS, "Blob");
    OK(esgm_type_free(t));

    esgm_type_t back = {0};
    OK(esgm_get_entity_structure_type(e, "Detection", &back));
    size_t n = 0;
    OK(esgm_type_attribute_count(back, &n));
    CHECK(n == 5);
    struct esgm_attribute_t a;
    OK(esgm_type_attribute(back, 2, &a));
    CHECK(str_is(a.name, "boxes"));
    CHECK(a.sort == ESGM_SORT_ENTITY_FRAME_SEQ);
    CHECK(str_is(a.element_type, "Blob"));
    FAILS(esgm_type_attribute(back, 5, &a), ESGM_OUT_OF_RANGE, "no index 5");
    struct esgm_str_t name;
    OK(esgm_type_name(back, &name));
    CHECK(str_is(name, "Detection"));
    OK(esgm_type_free(back));

    FAILS(esgm_get_entity_structure_type(e, "Detektion", &back),
          ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE, "Detektion");
    OK(esgm_destroy_entity_structure_type(e, "Detection"));
    FAILS(esgm_destroy_entity_structure_type(e, "Detection"),
          ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE, "Detection");

    char buf[4096];
    size_t len = 0;
    OK(esgm_entity_structure_type_names_json(e, buf, sizeof buf, &len));
    CHECK(strstr(buf, "\"RobotState\"") != NULL);
    CHECK(len == strlen(buf));
}

/* E2, T1, T4: a primitive trajectory, its adds and every query. */
static void primitive_and_queries(esgm_t e) {
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_odo", "RobotState", &t));
    FAILS(esgm_create_primitive_entity_trajectory_structure(e, "c_odo", "RobotState", &t),
          ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS, "c_odo");
    FAILS(esgm_create_primitive_entity_trajectory_structure(e, "c_x", "RobotStat", &t),
          ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE, "RobotStat");

    esgm_sample_t s = {0};
    FAILS(esgm_get_latest(t, &s), ESGM_VALUE_NOT_AVAILABLE, "c_odo");

    int32_t outcome = -1;
    for (int i = 1; i <= 5; i++) {
        OK(esgm_add_blocking(t, robot_state(i * ESGM_SECOND, (double)i), &outcome));
        CHECK(outcome == ESGM_OUTCOME_ADDED);
    }
    /* Out of order: latest is the last added, latest_vtime the most current. */
    OK(esgm_add(t, robot_state(ESGM_SECOND / 2, 0.5), &outcome));
    OK(esgm_get_latest(t, &s));
    CHECK(x_of(s) == 0.5);
    OK(esgm_sample_free(s));
    OK(esgm_get_latest_vtime(t, &s));
    CHECK(x_of(s) == 5.0);
    OK(esgm_sample_free(s));
    OK(esgm_get_nth_latest(t, 1, &s));
    CHECK(x_of(s) == 5.0);
    OK(esgm_sample_free(s));
    FAILS(esgm_get_nth_latest(t, 100, &s), ESGM_VALUE_NOT_AVAILABLE, "");

    OK(esgm_get_at(t, 3 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 3.0);
    struct esgm_sample_info_t info;
    OK(esgm_sample_info(s, &info));
    CHECK(str_is(info.name, "robot1"));
    CHECK(info.valid_time == 3 * ESGM_SECOND);
    CHECK(info.attribute_count == 3);
    OK(esgm_sample_free(s));
    FAILS(esgm_get_at(t, 3 * ESGM_SECOND + 1, &s), ESGM_VALUE_NOT_AVAILABLE, "");
    OK(esgm_get_closest_at_or_before(t, 3 * ESGM_SECOND + 1, &s));
    CHECK(x_of(s) == 3.0);
    OK(esgm_sample_free(s));

    esgm_sample_list_t list = {0};
    OK(esgm_get_between(t, 2 * ESGM_SECOND, 4 * ESGM_SECOND, &list));
    size_t n = 0;
    OK(esgm_sample_list_len(list, &n));
    CHECK(n == 3);
    for (size_t i = 0; i < n; i++) {
        OK(esgm_sample_list_get(list, i, &s));
        CHECK(x_of(s) == (double)(i + 2));
        OK(esgm_sample_free(s));
    }
    FAILS(esgm_sample_list_get(list, n, &s), ESGM_OUT_OF_RANGE, "no index 3");
    OK(esgm_sample_list_free(list));

    /* T2: approximations. */
    OK(esgm_get_at_approximating(t, 2500 * ESGM_MILLISECOND, ESGM_APPROXIMATION_LINEAR,
                                 (esgm_structure_t){0}, &s));
    CHECK(x_of(s) == 2.5);
    OK(esgm_sample_free(s));
    OK(esgm_get_at_approximating(t, 2400 * ESGM_MILLISECOND, ESGM_APPROXIMATION_CLOSEST,
                                 (esgm_structure_t){0}, &s));
    CHECK(x_of(s) == 2.0);
    OK(esgm_sample_free(s));
    OK(esgm_get_at_approximating(t, 2900 * ESGM_MILLISECOND,
                                 ESGM_APPROXIMATION_MOST_RECENT, (esgm_structure_t){0}, &s));
    CHECK(x_of(s) == 2.0);
    OK(esgm_sample_free(s));
    FAILS(esgm_get_at_approximating(t, 2900 * ESGM_MILLISECOND, ESGM_APPROXIMATION_NONE,
                                    (esgm_structure_t){0}, &s),
          ESGM_VALUE_NOT_AVAILABLE, "");
    esgm_structure_t fallback = robot_state(0, 42.0);
    OK(esgm_get_at_approximating(t, 100 * ESGM_SECOND, ESGM_APPROXIMATION_DEFAULT, fallback,
                                 &s));
    CHECK(x_of(s) == 42.0);
    OK(esgm_sample_free(s));
    OK(esgm_structure_free(fallback));
    FAILS(esgm_get_at_approximating(t, 0, ESGM_APPROXIMATION_DEFAULT, (esgm_structure_t){0},
                                    &s),
          ESGM_INVALID_ARGUMENT, "default value");
    FAILS(esgm_get_at_approximating(t, 0, 77, (esgm_structure_t){0}, &s),
          ESGM_INVALID_ARGUMENT, "approximation 77");

    int64_t start = 0, end = 0;
    OK(esgm_trajectory_start_time(t, &start));
    OK(esgm_trajectory_end_time(t, &end));
    CHECK(start == ESGM_SECOND / 2);
    CHECK(end == 5 * ESGM_SECOND);

    /* create_at and create_at_now, with their blocking forms. */
    esgm_structure_t attrs = robot_state(0, 7.0);
    OK(esgm_create_at_blocking(t, "robot7", 7 * ESGM_SECOND, attrs, &outcome));
    CHECK(outcome == ESGM_OUTCOME_ADDED);
    OK(esgm_get_at(t, 7 * ESGM_SECOND, &s));
    OK(esgm_sample_info(s, &info));
    CHECK(str_is(info.name, "robot7"));
    OK(esgm_sample_free(s));
    attrs = robot_state(0, 8.0);
    OK(esgm_create_at(t, "robot8", 8 * ESGM_SECOND, attrs, NULL));
    attrs = robot_state(0, 9.0);
    int64_t before = esgm_now();
    OK(esgm_create_at_now_blocking(t, "robot9", attrs, &outcome));
    OK(esgm_get_latest(t, &s));
    OK(esgm_sample_info(s, &info));
    CHECK(info.valid_time >= before);
    CHECK(x_of(s) == 9.0);
    OK(esgm_sample_free(s));
    attrs = robot_state(0, 10.0);
    OK(esgm_create_at_now(t, "robot10", attrs, NULL));

    /* A structure of the wrong shape: refused, naming the attribute and sorts. */
    esgm_structure_t bad = {0};
    OK(esgm_structure_new("robot1", 20 * ESGM_SECOND, 0, &bad));
    OK(esgm_structure_set_long(bad, "x", 1));
    OK(esgm_structure_set_double(bad, "y", 1));
    OK(esgm_structure_set_double(bad, "dir", 1));
    FAILS(esgm_add_blocking(t, bad, NULL), ESGM_INVALID_TYPE, "`x`");
    FAILS(esgm_structure_free(bad), ESGM_INVALID_HANDLE, "was freed"); /* taken by add */

    /* Stats and the trajectory's description. */
    struct esgm_trajectory_stats_t stats;
    OK(esgm_trajectory_stats(t, &stats));
    CHECK(stats.added >= 10);
    char buf[8192];
    size_t len = 0;
    OK(esgm_trajectory_stats_json(t, buf, sizeof buf, &len));
    CHECK(strstr(buf, "\"added\"") != NULL);
    FAILS(esgm_trajectory_stats_json(t, buf, 4, &len), ESGM_OUT_OF_RANGE, "bytes");
    CHECK(strlen(buf) == 3);
    OK(esgm_trajectory_stats_json(t, NULL, 0, &len));
    CHECK(len > 10);
    OK(esgm_trajectory_policy_json(t, buf, sizeof buf, NULL));
    CHECK(strstr(buf, "cache") != NULL);
    struct esgm_str_t name;
    OK(esgm_trajectory_name(t, &name));
    CHECK(str_is(name, "c_odo"));
    esgm_type_t type = {0};
    OK(esgm_trajectory_type(t, &type));
    OK(esgm_type_name(type, &name));
    CHECK(str_is(name, "RobotState"));
    OK(esgm_type_free(type));
    OK(esgm_get_entity_trajectory_structure_type(e, "c_odo", &type));
    OK(esgm_type_free(type));

    /* E5: found by name, the closest name suggested; destroyed. */
    esgm_trajectory_t again = {0};
    OK(esgm_get_entity_trajectory_structure(e, "c_odo", &again));
    OK(esgm_get_latest(again, &s));
    OK(esgm_sample_free(s));
    OK(esgm_trajectory_free(again));
    FAILS(esgm_get_entity_trajectory_structure(e, "c_od", &again),
          ESGM_NO_SUCH_ENTITY_STRUCTURE, "did you mean `c_odo`");
    OK(esgm_trajectories_json(e, buf, sizeof buf, NULL));
    CHECK(strstr(buf, "c_odo") != NULL);

    /* T5: reset. */
    OK(esgm_trajectory_reset_blocking(t));
    FAILS(esgm_get_latest(t, &s), ESGM_VALUE_NOT_AVAILABLE, "");
    OK(esgm_add(t, robot_state(30 * ESGM_SECOND, 30.0), NULL));
    OK(esgm_trajectory_reset(t));

    OK(esgm_destroy_entity_trajectory_structure(e, "c_odo"));
    FAILS(esgm_get_latest(t, &s), ESGM_NO_SUCH_ENTITY_STRUCTURE, "c_odo");
    FAILS(esgm_destroy_entity_trajectory_structure(e, "c_odo"),
          ESGM_NO_SUCH_ENTITY_STRUCTURE, "c_odo");
    OK(esgm_trajectory_free(t));
}

/* C1–C7 through a spec, T3 subscriptions and C7 violations. */
static void policies_subscriptions_violations(esgm_t e) {
    esgm_spec_t spec = {0};
    OK(esgm_spec_primitive("c_pol", "RobotState", &spec));
    OK(esgm_spec_order(spec, ESGM_ORDER_STRICT_MONOTONE));
    OK(esgm_spec_cache_count(spec, 3));
    OK(esgm_spec_filter(spec, "x > 0.0"));
    OK(esgm_spec_change(spec, ESGM_CHANGE_ANY_UPDATE, 0));
    OK(esgm_spec_readers(spec, 4));
    FAILS(esgm_spec_order(spec, 9), ESGM_INVALID_ARGUMENT, "order 9");
    FAILS(esgm_spec_change(spec, -1, 0), ESGM_INVALID_ARGUMENT, "change -1");
    FAILS(esgm_spec_delay(spec, -5), ESGM_ILLEGAL_POLICY, "delay");
    esgm_trajectory_t t = {0};
    OK(esgm_create_trajectory(e, spec, &t));
    OK(esgm_spec_free(spec));

    esgm_subscription_t sub = {0};
    OK(esgm_subscribe(t, 16, 0, &sub));
    esgm_violations_t viol = {0};
    OK(esgm_subscribe_violations(t, 16, &viol));

    int32_t outcome = -1;
    OK(esgm_add(t, robot_state(ESGM_SECOND, 1.0), &outcome));
    OK(esgm_add_blocking(t, robot_state(2 * ESGM_SECOND, 2.0), &outcome));
    /* The filter refuses x <= 0: dropped by add, a violation for add_blocking. */
    OK(esgm_add(t, robot_state(3 * ESGM_SECOND, -1.0), &outcome));
    CHECK(outcome == ESGM_OUTCOME_DROPPED || outcome == ESGM_OUTCOME_FORWARDED);
    FAILS(esgm_add_blocking(t, robot_state(4 * ESGM_SECOND, -1.0), NULL),
          ESGM_POLICY_VIOLATION, "filter");
    /* Strict order refuses an earlier valid time. */
    FAILS(esgm_add_blocking(t, robot_state(ESGM_SECOND, 5.0), NULL), ESGM_POLICY_VIOLATION,
          "order");

    esgm_sample_t s = {0};
    OK(esgm_subscription_recv(sub, 5 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 1.0);
    OK(esgm_sample_free(s));
    OK(esgm_subscription_recv(sub, 5 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 2.0);
    OK(esgm_sample_free(s));
    FAILS(esgm_subscription_recv(sub, 0, &s), ESGM_TIMEOUT, "nothing to receive now");
    FAILS(esgm_subscription_recv(sub, 20 * ESGM_MILLISECOND, &s), ESGM_TIMEOUT, "no sample");
    uint64_t overflowed = 1;
    OK(esgm_subscription_overflowed(sub, &overflowed));
    CHECK(overflowed == 0);

    esgm_violation_t v = {0};
    int filters = 0, orders = 0;
    for (int i = 0; i < 3; i++) {
        if (esgm_violations_recv(viol, 5 * ESGM_SECOND, &v) != ESGM_OK) {
            break;
        }
        struct esgm_violation_info_t info;
        OK(esgm_violation_info(v, &info));
        CHECK(str_is(info.trajectory, "c_pol"));
        filters += str_is(info.constraint, "filter");
        orders += str_is(info.constraint, "order");
        OK(esgm_violation_free(v));
    }
    CHECK(filters == 2);
    CHECK(orders == 1);
    OK(esgm_violations_free(viol));

    /* The cache keeps 3. */
    for (int i = 10; i < 15; i++) {
        OK(esgm_add_blocking(t, robot_state(i * ESGM_SECOND, (double)i), NULL));
    }
    esgm_sample_list_t list = {0};
    OK(esgm_get_between(t, 0, 100 * ESGM_SECOND, &list));
    size_t n = 0;
    OK(esgm_sample_list_len(list, &n));
    CHECK(n == 3);
    OK(esgm_sample_list_free(list));

    /* A late joiner asks for the last 2 first. */
    esgm_subscription_t late = {0};
    OK(esgm_subscribe(t, 0, 2, &late));
    OK(esgm_subscription_recv(late, 5 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 13.0);
    OK(esgm_sample_free(s));
    OK(esgm_unsubscribe(late));
    OK(esgm_unsubscribe(sub));

    /* Destroying the trajectory ends a subscription. */
    OK(esgm_subscribe(t, 0, 0, &sub));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_pol"));
    FAILS(esgm_subscription_recv(sub, 5 * ESGM_SECOND, &s), ESGM_CLOSED, "");
    OK(esgm_unsubscribe(sub));
    OK(esgm_trajectory_free(t));

    /* An illegal filter is refused when the trajectory is created. */
    OK(esgm_spec_primitive("c_bad", "RobotState", &spec));
    OK(esgm_spec_filter(spec, "speed > 1"));
    FAILS(esgm_create_trajectory(e, spec, &t), ESGM_ILLEGAL_POLICY, "speed");
    OK(esgm_spec_free(spec));

    /* Every other policy setting is accepted. */
    OK(esgm_spec_primitive("c_all", "RobotState", &spec));
    OK(esgm_spec_cache_duration(spec, 5 * ESGM_SECOND));
    OK(esgm_spec_cache_all(spec));
    OK(esgm_spec_delay(spec, 50 * ESGM_MILLISECOND));
    OK(esgm_spec_order(spec, ESGM_ORDER_MONOTONE));
    OK(esgm_spec_reorder(spec, true));
    OK(esgm_spec_duration(spec, 0, 0));
    OK(esgm_spec_change(spec, ESGM_CHANGE_SAMPLE_EVERY, 10 * ESGM_MILLISECOND));
    OK(esgm_spec_change(spec, ESGM_CHANGE_ANY_CHANGE, 0));
    OK(esgm_create_trajectory(e, spec, &t));
    OK(esgm_spec_replace(spec, true));
    esgm_trajectory_t replaced = {0};
    OK(esgm_create_trajectory(e, spec, &replaced));
    OK(esgm_spec_free(spec));
    OK(esgm_trajectory_free(replaced));
    OK(esgm_trajectory_free(t));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_all"));
}

/* Nested frames and sequences, built and read in place. */
static void frames_and_sequences(esgm_t e) {
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_blobs", "BlobSeq", &t));
    esgm_structure_t seq = {0};
    OK(esgm_structure_new("blobs", ESGM_SECOND, ESGM_SECOND, &seq));
    for (int i = 0; i < 3; i++) {
        esgm_structure_t blob = {0};
        OK(esgm_frame_new("blob", &blob));
        OK(esgm_structure_set_long(blob, "x", 10 * i));
        OK(esgm_structure_set_long(blob, "y", 20 * i));
        OK(esgm_structure_set_long(blob, "size", 100 + i));
        OK(esgm_structure_push_frame(seq, "items", blob));
    }
    FAILS(esgm_structure_push_frame(seq, "items", seq), ESGM_INVALID_ARGUMENT, "itself");
    OK(esgm_add_blocking(t, seq, NULL));

    esgm_sample_t s = {0};
    OK(esgm_get_latest(t, &s));
    struct esgm_value_t v;
    OK(esgm_sample_value(s, "items", &v));
    CHECK(v.sort == ESGM_SORT_ENTITY_FRAME_SEQ);
    CHECK(v.len == 3);
    OK(esgm_sample_value_at(s, 0, &v));
    CHECK(str_is(v.name, "items"));
    FAILS(esgm_sample_value_at(s, 1, &v), ESGM_OUT_OF_RANGE, "no index 1");
    esgm_sample_t blob = {0};
    OK(esgm_sample_frame_at(s, "items", 2, &blob));
    int64_t size = 0;
    OK(esgm_sample_get_long(blob, "size", &size));
    CHECK(size == 102);
    struct esgm_sample_info_t info;
    OK(esgm_sample_info(blob, &info));
    CHECK(str_is(info.name, "blob"));
    CHECK(info.valid_time == ESGM_SECOND);
    FAILS(esgm_sample_frame_at(s, "items", 3, &blob), ESGM_OUT_OF_RANGE, "3 frames");
    FAILS(esgm_sample_frame(s, "items", &blob), ESGM_INVALID_TYPE, "not EntityFrame");
    FAILS(esgm_sample_item(s, "items", 0, &v), ESGM_INVALID_TYPE, "esgm_sample_frame_at");
    /* The frame outlives the sample's handle: it holds the sample. */
    OK(esgm_sample_free(s));
    OK(esgm_sample_get_long(blob, "x", &size));
    CHECK(size == 20);
    char json[1024];
    OK(esgm_sample_to_json(blob, json, sizeof json, NULL));
    CHECK(strstr(json, "\"size\":102") != NULL);
    OK(esgm_sample_free(blob));
    OK(esgm_trajectory_free(t));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_blobs"));

    /* Every sort, through a type of our own. */
    esgm_type_t ty = {0};
    OK(esgm_type_new("AllSorts", &ty));
    OK(esgm_type_add_attribute(ty, "l", ESGM_SORT_LONG, NULL));
    OK(esgm_type_add_attribute(ty, "b", ESGM_SORT_BOOL, NULL));
    OK(esgm_type_add_attribute(ty, "s", ESGM_SORT_STRING, NULL));
    OK(esgm_type_add_attribute(ty, "sym", ESGM_SORT_SYMBOL, NULL));
    OK(esgm_type_add_attribute(ty, "t", ESGM_SORT_TIME, NULL));
    OK(esgm_type_add_attribute(ty, "o", ESGM_SORT_OCTET_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "ls", ESGM_SORT_LONG_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "ds", ESGM_SORT_DOUBLE_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "ss", ESGM_SORT_SYMBOL_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "v", ESGM_SORT_VEC, NULL));
    OK(esgm_type_add_attribute(ty, "vs", ESGM_SORT_VEC_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "p", ESGM_SORT_POS2, NULL));
    OK(esgm_type_add_attribute(ty, "ps", ESGM_SORT_POS2_SEQ, NULL));
    OK(esgm_type_add_attribute(ty, "pos", ESGM_SORT_POSITION, NULL));
    OK(esgm_type_add_attribute(ty, "alt", ESGM_SORT_ALTITUDE, NULL));
    OK(esgm_type_add_attribute(ty, "rot", ESGM_SORT_ROTATION, NULL));
    OK(esgm_type_add_attribute(ty, "pa", ESGM_SORT_POSITION_ALTITUDE, NULL));
    OK(esgm_type_add_attribute(ty, "pose", ESGM_SORT_POSITION_ALTITUDE_ROTATION, NULL));
    OK(esgm_type_add_attribute(ty, "agg", ESGM_SORT_AGG, NULL));
    OK(esgm_type_add_attribute(ty, "best", ESGM_SORT_ENTITY_FRAME, "Blob"));
    OK(esgm_create_type(e, ty));
    OK(esgm_type_free(ty));
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_sorts", "AllSorts", &t));
    esgm_structure_t a = {0};
    OK(esgm_structure_new("all", 5, 5, &a));
    OK(esgm_structure_set_long(a, "l", -7));
    OK(esgm_structure_set_bool(a, "b", true));
    OK(esgm_structure_set_string(a, "s", "hello"));
    OK(esgm_structure_set_symbol(a, "sym", "robot1"));
    OK(esgm_structure_set_time(a, "t", 123));
    const uint8_t bytes[4] = {1, 2, 3, 4};
    OK(esgm_structure_set_octets(a, "o", bytes, 4));
    const int64_t longs[3] = {1, 2, 3};
    OK(esgm_structure_set_long_seq(a, "ls", longs, 3));
    const double doubles[2] = {0.5, 1.5};
    OK(esgm_structure_set_double_seq(a, "ds", doubles, 2));
    const char *symbols[2] = {"a", "bc"};
    OK(esgm_structure_set_symbol_seq(a, "ss", symbols, 2));
    OK(esgm_structure_set_vec(a, "v", (struct esgm_vec3_t){1, 2, 3}));
    const struct esgm_vec3_t vecs[1] = {{4, 5, 6}};
    OK(esgm_structure_set_vec_seq(a, "vs", vecs, 1));
    OK(esgm_structure_set_pos2(a, "p", (struct esgm_pos2_t){7, 8}));
    const struct esgm_pos2_t points[2] = {{1, 1}, {2, 2}};
    OK(esgm_structure_set_pos2_seq(a, "ps", points, 2));
    OK(esgm_structure_set_position(a, "pos", (struct esgm_position_t){58.4, 15.6}));
    OK(esgm_structure_set_altitude(a, "alt", 120.0));
    OK(esgm_structure_set_rotation(a, "rot", (struct esgm_rotation_t){0.1, 0.2, 0.3}));
    OK(esgm_structure_set_position_altitude(
        a, "pa", (struct esgm_position_altitude_t){{1, 2}, 3}));
    OK(esgm_structure_set_pose(a, "pose", (struct esgm_pose_t){{1, 2}, 3, {4, 5, 6}}));
    OK(esgm_structure_set_json(a, "agg", "{\"Agg\": [{\"Long\": 1}, {\"String\": \"x\"}]}"));
    FAILS(esgm_structure_set_json(a, "agg", "{not json"), ESGM_INVALID_TYPE, "not a value");
    esgm_structure_t best = {0};
    OK(esgm_frame_new("blob", &best));
    OK(esgm_structure_set_long(best, "x", 1));
    OK(esgm_structure_set_long(best, "y", 2));
    OK(esgm_structure_set_long(best, "size", 3));
    OK(esgm_structure_set_frame(a, "best", best));
    FAILS(esgm_structure_set_long(best, "x", 1), ESGM_INVALID_HANDLE, "freed");
    OK(esgm_add_blocking(t, a, NULL));

    OK(esgm_get_latest(t, &s));
    int64_t l = 0;
    OK(esgm_sample_get_long(s, "l", &l));
    CHECK(l == -7);
    bool b = false;
    OK(esgm_sample_get_bool(s, "b", &b));
    CHECK(b);
    struct esgm_str_t text;
    OK(esgm_sample_get_string(s, "s", &text));
    CHECK(str_is(text, "hello"));
    OK(esgm_sample_value(s, "sym", &v));
    CHECK(v.sort == ESGM_SORT_SYMBOL && str_is(v.text, "robot1"));
    OK(esgm_sample_get_time(s, "t", &l));
    CHECK(l == 123);
    const uint8_t *data = NULL;
    size_t len = 0;
    OK(esgm_sample_get_octets(s, "o", &data, &len));
    CHECK(len == 4 && data[3] == 4);
    const int64_t *ls = NULL;
    OK(esgm_sample_get_long_seq(s, "ls", &ls, &len));
    CHECK(len == 3 && ls[2] == 3);
    const double *ds = NULL;
    OK(esgm_sample_get_double_seq(s, "ds", &ds, &len));
    CHECK(len == 2 && ds[1] == 1.5);
    OK(esgm_sample_item(s, "ss", 1, &v));
    CHECK(v.sort == ESGM_SORT_SYMBOL && str_is(v.text, "bc"));
    FAILS(esgm_sample_item(s, "ss", 2, &v), ESGM_OUT_OF_RANGE, "2 items");
    OK(esgm_sample_value(s, "v", &v));
    CHECK(v.vec.z == 3);
    OK(esgm_sample_item(s, "vs", 0, &v));
    CHECK(v.sort == ESGM_SORT_VEC && v.vec.y == 5);
    OK(esgm_sample_value(s, "p", &v));
    CHECK(v.pos2.y == 8);
    OK(esgm_sample_item(s, "ps", 1, &v));
    CHECK(v.pos2.x == 2);
    OK(esgm_sample_value(s, "pos", &v));
    CHECK(v.pose.position.north == 58.4);
    OK(esgm_sample_value(s, "alt", &v));
    CHECK(v.double_value == 120.0);
    OK(esgm_sample_value(s, "rot", &v));
    CHECK(v.pose.rotation.yaw == 0.3);
    OK(esgm_sample_value(s, "pa", &v));
    CHECK(v.pose.altitude == 3);
    OK(esgm_sample_value(s, "pose", &v));
    CHECK(v.pose.rotation.roll == 4 && v.pose.position.east == 2);
    OK(esgm_sample_value(s, "agg", &v));
    CHECK(v.sort == ESGM_SORT_AGG && v.len == 2);
    OK(esgm_sample_item(s, "agg", 1, &v));
    CHECK(v.sort == ESGM_SORT_STRING && str_is(v.text, "x"));
    OK(esgm_sample_frame(s, "best", &blob));
    OK(esgm_sample_get_long(blob, "size", &l));
    CHECK(l == 3);
    OK(esgm_sample_free(blob));
    FAILS(esgm_sample_get_double(s, "l", (double *)&l), ESGM_INVALID_TYPE, "is Long, not Double");
    FAILS(esgm_sample_get_long(s, "lx", &l), ESGM_NO_SUCH_ATTRIBUTE, "it has l, b, s");
    OK(esgm_sample_free(s));
    OK(esgm_trajectory_free(t));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_sorts"));
}

/* Images: written into a loan of the trajectory's memory, read in place. */
static void images(esgm_t e, int expect_shared) {
    /* A camera's trajectory keeps a few frames (a bounded cache): every one of them is
     * read where the camera wrote it, the writer's own cache included. */
    esgm_spec_t spec = {0};
    OK(esgm_spec_primitive("c_images", "Image", &spec));
    OK(esgm_spec_cache_count(spec, 5));
    esgm_trajectory_t t = {0};
    OK(esgm_create_trajectory(e, spec, &t));
    OK(esgm_spec_free(spec));
    esgm_image_loan_t loan = {0};
    OK(esgm_trajectory_image_loan(t, 640, 480, ESGM_IMAGE_RGB8, &loan));
    bool shared = false;
    OK(esgm_image_loan_is_shared(loan, &shared));
    CHECK(shared == (expect_shared != 0));
    uint8_t *pixels = NULL;
    size_t len = 0;
    OK(esgm_image_loan_pixels(loan, &pixels, &len));
    CHECK(len == 640 * 480 * 3);
    for (size_t i = 0; i < len; i++) {
        pixels[i] = (uint8_t)(i % 251);
    }
    esgm_structure_t img = {0};
    OK(esgm_structure_new("camera", ESGM_SECOND, ESGM_SECOND, &img));
    OK(esgm_structure_set_long(img, "width", 640));
    OK(esgm_structure_set_long(img, "height", 480));
    OK(esgm_structure_set_long(img, "format", 0));
    OK(esgm_structure_set_image(img, "image_data", loan));
    FAILS(esgm_image_loan_pixels(loan, &pixels, &len), ESGM_INVALID_HANDLE, "freed");
    OK(esgm_add_blocking(t, img, NULL));

    /* A loan dropped without adding goes back; the next one works. */
    OK(esgm_trajectory_image_loan(t, 64, 48, ESGM_IMAGE_MONO8, &loan));
    OK(esgm_image_loan_free(loan));
    FAILS(esgm_trajectory_image_loan(t, 0, 48, ESGM_IMAGE_RGB8, &loan), ESGM_INVALID_ARGUMENT,
          "0 × 48");
    FAILS(esgm_trajectory_image_loan(t, 64, 48, 7, &loan), ESGM_INVALID_ARGUMENT, "format 7");
    FAILS(esgm_trajectory_image_loan(t, -1, 48, ESGM_IMAGE_RGB8, &loan),
          ESGM_INVALID_ARGUMENT, "cannot be");

    esgm_sample_t s = {0};
    OK(esgm_get_latest(t, &s));
    const uint8_t *data = NULL;
    OK(esgm_sample_get_octets(s, "image_data", &data, &len));
    CHECK(len == 640 * 480 * 3);
    CHECK(data[0] == 0 && data[len - 1] == (uint8_t)((len - 1) % 251));
    /* Read in place: the pixels the producer wrote are the ones read. */
    /* Read in place: in the writer's own cache too, its pixels are the chunk the
     * producer wrote (held), not a copy. */
    bool held = false;
    OK(esgm_sample_octets_are_shared(s, "image_data", &held));
    CHECK(held == (expect_shared != 0));
    OK(esgm_sample_free(s));
    OK(esgm_trajectory_free(t));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_images"));
}

/* A unit written in C: doubles x of its input; no value for x < 0. */
static int unit_calls = 0;
static int unit_released = 0;

static int32_t doubler(void *user, const esgm_sample_t *inputs, size_t n, int64_t qtime,
                       esgm_structure_t *out) {
    (void)qtime;
    CHECK(user == &unit_calls);
    unit_calls++;
    if (n != 1) {
        esgm_set_last_error_message("expected one input");
        return ESGM_ERROR;
    }
    double x = x_of(inputs[0]);
    if (x < 0) {
        return ESGM_VALUE_NOT_AVAILABLE;
    }
    if (x == 13) {
        esgm_set_last_error_message("thirteen is unlucky");
        return ESGM_ERROR;
    }
    struct esgm_sample_info_t info;
    OK(esgm_sample_info(inputs[0], &info));
    *out = robot_state(info.valid_time, 2 * x);
    return ESGM_OK;
}

static void release(void *user) {
    CHECK(user == &unit_calls || user == &unit_released);
    unit_released++;
}

/* A sensor written in C: a camera rendering into the sampled trajectory's loan. */
static int sensor_calls = 0;

static int32_t camera(void *user, int64_t qtime, esgm_sensor_context_t ctx,
                      esgm_structure_t *out) {
    (void)user;
    sensor_calls++;
    esgm_image_loan_t loan = {0};
    OK(esgm_sensor_image_loan(ctx, 32, 24, ESGM_IMAGE_MONO8, &loan));
    uint8_t *pixels = NULL;
    size_t len = 0;
    OK(esgm_image_loan_pixels(loan, &pixels, &len));
    memset(pixels, 200, len);
    OK(esgm_structure_new("camera", qtime, qtime, out));
    OK(esgm_structure_set_long(*out, "width", 32));
    OK(esgm_structure_set_long(*out, "height", 24));
    OK(esgm_structure_set_long(*out, "format", 1));
    OK(esgm_structure_set_image(*out, "image_data", loan));
    return ESGM_OK;
}

/* E3, E4, E6, G2–G4: units, sensors and every operator kind. */
static void units_sensors_operators(esgm_t e) {
    const char *inputs[1] = {"RobotState"};
    OK(esgm_add_comp_unit(e, "CDoubler", "RobotState", inputs, 1, doubler, NULL, &unit_calls,
                          release));
    FAILS(esgm_add_comp_unit(e, "CDoubler", "RobotState", inputs, 1, doubler, NULL,
                             &unit_released, release),
          ESGM_COMP_UNIT_ALREADY_EXISTS, "CDoubler");
    CHECK(unit_released == 1); /* the refused registration's pointer, released */
    FAILS(esgm_add_comp_unit(e, "CNull", "RobotState", inputs, 1, NULL, NULL, NULL, NULL),
          ESGM_INVALID_ARGUMENT, "compute");

    esgm_trajectory_t in = {0}, out = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_in", "RobotState", &in));
    const char *names[1] = {"c_in"};
    OK(esgm_create_computed_entity_trajectory_structure(e, "c_doubled", "CDoubler", names, 1,
                                                        &out));
    const char *missing[1] = {"c_nope"};
    esgm_trajectory_t none = {0};
    FAILS(esgm_create_computed_entity_trajectory_structure(e, "c_x", "CDoubler", missing, 1,
                                                           &none),
          ESGM_NO_SUCH_ENTITY_STRUCTURE, "c_nope");
    FAILS(esgm_create_computed_entity_trajectory_structure(e, "c_x", "CDoubled", names, 1,
                                                           &none),
          ESGM_NO_SUCH_COMP_UNIT, "CDoubled");
    esgm_subscription_t sub = {0};
    OK(esgm_subscribe(out, 0, 0, &sub));
    OK(esgm_add(in, robot_state(ESGM_SECOND, 3.0), NULL));
    OK(esgm_add(in, robot_state(2 * ESGM_SECOND, -1.0), NULL)); /* no value */
    OK(esgm_add(in, robot_state(3 * ESGM_SECOND, 13.0), NULL)); /* fails, counted */
    OK(esgm_add(in, robot_state(4 * ESGM_SECOND, 5.0), NULL));
    esgm_sample_t s = {0};
    OK(esgm_subscription_recv(sub, 10 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 6.0);
    OK(esgm_sample_free(s));
    OK(esgm_subscription_recv(sub, 10 * ESGM_SECOND, &s));
    CHECK(x_of(s) == 10.0);
    OK(esgm_sample_free(s));
    OK(esgm_flush(e, 10 * ESGM_SECOND));
    CHECK(unit_calls == 4);
    char buf[65536];
    OK(esgm_stats_json(e, buf, sizeof buf, NULL));
    CHECK(strstr(buf, "thirteen is unlucky") != NULL || strstr(buf, "fail") != NULL);
    FAILS(esgm_remove_comp_unit(e, "CDoubler"), ESGM_OPERATION_NOT_SUPPORTED, "CDoubler");
    OK(esgm_unsubscribe(sub));

    /* G2: sync; G3: merge; G4: generated, from the same inputs. */
    esgm_trajectory_t other = {0}, sync = {0}, merge = {0}, gen = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_in2", "RobotState", &other));
    const char *both[2] = {"c_in", "c_in2"};
    esgm_spec_t spec = {0};
    OK(esgm_spec_sync("c_sync", both, 2, "approximate", 10 * ESGM_MILLISECOND, 10, &spec));
    OK(esgm_create_trajectory(e, spec, &sync));
    OK(esgm_spec_free(spec));
    FAILS(esgm_spec_sync("c_sync2", both, 2, "exact", 5, 10, &spec), ESGM_ILLEGAL_POLICY,
          "c_sync2");
    FAILS(esgm_spec_sync("c_sync2", both, 2, "nearest", -1, 10, &spec), ESGM_ILLEGAL_POLICY,
          "nearest");
    OK(esgm_spec_merge("c_merge", both, 2, &spec));
    OK(esgm_create_trajectory(e, spec, &merge));
    OK(esgm_spec_free(spec));
    const char *generators[1] = {"c_in:linear"};
    OK(esgm_spec_generated("c_gen", generators, 1, 100 * ESGM_MILLISECOND, NULL, &spec));
    OK(esgm_spec_lag(spec, 0));
    OK(esgm_spec_between(spec, 0, 0));
    OK(esgm_create_trajectory(e, spec, &gen));
    OK(esgm_spec_free(spec));
    const char *bad_generators[1] = {"c_in:sideways"};
    FAILS(esgm_spec_generated("c_gen2", bad_generators, 1, ESGM_SECOND, NULL, &spec),
          ESGM_ILLEGAL_POLICY, "sideways");
    FAILS(esgm_spec_generated("c_gen2", bad_generators, 0, ESGM_SECOND, NULL, &spec),
          ESGM_INVALID_ARGUMENT, "at least one");

    esgm_subscription_t sync_sub = {0}, merge_sub = {0};
    OK(esgm_subscribe(sync, 0, 0, &sync_sub));
    OK(esgm_subscribe(merge, 0, 0, &merge_sub));
    /* ApproximateTime decides a set once later items show no better match can come. */
    for (int i = 10; i < 14; i++) {
        OK(esgm_add(in, robot_state(i * ESGM_SECOND, 1.0), NULL));
        OK(esgm_add(other, robot_state(i * ESGM_SECOND + ESGM_MILLISECOND, 2.0), NULL));
    }
    OK(esgm_subscription_recv(sync_sub, 10 * ESGM_SECOND, &s));
    struct esgm_sample_info_t info;
    OK(esgm_sample_info(s, &info));
    CHECK(info.valid_time == 10 * ESGM_SECOND + ESGM_MILLISECOND);
    esgm_sample_t member = {0};
    OK(esgm_sample_frame(s, "c_in2", &member));
    CHECK(x_of(member) == 2.0);
    OK(esgm_sample_free(member));
    OK(esgm_sample_free(s));
    int merged = 0;
    while (esgm_subscription_recv(merge_sub, 2 * ESGM_SECOND, &s) == ESGM_OK) {
        merged++;
        OK(esgm_sample_free(s));
        if (merged == 8) {
            break;
        }
    }
    CHECK(merged == 8);
    OK(esgm_unsubscribe(sync_sub));
    OK(esgm_unsubscribe(merge_sub));

    /* E3: a sensor sampled every 50 ms, rendering into loans. */
    OK(esgm_add_sensor_interface(e, "c_camera", "Image", camera, NULL, NULL));
    FAILS(esgm_add_sensor_interface(e, "c_camera", "Image", camera, NULL, NULL),
          ESGM_SENSOR_ALREADY_EXISTS, "c_camera");
    esgm_trajectory_t frames = {0};
    FAILS(esgm_create_entity_trajectory_structure(e, "c_frames", "c_camera", 0, 0,
                                                  50 * ESGM_MILLISECOND, 0, -1, &frames),
          ESGM_ILLEGAL_POLICY, "cache_size");
    FAILS(esgm_create_entity_trajectory_structure(e, "c_frames", "c_cam", 0, 0,
                                                  50 * ESGM_MILLISECOND, 0, 5, &frames),
          ESGM_NO_SUCH_SENSOR, "c_cam");
    OK(esgm_create_entity_trajectory_structure(e, "c_frames", "c_camera", 0, 0,
                                               50 * ESGM_MILLISECOND, 0, 5, &frames));
    esgm_subscription_t frame_sub = {0};
    OK(esgm_subscribe(frames, 0, 0, &frame_sub));
    OK(esgm_subscription_recv(frame_sub, 10 * ESGM_SECOND, &s));
    const uint8_t *data = NULL;
    size_t len = 0;
    OK(esgm_sample_get_octets(s, "image_data", &data, &len));
    CHECK(len == 32 * 24 && data[0] == 200 && data[len - 1] == 200);
    OK(esgm_sample_free(s));
    OK(esgm_unsubscribe(frame_sub));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_frames"));
    OK(esgm_remove_sensor_interface(e, "c_camera"));
    FAILS(esgm_remove_sensor_interface(e, "c_camera"), ESGM_NO_SUCH_SENSOR, "c_camera");
    CHECK(sensor_calls >= 1);

    OK(esgm_trajectory_free(gen));
    OK(esgm_trajectory_free(merge));
    OK(esgm_trajectory_free(sync));
    OK(esgm_trajectory_free(other));
    OK(esgm_trajectory_free(out));
    OK(esgm_trajectory_free(in));
    const char *order[] = {"c_gen", "c_merge", "c_sync", "c_doubled", "c_in2", "c_in"};
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++) {
        OK(esgm_destroy_entity_trajectory_structure(e, order[i]));
    }
    OK(esgm_remove_comp_unit(e, "CDoubler"));
}

/* E7 and the whole system. */
static void system_operations(esgm_t e) {
    bool alive = false;
    OK(esgm_ping(e, &alive));
    CHECK(alive);
    OK(esgm_set_log_level(e, ESGM_LOG_WARN));
    int32_t level = -1;
    OK(esgm_get_log_level(e, &level));
    FAILS(esgm_set_log_level(e, 17), ESGM_INVALID_ARGUMENT, "log level 17");
    OK(esgm_reset(e));
    OK(esgm_flush(e, 5 * ESGM_SECOND));
    FAILS(esgm_flush(e, -1), ESGM_INVALID_ARGUMENT, "timeout_ns");
    char buf[65536];
    OK(esgm_memory_stats_json(e, buf, sizeof buf, NULL));
    CHECK(buf[0] == '{');
    struct esgm_str_t name;
    OK(esgm_domain_name(e, &name));
    CHECK(name.len > 0);
    CHECK(strlen(esgm_version()) > 0);
}

/* Bad input of every kind: a status and a message, never a crash. */
static void bad_input(esgm_t e) {
    esgm_trajectory_t t = {0};
    FAILS(esgm_get_entity_trajectory_structure(e, NULL, &t), ESGM_INVALID_ARGUMENT,
          "`name` is a null pointer");
    FAILS(esgm_get_entity_trajectory_structure(e, "x", NULL), ESGM_INVALID_ARGUMENT,
          "`out` is a null pointer");
    FAILS(esgm_get_entity_trajectory_structure(e, "\xff\xfe", &t), ESGM_INVALID_ARGUMENT,
          "not UTF-8");
    esgm_t null_esgm = {0};
    FAILS(esgm_get_entity_trajectory_structure(null_esgm, "x", &t), ESGM_INVALID_HANDLE,
          "null esgm_t");
    esgm_t made_up = {0x1234567812345678ULL};
    FAILS(esgm_get_entity_trajectory_structure(made_up, "x", &t), ESGM_INVALID_HANDLE,
          "never made");
    /* A handle of another kind. */
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_bad", "RobotState", &t));
    esgm_sample_t as_sample = {t.id};
    FAILS(esgm_sample_info(as_sample, NULL), ESGM_INVALID_HANDLE, "esgm_trajectory_t");
    struct esgm_sample_info_t info;
    FAILS(esgm_sample_info(as_sample, &info), ESGM_INVALID_HANDLE,
          "is an esgm_trajectory_t, not an esgm_sample_t");
    /* A freed handle, freed again. */
    esgm_trajectory_t copy = t;
    OK(esgm_trajectory_free(t));
    FAILS(esgm_trajectory_free(copy), ESGM_INVALID_HANDLE, "was freed");
    esgm_sample_t s = {0};
    FAILS(esgm_get_latest(copy, &s), ESGM_INVALID_HANDLE, "was freed");
    /* Null handles are fine to free. */
    OK(esgm_sample_free((esgm_sample_t){0}));
    OK(esgm_trajectory_free((esgm_trajectory_t){0}));
    OK(esgm_structure_free((esgm_structure_t){0}));
    /* A length without a pointer. */
    esgm_structure_t st = {0};
    OK(esgm_structure_new("x", 0, 0, &st));
    FAILS(esgm_structure_set_long_seq(st, "ls", NULL, 3), ESGM_INVALID_ARGUMENT,
          "`values` is a null pointer but its length is 3");
    FAILS(esgm_structure_set_string(st, "s", NULL), ESGM_INVALID_ARGUMENT, "`value`");
    const char *symbols[2] = {"ok", NULL};
    FAILS(esgm_structure_set_symbol_seq(st, "ss", symbols, 2), ESGM_INVALID_ARGUMENT,
          "values[1]");
    OK(esgm_structure_free(st));
    const char *inputs[1] = {NULL};
    FAILS(esgm_create_computed_entity_trajectory_structure(e, "c_y", "U", inputs, 1, &t),
          ESGM_INVALID_ARGUMENT, "inputs[0]");
    FAILS(esgm_create_computed_entity_trajectory_structure(e, "c_y", "U", NULL, 2, &t),
          ESGM_INVALID_ARGUMENT, "`inputs` is a null pointer");
    OK(esgm_destroy_entity_trajectory_structure(e, "c_bad"));
    /* A message with the name that was wrong, and a status with its name. */
    CHECK(strcmp(esgm_status_name(ESGM_POLICY_VIOLATION), "ESGM_POLICY_VIOLATION") == 0);
    CHECK(strcmp(esgm_status_name(12345), "ESGM_UNKNOWN_STATUS") == 0);
    esgm_set_last_error_message("mine");
    CHECK(strcmp(esgm_last_error_message(), "mine") == 0);
    esgm_set_last_error_message(NULL);
    CHECK(strcmp(esgm_last_error_message(), "") == 0);
}

/* After esgm_free, every handle made from it says so; samples stay readable. */
static void after_free(esgm_t e) {
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_last", "RobotState", &t));
    OK(esgm_add_blocking(t, robot_state(ESGM_SECOND, 4.0), NULL));
    esgm_sample_t s = {0};
    OK(esgm_get_latest(t, &s));
    esgm_subscription_t sub = {0};
    OK(esgm_subscribe(t, 0, 0, &sub));
    OK(esgm_free(e));
    FAILS(esgm_free(e), ESGM_INVALID_HANDLE, "was freed");
    FAILS(esgm_get_latest(t, &s), ESGM_CLOSED, "esgm_free");
    FAILS(esgm_subscription_recv(sub, ESGM_SECOND, &s), ESGM_CLOSED, "esgm_free");
    FAILS(esgm_add(t, robot_state(2 * ESGM_SECOND, 1.0), NULL), ESGM_CLOSED, "esgm_free");
    esgm_trajectory_t u = {0};
    FAILS(esgm_get_entity_trajectory_structure(e, "c_last", &u), ESGM_INVALID_HANDLE,
          "was freed");
    CHECK(x_of(s) == 4.0);
    OK(esgm_sample_free(s));
    OK(esgm_unsubscribe(sub));
    OK(esgm_trajectory_free(t));
    CHECK(unit_released == 2); /* the unit's pointer was released with its ESGM */
}

/* Many attributes in one call, both ways; a bad value frees what the call took. */
static void values_in_one_call(esgm_t e) {
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_values", "BlobSeq", &t));
    esgm_structure_t blobs[2] = {{0}, {0}};
    for (int i = 0; i < 2; i++) {
        struct esgm_value_t b[3] = {
            {.name = {"x", 1}, .sort = ESGM_SORT_LONG, .long_value = 10 * i},
            {.name = {"y", 1}, .sort = ESGM_SORT_LONG, .long_value = 20 * i},
            {.name = {"size", 4}, .sort = ESGM_SORT_LONG, .long_value = 100 + i},
        };
        OK(esgm_frame_new("blob", &blobs[i]));
        OK(esgm_structure_set_values(blobs[i], b, 3));
    }
    struct esgm_value_t items = {.name = {"items", 5}, .sort = ESGM_SORT_ENTITY_FRAME_SEQ,
                                 .data = blobs, .len = 2};
    int32_t outcome = -1;
    OK(esgm_add_values_blocking(t, "blobs", ESGM_SECOND, ESGM_SECOND, &items, 1, &outcome));
    CHECK(outcome == ESGM_OUTCOME_ADDED);
    FAILS(esgm_structure_free(blobs[0]), ESGM_INVALID_HANDLE, "freed"); /* taken */

    esgm_sample_t s = {0};
    OK(esgm_get_latest(t, &s));
    struct esgm_value_t out[4];
    size_t count = 0;
    OK(esgm_sample_values(s, out, 4, &count));
    CHECK(count == 1 && str_is(out[0].name, "items") && out[0].len == 2);
    esgm_sample_t blob = {0};
    OK(esgm_sample_frame_at(s, "items", 1, &blob));
    OK(esgm_sample_values(blob, out, 2, &count));
    CHECK(count == 3); /* two fit; three there */
    CHECK(str_is(out[1].name, "y") && out[1].long_value == 20);
    OK(esgm_sample_values(blob, NULL, 0, &count));
    CHECK(count == 3);
    FAILS(esgm_sample_values(blob, NULL, 3, &count), ESGM_INVALID_ARGUMENT, "`out`");
    OK(esgm_sample_free(blob));
    OK(esgm_sample_free(s));

    /* A bad value: refused with its name; the frames after it are freed, not leaked. */
    esgm_structure_t frame = {0};
    OK(esgm_frame_new("blob", &frame));
    struct esgm_value_t bad[2] = {
        {.name = {"items", 5}, .sort = 999},
        {.name = {"best", 4}, .sort = ESGM_SORT_ENTITY_FRAME, .handle = frame.id},
    };
    FAILS(esgm_add_values(t, "blobs", 2, 2, bad, 2, NULL), ESGM_INVALID_ARGUMENT, "items.sort");
    FAILS(esgm_structure_free(frame), ESGM_INVALID_HANDLE, "freed");
    struct esgm_value_t nodata = {.name = {"ls", 2}, .sort = ESGM_SORT_LONG_SEQ, .len = 3};
    FAILS(esgm_add_values(t, "blobs", 2, 2, &nodata, 1, NULL), ESGM_INVALID_ARGUMENT,
          "`ls.data` is null");
    struct esgm_value_t bad_utf8 = {.name = {"\xff", 1}, .sort = ESGM_SORT_LONG};
    FAILS(esgm_add_values(t, "blobs", 2, 2, &bad_utf8, 1, NULL), ESGM_INVALID_ARGUMENT,
          "values[0].name");
    FAILS(esgm_add_values(t, "blobs", 2, 2, NULL, 1, NULL), ESGM_INVALID_ARGUMENT, "values");
    OK(esgm_trajectory_free(t));
    OK(esgm_destroy_entity_trajectory_structure(e, "c_values"));
}

static int semantics(esgm_t e, int shared_images) {
    types(e);
    primitive_and_queries(e);
    policies_subscriptions_violations(e);
    frames_and_sequences(e);
    values_in_one_call(e);
    images(e, shared_images);
    units_sensors_operators(e);
    system_operations(e);
    bad_input(e);
    after_free(e);
    return failures;
}

/* The killed writer: writes a gradient image into a loan, adds it, says so, waits. */
static int writer(const char *domain, const char *name) {
    esgm_t e = {0};
    OK(esgm_connect(domain, &e));
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, name, "Image", &t));
    esgm_image_loan_t loan = {0};
    OK(esgm_trajectory_image_loan(t, 640, 480, ESGM_IMAGE_RGB8, &loan));
    uint8_t *pixels = NULL;
    size_t len = 0;
    OK(esgm_image_loan_pixels(loan, &pixels, &len));
    for (size_t i = 0; i < len; i++) {
        pixels[i] = (uint8_t)(i % 253);
    }
    esgm_structure_t img = {0};
    OK(esgm_structure_new("camera", ESGM_SECOND, ESGM_SECOND, &img));
    OK(esgm_structure_set_long(img, "width", 640));
    OK(esgm_structure_set_long(img, "height", 480));
    OK(esgm_structure_set_long(img, "format", 0));
    OK(esgm_structure_set_image(img, "image_data", loan));
    OK(esgm_add_blocking(t, img, NULL));
    if (failures) {
        return 1;
    }
    printf("ready\n");
    fflush(stdout);
    for (;;) {
        pause();
    }
}

/* A sample read in place stays readable after its writer was killed (SIGKILL). */
static int killed_writer(const char *self, const char *domain) {
    int pipe_fds[2];
    CHECK(pipe(pipe_fds) == 0);
    pid_t child = fork();
    if (child == 0) {
        dup2(pipe_fds[1], STDOUT_FILENO);
        close(pipe_fds[0]);
        execl(self, self, "writer", domain, "c_kill_images", (char *)NULL);
        _exit(127);
    }
    close(pipe_fds[1]);
    char line[32] = {0};
    ssize_t got = read(pipe_fds[0], line, sizeof line - 1);
    CHECK(got > 0 && strncmp(line, "ready", 5) == 0);

    esgm_t e = {0};
    OK(esgm_connect(domain, &e));
    esgm_trajectory_t t = {0};
    OK(esgm_get_entity_trajectory_structure(e, "c_kill_images", &t));
    esgm_sample_t s = {0};
    /* The replica fills from the writer's history: wait for it. */
    for (int i = 0; i < 500 && esgm_get_latest(t, &s) != ESGM_OK; i++) {
        nanosleep(&(struct timespec){0, 10 * 1000 * 1000}, NULL);
    }
    OK(esgm_get_latest(t, &s));
    bool shared = false;
    OK(esgm_sample_octets_are_shared(s, "image_data", &shared));
    CHECK(shared);
    const uint8_t *data = NULL;
    size_t len = 0;
    OK(esgm_sample_get_octets(s, "image_data", &data, &len));
    CHECK(len == 640 * 480 * 3);

    CHECK(kill(child, SIGKILL) == 0);
    int status = 0;
    CHECK(waitpid(child, &status, 0) == child);
    CHECK(WIFSIGNALED(status));

    /* Every pixel, after the writer's death: still mapped, still what it wrote. */
    size_t wrong = 0;
    for (size_t i = 0; i < len; i++) {
        wrong += data[i] != (uint8_t)(i % 253);
    }
    CHECK(wrong == 0);
    OK(esgm_sample_free(s));
    OK(esgm_trajectory_free(t));
    OK(esgm_free(e));
    close(pipe_fds[0]);
    return failures;
}

/* Handles used after the domain went down: the harness stops the coordinator when
 * this prints "connected" and answers on stdin; every call then returns a status. */
static int down(const char *domain) {
    esgm_t e = {0};
    OK(esgm_connect(domain, &e));
    esgm_trajectory_t t = {0};
    OK(esgm_create_primitive_entity_trajectory_structure(e, "c_down", "RobotState", &t));
    OK(esgm_add_blocking(t, robot_state(ESGM_SECOND, 1.0), NULL));
    printf("connected\n");
    fflush(stdout);
    char line[16];
    if (fgets(line, sizeof line, stdin) == NULL) {
        return 1;
    }
    /* The coordinator is gone: what needs it fails with a status, the rest works. */
    bool alive = true;
    OK(esgm_ping(e, &alive));
    CHECK(!alive);
    esgm_trajectory_t u = {0};
    enum esgm_status made =
        esgm_create_primitive_entity_trajectory_structure(e, "c_down2", "RobotState", &u);
    CHECK(made == ESGM_UNAVAILABLE);
    CHECK(strlen(esgm_last_error_message()) > 0);
    esgm_sample_t s = {0};
    OK(esgm_get_latest(t, &s)); /* this process's own history */
    OK(esgm_sample_free(s));
    enum esgm_status added = esgm_add(t, robot_state(2 * ESGM_SECOND, 2.0), NULL);
    CHECK(added == ESGM_OK || added == ESGM_UNAVAILABLE);
    enum esgm_status stats = esgm_stats_json(e, NULL, 0, NULL);
    CHECK(stats == ESGM_OK || stats == ESGM_UNAVAILABLE);
    CHECK(esgm_serve(e, 0) == ESGM_OK); /* returns at once: the coordinator is gone */
    OK(esgm_trajectory_free(t));
    OK(esgm_free(e));
    return failures;
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: api_test in-process | shm DOMAIN | killed-writer DOMAIN | "
                        "writer DOMAIN NAME | down DOMAIN\n");
        return 2;
    }
    runtime = argv[1];
    int result;
    if (strcmp(argv[1], "in-process") == 0) {
        esgm_t e = {0};
        OK(esgm_in_process(&e));
        FAILS(esgm_serve(e, 0), ESGM_OPERATION_NOT_SUPPORTED, "in-process");
        result = semantics(e, 0);
    } else if (strcmp(argv[1], "shm") == 0 && argc == 3) {
        esgm_t e = {0};
        OK(esgm_connect(argv[2], &e));
        result = failures ? failures : semantics(e, 1);
    } else if (strcmp(argv[1], "killed-writer") == 0 && argc == 3) {
        result = killed_writer(argv[0], argv[2]);
    } else if (strcmp(argv[1], "writer") == 0 && argc == 4) {
        result = writer(argv[2], argv[3]);
    } else if (strcmp(argv[1], "down") == 0 && argc == 3) {
        result = down(argv[2]);
    } else {
        fprintf(stderr, "unknown mode %s\n", argv[1]);
        return 2;
    }
    if (result == 0) {
        printf("api_test %s: every check held\n", argv[1]);
    } else {
        printf("api_test %s: %d checks failed\n", argv[1], result);
    }
    return result == 0 ? 0 : 1;
}
