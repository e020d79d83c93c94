/*
 * esgm.h: esgm's C ABI (SPEC L3). Generated from esgm-shm/c by cbindgen; do not edit
 * (ESGM_BLESS=1 cargo test -p esgm-c --test header rewrites it).
 *
 * Every function returns an esgm_status (ESGM_OK is 0); esgm_last_error_message()
 * says what went wrong on this thread, with the name that was wrong. Handles are
 * checked: a freed, foreign or made-up one is ESGM_INVALID_HANDLE, never a crash.
 * Times are int64_t nanoseconds on the host's one timeline (esgm_now()).
 *
 * The C++17 wrapper is <esgm/esgm.hpp>. Link with -lesgm_c (pkg-config esgm, or
 * CMake: find_package(esgm CONFIG REQUIRED) and the target esgm::esgm).
 */

#ifndef ESGM_H
#define ESGM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
/** One microsecond in esgm's time unit (int64_t nanoseconds). */
#define ESGM_MICROSECOND INT64_C(1000)
/** One millisecond in nanoseconds. */
#define ESGM_MILLISECOND INT64_C(1000000)
/** One second in nanoseconds. */
#define ESGM_SECOND INT64_C(1000000000)
/** The seed's TIMEUNITS_PER_SECOND. */
#define ESGM_TIMEUNITS_PER_SECOND ESGM_SECOND
/** The seed's TIMEUNITS_PER_MILLI_SECOND. */
#define ESGM_TIMEUNITS_PER_MILLI_SECOND ESGM_MILLISECOND
/** A timeout that never ends (esgm_subscription_recv). */
#define ESGM_FOREVER INT64_C(-1)
/** As a unit's input type: any structure (the seed's ENTITY_FRAME_TYPE). */
#define ESGM_ANY_STRUCTURE "EntityFrame"


/**
 * The outcome of every esgm function. `ESGM_OK` is 0; every other value names what
 * went wrong, after the seed's IDL exceptions where one fits, and
 * `esgm_last_error_message()` says it in words with the name that was wrong.
 */
typedef enum esgm_status {
  /**
   * Success.
   */
  ESGM_OK = 0,
  /**
   * No sample answers the query (an empty trajectory, a time outside what it holds),
   * or a unit or sensor has no value now.
   */
  ESGM_VALUE_NOT_AVAILABLE = 1,
  /**
   * No trajectory of that name (or it was destroyed).
   */
  ESGM_NO_SUCH_ENTITY_STRUCTURE = 2,
  /**
   * No type of that name.
   */
  ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE = 3,
  /**
   * A trajectory of that name exists.
   */
  ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS = 4,
  /**
   * A type of that name exists.
   */
  ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS = 5,
  /**
   * No sensor of that name.
   */
  ESGM_NO_SUCH_SENSOR = 6,
  /**
   * No computational unit of that name.
   */
  ESGM_NO_SUCH_COMP_UNIT = 7,
  /**
   * A sensor of that name exists.
   */
  ESGM_SENSOR_ALREADY_EXISTS = 8,
  /**
   * A computational unit of that name exists.
   */
  ESGM_COMP_UNIT_ALREADY_EXISTS = 9,
  /**
   * The trajectory's policy refused the structure (blocking adds only; the others
   * drop it, count it and say `ESGM_OUTCOME_DROPPED`).
   */
  ESGM_POLICY_VIOLATION = 10,
  /**
   * A policy that cannot be (a negative cache, a filter that does not type-check…).
   */
  ESGM_ILLEGAL_POLICY = 11,
  /**
   * A structure, input or definition that does not fit its type, or an attribute
   * read as a sort it does not have.
   */
  ESGM_INVALID_TYPE = 12,
  /**
   * Not an operation of this trajectory or runtime (an add to a computed one…).
   */
  ESGM_OPERATION_NOT_SUPPORTED = 13,
  /**
   * A limit of the domain was reached; the message names it, its value and the
   * setting that raises it.
   */
  ESGM_LIMIT_REACHED = 14,
  /**
   * The trajectory's writer has exited.
   */
  ESGM_WRITER_GONE = 15,
  /**
   * A part of the system did not answer (no coordinator, a process gone).
   */
  ESGM_UNAVAILABLE = 16,
  /**
   * A wait ended at its timeout with nothing to return.
   */
  ESGM_TIMEOUT = 17,
  /**
   * An attribute the structure does not have; the message lists those it has.
   */
  ESGM_NO_SUCH_ATTRIBUTE = 18,
  /**
   * A handle that is null, freed, of another kind or made up.
   */
  ESGM_INVALID_HANDLE = 19,
  /**
   * A null pointer, a string that is not UTF-8, a value out of range.
   */
  ESGM_INVALID_ARGUMENT = 20,
  /**
   * An index past the end of a list or sequence.
   */
  ESGM_OUT_OF_RANGE = 21,
  /**
   * The subscription ended: its trajectory was destroyed or its ESGM freed.
   */
  ESGM_CLOSED = 22,
  /**
   * Any other error esgm reports; the message says which.
   */
  ESGM_ERROR = 98,
  /**
   * A bug in esgm (a panic caught at the boundary); the message says where.
   */
  ESGM_INTERNAL = 99,
} esgm_status;

/**
 * The sorts of values (the seed's `ValueSort`), as C code names them.
 */
typedef enum esgm_sort {
  /**
   * No value (`NoValue`).
   */
  ESGM_SORT_NO_VALUE = 0,
  /**
   * A 64-bit signed integer (`LONG_TYPE`).
   */
  ESGM_SORT_LONG = 1,
  /**
   * A 64-bit float (`DOUBLE_TYPE`).
   */
  ESGM_SORT_DOUBLE = 2,
  /**
   * A boolean (`BOOL_TYPE`).
   */
  ESGM_SORT_BOOL = 3,
  /**
   * Text (`STRING_TYPE`).
   */
  ESGM_SORT_STRING = 4,
  /**
   * A time-point in nanoseconds (`TIME_TYPE`).
   */
  ESGM_SORT_TIME = 5,
  /**
   * A name of something in the system (`SYMBOL_TYPE`).
   */
  ESGM_SORT_SYMBOL = 6,
  /**
   * Raw bytes, such as an image's pixels, never copied between processes
   * (`OCTET_SEQ_TYPE`).
   */
  ESGM_SORT_OCTET_SEQ = 7,
  /**
   * Integers (`LONG_SEQ_TYPE`).
   */
  ESGM_SORT_LONG_SEQ = 8,
  /**
   * Floats (`DOUBLE_SEQ_TYPE`).
   */
  ESGM_SORT_DOUBLE_SEQ = 9,
  /**
   * Symbols (`SYMBOL_SEQ_TYPE`).
   */
  ESGM_SORT_SYMBOL_SEQ = 10,
  /**
   * A 3-D vector (`VEC_TYPE`).
   */
  ESGM_SORT_VEC = 11,
  /**
   * 3-D vectors (`VEC_SEQ_TYPE`).
   */
  ESGM_SORT_VEC_SEQ = 12,
  /**
   * A 2-D point (`POS2_TYPE`).
   */
  ESGM_SORT_POS2 = 13,
  /**
   * 2-D points (`POS2_SEQ_TYPE`).
   */
  ESGM_SORT_POS2_SEQ = 14,
  /**
   * A horizontal world position (`POSITION_TYPE`).
   */
  ESGM_SORT_POSITION = 15,
  /**
   * An altitude in metres (`ALTITUDE_TYPE`).
   */
  ESGM_SORT_ALTITUDE = 16,
  /**
   * Roll, pitch, yaw (`ROTATION_TYPE`).
   */
  ESGM_SORT_ROTATION = 17,
  /**
   * A position with an altitude (`POSITION_ALTITUDE_TYPE`).
   */
  ESGM_SORT_POSITION_ALTITUDE = 18,
  /**
   * A full pose (`POSITION_ALTITUDE_ROTATION_TYPE`).
   */
  ESGM_SORT_POSITION_ALTITUDE_ROTATION = 19,
  /**
   * A tuple of values (`AGG_TYPE`).
   */
  ESGM_SORT_AGG = 20,
  /**
   * A collection of values (`COLLECTION_TYPE`).
   */
  ESGM_SORT_COLLECTION = 21,
  /**
   * A nested frame of a named type (`ENTITY_FRAME_TYPE`).
   */
  ESGM_SORT_ENTITY_FRAME = 22,
  /**
   * A sequence of frames of a named type (`ENTITY_FRAME_SEQ_TYPE`).
   */
  ESGM_SORT_ENTITY_FRAME_SEQ = 23,
  /**
   * As an attribute's sort: any value (`ANY_VALUE_TYPE`).
   */
  ESGM_SORT_ANY_VALUE = 24,
  /**
   * `UNKNOWN_VALUE_TYPE`.
   */
  ESGM_SORT_UNKNOWN_VALUE = 25,
} esgm_sort;

/**
 * The log levels of `esgm_set_log_level`.
 */
typedef enum esgm_log_level {
  /**
   * Errors only.
   */
  ESGM_LOG_ERROR = 0,
  /**
   * Warnings and errors.
   */
  ESGM_LOG_WARN = 1,
  /**
   * Informational messages.
   */
  ESGM_LOG_INFO = 2,
  /**
   * Debugging detail (every drop).
   */
  ESGM_LOG_DEBUG = 3,
  /**
   * Everything.
   */
  ESGM_LOG_TRACE = 4,
} esgm_log_level;

/**
 * The image formats of `esgm_trajectory_image_loan`.
 */
typedef enum esgm_image_format {
  /**
   * 8-bit red, green, blue per pixel (3 bytes).
   */
  ESGM_IMAGE_RGB8 = 0,
  /**
   * 8-bit grey per pixel (1 byte).
   */
  ESGM_IMAGE_MONO8 = 1,
} esgm_image_format;

/**
 * C1: what must differ between consecutive samples (`esgm_spec_change`).
 */
typedef enum esgm_change {
  /**
   * No restriction.
   */
  ESGM_CHANGE_NONE = 0,
  /**
   * Each value differs from the previous one.
   */
  ESGM_CHANGE_ANY_CHANGE = 1,
  /**
   * Each sample differs in value, valid time or create time.
   */
  ESGM_CHANGE_ANY_UPDATE = 2,
  /**
   * Valid times at least `period` apart (a sample every period).
   */
  ESGM_CHANGE_SAMPLE_EVERY = 3,
} esgm_change;

/**
 * C5: how consecutive valid times relate (`esgm_spec_order`).
 */
typedef enum esgm_order {
  /**
   * No restriction.
   */
  ESGM_ORDER_ANY = 0,
  /**
   * Never earlier than the previous.
   */
  ESGM_ORDER_MONOTONE = 1,
  /**
   * Always later than the previous.
   */
  ESGM_ORDER_STRICT_MONOTONE = 2,
} esgm_order;

/**
 * How `esgm_get_at_approximating` answers when no sample is valid exactly then
 * (the seed's `ValueApproximationConstraint`).
 */
typedef enum esgm_approximation {
  /**
   * No approximation: only a sample valid exactly then.
   */
  ESGM_APPROXIMATION_NONE = 0,
  /**
   * The sample closest in valid time, before or after (before wins a tie).
   */
  ESGM_APPROXIMATION_CLOSEST = 1,
  /**
   * The latest sample valid before (`get_closest_at_or_before`).
   */
  ESGM_APPROXIMATION_MOST_RECENT = 2,
  /**
   * A default value (a structure's attributes), valid then.
   */
  ESGM_APPROXIMATION_DEFAULT = 3,
  /**
   * Linear interpolation of numeric attributes between the samples before and
   * after; others hold the value before.
   */
  ESGM_APPROXIMATION_LINEAR = 4,
  /**
   * Linear, refusing an answer with an attribute that could not be interpolated.
   */
  ESGM_APPROXIMATION_LINEAR_STRICT = 5,
} esgm_approximation;

/**
 * What became of an added structure.
 */
typedef enum esgm_outcome {
  /**
   * It entered the trajectory.
   */
  ESGM_OUTCOME_ADDED = 0,
  /**
   * It is held for reordering within the delay (C6), and released in valid-time
   * order.
   */
  ESGM_OUTCOME_HELD = 1,
  /**
   * It was sent to the trajectory's writer in another process, whose gate decides
   * (a blocking add waits for that decision instead).
   */
  ESGM_OUTCOME_FORWARDED = 2,
  /**
   * The policy refused it: dropped, counted and reported (non-blocking adds).
   */
  ESGM_OUTCOME_DROPPED = 3,
} esgm_outcome;

/**
 * A trajectory of the system, by name: query it, subscribe to it, add to it.
 * Freeing the handle leaves the trajectory; `esgm_destroy_entity_trajectory_structure`
 * destroys it.
 */
typedef struct esgm_trajectory_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_trajectory_t;

/**
 * An entity structure (or a nested frame) being built: add it to a trajectory,
 * return it from a unit or sensor, or set it as a frame of another. Each of those
 * takes it: its handle is freed then, whether the call succeeded or not.
 */
typedef struct esgm_structure_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_structure_t;

/**
 * The ESGM: one system of processes joined through shared memory, or one in this
 * process. Every other handle is made from one.
 */
typedef struct esgm_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_t;

/**
 * Text esgm lends: `len` bytes of UTF-8 at `ptr`, not NUL-terminated, valid while
 * the handle it was read from lives. A C++ `std::string_view` of it costs nothing.
 */
typedef struct esgm_str_t {
  /**
   * The first byte (never null: an empty text points at a static byte).
   */
  const char *ptr;
  /**
   * Its length in bytes.
   */
  size_t len;
} esgm_str_t;

/**
 * Asked every quarter second by `esgm_serve_while`: nonzero to go on serving.
 */
typedef int32_t (*esgm_go_on_fn)(void *user);

/**
 * A writable buffer for one image's pixels, in the trajectory's shared memory:
 * write the frame into `esgm_image_loan_pixels`, then hand it to a structure with
 * `esgm_structure_set_image` (or free it unused).
 */
typedef struct esgm_image_loan_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_image_loan_t;

/**
 * A sample (an entity structure as stored, with its add and query time), or a frame
 * nested in one. Everything read from it is valid while it lives.
 */
typedef struct esgm_sample_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_sample_t;

/**
 * The samples a query returned, in valid-time order.
 */
typedef struct esgm_sample_list_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_sample_list_t;

/**
 * A sample's name and times.
 */
typedef struct esgm_sample_info_t {
  /**
   * The structure's (or frame's) name.
   */
  struct esgm_str_t name;
  /**
   * When it is valid (ns).
   */
  int64_t valid_time;
  /**
   * When it was created (ns).
   */
  int64_t create_time;
  /**
   * When it entered the trajectory (ns).
   */
  int64_t add_time;
  /**
   * When the query it answers was asked (ns; a subscriber's: the add time).
   */
  int64_t query_time;
  /**
   * Its number of attributes.
   */
  size_t attribute_count;
} esgm_sample_info_t;

/**
 * A 3-D vector (`ESGM_SORT_VEC`).
 */
typedef struct esgm_vec3_t {
  /**
   * x component.
   */
  double x;
  /**
   * y component.
   */
  double y;
  /**
   * z component.
   */
  double z;
} esgm_vec3_t;

/**
 * A 2-D point (`ESGM_SORT_POS2`).
 */
typedef struct esgm_pos2_t {
  /**
   * x coordinate.
   */
  double x;
  /**
   * y coordinate.
   */
  double y;
} esgm_pos2_t;

/**
 * A horizontal world position in metres (`ESGM_SORT_POSITION`).
 */
typedef struct esgm_position_t {
  /**
   * Metres north of the origin.
   */
  double north;
  /**
   * Metres east of the origin.
   */
  double east;
} esgm_position_t;

/**
 * An orientation in radians (`ESGM_SORT_ROTATION`).
 */
typedef struct esgm_rotation_t {
  /**
   * About the forward axis.
   */
  double roll;
  /**
   * About the lateral axis.
   */
  double pitch;
  /**
   * About the vertical axis (heading).
   */
  double yaw;
} esgm_rotation_t;

/**
 * A full pose (`ESGM_SORT_POSITION_ALTITUDE_ROTATION`).
 */
typedef struct esgm_pose_t {
  /**
   * Horizontal position.
   */
  struct esgm_position_t position;
  /**
   * Altitude in metres.
   */
  double altitude;
  /**
   * Orientation.
   */
  struct esgm_rotation_t rotation;
} esgm_pose_t;

/**
 * One attribute's value, as C reads and writes it: `sort` says which fields hold it.
 *
 * - `ESGM_SORT_LONG`, `ESGM_SORT_TIME`: `long_value`;
 * - `ESGM_SORT_DOUBLE`, `ESGM_SORT_ALTITUDE`: `double_value`;
 * - `ESGM_SORT_BOOL`: `bool_value`;
 * - `ESGM_SORT_STRING`, `ESGM_SORT_SYMBOL`: `text`;
 * - `ESGM_SORT_OCTET_SEQ`: `data` (bytes) and `len`; written: copied, unless `handle`
 *   is an `esgm_image_loan_t`'s id, whose pixels are handed over (and the loan taken);
 * - `ESGM_SORT_LONG_SEQ`, `ESGM_SORT_DOUBLE_SEQ`: `data` (`int64_t`s or `double`s),
 *   `len`;
 * - `ESGM_SORT_SYMBOL_SEQ`, `ESGM_SORT_VEC_SEQ`, `ESGM_SORT_POS2_SEQ`, `ESGM_SORT_AGG`,
 *   `ESGM_SORT_COLLECTION`: read, `len` items (`esgm_sample_item`); written, `data` is
 *   `len` `esgm_str_t`s, `esgm_vec3_t`s, `esgm_pos2_t`s or `esgm_value_t`s;
 * - `ESGM_SORT_ENTITY_FRAME_SEQ`: read, `len` frames (`esgm_sample_frame_at`); written,
 *   `data` is `len` `esgm_structure_t`s (frames, taken);
 * - `ESGM_SORT_ENTITY_FRAME`: read, nothing here (`esgm_sample_frame`); written,
 *   `handle` is an `esgm_structure_t`'s id (a frame, taken);
 * - `ESGM_SORT_VEC`: `vec`; `ESGM_SORT_POS2`: `pos2`;
 * - `ESGM_SORT_POSITION`, `ESGM_SORT_POSITION_ALTITUDE`,
 *   `ESGM_SORT_POSITION_ALTITUDE_ROTATION`, `ESGM_SORT_ROTATION`: `pose`'s fields.
 *
 * Read, its pointers are into the sample, valid while its handle lives.
 */
typedef struct esgm_value_t {
  /**
   * The attribute's name (empty for a sequence's item).
   */
  struct esgm_str_t name;
  /**
   * Its sort (an `esgm_sort`).
   */
  int32_t sort;
  /**
   * An integer or a time.
   */
  int64_t long_value;
  /**
   * A float or an altitude.
   */
  double double_value;
  /**
   * A boolean.
   */
  bool bool_value;
  /**
   * A string or a symbol.
   */
  struct esgm_str_t text;
  /**
   * Bytes, numbers or items of a sequence.
   */
  const void *data;
  /**
   * The number of bytes or items.
   */
  size_t len;
  /**
   * A vector.
   */
  struct esgm_vec3_t vec;
  /**
   * A 2-D point.
   */
  struct esgm_pos2_t pos2;
  /**
   * A position, altitude and rotation.
   */
  struct esgm_pose_t pose;
  /**
   * Written: a frame's `esgm_structure_t` or an image's `esgm_image_loan_t` id
   * (taken); 0 otherwise. Read: 0.
   */
  uint64_t handle;
} esgm_value_t;

/**
 * What a sensor's call may use while it runs: image loans of the sampled
 * trajectory's memory.
 */
typedef struct esgm_sensor_context_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_sensor_context_t;

/**
 * A sensor's function: `user` as registered, the query time (the scheduled sample
 * time: stamp the structure's valid time with it), the call's context, and where to
 * put the structure. Returns an `esgm_status`.
 */
typedef int32_t (*esgm_sensor_fn)(void *user,
                                  int64_t qtime,
                                  struct esgm_sensor_context_t context,
                                  struct esgm_structure_t *out);

/**
 * Releases a user pointer esgm was given, once esgm calls nothing with it any more.
 */
typedef void (*esgm_free_fn)(void *user);

/**
 * A trajectory described in full (its source and its policy), to create with
 * `esgm_create_trajectory`.
 */
typedef struct esgm_spec_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_spec_t;

/**
 * A position with an altitude (`ESGM_SORT_POSITION_ALTITUDE`).
 */
typedef struct esgm_position_altitude_t {
  /**
   * Horizontal position.
   */
  struct esgm_position_t position;
  /**
   * Altitude in metres.
   */
  double altitude;
} esgm_position_altitude_t;

/**
 * A subscription to a trajectory's structures: receive them in add order, free it
 * to unsubscribe.
 */
typedef struct esgm_subscription_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_subscription_t;

/**
 * A subscription to a trajectory's policy violations.
 */
typedef struct esgm_violations_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_violations_t;

/**
 * One policy violation: which constraint a structure broke, and when.
 */
typedef struct esgm_violation_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_violation_t;

/**
 * A violation, as `esgm_violation_info` reads it; the texts are valid while its handle
 * lives.
 */
typedef struct esgm_violation_info_t {
  /**
   * The trajectory.
   */
  struct esgm_str_t trajectory;
  /**
   * The constraint broken: `"change"`, `"cache"`, `"filter"`, `"duration"`,
   * `"order"` or `"delay"`.
   */
  struct esgm_str_t constraint;
  /**
   * What exactly was wrong, for people.
   */
  struct esgm_str_t detail;
  /**
   * The structure's valid time (ns).
   */
  int64_t valid_time;
  /**
   * Its create time (ns).
   */
  int64_t create_time;
  /**
   * When it was offered (ns).
   */
  int64_t add_time;
} esgm_violation_info_t;

/**
 * An entity structure type being made, or one read from the system: a name and
 * its attributes, each with a sort (and, for frames, the type of its elements).
 */
typedef struct esgm_type_t {
  /**
   * The handle's id; 0 is the null handle.
   */
  uint64_t id;
} esgm_type_t;

/**
 * A trajectory's main statistics (E7); `esgm_trajectory_stats_json` has all of
 * them, drops by cause included.
 */
typedef struct esgm_trajectory_stats_t {
  /**
   * Structures added.
   */
  uint64_t added;
  /**
   * Structures dropped, every cause together (policy, type, reset, lost…).
   */
  uint64_t dropped;
  /**
   * Policy violations reported.
   */
  uint64_t violations;
  /**
   * Samples evicted by the cache policy.
   */
  uint64_t evicted;
  /**
   * Samples stored now.
   */
  uint64_t stored;
  /**
   * Samples held for reordering now.
   */
  uint64_t held;
  /**
   * Subscribers now.
   */
  uint64_t subscribers;
  /**
   * Samples subscribers missed because their queue was full.
   */
  uint64_t subscriber_overflow;
  /**
   * Sample points a sampled trajectory missed.
   */
  uint64_t missed_sample_points;
  /**
   * Structures per second, recently.
   */
  double rate_hz;
  /**
   * Add delay (add time − valid time) percentiles in nanoseconds; -1 before any add.
   */
  int64_t add_delay_p50;
  /**
   * 90th percentile.
   */
  int64_t add_delay_p90;
  /**
   * 99th percentile.
   */
  int64_t add_delay_p99;
  /**
   * Largest.
   */
  int64_t add_delay_max;
} esgm_trajectory_stats_t;

/**
 * One attribute of a type, as `esgm_type_attribute` reads it; the texts are valid
 * while the type's handle lives.
 */
typedef struct esgm_attribute_t {
  /**
   * Its name.
   */
  struct esgm_str_t name;
  /**
   * Its sort (an `esgm_sort`).
   */
  int32_t sort;
  /**
   * For a frame or frame sequence, the type of its elements; else empty.
   */
  struct esgm_str_t element_type;
} esgm_attribute_t;

/**
 * A unit's function: `user` as registered, `n` input samples, the query time (or the
 * time of a temporal function), and where to put its output. Returns an
 * `esgm_status`.
 */
typedef int32_t (*esgm_compute_fn)(void *user,
                                   const struct esgm_sample_t *inputs,
                                   size_t n,
                                   int64_t time,
                                   struct esgm_structure_t *out);

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/**
 * T4: adds the structure `s` (which it takes) to `t`; a policy violation drops it
 * (`ESGM_OUTCOME_DROPPED`). `outcome` (an `esgm_outcome`) may be null.
 */
enum esgm_status esgm_add(struct esgm_trajectory_t t, struct esgm_structure_t s, int32_t *outcome);

/**
 * T4: adds the structure `s` (which it takes) to `t` and waits for the writer's
 * gate: `ESGM_POLICY_VIOLATION` (the message says which constraint) if it refused.
 */
enum esgm_status esgm_add_blocking(struct esgm_trajectory_t t,
                                   struct esgm_structure_t s,
                                   int32_t *outcome);

/**
 * T4 (`create_at`): adds a structure `name` valid at `valid_time` with the
 * attributes of `attributes` (a structure, which it takes; its name and times are
 * not used).
 */
enum esgm_status esgm_create_at(struct esgm_trajectory_t t,
                                const char *name,
                                int64_t valid_time,
                                struct esgm_structure_t attributes,
                                int32_t *outcome);

/**
 * T4 (`create_at_blocking`): `esgm_create_at`, waiting for the gate.
 */
enum esgm_status esgm_create_at_blocking(struct esgm_trajectory_t t,
                                         const char *name,
                                         int64_t valid_time,
                                         struct esgm_structure_t attributes,
                                         int32_t *outcome);

/**
 * T4 (`create_at_now`): adds a structure `name` valid now (the trajectory's clock).
 */
enum esgm_status esgm_create_at_now(struct esgm_trajectory_t t,
                                    const char *name,
                                    struct esgm_structure_t attributes,
                                    int32_t *outcome);

/**
 * T4 (`create_at_now_blocking`): `esgm_create_at_now`, waiting for the gate.
 */
enum esgm_status esgm_create_at_now_blocking(struct esgm_trajectory_t t,
                                             const char *name,
                                             struct esgm_structure_t attributes,
                                             int32_t *outcome);

/**
 * Joins the system of `domain` (started by `esgm up --domain DOMAIN` or `esgm demo`);
 * a null `domain` means `ESGM_DOMAIN` from the environment, else `esgm`. Fails with
 * `ESGM_UNAVAILABLE` when no coordinator answers, `ESGM_LIMIT_REACHED` when the domain
 * has as many processes as it admits.
 */
enum esgm_status esgm_connect(const char *domain, struct esgm_t *out);

/**
 * Joins the system as a named process: `host` is this process's name in the registry
 * (`esgm ps`), null for a unique one of its own.
 */
enum esgm_status esgm_connect_as(const char *domain, const char *host, struct esgm_t *out);

/**
 * Joins the system a supervisor started this process for: the domain, the process's
 * name and the access to its files come from the environment `esgm up` gives every
 * program a system file declares (`ESGM_DOMAIN`, `ESGM_WORKER`, `ESGM_SHM_ACCESS`).
 * The name the unit or sensor was declared under is `ESGM_NAME` (`getenv`).
 */
enum esgm_status esgm_connect_from_env(struct esgm_t *out);

/**
 * An ESGM in this process (the embedded runtime), with the library types: the same
 * calls, no other process, nothing in shared memory.
 */
enum esgm_status esgm_in_process(struct esgm_t *out);

/**
 * Leaves the system (or stops the in-process one): waits for this ESGM's unit and
 * sensor callbacks under way and calls none after it returns, releases their user
 * pointers, and makes every trajectory and subscription handle made from it fail
 * with `ESGM_CLOSED`. Samples stay readable until freed: their images stay mapped.
 * A null handle is fine. Not from a callback of the same ESGM (it would wait for
 * itself): that is `ESGM_OPERATION_NOT_SUPPORTED`.
 */
enum esgm_status esgm_free(struct esgm_t esgm);

/**
 * Writes true to `out` if the system answers (its coordinator, for a connected
 * ESGM).
 */
enum esgm_status esgm_ping(struct esgm_t esgm, bool *out);

/**
 * The domain's name (`"esgm"` for an in-process ESGM), valid while `esgm` lives.
 */
enum esgm_status esgm_domain_name(struct esgm_t esgm, struct esgm_str_t *out);

/**
 * Waits until every structure added before the call was processed by every unit, sync
 * and merge, delivered to every subscriber and entered in every other process's
 * replica; `ESGM_UNAVAILABLE` if that takes longer than `timeout_ns`.
 */
enum esgm_status esgm_flush(struct esgm_t esgm, int64_t timeout_ns);

/**
 * Empties every trajectory of the system (E7), in every process that holds one.
 */
enum esgm_status esgm_reset(struct esgm_t esgm);

/**
 * The system's statistics (E7) as JSON: every trajectory's listing, store statistics
 * (added, dropped by cause, violations, rate, add delays) and worker counters. Copied
 * into `buf` (`capacity` bytes, NUL-terminated); `len` gets the full length, so a
 * call with a null `buf` and capacity 0 asks the size. `ESGM_OUT_OF_RANGE` when cut.
 */
enum esgm_status esgm_stats_json(struct esgm_t esgm, char *buf, size_t capacity, size_t *len);

/**
 * The memory in use (E7) as JSON, added up over every process; as
 * [`esgm_stats_json`].
 */
enum esgm_status esgm_memory_stats_json(struct esgm_t esgm,
                                        char *buf,
                                        size_t capacity,
                                        size_t *len);

/**
 * Sets the log level of every process of the system (E7): each running process's
 * log filter is replaced. `level` is an `esgm_log_level`.
 */
enum esgm_status esgm_set_log_level(struct esgm_t esgm, int32_t level);

/**
 * The log level (an `esgm_log_level`).
 */
enum esgm_status esgm_get_log_level(struct esgm_t esgm, int32_t *out);

/**
 * Serves this process's units and sensors until the system ends: returns `ESGM_OK`
 * once its coordinator has been gone for `patience_ns` (`esgm down`), the main loop
 * of a worker a system file declares. An in-process ESGM has no coordinator:
 * `ESGM_OPERATION_NOT_SUPPORTED`.
 */
enum esgm_status esgm_serve(struct esgm_t esgm, int64_t patience_ns);

/**
 * [`esgm_serve`], also returning (with `ESGM_TIMEOUT`) as soon as `go_on(user)`,
 * asked every quarter second, returns 0: a program that handles its own signals
 * stops this way. A null `go_on` serves until the system ends.
 */
enum esgm_status esgm_serve_while(struct esgm_t esgm,
                                  int64_t patience_ns,
                                  esgm_go_on_fn go_on,
                                  void *user);

/**
 * Logs esgm's messages to stderr, filtered by `RUST_LOG` (default: warnings), as
 * every esgm program does; `esgm_set_log_level` and `esgm log-level` change the
 * filter while the process runs. Call once, first thing; later calls do nothing. A
 * program that does not call it hears nothing from esgm but its statuses.
 */
enum esgm_status esgm_init_logging(void);

/**
 * Now on the host's one timeline (nanoseconds of the system clock), the time every
 * process of a system stamps with.
 */
int64_t esgm_now(void);

/**
 * esgm's version (`"0.1.0"`), a static string.
 */
const char *esgm_version(void);

/**
 * The writable pixels of `loan`: `len` bytes at `data` (row by row, `width` ×
 * bytes per pixel each), valid until the loan is added or freed.
 */
enum esgm_status esgm_image_loan_pixels(struct esgm_image_loan_t loan, uint8_t **data, size_t *len);

/**
 * Writes true to `out` if the loan's pixels are in the trajectory's shared memory
 * (other processes will read them in place), false if on the heap.
 */
enum esgm_status esgm_image_loan_is_shared(struct esgm_image_loan_t loan, bool *out);

/**
 * Gives an unused loan back. Null is fine.
 */
enum esgm_status esgm_image_loan_free(struct esgm_image_loan_t loan);

/**
 * The latest sample added (T1).
 */
enum esgm_status esgm_get_latest(struct esgm_trajectory_t t, struct esgm_sample_t *out);

/**
 * The most current value: the sample with the latest valid time (the seed's
 * `get_latest_vtime`), which differs from the latest added when structures arrive
 * out of order.
 */
enum esgm_status esgm_get_latest_vtime(struct esgm_trajectory_t t, struct esgm_sample_t *out);

/**
 * The `n`-th latest sample (0: the latest).
 */
enum esgm_status esgm_get_nth_latest(struct esgm_trajectory_t t,
                                     size_t n,
                                     struct esgm_sample_t *out);

/**
 * The sample valid exactly at `time`.
 */
enum esgm_status esgm_get_at(struct esgm_trajectory_t t, int64_t time, struct esgm_sample_t *out);

/**
 * The sample with the latest valid time not after `time`.
 */
enum esgm_status esgm_get_closest_at_or_before(struct esgm_trajectory_t t,
                                               int64_t time,
                                               struct esgm_sample_t *out);

/**
 * The samples valid from `from` to `to` (inclusive), in valid-time order (T1); an
 * empty list when none are.
 */
enum esgm_status esgm_get_between(struct esgm_trajectory_t t,
                                  int64_t from,
                                  int64_t to,
                                  struct esgm_sample_list_t *out);

/**
 * The value at `time` approximated by `approximation` (an `esgm_approximation`, T2).
 * `ESGM_APPROXIMATION_DEFAULT` answers with the attributes of `default_value` (a
 * structure, which is not taken; a null handle for the other approximations).
 */
enum esgm_status esgm_get_at_approximating(struct esgm_trajectory_t t,
                                           int64_t time,
                                           int32_t approximation,
                                           struct esgm_structure_t default_value,
                                           struct esgm_sample_t *out);

/**
 * Its name and times.
 */
enum esgm_status esgm_sample_info(struct esgm_sample_t s, struct esgm_sample_info_t *out);

/**
 * The attribute `attribute` as a value of whatever sort it is.
 */
enum esgm_status esgm_sample_value(struct esgm_sample_t s,
                                   const char *attribute,
                                   struct esgm_value_t *out);

/**
 * The attribute at `index` (0 to its count − 1, in the structure's order), with its
 * name.
 */
enum esgm_status esgm_sample_value_at(struct esgm_sample_t s,
                                      size_t index,
                                      struct esgm_value_t *out);

/**
 * Item `index` of the sequence attribute `attribute` (a symbol, vector, point or
 * value of a `SymbolSeq`, `VecSeq`, `Pos2Seq`, `Agg` or `Collection`; an integer or
 * float of a `LongSeq` or `DoubleSeq`). A frame sequence's items are frames:
 * `esgm_sample_frame_at`.
 */
enum esgm_status esgm_sample_item(struct esgm_sample_t s,
                                  const char *attribute,
                                  size_t index,
                                  struct esgm_value_t *out);

/**
 * Reads a `Long` attribute.
 */
enum esgm_status esgm_sample_get_long(struct esgm_sample_t s, const char *attribute, int64_t *out);

/**
 * Reads a `Double` attribute.
 */
enum esgm_status esgm_sample_get_double(struct esgm_sample_t s, const char *attribute, double *out);

/**
 * Reads a `Bool` attribute.
 */
enum esgm_status esgm_sample_get_bool(struct esgm_sample_t s, const char *attribute, bool *out);

/**
 * Reads a `Time` attribute (ns).
 */
enum esgm_status esgm_sample_get_time(struct esgm_sample_t s, const char *attribute, int64_t *out);

/**
 * Reads a `String` attribute, lent while the sample lives.
 */
enum esgm_status esgm_sample_get_string(struct esgm_sample_t s,
                                        const char *attribute,
                                        struct esgm_str_t *out);

/**
 * Reads an `OctetSeq` attribute (an image's pixels): `len` bytes at `data`, in the
 * writer's shared memory where it was written there, valid while the sample lives.
 */
enum esgm_status esgm_sample_get_octets(struct esgm_sample_t s,
                                        const char *attribute,
                                        const uint8_t **data,
                                        size_t *len);

/**
 * Writes true to `out` if the `OctetSeq` attribute's bytes are read in place in
 * another process's shared memory (a held image), false if on this process's heap.
 */
enum esgm_status esgm_sample_octets_are_shared(struct esgm_sample_t s,
                                               const char *attribute,
                                               bool *out);

/**
 * Reads a `LongSeq` attribute: `len` integers at `data`, valid while the sample lives.
 */
enum esgm_status esgm_sample_get_long_seq(struct esgm_sample_t s,
                                          const char *attribute,
                                          const int64_t **data,
                                          size_t *len);

/**
 * Reads a `DoubleSeq` attribute: `len` floats at `data`, valid while the sample lives.
 */
enum esgm_status esgm_sample_get_double_seq(struct esgm_sample_t s,
                                            const char *attribute,
                                            const double **data,
                                            size_t *len);

/**
 * The `EntityFrame` attribute `attribute`, as a new handle (to free) that reads like
 * a sample.
 */
enum esgm_status esgm_sample_frame(struct esgm_sample_t s,
                                   const char *attribute,
                                   struct esgm_sample_t *out);

/**
 * Frame `index` of the `EntityFrameSeq` attribute `attribute` (its count is the
 * value's `len`), as a new handle (to free) that reads like a sample.
 */
enum esgm_status esgm_sample_frame_at(struct esgm_sample_t s,
                                      const char *attribute,
                                      size_t index,
                                      struct esgm_sample_t *out);

/**
 * The sample (or frame) as JSON, for printing: name, times and attributes (an image's
 * bytes as its length only), copied into `buf` as `esgm_stats_json` does.
 */
enum esgm_status esgm_sample_to_json(struct esgm_sample_t s,
                                     char *buf,
                                     size_t capacity,
                                     size_t *len);

/**
 * Another handle on the same sample (or frame), to free separately: keep an input of
 * a unit's callback beyond the call this way.
 */
enum esgm_status esgm_sample_clone(struct esgm_sample_t s, struct esgm_sample_t *out);

/**
 * Frees a sample's handle; its memory (an image's shared memory chunk) goes when no
 * handle or process holds it. Null is fine.
 */
enum esgm_status esgm_sample_free(struct esgm_sample_t s);

/**
 * The number of samples in `list`.
 */
enum esgm_status esgm_sample_list_len(struct esgm_sample_list_t list, size_t *out);

/**
 * Sample `index` of `list`, as a new handle to free.
 */
enum esgm_status esgm_sample_list_get(struct esgm_sample_list_t list,
                                      size_t index,
                                      struct esgm_sample_t *out);

/**
 * Frees a list (samples taken from it stay). Null is fine.
 */
enum esgm_status esgm_sample_list_free(struct esgm_sample_list_t list);

/**
 * Registers the sensor `name` producing structures of `type_name` (E6):
 * `get_current_value` is called at each sample time of every trajectory sampled from
 * it, with `user`, which `free_user` (may be null) releases once esgm calls it no
 * more. `ESGM_SENSOR_ALREADY_EXISTS` if the name is taken; then `user` is released at
 * once.
 */
enum esgm_status esgm_add_sensor_interface(struct esgm_t esgm,
                                           const char *name,
                                           const char *type_name,
                                           esgm_sensor_fn get_current_value,
                                           void *user,
                                           esgm_free_fn free_user);

/**
 * Removes the sensor `name` (E6); `ESGM_OPERATION_NOT_SUPPORTED` while a trajectory
 * samples it.
 */
enum esgm_status esgm_remove_sensor_interface(struct esgm_t esgm, const char *name);

/**
 * A loan of the sampled trajectory's memory for one `width` × `height` image of
 * `format` (an `esgm_image_format`), during a sensor's call: render the frame into
 * it and set it as the structure's image. Its shared memory on the shared-memory
 * runtime (never copied after), the heap otherwise.
 */
enum esgm_status esgm_sensor_image_loan(struct esgm_sensor_context_t context,
                                        int64_t width,
                                        int64_t height,
                                        int32_t format,
                                        struct esgm_image_loan_t *out);

/**
 * A spec of a primitive trajectory `name` of `type_name`, which programs add to (E2).
 */
enum esgm_status esgm_spec_primitive(const char *name,
                                     const char *type_name,
                                     struct esgm_spec_t *out);

/**
 * A spec of a trajectory `name` sampled from `sensor` every `sample_period` ns (E3),
 * from now on (`esgm_spec_between` bounds it).
 */
enum esgm_status esgm_spec_sampled(const char *name,
                                   const char *sensor,
                                   int64_t sample_period,
                                   struct esgm_spec_t *out);

/**
 * A spec of a trajectory `name` computed by the unit `unit` from the `n` trajectories
 * `inputs`, in the unit's order (E4).
 */
enum esgm_status esgm_spec_computed(const char *name,
                                    const char *unit,
                                    const char *const *inputs,
                                    size_t n,
                                    struct esgm_spec_t *out);

/**
 * A spec of a synchronized trajectory `name` (G2): states holding one sample of each
 * of the `n` `inputs` valid at the same time, as ROS message_filters match them.
 * `sync_policy` is `"exact"` (null: exact, or approximate when a tolerance is given),
 * `"approximate"` or `"epsilon"`; `tolerance_ns` is the largest difference of valid
 * times (negative: none, for exact); `queue_size` items are kept per input.
 */
enum esgm_status esgm_spec_sync(const char *name,
                                const char *const *inputs,
                                size_t n,
                                const char *sync_policy,
                                int64_t tolerance_ns,
                                size_t queue_size,
                                struct esgm_spec_t *out);

/**
 * A spec of a merged trajectory `name` (G3): every sample of the `n` `inputs` (of one
 * type), as they come.
 */
enum esgm_status esgm_spec_merge(const char *name,
                                 const char *const *inputs,
                                 size_t n,
                                 struct esgm_spec_t *out);

/**
 * A spec of a trajectory `name` sampled every `sample_period` ns from fluent
 * generators (G1, G4): each of the `n` `generators` is `"TRAJECTORY[:APPROXIMATION[:MERGE]]"`
 * (`"robot_state:linear"`; approximation none, closest, most-recent or linear; merge
 * keep-first, keep-last, average or median). One generator gives its values, several
 * their state, and with a `unit` (null for none) that unit's temporal function of
 * them (its `compute_at`).
 */
enum esgm_status esgm_spec_generated(const char *name,
                                     const char *const *generators,
                                     size_t n,
                                     int64_t sample_period,
                                     const char *unit,
                                     struct esgm_spec_t *out);

/**
 * Frees a spec. Null is fine.
 */
enum esgm_status esgm_spec_free(struct esgm_spec_t spec);

/**
 * A sampled or generated trajectory's start and end (valid times, ns; 0 = now and
 * forever, as the seed has them); also its duration constraint (C4).
 */
enum esgm_status esgm_spec_between(struct esgm_spec_t spec, int64_t from, int64_t to);

/**
 * A generated trajectory reads its generators `lag` ns before each sample time (so an
 * interpolation has a sample after the time it reads at).
 */
enum esgm_status esgm_spec_lag(struct esgm_spec_t spec, int64_t lag);

/**
 * C2: keep every sample.
 */
enum esgm_status esgm_spec_cache_all(struct esgm_spec_t spec);

/**
 * C2: keep the last `n` samples (0: every sample, as the seed's `cache_size`).
 */
enum esgm_status esgm_spec_cache_count(struct esgm_spec_t spec, size_t n);

/**
 * C2: keep the samples valid less than `span` ns before the newest.
 */
enum esgm_status esgm_spec_cache_duration(struct esgm_spec_t spec, int64_t span);

/**
 * C1: `change` is an `esgm_change`; `period` (ns) is for `ESGM_CHANGE_SAMPLE_EVERY`.
 */
enum esgm_status esgm_spec_change(struct esgm_spec_t spec, int32_t change, int64_t period);

/**
 * C3: a filter over attributes (`"size > 10 && x < 320"`), type-checked against the
 * trajectory's type when it is created (`ESGM_ILLEGAL_POLICY` names what is wrong).
 */
enum esgm_status esgm_spec_filter(struct esgm_spec_t spec, const char *expression);

/**
 * C4: valid times within `[from, to]` (0 = the creation time, and forever).
 */
enum esgm_status esgm_spec_duration(struct esgm_spec_t spec, int64_t from, int64_t to);

/**
 * C5: `order` is an `esgm_order`.
 */
enum esgm_status esgm_spec_order(struct esgm_spec_t spec, int32_t order);

/**
 * C6: at most `max_delay` ns from valid time to add time (0: any delay, as the
 * seed's); with a monotone order, late samples within it are held and released in
 * valid-time order unless `esgm_spec_reorder(spec, false)`.
 */
enum esgm_status esgm_spec_delay(struct esgm_spec_t spec, int64_t max_delay);

/**
 * C6: whether samples within the delay are held and reordered.
 */
enum esgm_status esgm_spec_reorder(struct esgm_spec_t spec, bool reorder);

/**
 * How many processes may read the trajectory at once (default: the domain's
 * `--readers`); a reader past it gets `ESGM_LIMIT_REACHED`.
 */
enum esgm_status esgm_spec_readers(struct esgm_spec_t spec, size_t readers);

/**
 * Re-points an existing name to the new trajectory (subscribers stay attached)
 * instead of failing with `ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS`.
 */
enum esgm_status esgm_spec_replace(struct esgm_spec_t spec, bool replace);

/**
 * Creates the trajectory `spec` describes (the spec stays, to free).
 */
enum esgm_status esgm_create_trajectory(struct esgm_t esgm,
                                        struct esgm_spec_t spec,
                                        struct esgm_trajectory_t *out);

/**
 * The seed's `create_primitive_entity_trajectory_structure(name, type_name)` (E2).
 */
enum esgm_status esgm_create_primitive_entity_trajectory_structure(struct esgm_t esgm,
                                                                   const char *name,
                                                                   const char *type_name,
                                                                   struct esgm_trajectory_t *out);

/**
 * The seed's `create_entity_trajectory_structure(name, sensor, from, to,
 * sample_period, delay, cache_size)` (E3): `sensor` pulled every `sample_period` ns
 * (from = 0: now; to = 0: forever; delay = 0: any; cache_size = 0: all);
 * `ESGM_ILLEGAL_POLICY` for a nonsensical policy.
 */
enum esgm_status esgm_create_entity_trajectory_structure(struct esgm_t esgm,
                                                         const char *name,
                                                         const char *sensor,
                                                         int64_t from,
                                                         int64_t to,
                                                         int64_t sample_period,
                                                         int64_t delay,
                                                         int64_t cache_size,
                                                         struct esgm_trajectory_t *out);

/**
 * The seed's `create_computed_entity_trajectory_structure(name, cu, inputs)` (E4):
 * the unit `cu` runs on every update of any of the `n` `inputs`, with the latest
 * sample of each, in this order.
 */
enum esgm_status esgm_create_computed_entity_trajectory_structure(struct esgm_t esgm,
                                                                  const char *name,
                                                                  const char *cu,
                                                                  const char *const *inputs,
                                                                  size_t n,
                                                                  struct esgm_trajectory_t *out);

/**
 * The message of the last call that failed on this thread: what was wrong, with the
 * name that was wrong (`no entity trajectory structure `robt``). Empty if none
 * failed. The text stays valid until the next failing call on this thread; copy it
 * to keep it.
 */
const char *esgm_last_error_message(void);

/**
 * The name of a status (`"ESGM_POLICY_VIOLATION"`), a static string; an unknown value
 * gives `"ESGM_UNKNOWN_STATUS"`.
 */
const char *esgm_status_name(int32_t status);

/**
 * Sets this thread's last error message: a unit or sensor callback that fails says
 * why here before it returns its status, and esgm logs and counts that reason. A null
 * `message` clears it.
 */
void esgm_set_last_error_message(const char *message);

/**
 * A new structure `name`, valid at `valid_time` and created at `create_time`
 * (nanoseconds; `esgm_now()` for now), without attributes yet.
 */
enum esgm_status esgm_structure_new(const char *name,
                                    int64_t valid_time,
                                    int64_t create_time,
                                    struct esgm_structure_t *out);

/**
 * A new frame `name` to nest in a structure (`esgm_structure_set_frame`,
 * `esgm_structure_push_frame`): a structure whose times are not used.
 */
enum esgm_status esgm_frame_new(const char *name, struct esgm_structure_t *out);

/**
 * Frees a structure not handed to esgm. Null is fine.
 */
enum esgm_status esgm_structure_free(struct esgm_structure_t s);

/**
 * Renames the structure.
 */
enum esgm_status esgm_structure_set_name(struct esgm_structure_t s, const char *name);

/**
 * Sets its valid and create times (nanoseconds).
 */
enum esgm_status esgm_structure_set_times(struct esgm_structure_t s,
                                          int64_t valid_time,
                                          int64_t create_time);

/**
 * Sets a `Long` attribute.
 */
enum esgm_status esgm_structure_set_long(struct esgm_structure_t s,
                                         const char *attribute,
                                         int64_t value);

/**
 * Sets a `Double` attribute.
 */
enum esgm_status esgm_structure_set_double(struct esgm_structure_t s,
                                           const char *attribute,
                                           double value);

/**
 * Sets a `Bool` attribute.
 */
enum esgm_status esgm_structure_set_bool(struct esgm_structure_t s,
                                         const char *attribute,
                                         bool value);

/**
 * Sets a `Time` attribute (nanoseconds).
 */
enum esgm_status esgm_structure_set_time(struct esgm_structure_t s,
                                         const char *attribute,
                                         int64_t value);

/**
 * Sets an `Altitude` attribute (metres).
 */
enum esgm_status esgm_structure_set_altitude(struct esgm_structure_t s,
                                             const char *attribute,
                                             double value);

/**
 * Sets a `String` attribute (UTF-8, copied).
 */
enum esgm_status esgm_structure_set_string(struct esgm_structure_t s,
                                           const char *attribute,
                                           const char *value);

/**
 * Sets a `Symbol` attribute (UTF-8, copied).
 */
enum esgm_status esgm_structure_set_symbol(struct esgm_structure_t s,
                                           const char *attribute,
                                           const char *value);

/**
 * Sets an `OctetSeq` attribute to a copy of `len` bytes at `data`. An image to be
 * read in place by other processes is written into a loan instead
 * (`esgm_structure_set_image`), which is not copied.
 */
enum esgm_status esgm_structure_set_octets(struct esgm_structure_t s,
                                           const char *attribute,
                                           const uint8_t *data,
                                           size_t len);

/**
 * Sets an `OctetSeq` attribute to the pixels written into `loan`, which it takes:
 * the pixels are handed over where they are (the trajectory's shared memory), never
 * copied; the loan's handle is freed.
 */
enum esgm_status esgm_structure_set_image(struct esgm_structure_t s,
                                          const char *attribute,
                                          struct esgm_image_loan_t loan);

/**
 * Sets a `LongSeq` attribute to a copy of `n` integers at `values`.
 */
enum esgm_status esgm_structure_set_long_seq(struct esgm_structure_t s,
                                             const char *attribute,
                                             const int64_t *values,
                                             size_t n);

/**
 * Sets a `DoubleSeq` attribute to a copy of `n` floats at `values`.
 */
enum esgm_status esgm_structure_set_double_seq(struct esgm_structure_t s,
                                               const char *attribute,
                                               const double *values,
                                               size_t n);

/**
 * Sets a `SymbolSeq` attribute to copies of `n` strings at `values`.
 */
enum esgm_status esgm_structure_set_symbol_seq(struct esgm_structure_t s,
                                               const char *attribute,
                                               const char *const *values,
                                               size_t n);

/**
 * Sets a `Vec` attribute.
 */
enum esgm_status esgm_structure_set_vec(struct esgm_structure_t s,
                                        const char *attribute,
                                        struct esgm_vec3_t value);

/**
 * Sets a `VecSeq` attribute to a copy of `n` vectors at `values`.
 */
enum esgm_status esgm_structure_set_vec_seq(struct esgm_structure_t s,
                                            const char *attribute,
                                            const struct esgm_vec3_t *values,
                                            size_t n);

/**
 * Sets a `Pos2` attribute.
 */
enum esgm_status esgm_structure_set_pos2(struct esgm_structure_t s,
                                         const char *attribute,
                                         struct esgm_pos2_t value);

/**
 * Sets a `Pos2Seq` attribute to a copy of `n` points at `values`.
 */
enum esgm_status esgm_structure_set_pos2_seq(struct esgm_structure_t s,
                                             const char *attribute,
                                             const struct esgm_pos2_t *values,
                                             size_t n);

/**
 * Sets a `Position` attribute.
 */
enum esgm_status esgm_structure_set_position(struct esgm_structure_t s,
                                             const char *attribute,
                                             struct esgm_position_t value);

/**
 * Sets a `Rotation` attribute.
 */
enum esgm_status esgm_structure_set_rotation(struct esgm_structure_t s,
                                             const char *attribute,
                                             struct esgm_rotation_t value);

/**
 * Sets a `PositionAltitude` attribute.
 */
enum esgm_status esgm_structure_set_position_altitude(struct esgm_structure_t s,
                                                      const char *attribute,
                                                      struct esgm_position_altitude_t value);

/**
 * Sets a `PositionAltitudeRotation` attribute (a pose).
 */
enum esgm_status esgm_structure_set_pose(struct esgm_structure_t s,
                                         const char *attribute,
                                         struct esgm_pose_t value);

/**
 * Sets an attribute to no value (`NoValue`).
 */
enum esgm_status esgm_structure_set_no_value(struct esgm_structure_t s, const char *attribute);

/**
 * Sets an attribute of any sort from esgm's JSON form of a value (`{"Long": 5}`,
 * `{"Agg": [{"Double": 1.5}, {"String": "a"}]}`): the way to set `Agg` and
 * `Collection` values, which have no typed setter.
 */
enum esgm_status esgm_structure_set_json(struct esgm_structure_t s,
                                         const char *attribute,
                                         const char *json);

/**
 * Sets an `EntityFrame` attribute to `frame` (made with `esgm_frame_new`), which it
 * takes.
 */
enum esgm_status esgm_structure_set_frame(struct esgm_structure_t s,
                                          const char *attribute,
                                          struct esgm_structure_t frame);

/**
 * Appends `frame` (which it takes) to the `EntityFrameSeq` attribute `attribute`,
 * which a first push creates; an attribute of another sort is `ESGM_INVALID_TYPE`.
 */
enum esgm_status esgm_structure_push_frame(struct esgm_structure_t s,
                                           const char *attribute,
                                           struct esgm_structure_t frame);

/**
 * Sets an `EntityFrameSeq` attribute to the empty sequence (a `BlobSeq` of no blobs).
 */
enum esgm_status esgm_structure_set_empty_frame_seq(struct esgm_structure_t s,
                                                    const char *attribute);

/**
 * T3: subscribes to `t`: every structure added from now on, after the last `last`
 * it holds (0: none), kept in a queue of `queue` samples (0: 64) for a slow reader;
 * what overflows it is counted (`esgm_subscription_overflowed`).
 */
enum esgm_status esgm_subscribe(struct esgm_trajectory_t t,
                                size_t queue,
                                size_t last,
                                struct esgm_subscription_t *out);

/**
 * The next structure, waiting at most `timeout_ns` (0: only what is there; negative:
 * for ever): `ESGM_TIMEOUT` when none came, `ESGM_CLOSED` when the trajectory was
 * destroyed or the ESGM freed.
 */
enum esgm_status esgm_subscription_recv(struct esgm_subscription_t sub,
                                        int64_t timeout_ns,
                                        struct esgm_sample_t *out);

/**
 * The samples this subscription missed because its queue was full.
 */
enum esgm_status esgm_subscription_overflowed(struct esgm_subscription_t sub, uint64_t *out);

/**
 * T3 (`unsubscribe`): ends the subscription and frees its handle. Null is fine.
 */
enum esgm_status esgm_unsubscribe(struct esgm_subscription_t sub);

/**
 * C7: subscribes to the policy violations of `t` from now on, kept in a queue of
 * `queue` (0: 64).
 */
enum esgm_status esgm_subscribe_violations(struct esgm_trajectory_t t,
                                           size_t queue,
                                           struct esgm_violations_t *out);

/**
 * The next violation, waiting as `esgm_subscription_recv` does.
 */
enum esgm_status esgm_violations_recv(struct esgm_violations_t sub,
                                      int64_t timeout_ns,
                                      struct esgm_violation_t *out);

/**
 * Ends a violations subscription and frees its handle. Null is fine.
 */
enum esgm_status esgm_violations_free(struct esgm_violations_t sub);

/**
 * What the violation `v` says.
 */
enum esgm_status esgm_violation_info(struct esgm_violation_t v, struct esgm_violation_info_t *out);

/**
 * Frees a violation. Null is fine.
 */
enum esgm_status esgm_violation_free(struct esgm_violation_t v);

/**
 * A handle on the trajectory `name` (E5); `ESGM_NO_SUCH_ENTITY_STRUCTURE` if there is
 * none (the message names the closest name there is).
 */
enum esgm_status esgm_get_entity_trajectory_structure(struct esgm_t esgm,
                                                      const char *name,
                                                      struct esgm_trajectory_t *out);

/**
 * The type of the trajectory `name` (E5), as a new handle to free.
 */
enum esgm_status esgm_get_entity_trajectory_structure_type(struct esgm_t esgm,
                                                           const char *name,
                                                           struct esgm_type_t *out);

/**
 * Destroys the trajectory `name` (E5): its name can be reused; handles on it fail
 * with `ESGM_NO_SUCH_ENTITY_STRUCTURE` and its subscriptions end.
 */
enum esgm_status esgm_destroy_entity_trajectory_structure(struct esgm_t esgm, const char *name);

/**
 * Every trajectory of the system as JSON (name, kind, type, inputs, source, where it
 * is written), copied into `buf` as `esgm_stats_json` does.
 */
enum esgm_status esgm_trajectories_json(struct esgm_t esgm,
                                        char *buf,
                                        size_t capacity,
                                        size_t *len);

/**
 * Frees a trajectory handle (the trajectory stays). Null is fine.
 */
enum esgm_status esgm_trajectory_free(struct esgm_trajectory_t t);

/**
 * Another handle on the same trajectory, to free separately.
 */
enum esgm_status esgm_trajectory_clone(struct esgm_trajectory_t t, struct esgm_trajectory_t *out);

/**
 * The trajectory's name (`name`), valid while the handle lives.
 */
enum esgm_status esgm_trajectory_name(struct esgm_trajectory_t t, struct esgm_str_t *out);

/**
 * Its type (`type`), as a new handle to free.
 */
enum esgm_status esgm_trajectory_type(struct esgm_trajectory_t t, struct esgm_type_t *out);

/**
 * Its policy (`pol`: change, cache, filter, duration, order, delay, reorder) as JSON,
 * copied into `buf` as `esgm_stats_json` does.
 */
enum esgm_status esgm_trajectory_policy_json(struct esgm_trajectory_t t,
                                             char *buf,
                                             size_t capacity,
                                             size_t *len);

/**
 * The earliest valid time it holds (`start_time`); `ESGM_VALUE_NOT_AVAILABLE` when
 * empty.
 */
enum esgm_status esgm_trajectory_start_time(struct esgm_trajectory_t t, int64_t *out);

/**
 * The latest valid time it holds (`end_time`); `ESGM_VALUE_NOT_AVAILABLE` when empty.
 */
enum esgm_status esgm_trajectory_end_time(struct esgm_trajectory_t t, int64_t *out);

/**
 * Empties the trajectory (T5), in its writer and every reader; returns before they
 * all have.
 */
enum esgm_status esgm_trajectory_reset(struct esgm_trajectory_t t);

/**
 * Empties the trajectory (T5) and returns once its writer and every connected reader
 * have forgotten it.
 */
enum esgm_status esgm_trajectory_reset_blocking(struct esgm_trajectory_t t);

/**
 * Writes its main statistics to `out`.
 */
enum esgm_status esgm_trajectory_stats(struct esgm_trajectory_t t,
                                       struct esgm_trajectory_stats_t *out);

/**
 * Its statistics as JSON (drops by cause among them), copied into `buf` as
 * `esgm_stats_json` does.
 */
enum esgm_status esgm_trajectory_stats_json(struct esgm_trajectory_t t,
                                            char *buf,
                                            size_t capacity,
                                            size_t *len);

/**
 * A loan of the trajectory's own memory for one `width` × `height` image of `format`
 * (an `esgm_image_format`): its shared memory when this process writes it and other
 * processes read it, so the frame written there is never copied; else the heap.
 */
enum esgm_status esgm_trajectory_image_loan(struct esgm_trajectory_t t,
                                            int64_t width,
                                            int64_t height,
                                            int32_t format,
                                            struct esgm_image_loan_t *out);

/**
 * A new type called `name`, without attributes yet.
 */
enum esgm_status esgm_type_new(const char *name, struct esgm_type_t *out);

/**
 * Adds the attribute `name` of `sort` (an `esgm_sort`) to `t`; a frame or frame
 * sequence names the registered type of its elements in `element_type` (null for
 * every other sort). A name already in the type, or a frame without its element type,
 * is `ESGM_INVALID_TYPE`.
 */
enum esgm_status esgm_type_add_attribute(struct esgm_type_t t,
                                         const char *name,
                                         int32_t sort,
                                         const char *element_type);

/**
 * Frees a type's handle (a registered type stays registered). Null is fine.
 */
enum esgm_status esgm_type_free(struct esgm_type_t t);

/**
 * The type's name, valid while its handle lives.
 */
enum esgm_status esgm_type_name(struct esgm_type_t t, struct esgm_str_t *out);

/**
 * The number of attributes of `t`.
 */
enum esgm_status esgm_type_attribute_count(struct esgm_type_t t, size_t *out);

/**
 * The attribute at `index` (in declaration order) of `t`.
 */
enum esgm_status esgm_type_attribute(struct esgm_type_t t,
                                     size_t index,
                                     struct esgm_attribute_t *out);

/**
 * Registers `t` under `type_name` (E1; the IDL's form, where the registered name may
 * differ from the type's own). `ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS` when the
 * name is taken by another definition.
 */
enum esgm_status esgm_create_entity_structure_type(struct esgm_t esgm,
                                                   const char *type_name,
                                                   struct esgm_type_t t);

/**
 * Registers `t` under its own name.
 */
enum esgm_status esgm_create_type(struct esgm_t esgm, struct esgm_type_t t);

/**
 * Removes the type `type_name` (existing trajectories keep theirs).
 */
enum esgm_status esgm_destroy_entity_structure_type(struct esgm_t esgm, const char *type_name);

/**
 * The registered type `type_name`, as a new handle to free.
 */
enum esgm_status esgm_get_entity_structure_type(struct esgm_t esgm,
                                                const char *type_name,
                                                struct esgm_type_t *out);

/**
 * The registered types' names as a JSON array, copied into `buf` as
 * `esgm_stats_json` does.
 */
enum esgm_status esgm_entity_structure_type_names_json(struct esgm_t esgm,
                                                       char *buf,
                                                       size_t capacity,
                                                       size_t *len);

/**
 * Registers the computational unit `name` (E6): it produces structures of
 * `type_name` from `n` inputs whose types are `input_types` (type names;
 * `"EntityFrame"` accepts any structure, as the seed's `ENTITY_FRAME_TYPE`).
 * `compute` is called on every update of an input of a trajectory computed by it;
 * `compute_at` (may be null) answers a generated trajectory's temporal function.
 * Both get `user`, which `free_user` (may be null) releases once esgm calls neither
 * any more (the unit removed, or its ESGM freed). `ESGM_COMP_UNIT_ALREADY_EXISTS` if
 * the name is taken; then `user` is released at once.
 */
enum esgm_status esgm_add_comp_unit(struct esgm_t esgm,
                                    const char *name,
                                    const char *type_name,
                                    const char *const *input_types,
                                    size_t n,
                                    esgm_compute_fn compute,
                                    esgm_compute_fn compute_at,
                                    void *user,
                                    esgm_free_fn free_user);

/**
 * Removes the unit `name` (E6); `ESGM_OPERATION_NOT_SUPPORTED` while a trajectory
 * uses it. Its user pointer is released once esgm calls it no more.
 */
enum esgm_status esgm_remove_comp_unit(struct esgm_t esgm, const char *name);

/**
 * Sets `n` attributes of the structure `s` from `values` at once (frames and loans in
 * them are taken).
 */
enum esgm_status esgm_structure_set_values(struct esgm_structure_t s,
                                           const struct esgm_value_t *values,
                                           size_t n);

/**
 * T4 in one call: adds a structure `name`, valid at `valid_time` and created at
 * `create_time`, with the `n` attributes `values` (frames and loans in them taken),
 * to `t`; a policy violation drops it (`ESGM_OUTCOME_DROPPED`). `outcome` may be null.
 */
enum esgm_status esgm_add_values(struct esgm_trajectory_t t,
                                 const char *name,
                                 int64_t valid_time,
                                 int64_t create_time,
                                 const struct esgm_value_t *values,
                                 size_t n,
                                 int32_t *outcome);

/**
 * `esgm_add_values`, waiting for the writer's gate: `ESGM_POLICY_VIOLATION` if it
 * refused the structure.
 */
enum esgm_status esgm_add_values_blocking(struct esgm_trajectory_t t,
                                          const char *name,
                                          int64_t valid_time,
                                          int64_t create_time,
                                          const struct esgm_value_t *values,
                                          size_t n,
                                          int32_t *outcome);

/**
 * Reads every attribute of the sample (or frame) `s` at once into `out`, which has
 * room for `capacity` values (read-only views, valid while `s` lives); `count` gets
 * the number of attributes (more than `capacity` when some did not fit).
 */
enum esgm_status esgm_sample_values(struct esgm_sample_t s,
                                    struct esgm_value_t *out,
                                    size_t capacity,
                                    size_t *count);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* ESGM_H */

/* esgm.h ends here. */
