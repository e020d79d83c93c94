// esgm.hpp: esgm for C++17, header-only, over esgm's C ABI (<esgm.h>).
//
// The seed's operations keep their names (create_primitive_entity_trajectory_structure,
// get_latest, get_between, add_comp_unit, ...); what C++ adds on top:
//   - RAII handles (Esgm, Trajectory, Sample, Structure, Subscription, ImageLoan, ...);
//   - exceptions carrying the IDL's error (esgm::NoSuchEntityStructure,
//     esgm::PolicyViolation, esgm::ValueNotAvailable, ...), all esgm::Error;
//   - typed structures: a plain struct and one macro, ESGM_ENTITY(Type, "Name", fields...);
//   - range-for over a subscription;
//   - lambdas or classes as computational units and sensors;
//   - esgm::Span views of images and sequences, read in place (no copy).
//
//   #include <esgm/esgm.hpp>
//   auto esgm = esgm::Esgm::connect("lab");             // or esgm::Esgm::in_process()
//   auto robot_state = esgm.create_primitive_entity_trajectory_structure("robot_state", "RobotState");
//   robot_state.create_at_now("robot1", esgm::Structure().set("x", 1.0).set("y", 2.0).set("dir", 3.0));
//   for (const esgm::Sample& s : robot_state.subscribe()) { std::cout << s.get<double>("x"); }
//
// Link with esgm::esgm (CMake: find_package(esgm CONFIG REQUIRED)) or `pkg-config esgm`.
#ifndef ESGM_ESGM_HPP
#define ESGM_ESGM_HPP

#include <esgm.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <algorithm>
#include <cstdlib>
#include <functional>
#include <iterator>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace esgm {

// ---------------------------------------------------------------------------------
// Time

/// A time-point or span: nanoseconds on the host's one timeline.
using Time = std::int64_t;

/// Now, as every process of a system stamps it.
inline Time now() noexcept { return esgm_now(); }
/// `n` microseconds.
constexpr Time microseconds(std::int64_t n) noexcept { return n * ESGM_MICROSECOND; }
/// `n` milliseconds.
constexpr Time milliseconds(std::int64_t n) noexcept { return n * ESGM_MILLISECOND; }
/// `n` seconds.
constexpr Time seconds(std::int64_t n) noexcept { return n * ESGM_SECOND; }
/// A std::chrono duration in esgm's unit.
template <class Rep, class Period>
constexpr Time to_time(std::chrono::duration<Rep, Period> d) noexcept {
    return static_cast<Time>(std::chrono::duration_cast<std::chrono::nanoseconds>(d).count());
}
/// The seed's TIMEUNITS_PER_SECOND.
constexpr Time TIMEUNITS_PER_SECOND = ESGM_TIMEUNITS_PER_SECOND;
/// The seed's TIMEUNITS_PER_MILLI_SECOND.
constexpr Time TIMEUNITS_PER_MILLI_SECOND = ESGM_TIMEUNITS_PER_MILLI_SECOND;

// ---------------------------------------------------------------------------------
// Errors: one class per IDL exception (and per C status), all esgm::Error.

/// Every esgm error: what() is the message with the name that was wrong.
class Error : public std::runtime_error {
public:
    Error(esgm_status status, const std::string& message)
        : std::runtime_error(message), status_(status) {}
    /// The C status.
    esgm_status status() const noexcept { return status_; }
    /// The status's name ("ESGM_POLICY_VIOLATION").
    const char* status_name() const noexcept { return esgm_status_name(status_); }

private:
    esgm_status status_;
};

#define ESGM_ERROR_CLASS(Name, Status)                                                  \
    class Name : public Error {                                                         \
    public:                                                                             \
        explicit Name(const std::string& message = #Name) : Error(Status, message) {}  \
    }
ESGM_ERROR_CLASS(ValueNotAvailable, ESGM_VALUE_NOT_AVAILABLE);
ESGM_ERROR_CLASS(NoSuchEntityStructure, ESGM_NO_SUCH_ENTITY_STRUCTURE);
ESGM_ERROR_CLASS(NoSuchEntityStructureType, ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE);
ESGM_ERROR_CLASS(EntityStructureAlreadyExists, ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS);
ESGM_ERROR_CLASS(EntityStructureTypeAlreadyExists, ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS);
ESGM_ERROR_CLASS(NoSuchSensor, ESGM_NO_SUCH_SENSOR);
ESGM_ERROR_CLASS(NoSuchCompUnit, ESGM_NO_SUCH_COMP_UNIT);
ESGM_ERROR_CLASS(SensorAlreadyExists, ESGM_SENSOR_ALREADY_EXISTS);
ESGM_ERROR_CLASS(CompUnitAlreadyExists, ESGM_COMP_UNIT_ALREADY_EXISTS);
ESGM_ERROR_CLASS(PolicyViolation, ESGM_POLICY_VIOLATION);
ESGM_ERROR_CLASS(IllegalPolicy, ESGM_ILLEGAL_POLICY);
ESGM_ERROR_CLASS(InvalidType, ESGM_INVALID_TYPE);
ESGM_ERROR_CLASS(OperationNotSupported, ESGM_OPERATION_NOT_SUPPORTED);
ESGM_ERROR_CLASS(LimitReached, ESGM_LIMIT_REACHED);
ESGM_ERROR_CLASS(WriterGone, ESGM_WRITER_GONE);
ESGM_ERROR_CLASS(Unavailable, ESGM_UNAVAILABLE);
ESGM_ERROR_CLASS(Timeout, ESGM_TIMEOUT);
ESGM_ERROR_CLASS(NoSuchAttribute, ESGM_NO_SUCH_ATTRIBUTE);
ESGM_ERROR_CLASS(InvalidHandle, ESGM_INVALID_HANDLE);
ESGM_ERROR_CLASS(InvalidArgument, ESGM_INVALID_ARGUMENT);
ESGM_ERROR_CLASS(OutOfRange, ESGM_OUT_OF_RANGE);
ESGM_ERROR_CLASS(Closed, ESGM_CLOSED);
ESGM_ERROR_CLASS(Internal, ESGM_INTERNAL);
#undef ESGM_ERROR_CLASS

namespace detail {

/// Throws the exception of `status`, with this thread's last message.
[[noreturn]] inline void raise(esgm_status status) {
    const std::string m = esgm_last_error_message();
    switch (status) {
    case ESGM_VALUE_NOT_AVAILABLE: throw ValueNotAvailable(m);
    case ESGM_NO_SUCH_ENTITY_STRUCTURE: throw NoSuchEntityStructure(m);
    case ESGM_NO_SUCH_ENTITY_STRUCTURE_TYPE: throw NoSuchEntityStructureType(m);
    case ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS: throw EntityStructureAlreadyExists(m);
    case ESGM_ENTITY_STRUCTURE_TYPE_ALREADY_EXISTS: throw EntityStructureTypeAlreadyExists(m);
    case ESGM_NO_SUCH_SENSOR: throw NoSuchSensor(m);
    case ESGM_NO_SUCH_COMP_UNIT: throw NoSuchCompUnit(m);
    case ESGM_SENSOR_ALREADY_EXISTS: throw SensorAlreadyExists(m);
    case ESGM_COMP_UNIT_ALREADY_EXISTS: throw CompUnitAlreadyExists(m);
    case ESGM_POLICY_VIOLATION: throw PolicyViolation(m);
    case ESGM_ILLEGAL_POLICY: throw IllegalPolicy(m);
    case ESGM_INVALID_TYPE: throw InvalidType(m);
    case ESGM_OPERATION_NOT_SUPPORTED: throw OperationNotSupported(m);
    case ESGM_LIMIT_REACHED: throw LimitReached(m);
    case ESGM_WRITER_GONE: throw WriterGone(m);
    case ESGM_UNAVAILABLE: throw Unavailable(m);
    case ESGM_TIMEOUT: throw Timeout(m);
    case ESGM_NO_SUCH_ATTRIBUTE: throw NoSuchAttribute(m);
    case ESGM_INVALID_HANDLE: throw InvalidHandle(m);
    case ESGM_INVALID_ARGUMENT: throw InvalidArgument(m);
    case ESGM_OUT_OF_RANGE: throw OutOfRange(m);
    case ESGM_CLOSED: throw Closed(m);
    case ESGM_INTERNAL: throw Internal(m);
    case ESGM_OK:
    case ESGM_ERROR:
    default: throw Error(status, m);
    }
}

/// Throws unless `status` is ESGM_OK.
inline void check(esgm_status status) {
    if (status != ESGM_OK) {
        raise(status);
    }
}

/// A NUL-terminated copy of a view, for the C ABI.
inline std::string z(std::string_view s) { return std::string(s); }

/// Text lent by the C ABI as a view.
inline std::string_view view(esgm_str_t s) noexcept { return std::string_view(s.ptr, s.len); }

/// Reads text the C ABI copies into a caller's buffer (it says how long it is first).
template <class F>
std::string copied(F&& fill) {
    size_t len = 0;
    check(fill(nullptr, 0, &len));
    std::string text(len + 1, '\0');
    check(fill(text.data(), text.size(), &len));
    text.resize(len);
    return text;
}

/// A move-only owner of a C handle, freed by `Free` when it goes.
template <class H, esgm_status (*Free)(H)>
class Owned {
public:
    Owned() noexcept = default;
    explicit Owned(H h) noexcept : h_(h) {}
    Owned(const Owned&) = delete;
    Owned& operator=(const Owned&) = delete;
    Owned(Owned&& o) noexcept : h_(o.release()) {}
    Owned& operator=(Owned&& o) noexcept {
        if (this != &o) {
            reset();
            h_ = o.release();
        }
        return *this;
    }
    ~Owned() { reset(); }
    /// The handle, still owned.
    H get() const noexcept { return h_; }
    /// The handle, no longer owned (the C call that takes it frees it).
    H release() noexcept {
        H h = h_;
        h_ = H{};
        return h;
    }
    /// Frees the handle now.
    void reset() noexcept {
        if (h_.id != 0) {
            // Freeing a handle this object owns cannot fail but for a bug elsewhere; a
            // destructor has nobody to tell.
            (void)Free(h_);
            h_ = H{};
        }
    }
    explicit operator bool() const noexcept { return h_.id != 0; }

private:
    H h_{};
};

}  // namespace detail

// ---------------------------------------------------------------------------------
// Views

/// A view of `size()` items at `data()`, read in place (C++20's std::span, for C++17).
template <class T>
class Span {
public:
    constexpr Span() noexcept = default;
    constexpr Span(T* data, std::size_t size) noexcept : data_(data), size_(size) {}
    constexpr T* data() const noexcept { return data_; }
    constexpr std::size_t size() const noexcept { return size_; }
    constexpr std::size_t size_bytes() const noexcept { return size_ * sizeof(T); }
    constexpr bool empty() const noexcept { return size_ == 0; }
    constexpr T* begin() const noexcept { return data_; }
    constexpr T* end() const noexcept { return data_ + size_; }
    constexpr T& operator[](std::size_t i) const noexcept { return data_[i]; }
    /// Item `i`, or OutOfRange.
    T& at(std::size_t i) const {
        if (i >= size_) {
            throw OutOfRange("index " + std::to_string(i) + " of a span of " +
                             std::to_string(size_));
        }
        return data_[i];
    }

private:
    T* data_ = nullptr;
    std::size_t size_ = 0;
};

/// The sorts of values (the seed's ValueSort).
enum class Sort : std::int32_t {
    NoValue = ESGM_SORT_NO_VALUE,
    Long = ESGM_SORT_LONG,
    Double = ESGM_SORT_DOUBLE,
    Bool = ESGM_SORT_BOOL,
    String = ESGM_SORT_STRING,
    Time = ESGM_SORT_TIME,
    Symbol = ESGM_SORT_SYMBOL,
    OctetSeq = ESGM_SORT_OCTET_SEQ,
    LongSeq = ESGM_SORT_LONG_SEQ,
    DoubleSeq = ESGM_SORT_DOUBLE_SEQ,
    SymbolSeq = ESGM_SORT_SYMBOL_SEQ,
    Vec = ESGM_SORT_VEC,
    VecSeq = ESGM_SORT_VEC_SEQ,
    Pos2 = ESGM_SORT_POS2,
    Pos2Seq = ESGM_SORT_POS2_SEQ,
    Position = ESGM_SORT_POSITION,
    Altitude = ESGM_SORT_ALTITUDE,
    Rotation = ESGM_SORT_ROTATION,
    PositionAltitude = ESGM_SORT_POSITION_ALTITUDE,
    PositionAltitudeRotation = ESGM_SORT_POSITION_ALTITUDE_ROTATION,
    Agg = ESGM_SORT_AGG,
    Collection = ESGM_SORT_COLLECTION,
    EntityFrame = ESGM_SORT_ENTITY_FRAME,
    EntityFrameSeq = ESGM_SORT_ENTITY_FRAME_SEQ,
    AnyValue = ESGM_SORT_ANY_VALUE,
    UnknownValue = ESGM_SORT_UNKNOWN_VALUE,
};

/// A 3-D vector.
using Vec3 = esgm_vec3_t;
/// A 2-D point.
using Pos2 = esgm_pos2_t;
/// A horizontal world position.
using Position = esgm_position_t;
/// Roll, pitch, yaw.
using Rotation = esgm_rotation_t;
/// A position with an altitude.
using PositionAltitude = esgm_position_altitude_t;
/// A full pose.
using Pose = esgm_pose_t;

/// A symbol (a name of something in the system), to set a Symbol attribute.
struct Symbol {
    std::string name;
};
/// A time-point, to set a Time attribute (a plain integer is a Long).
struct TimePoint {
    Time t;
};
/// An altitude in metres, to set an Altitude attribute (a plain double is a Double).
struct Altitude {
    double metres;
};

/// The image formats of loans.
enum class ImageFormat : std::int32_t { Rgb8 = ESGM_IMAGE_RGB8, Mono8 = ESGM_IMAGE_MONO8 };

// ---------------------------------------------------------------------------------
// Types

/// One attribute of a type.
struct Attribute {
    std::string name;
    Sort sort;
    /// For frames and frame sequences, the type of their elements.
    std::string element_type;
};

/// An entity structure type (E1): a name and typed attributes.
class Type {
public:
    /// A type called `name`, without attributes yet.
    explicit Type(std::string name) : name_(std::move(name)) {}
    /// Adds an attribute of `sort`.
    Type& attr(std::string name, Sort sort) {
        attributes_.push_back({std::move(name), sort, {}});
        return *this;
    }
    /// Adds a nested frame of type `element_type`.
    Type& frame(std::string name, std::string element_type) {
        attributes_.push_back({std::move(name), Sort::EntityFrame, std::move(element_type)});
        return *this;
    }
    /// Adds a sequence of frames of type `element_type`.
    Type& frame_seq(std::string name, std::string element_type) {
        attributes_.push_back(
            {std::move(name), Sort::EntityFrameSeq, std::move(element_type)});
        return *this;
    }
    const std::string& name() const noexcept { return name_; }
    const std::vector<Attribute>& attributes() const noexcept { return attributes_; }

    /// The type as a C handle (to free).
    detail::Owned<esgm_type_t, esgm_type_free> to_c() const {
        esgm_type_t t{};
        detail::check(esgm_type_new(name_.c_str(), &t));
        detail::Owned<esgm_type_t, esgm_type_free> owned(t);
        for (const Attribute& a : attributes_) {
            detail::check(esgm_type_add_attribute(
                t, a.name.c_str(), static_cast<std::int32_t>(a.sort),
                a.element_type.empty() ? nullptr : a.element_type.c_str()));
        }
        return owned;
    }

    /// A type read from a C handle.
    static Type from_c(esgm_type_t t) {
        esgm_str_t name{};
        detail::check(esgm_type_name(t, &name));
        Type type{std::string(detail::view(name))};
        size_t n = 0;
        detail::check(esgm_type_attribute_count(t, &n));
        for (size_t i = 0; i < n; i++) {
            esgm_attribute_t a{};
            detail::check(esgm_type_attribute(t, i, &a));
            type.attributes_.push_back({std::string(detail::view(a.name)),
                                        static_cast<Sort>(a.sort),
                                        std::string(detail::view(a.element_type))});
        }
        return type;
    }

private:
    std::string name_;
    std::vector<Attribute> attributes_;
};

// ---------------------------------------------------------------------------------
// Image loans

/// A writable buffer for one image's pixels in a trajectory's shared memory: write the
/// frame into pixels(), then set it as a structure's image (Structure::set_image),
/// which hands the pixels over where they are.
class ImageLoan {
public:
    explicit ImageLoan(esgm_image_loan_t h) : h_(h) {}
    /// The pixels to write, row by row.
    Span<std::uint8_t> pixels() const {
        std::uint8_t* data = nullptr;
        size_t len = 0;
        detail::check(esgm_image_loan_pixels(h_.get(), &data, &len));
        return {data, len};
    }
    /// True if the pixels are in shared memory (read in place by other processes).
    bool shared() const {
        bool s = false;
        detail::check(esgm_image_loan_is_shared(h_.get(), &s));
        return s;
    }
    esgm_image_loan_t release() noexcept { return h_.release(); }

private:
    detail::Owned<esgm_image_loan_t, esgm_image_loan_free> h_;
};

// ---------------------------------------------------------------------------------
// Structures (to add)

template <class T>
struct Entity;  // specialised by ESGM_ENTITY for typed structs

namespace detail {
class ValueList;
}

/// An entity structure (or nested frame) being built: set attributes, then add it to
/// a trajectory or return it from a unit or sensor (which take it).
class Structure {
public:
    /// A structure `name` valid at `valid_time`, created at `create_time` (default: the
    /// valid time).
    explicit Structure(std::string_view name = "", Time valid_time = 0,
                       std::optional<Time> create_time = std::nullopt) {
        esgm_structure_t s{};
        detail::check(esgm_structure_new(detail::z(name).c_str(), valid_time,
                                         create_time.value_or(valid_time), &s));
        h_ = Owned(s);
    }
    /// A nested frame `name` (its times are not used).
    static Structure frame(std::string_view name) { return Structure(name, 0, 0); }

    /// Sets its name.
    Structure& name(std::string_view name) & {
        detail::check(esgm_structure_set_name(h_.get(), detail::z(name).c_str()));
        return *this;
    }
    Structure&& name(std::string_view name) && { return std::move(this->name(name)); }
    /// Sets its valid and create times.
    Structure& times(Time valid_time, std::optional<Time> create_time = std::nullopt) & {
        detail::check(
            esgm_structure_set_times(h_.get(), valid_time, create_time.value_or(valid_time)));
        return *this;
    }
    Structure&& times(Time valid_time, std::optional<Time> create_time = std::nullopt) && {
        return std::move(this->times(valid_time, create_time));
    }

    /// Sets an attribute: integers are Long, floating point Double, bool Bool, text
    /// String; Symbol, TimePoint and Altitude say their sort; vectors of integers,
    /// floats and strings are LongSeq, DoubleSeq and SymbolSeq; the geometric structs
    /// their sorts; a Structure a frame; a vector of Structures a frame sequence; a
    /// typed struct (ESGM_ENTITY) a frame of its type.
    template <class V>
    Structure& set(std::string_view attribute, V&& value) & {
        const std::string a(attribute);
        put(a.c_str(), std::forward<V>(value));
        return *this;
    }
    /// set() on a temporary, to build and hand over in one expression.
    template <class V>
    Structure&& set(std::string_view attribute, V&& value) && {
        return std::move(this->set(attribute, std::forward<V>(value)));
    }
    /// Sets an OctetSeq attribute to a copy of `bytes` (an image to be read in place by
    /// others is written into a loan instead: set_image).
    Structure& set_octets(std::string_view attribute, Span<const std::uint8_t> bytes) {
        detail::check(esgm_structure_set_octets(h_.get(), detail::z(attribute).c_str(),
                                                bytes.data(), bytes.size()));
        return *this;
    }
    /// Sets an OctetSeq attribute to the pixels written into `loan`, which it takes.
    Structure& set_image(std::string_view attribute, ImageLoan&& loan) & {
        detail::check(esgm_structure_set_image(h_.get(), detail::z(attribute).c_str(),
                                               loan.release()));
        return *this;
    }
    Structure&& set_image(std::string_view attribute, ImageLoan&& loan) && {
        return std::move(this->set_image(attribute, std::move(loan)));
    }
    /// Appends a frame to an EntityFrameSeq attribute (taking it).
    Structure& push_frame(std::string_view attribute, Structure&& frame) & {
        detail::check(esgm_structure_push_frame(h_.get(), detail::z(attribute).c_str(),
                                                frame.release()));
        return *this;
    }
    Structure&& push_frame(std::string_view attribute, Structure&& frame) && {
        return std::move(this->push_frame(attribute, std::move(frame)));
    }
    /// Sets an EntityFrameSeq attribute to no frames.
    Structure& set_empty_frames(std::string_view attribute) {
        detail::check(esgm_structure_set_empty_frame_seq(h_.get(), detail::z(attribute).c_str()));
        return *this;
    }
    /// Sets an attribute of any sort from esgm's JSON form of a value ({"Long": 5}).
    Structure& set_json(std::string_view attribute, std::string_view json) {
        detail::check(esgm_structure_set_json(h_.get(), detail::z(attribute).c_str(),
                                              detail::z(json).c_str()));
        return *this;
    }
    /// Sets many attributes at once (one call into esgm), taking the frames in them.
    Structure& set_values(detail::ValueList& values);
    /// Sets an attribute to no value.
    Structure& set_no_value(std::string_view attribute) {
        detail::check(esgm_structure_set_no_value(h_.get(), detail::z(attribute).c_str()));
        return *this;
    }

    esgm_structure_t get() const noexcept { return h_.get(); }
    /// The handle, for a C call that takes it.
    esgm_structure_t release() noexcept { return h_.release(); }

private:
    using Owned = detail::Owned<esgm_structure_t, esgm_structure_free>;
    Owned h_;

    template <class V>
    void put(const char* a, V&& value) {
        using T = std::decay_t<V>;
        esgm_structure_t s = h_.get();
        if constexpr (std::is_same_v<T, bool>) {
            detail::check(esgm_structure_set_bool(s, a, value));
        } else if constexpr (std::is_integral_v<T>) {
            detail::check(esgm_structure_set_long(s, a, static_cast<std::int64_t>(value)));
        } else if constexpr (std::is_floating_point_v<T>) {
            detail::check(esgm_structure_set_double(s, a, static_cast<double>(value)));
        } else if constexpr (std::is_convertible_v<T, std::string_view>) {
            detail::check(esgm_structure_set_string(s, a, detail::z(value).c_str()));
        } else if constexpr (std::is_same_v<T, Symbol>) {
            detail::check(esgm_structure_set_symbol(s, a, value.name.c_str()));
        } else if constexpr (std::is_same_v<T, TimePoint>) {
            detail::check(esgm_structure_set_time(s, a, value.t));
        } else if constexpr (std::is_same_v<T, Altitude>) {
            detail::check(esgm_structure_set_altitude(s, a, value.metres));
        } else if constexpr (std::is_same_v<T, Vec3>) {
            detail::check(esgm_structure_set_vec(s, a, value));
        } else if constexpr (std::is_same_v<T, Pos2>) {
            detail::check(esgm_structure_set_pos2(s, a, value));
        } else if constexpr (std::is_same_v<T, Position>) {
            detail::check(esgm_structure_set_position(s, a, value));
        } else if constexpr (std::is_same_v<T, Rotation>) {
            detail::check(esgm_structure_set_rotation(s, a, value));
        } else if constexpr (std::is_same_v<T, PositionAltitude>) {
            detail::check(esgm_structure_set_position_altitude(s, a, value));
        } else if constexpr (std::is_same_v<T, Pose>) {
            detail::check(esgm_structure_set_pose(s, a, value));
        } else if constexpr (std::is_same_v<T, Structure>) {
            detail::check(esgm_structure_set_frame(s, a, value.release()));
        } else if constexpr (std::is_same_v<T, ImageLoan>) {
            detail::check(esgm_structure_set_image(s, a, value.release()));
        } else if constexpr (std::is_same_v<T, std::vector<std::uint8_t>>) {
            detail::check(esgm_structure_set_octets(s, a, value.data(), value.size()));
        } else if constexpr (std::is_same_v<T, std::vector<std::int64_t>>) {
            detail::check(esgm_structure_set_long_seq(s, a, value.data(), value.size()));
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
            detail::check(esgm_structure_set_double_seq(s, a, value.data(), value.size()));
        } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
            std::vector<const char*> items;
            items.reserve(value.size());
            for (const std::string& item : value) {
                items.push_back(item.c_str());
            }
            detail::check(esgm_structure_set_symbol_seq(s, a, items.data(), items.size()));
        } else if constexpr (std::is_same_v<T, std::vector<Vec3>>) {
            detail::check(esgm_structure_set_vec_seq(s, a, value.data(), value.size()));
        } else if constexpr (std::is_same_v<T, std::vector<Pos2>>) {
            detail::check(esgm_structure_set_pos2_seq(s, a, value.data(), value.size()));
        } else if constexpr (std::is_same_v<T, std::vector<Structure>>) {
            detail::check(esgm_structure_set_empty_frame_seq(s, a));
            for (Structure& f : value) {
                detail::check(esgm_structure_push_frame(s, a, f.release()));
            }
        } else if constexpr (is_vector_of_entities<T>::value) {
            detail::check(esgm_structure_set_empty_frame_seq(s, a));
            for (const auto& item : value) {
                Structure f = Entity<typename T::value_type>::to_frame(item);
                detail::check(esgm_structure_push_frame(s, a, f.release()));
            }
        } else {
            Structure f = Entity<T>::to_frame(value);
            detail::check(esgm_structure_set_frame(s, a, f.release()));
        }
    }

    template <class T>
    struct is_vector_of_entities : std::false_type {};
    template <class U>
    struct is_vector_of_entities<std::vector<U>> {
        static constexpr bool value = !std::is_arithmetic_v<U> && !std::is_same_v<U, std::string> &&
                                      !std::is_same_v<U, Vec3> && !std::is_same_v<U, Pos2> &&
                                      !std::is_same_v<U, Structure>;
    };
};

// ---------------------------------------------------------------------------------
// Samples (to read)

class Sample;

namespace detail {
template <class T>
T get_value(const Sample& s, const esgm_value_t& v, std::string_view what);
}

/// An image read in place: its size, format and pixels (valid while the Sample lives).
struct ImageView {
    std::int64_t width;
    std::int64_t height;
    std::int64_t format;
    Span<const std::uint8_t> pixels;
    /// True if the pixels are read in another process's shared memory (not a copy).
    bool shared;
};

/// A sample (an entity structure as stored, with its add and query time), or a frame
/// nested in one. Everything read from it is read in place and valid while it lives;
/// an image's pixels stay in the writer's shared memory, whatever the writer does.
class Sample {
public:
    /// Takes ownership of a C sample handle.
    explicit Sample(esgm_sample_t h) noexcept : h_(h), owned_(true) {}
    /// A view of a handle somebody else owns (a unit's inputs during the call).
    static Sample borrow(esgm_sample_t h) noexcept {
        Sample s(h);
        s.owned_ = false;
        return s;
    }
    Sample(const Sample& o) : h_(o.clone_handle()), owned_(true) {}
    Sample& operator=(const Sample& o) {
        if (this != &o) {
            esgm_sample_t c = o.clone_handle();
            free();
            h_ = c;
            owned_ = true;
        }
        return *this;
    }
    Sample(Sample&& o) noexcept : h_(o.h_), owned_(o.owned_) { o.h_ = esgm_sample_t{}; }
    Sample& operator=(Sample&& o) noexcept {
        if (this != &o) {
            free();
            h_ = o.h_;
            owned_ = o.owned_;
            o.h_ = esgm_sample_t{};
        }
        return *this;
    }
    ~Sample() { free(); }

    /// Its name and times.
    esgm_sample_info_t info() const {
        esgm_sample_info_t i{};
        detail::check(esgm_sample_info(h_, &i));
        return i;
    }
    std::string_view name() const { return detail::view(info().name); }
    Time valid_time() const { return info().valid_time; }
    Time create_time() const { return info().create_time; }
    Time add_time() const { return info().add_time; }
    Time query_time() const { return info().query_time; }
    /// Its number of attributes.
    std::size_t size() const { return info().attribute_count; }

    /// The attribute `attribute` as it is (its sort says which fields hold it).
    esgm_value_t value(std::string_view attribute) const {
        esgm_value_t v{};
        detail::check(esgm_sample_value(h_, detail::z(attribute).c_str(), &v));
        return v;
    }
    /// The attribute at `index`, with its name.
    esgm_value_t value(std::size_t index) const {
        esgm_value_t v{};
        detail::check(esgm_sample_value_at(h_, index, &v));
        return v;
    }
    /// True if it has the attribute.
    bool has(std::string_view attribute) const {
        esgm_value_t v{};
        return esgm_sample_value(h_, detail::z(attribute).c_str(), &v) == ESGM_OK;
    }

    /// The attribute `attribute` as a T: std::int64_t (Long or Time), int, double
    /// (Double or Altitude), bool, std::string_view / std::string (String or Symbol),
    /// Span<const std::uint8_t> (OctetSeq), Span<const std::int64_t> (LongSeq),
    /// Span<const double> (DoubleSeq), the geometric structs, Sample (a frame), a typed
    /// struct of ESGM_ENTITY, or std::vector<Sample> / std::vector<typed struct> (a frame
    /// sequence). A wrong sort throws InvalidType, a missing attribute NoSuchAttribute.
    template <class T>
    T get(std::string_view attribute) const {
        return detail::get_value<T>(*this, value(attribute), attribute);
    }
    /// The attribute at `index` as a T.
    template <class T>
    T get(std::size_t index) const {
        esgm_value_t v = value(index);
        return detail::get_value<T>(*this, v, detail::view(v.name));
    }
    /// The typed struct this sample holds (ESGM_ENTITY).
    template <class T>
    T as() const {
        return Entity<T>::from_sample(*this);
    }

    /// The pixels of an OctetSeq attribute, in place.
    Span<const std::uint8_t> octets(std::string_view attribute) const {
        const std::uint8_t* data = nullptr;
        size_t len = 0;
        detail::check(esgm_sample_get_octets(h_, detail::z(attribute).c_str(), &data, &len));
        return {data, len};
    }
    /// True if an OctetSeq attribute is read in another process's shared memory.
    bool shared(std::string_view attribute) const {
        bool s = false;
        detail::check(esgm_sample_octets_are_shared(h_, detail::z(attribute).c_str(), &s));
        return s;
    }
    /// An Image structure (width, height, format, image_data) read in place.
    ImageView image() const {
        return {get<std::int64_t>("width"), get<std::int64_t>("height"),
                get<std::int64_t>("format"), octets("image_data"), shared("image_data")};
    }
    /// The nested frame `attribute`.
    Sample frame(std::string_view attribute) const {
        esgm_sample_t f{};
        detail::check(esgm_sample_frame(h_, detail::z(attribute).c_str(), &f));
        return Sample(f);
    }
    /// Frame `index` of the frame sequence `attribute`.
    Sample frame(std::string_view attribute, std::size_t index) const {
        esgm_sample_t f{};
        detail::check(esgm_sample_frame_at(h_, detail::z(attribute).c_str(), index, &f));
        return Sample(f);
    }
    /// Every frame of the frame sequence `attribute`.
    std::vector<Sample> frames(std::string_view attribute) const {
        esgm_value_t v = value(attribute);
        if (v.sort != ESGM_SORT_ENTITY_FRAME_SEQ) {
            throw InvalidType("attribute `" + std::string(attribute) +
                              "` is not an EntityFrameSeq");
        }
        std::vector<Sample> out;
        out.reserve(v.len);
        for (std::size_t i = 0; i < v.len; i++) {
            out.push_back(frame(attribute, i));
        }
        return out;
    }
    /// Item `index` of a sequence attribute (SymbolSeq, VecSeq, Pos2Seq, Agg, ...).
    esgm_value_t item(std::string_view attribute, std::size_t index) const {
        esgm_value_t v{};
        detail::check(esgm_sample_item(h_, detail::z(attribute).c_str(), index, &v));
        return v;
    }
    /// The sample as JSON (name, times, attributes; an image as its length).
    std::string to_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_sample_to_json(h_, b, c, l);
        });
    }

    esgm_sample_t get() const noexcept { return h_; }

private:
    esgm_sample_t h_{};
    bool owned_ = true;

    esgm_sample_t clone_handle() const {
        if (h_.id == 0) {
            return esgm_sample_t{};
        }
        esgm_sample_t c{};
        detail::check(esgm_sample_clone(h_, &c));
        return c;
    }
    void free() noexcept {
        if (owned_ && h_.id != 0) {
            (void)esgm_sample_free(h_);
        }
        h_ = esgm_sample_t{};
    }
};

namespace detail {

template <class>
inline constexpr bool always_false = false;

template <class T>
struct is_vector : std::false_type {};
template <class U>
struct is_vector<std::vector<U>> : std::true_type {};

[[noreturn]] inline void wrong_sort(std::string_view what, const esgm_value_t& v,
                                    const char* wanted) {
    throw InvalidType("attribute `" + std::string(what) + "` is of sort " +
                      std::to_string(v.sort) + " (see esgm_sort), not " + wanted);
}

template <class T>
T get_value(const Sample& s, const esgm_value_t& v, std::string_view what) {
    if constexpr (std::is_same_v<T, bool>) {
        if (v.sort != ESGM_SORT_BOOL) wrong_sort(what, v, "Bool");
        return v.bool_value;
    } else if constexpr (std::is_integral_v<T>) {
        if (v.sort != ESGM_SORT_LONG && v.sort != ESGM_SORT_TIME) wrong_sort(what, v, "Long");
        return static_cast<T>(v.long_value);
    } else if constexpr (std::is_floating_point_v<T>) {
        if (v.sort != ESGM_SORT_DOUBLE && v.sort != ESGM_SORT_ALTITUDE)
            wrong_sort(what, v, "Double");
        return static_cast<T>(v.double_value);
    } else if constexpr (std::is_same_v<T, std::string_view> || std::is_same_v<T, std::string>) {
        if (v.sort != ESGM_SORT_STRING && v.sort != ESGM_SORT_SYMBOL)
            wrong_sort(what, v, "String");
        return T(view(v.text));
    } else if constexpr (std::is_same_v<T, Span<const std::uint8_t>>) {
        if (v.sort != ESGM_SORT_OCTET_SEQ) wrong_sort(what, v, "OctetSeq");
        return {static_cast<const std::uint8_t*>(v.data), v.len};
    } else if constexpr (std::is_same_v<T, Span<const std::int64_t>>) {
        if (v.sort != ESGM_SORT_LONG_SEQ) wrong_sort(what, v, "LongSeq");
        return {static_cast<const std::int64_t*>(v.data), v.len};
    } else if constexpr (std::is_same_v<T, Span<const double>>) {
        if (v.sort != ESGM_SORT_DOUBLE_SEQ) wrong_sort(what, v, "DoubleSeq");
        return {static_cast<const double*>(v.data), v.len};
    } else if constexpr (std::is_same_v<T, std::vector<std::int64_t>>) {
        auto span = get_value<Span<const std::int64_t>>(s, v, what);
        return T(span.begin(), span.end());
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
        auto span = get_value<Span<const double>>(s, v, what);
        return T(span.begin(), span.end());
    } else if constexpr (std::is_same_v<T, std::vector<std::uint8_t>>) {
        auto span = get_value<Span<const std::uint8_t>>(s, v, what);
        return T(span.begin(), span.end());
    } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
        if (v.sort != ESGM_SORT_SYMBOL_SEQ) wrong_sort(what, v, "SymbolSeq");
        T out;
        for (std::size_t i = 0; i < v.len; i++) {
            out.emplace_back(view(s.item(what, i).text));
        }
        return out;
    } else if constexpr (std::is_same_v<T, Vec3>) {
        if (v.sort != ESGM_SORT_VEC) wrong_sort(what, v, "Vec");
        return v.vec;
    } else if constexpr (std::is_same_v<T, Pos2>) {
        if (v.sort != ESGM_SORT_POS2) wrong_sort(what, v, "Pos2");
        return v.pos2;
    } else if constexpr (std::is_same_v<T, Position>) {
        if (v.sort != ESGM_SORT_POSITION) wrong_sort(what, v, "Position");
        return v.pose.position;
    } else if constexpr (std::is_same_v<T, Rotation>) {
        if (v.sort != ESGM_SORT_ROTATION) wrong_sort(what, v, "Rotation");
        return v.pose.rotation;
    } else if constexpr (std::is_same_v<T, PositionAltitude>) {
        if (v.sort != ESGM_SORT_POSITION_ALTITUDE) wrong_sort(what, v, "PositionAltitude");
        return PositionAltitude{v.pose.position, v.pose.altitude};
    } else if constexpr (std::is_same_v<T, Pose>) {
        if (v.sort != ESGM_SORT_POSITION_ALTITUDE_ROTATION)
            wrong_sort(what, v, "PositionAltitudeRotation");
        return v.pose;
    } else if constexpr (std::is_same_v<T, std::vector<Vec3>> || std::is_same_v<T, std::vector<Pos2>>) {
        T out;
        for (std::size_t i = 0; i < v.len; i++) {
            out.push_back(get_value<typename T::value_type>(s, s.item(what, i), what));
        }
        return out;
    } else if constexpr (std::is_same_v<T, Sample>) {
        return s.frame(what);
    } else if constexpr (std::is_same_v<T, std::vector<Sample>>) {
        return s.frames(what);
    } else if constexpr (is_vector<T>::value) {
        T out;
        for (const Sample& f : s.frames(what)) {
            out.push_back(Entity<typename T::value_type>::from_sample(f));
        }
        return out;
    } else {
        return Entity<T>::from_sample(s.frame(what));
    }
}

}  // namespace detail

// ---------------------------------------------------------------------------------
// Typed structures: ESGM_ENTITY(Type, "TypeName", field, field, ...)

/// The sort of a C++ field type (for a typed struct's type).
template <class T, class = void>
struct SortOf;
template <class T>
struct SortOf<T, std::enable_if_t<std::is_same_v<T, bool>>> {
    static constexpr Sort value = Sort::Bool;
};
template <class T>
struct SortOf<T, std::enable_if_t<std::is_integral_v<T> && !std::is_same_v<T, bool>>> {
    static constexpr Sort value = Sort::Long;
};
template <class T>
struct SortOf<T, std::enable_if_t<std::is_floating_point_v<T>>> {
    static constexpr Sort value = Sort::Double;
};
template <>
struct SortOf<std::string> {
    static constexpr Sort value = Sort::String;
};
template <>
struct SortOf<std::vector<std::int64_t>> {
    static constexpr Sort value = Sort::LongSeq;
};
template <>
struct SortOf<std::vector<double>> {
    static constexpr Sort value = Sort::DoubleSeq;
};
template <>
struct SortOf<std::vector<std::string>> {
    static constexpr Sort value = Sort::SymbolSeq;
};
template <>
struct SortOf<std::vector<std::uint8_t>> {
    static constexpr Sort value = Sort::OctetSeq;
};
template <>
struct SortOf<Vec3> {
    static constexpr Sort value = Sort::Vec;
};
template <>
struct SortOf<Pos2> {
    static constexpr Sort value = Sort::Pos2;
};
template <>
struct SortOf<Position> {
    static constexpr Sort value = Sort::Position;
};
template <>
struct SortOf<Rotation> {
    static constexpr Sort value = Sort::Rotation;
};
template <>
struct SortOf<PositionAltitude> {
    static constexpr Sort value = Sort::PositionAltitude;
};
template <>
struct SortOf<Pose> {
    static constexpr Sort value = Sort::PositionAltitudeRotation;
};

namespace detail {

template <class T, class = void>
struct is_entity : std::false_type {};
template <class T>
struct is_entity<T, std::void_t<decltype(Entity<T>::type_name)>> : std::true_type {};

template <class T>
struct is_entity_vector : std::false_type {};
template <class U>
struct is_entity_vector<std::vector<U>> : is_entity<U> {};

/// Attribute values to write in one call (esgm_add_values, esgm_structure_set_values):
/// views of the caller's data, plus the frames and loans the call takes. Frames made
/// for it are freed if it is never handed over.
class ValueList {
public:
    ValueList() = default;
    ValueList(const ValueList&) = delete;
    ValueList& operator=(const ValueList&) = delete;
    ~ValueList() {
        if (handed_over_) return;
        for (const esgm_value_t& v : values_) {
            if (v.sort == ESGM_SORT_ENTITY_FRAME && v.handle != 0) {
                (void)esgm_structure_free(esgm_structure_t{v.handle});
            }
        }
        for (const auto& frames : frames_) {
            for (esgm_structure_t f : frames) (void)esgm_structure_free(f);
        }
    }
    const esgm_value_t* data() const noexcept { return values_.data(); }
    std::size_t size() const noexcept { return values_.size(); }
    /// The C call took everything: nothing left to free.
    void handed_over() noexcept { handed_over_ = true; }

    /// Adds `value` (a field's; it must live until the values are handed over) as
    /// attribute `name`: the sorts as Structure::set maps them.
    template <class V>
    void add(const char* name, const V& value) {
        esgm_value_t v{};
        v.name = esgm_str_t{name, std::char_traits<char>::length(name)};
        using T = V;
        if constexpr (std::is_same_v<T, bool>) {
            v.sort = ESGM_SORT_BOOL;
            v.bool_value = value;
        } else if constexpr (std::is_integral_v<T>) {
            v.sort = ESGM_SORT_LONG;
            v.long_value = static_cast<std::int64_t>(value);
        } else if constexpr (std::is_floating_point_v<T>) {
            v.sort = ESGM_SORT_DOUBLE;
            v.double_value = static_cast<double>(value);
        } else if constexpr (std::is_same_v<T, std::string> || std::is_same_v<T, std::string_view>) {
            v.sort = ESGM_SORT_STRING;
            v.text = esgm_str_t{value.data(), value.size()};
        } else if constexpr (std::is_same_v<T, Symbol>) {
            v.sort = ESGM_SORT_SYMBOL;
            v.text = esgm_str_t{value.name.data(), value.name.size()};
        } else if constexpr (std::is_same_v<T, TimePoint>) {
            v.sort = ESGM_SORT_TIME;
            v.long_value = value.t;
        } else if constexpr (std::is_same_v<T, Altitude>) {
            v.sort = ESGM_SORT_ALTITUDE;
            v.double_value = value.metres;
        } else if constexpr (std::is_same_v<T, Vec3>) {
            v.sort = ESGM_SORT_VEC;
            v.vec = value;
        } else if constexpr (std::is_same_v<T, Pos2>) {
            v.sort = ESGM_SORT_POS2;
            v.pos2 = value;
        } else if constexpr (std::is_same_v<T, Position>) {
            v.sort = ESGM_SORT_POSITION;
            v.pose.position = value;
        } else if constexpr (std::is_same_v<T, Rotation>) {
            v.sort = ESGM_SORT_ROTATION;
            v.pose.rotation = value;
        } else if constexpr (std::is_same_v<T, PositionAltitude>) {
            v.sort = ESGM_SORT_POSITION_ALTITUDE;
            v.pose.position = value.position;
            v.pose.altitude = value.altitude;
        } else if constexpr (std::is_same_v<T, Pose>) {
            v.sort = ESGM_SORT_POSITION_ALTITUDE_ROTATION;
            v.pose = value;
        } else if constexpr (std::is_same_v<T, std::vector<std::uint8_t>>) {
            v.sort = ESGM_SORT_OCTET_SEQ;
            v.data = value.data();
            v.len = value.size();
        } else if constexpr (std::is_same_v<T, std::vector<std::int64_t>>) {
            v.sort = ESGM_SORT_LONG_SEQ;
            v.data = value.data();
            v.len = value.size();
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
            v.sort = ESGM_SORT_DOUBLE_SEQ;
            v.data = value.data();
            v.len = value.size();
        } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
            std::vector<esgm_str_t>& texts = texts_.emplace_back();
            for (const std::string& t : value) texts.push_back(esgm_str_t{t.data(), t.size()});
            v.sort = ESGM_SORT_SYMBOL_SEQ;
            v.data = texts.data();
            v.len = texts.size();
        } else if constexpr (std::is_same_v<T, std::vector<Vec3>>) {
            v.sort = ESGM_SORT_VEC_SEQ;
            v.data = value.data();
            v.len = value.size();
        } else if constexpr (std::is_same_v<T, std::vector<Pos2>>) {
            v.sort = ESGM_SORT_POS2_SEQ;
            v.data = value.data();
            v.len = value.size();
        } else if constexpr (is_entity_vector<T>::value) {
            std::vector<esgm_structure_t>& frames = frames_.emplace_back();
            for (const auto& item : value) {
                frames.push_back(Entity<typename T::value_type>::to_frame(item).release());
            }
            v.sort = ESGM_SORT_ENTITY_FRAME_SEQ;
            v.data = frames.data();
            v.len = frames.size();
        } else {
            v.sort = ESGM_SORT_ENTITY_FRAME;
            v.handle = Entity<T>::to_frame(value).release().id;
        }
        values_.push_back(v);
    }

private:
    std::vector<esgm_value_t> values_;
    std::vector<std::vector<esgm_structure_t>> frames_;
    std::vector<std::vector<esgm_str_t>> texts_;
    bool handed_over_ = false;
};

/// A sample's attributes read in one call (esgm_sample_values), looked up by name:
/// up to 16 on the stack, more on the heap.
class ValueMap {
public:
    explicit ValueMap(const Sample& sample) : sample_(sample) {
        check(esgm_sample_values(sample.get(), local_, LOCAL, &count_));
        if (count_ > LOCAL) {
            heap_.resize(count_);
            check(esgm_sample_values(sample.get(), heap_.data(), heap_.size(), &count_));
        }
    }
    /// Attribute `name` as a T (see Sample::get).
    template <class T>
    T get(const char* name) const {
        const std::string_view wanted(name);
        const esgm_value_t* values = count_ > LOCAL ? heap_.data() : local_;
        for (std::size_t i = 0; i < count_; i++) {
            if (view(values[i].name) == wanted) return get_value<T>(sample_, values[i], wanted);
        }
        std::string there;
        for (std::size_t i = 0; i < count_; i++) {
            there += (there.empty() ? "" : ", ") + std::string(view(values[i].name));
        }
        throw NoSuchAttribute("`" + std::string(sample_.name()) + "` has no attribute `" +
                              std::string(wanted) + "`; it has " + (there.empty() ? "none" : there));
    }

private:
    static constexpr std::size_t LOCAL = 16;
    const Sample& sample_;
    esgm_value_t local_[LOCAL];
    std::size_t count_ = 0;
    std::vector<esgm_value_t> heap_;
};

}  // namespace detail

inline Structure& Structure::set_values(detail::ValueList& values) {
    esgm_status st = esgm_structure_set_values(h_.get(), values.data(), values.size());
    values.handed_over();
    detail::check(st);
    return *this;
}

namespace detail {

/// Adds field `name` of C++ type F to `type`.
template <class F>
void add_field(Type& type, const char* name) {
    if constexpr (is_entity<F>::value) {
        type.frame(name, Entity<F>::type_name);
    } else if constexpr (is_entity_vector<F>::value) {
        type.frame_seq(name, Entity<typename F::value_type>::type_name);
    } else {
        type.attr(name, SortOf<F>::value);
    }
}

}  // namespace detail

// ESGM_ENTITY's field list, expanded one field at a time (up to 32 fields).
#define ESGM_DETAIL_EXPAND(x) x
#define ESGM_DETAIL_FE_1(m, a) m(a)
#define ESGM_DETAIL_FE_2(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_1(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_3(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_2(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_4(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_3(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_5(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_4(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_6(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_5(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_7(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_6(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_8(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_7(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_9(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_8(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_10(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_9(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_11(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_10(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_12(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_11(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_13(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_12(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_14(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_13(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_15(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_14(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_16(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_15(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_17(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_16(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_18(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_17(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_19(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_18(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_20(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_19(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_21(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_20(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_22(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_21(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_23(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_22(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_24(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_23(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_25(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_24(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_26(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_25(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_27(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_26(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_28(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_27(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_29(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_28(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_30(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_29(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_31(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_30(m, __VA_ARGS__))
#define ESGM_DETAIL_FE_32(m, a, ...) m(a) ESGM_DETAIL_EXPAND(ESGM_DETAIL_FE_31(m, __VA_ARGS__))
#define ESGM_DETAIL_PICK(_1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15,   \
                         _16, _17, _18, _19, _20, _21, _22, _23, _24, _25, _26, _27, _28,     \
                         _29, _30, _31, _32, NAME, ...)                                       \
    NAME
#define ESGM_DETAIL_FOR_EACH(m, ...)                                                         \
    ESGM_DETAIL_EXPAND(ESGM_DETAIL_PICK(                                                     \
        __VA_ARGS__, ESGM_DETAIL_FE_32, ESGM_DETAIL_FE_31, ESGM_DETAIL_FE_30,                 \
        ESGM_DETAIL_FE_29, ESGM_DETAIL_FE_28, ESGM_DETAIL_FE_27, ESGM_DETAIL_FE_26,           \
        ESGM_DETAIL_FE_25, ESGM_DETAIL_FE_24, ESGM_DETAIL_FE_23, ESGM_DETAIL_FE_22,           \
        ESGM_DETAIL_FE_21, ESGM_DETAIL_FE_20, ESGM_DETAIL_FE_19, ESGM_DETAIL_FE_18,           \
        ESGM_DETAIL_FE_17, ESGM_DETAIL_FE_16, ESGM_DETAIL_FE_15, ESGM_DETAIL_FE_14,           \
        ESGM_DETAIL_FE_13, ESGM_DETAIL_FE_12, ESGM_DETAIL_FE_11, ESGM_DETAIL_FE_10,           \
        ESGM_DETAIL_FE_9, ESGM_DETAIL_FE_8, ESGM_DETAIL_FE_7, ESGM_DETAIL_FE_6,               \
        ESGM_DETAIL_FE_5, ESGM_DETAIL_FE_4, ESGM_DETAIL_FE_3, ESGM_DETAIL_FE_2,               \
        ESGM_DETAIL_FE_1, unused)(m, __VA_ARGS__))

#define ESGM_DETAIL_TYPE_FIELD(f) ::esgm::detail::add_field<decltype(Self::f)>(t, #f);
#define ESGM_DETAIL_PUT_FIELD(f) out.add(#f, value.f);
#define ESGM_DETAIL_GET_FIELD(f) value.f = values.get<decltype(Self::f)>(#f);

/// Makes the struct `Type` an entity structure type named `NAME` whose attributes are
/// the listed fields (each of a type SortOf knows, another ESGM_ENTITY struct — a
/// frame — or a std::vector of one — a frame sequence). Use it at global scope:
///
///   struct RobotState { double x, y, dir; };
///   ESGM_ENTITY(RobotState, "RobotState", x, y, dir)
///
/// then esgm.create_type<RobotState>(), trajectory.add(RobotState{...}, "robot1", t),
/// sample.as<RobotState>().
#define ESGM_ENTITY(Type_, NAME, ...)                                                     \
    template <>                                                                          \
    struct esgm::Entity<Type_> {                                                         \
        using Self = Type_;                                                              \
        [[maybe_unused]] static constexpr const char* type_name = NAME;                  \
        static ::esgm::Type type() {                                                     \
            ::esgm::Type t(NAME);                                                        \
            ESGM_DETAIL_FOR_EACH(ESGM_DETAIL_TYPE_FIELD, __VA_ARGS__)                    \
            return t;                                                                    \
        }                                                                                \
        static void put_values(const Self& value, ::esgm::detail::ValueList& out) {      \
            ESGM_DETAIL_FOR_EACH(ESGM_DETAIL_PUT_FIELD, __VA_ARGS__)                     \
        }                                                                                \
        static ::esgm::Structure to_structure(const Self& value, std::string_view name,  \
                                              ::esgm::Time valid_time,                   \
                                              std::optional<::esgm::Time> create_time =  \
                                                  std::nullopt) {                        \
            ::esgm::Structure s(name, valid_time, create_time);                          \
            ::esgm::detail::ValueList values;                                            \
            put_values(value, values);                                                   \
            s.set_values(values);                                                        \
            return s;                                                                    \
        }                                                                                \
        static ::esgm::Structure to_frame(const Self& value) {                           \
            return to_structure(value, NAME, 0, 0);                                      \
        }                                                                                \
        static Self from_sample(const ::esgm::Sample& sample) {                          \
            const ::esgm::detail::ValueMap values(sample);                               \
            Self value{};                                                                \
            ESGM_DETAIL_FOR_EACH(ESGM_DETAIL_GET_FIELD, __VA_ARGS__)                     \
            return value;                                                                \
        }                                                                                \
    };

// ---------------------------------------------------------------------------------
// Subscriptions

/// A subscription to a trajectory's structures (T3), in add order. Iterate it with
/// range-for (each step waits for the next sample; the loop ends when the trajectory
/// is destroyed or the ESGM freed), or recv() with a timeout. Unsubscribes when it goes.
class Subscription {
public:
    explicit Subscription(esgm_subscription_t h) : h_(h) {}

    /// The next sample, waiting at most `timeout` (nullopt if none came).
    template <class Rep = std::int64_t, class Period = std::nano>
    std::optional<Sample> recv(std::chrono::duration<Rep, Period> timeout) {
        esgm_sample_t s{};
        esgm_status st = esgm_subscription_recv(h_.get(), to_time(timeout), &s);
        if (st == ESGM_TIMEOUT) {
            return std::nullopt;
        }
        detail::check(st);
        return Sample(s);
    }
    /// The next sample, waiting for it (Closed when the subscription ends).
    Sample recv() {
        esgm_sample_t s{};
        detail::check(esgm_subscription_recv(h_.get(), ESGM_FOREVER, &s));
        return Sample(s);
    }
    /// The next sample if one is there now.
    std::optional<Sample> try_recv() { return recv(std::chrono::nanoseconds(0)); }
    /// Samples missed because the queue was full.
    std::uint64_t overflowed() const {
        std::uint64_t n = 0;
        detail::check(esgm_subscription_overflowed(h_.get(), &n));
        return n;
    }

    /// Range-for: each step waits for the next sample.
    class iterator {
    public:
        using value_type = Sample;
        using difference_type = std::ptrdiff_t;
        using reference = const Sample&;
        using pointer = const Sample*;
        using iterator_category = std::input_iterator_tag;

        iterator() = default;
        explicit iterator(Subscription* sub) : sub_(sub) { ++*this; }
        const Sample& operator*() const { return *current_; }
        const Sample* operator->() const { return &*current_; }
        iterator& operator++() {
            try {
                current_.emplace(sub_->recv());
            } catch (const Closed&) {
                sub_ = nullptr;
                current_.reset();
            }
            return *this;
        }
        bool operator==(const iterator& o) const { return sub_ == o.sub_; }
        bool operator!=(const iterator& o) const { return sub_ != o.sub_; }

    private:
        Subscription* sub_ = nullptr;
        std::optional<Sample> current_;
    };
    iterator begin() { return iterator(this); }
    iterator end() { return iterator(); }

    esgm_subscription_t get() const noexcept { return h_.get(); }

private:
    detail::Owned<esgm_subscription_t, esgm_unsubscribe> h_;
};

/// A policy violation (C7).
struct Violation {
    std::string trajectory;
    /// "change", "cache", "filter", "duration", "order" or "delay".
    std::string constraint;
    std::string detail;
    Time valid_time;
    Time create_time;
    Time add_time;
};

/// A subscription to a trajectory's policy violations.
class Violations {
public:
    explicit Violations(esgm_violations_t h) : h_(h) {}
    /// The next violation, waiting at most `timeout`.
    template <class Rep = std::int64_t, class Period = std::nano>
    std::optional<Violation> recv(std::chrono::duration<Rep, Period> timeout) {
        esgm_violation_t v{};
        esgm_status st = esgm_violations_recv(h_.get(), to_time(timeout), &v);
        if (st == ESGM_TIMEOUT) {
            return std::nullopt;
        }
        detail::check(st);
        detail::Owned<esgm_violation_t, esgm_violation_free> owned(v);
        esgm_violation_info_t i{};
        detail::check(esgm_violation_info(v, &i));
        return Violation{std::string(detail::view(i.trajectory)),
                         std::string(detail::view(i.constraint)),
                         std::string(detail::view(i.detail)), i.valid_time, i.create_time,
                         i.add_time};
    }

private:
    detail::Owned<esgm_violations_t, esgm_violations_free> h_;
};

// ---------------------------------------------------------------------------------
// Trajectories

/// What became of an added structure.
enum class Outcome : std::int32_t {
    Added = ESGM_OUTCOME_ADDED,
    Held = ESGM_OUTCOME_HELD,
    Forwarded = ESGM_OUTCOME_FORWARDED,
    Dropped = ESGM_OUTCOME_DROPPED,
};

/// How get_at_approximating answers without a sample valid exactly then.
enum class Approximation : std::int32_t {
    None = ESGM_APPROXIMATION_NONE,
    Closest = ESGM_APPROXIMATION_CLOSEST,
    MostRecent = ESGM_APPROXIMATION_MOST_RECENT,
    Default = ESGM_APPROXIMATION_DEFAULT,
    Linear = ESGM_APPROXIMATION_LINEAR,
    LinearStrict = ESGM_APPROXIMATION_LINEAR_STRICT,
};
/// The seed's MOST_RECENT_VALUE_APPROXIMATION.
constexpr Approximation MOST_RECENT_VALUE_APPROXIMATION = Approximation::MostRecent;

/// A trajectory of the system, by name (the seed's EntityTrajectoryStructure).
class Trajectory {
public:
    explicit Trajectory(esgm_trajectory_t h) : h_(h) {}
    Trajectory(const Trajectory& o) : h_(o.clone()) {}
    Trajectory& operator=(const Trajectory& o) {
        if (this != &o) {
            h_ = Owned(o.clone());
        }
        return *this;
    }
    Trajectory(Trajectory&&) noexcept = default;
    Trajectory& operator=(Trajectory&&) noexcept = default;

    std::string name() const {
        esgm_str_t n{};
        detail::check(esgm_trajectory_name(h_.get(), &n));
        return std::string(detail::view(n));
    }
    /// Its type.
    Type type() const {
        esgm_type_t t{};
        detail::check(esgm_trajectory_type(h_.get(), &t));
        detail::Owned<esgm_type_t, esgm_type_free> owned(t);
        return Type::from_c(t);
    }
    /// Its policy (pol), as JSON.
    std::string policy_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_trajectory_policy_json(h_.get(), b, c, l);
        });
    }
    Time start_time() const {
        Time t = 0;
        detail::check(esgm_trajectory_start_time(h_.get(), &t));
        return t;
    }
    Time end_time() const {
        Time t = 0;
        detail::check(esgm_trajectory_end_time(h_.get(), &t));
        return t;
    }

    // T1, T2: queries (ValueNotAvailable where nothing answers).
    Sample get_latest() const {
        return one([&](esgm_sample_t* s) { return esgm_get_latest(h_.get(), s); });
    }
    Sample get_latest_vtime() const {
        return one([&](esgm_sample_t* s) { return esgm_get_latest_vtime(h_.get(), s); });
    }
    Sample get_nth_latest(std::size_t n) const {
        return one([&](esgm_sample_t* s) { return esgm_get_nth_latest(h_.get(), n, s); });
    }
    Sample get_at(Time t) const {
        return one([&](esgm_sample_t* s) { return esgm_get_at(h_.get(), t, s); });
    }
    Sample get_closest_at_or_before(Time t) const {
        return one(
            [&](esgm_sample_t* s) { return esgm_get_closest_at_or_before(h_.get(), t, s); });
    }
    std::vector<Sample> get_between(Time from, Time to) const {
        esgm_sample_list_t l{};
        detail::check(esgm_get_between(h_.get(), from, to, &l));
        detail::Owned<esgm_sample_list_t, esgm_sample_list_free> list(l);
        size_t n = 0;
        detail::check(esgm_sample_list_len(l, &n));
        std::vector<Sample> out;
        out.reserve(n);
        for (size_t i = 0; i < n; i++) {
            esgm_sample_t s{};
            detail::check(esgm_sample_list_get(l, i, &s));
            out.emplace_back(s);
        }
        return out;
    }
    Sample get_at_approximating(Time t, Approximation aprx) const {
        return one([&](esgm_sample_t* s) {
            return esgm_get_at_approximating(h_.get(), t, static_cast<std::int32_t>(aprx),
                                             esgm_structure_t{}, s);
        });
    }
    /// The default-value approximation: `fallback`'s attributes, valid at `t`.
    Sample get_at_approximating(Time t, const Structure& fallback) const {
        return one([&](esgm_sample_t* s) {
            return esgm_get_at_approximating(h_.get(), t, ESGM_APPROXIMATION_DEFAULT,
                                             fallback.get(), s);
        });
    }

    // T3, C7
    Subscription subscribe(std::size_t queue = 64, std::size_t last = 0) const {
        esgm_subscription_t s{};
        detail::check(esgm_subscribe(h_.get(), queue, last, &s));
        return Subscription(s);
    }
    Violations subscribe_violations(std::size_t queue = 64) const {
        esgm_violations_t v{};
        detail::check(esgm_subscribe_violations(h_.get(), queue, &v));
        return Violations(v);
    }

    // T4: adds (the structure is taken).
    Outcome add(Structure&& s) { return added(esgm_add, std::move(s)); }
    Outcome add_blocking(Structure&& s) { return added(esgm_add_blocking, std::move(s)); }
    /// Adds a typed struct (ESGM_ENTITY) as a structure `name` valid at `valid_time`.
    /// Adds a typed struct (ESGM_ENTITY) as a structure `name` valid at `valid_time`
    /// (created then too, unless `create_time`): one call into esgm.
    template <class T, class = std::enable_if_t<detail::is_entity<T>::value>>
    Outcome add(const T& value, std::string_view name, Time valid_time,
                std::optional<Time> create_time = std::nullopt) {
        return add_values(esgm_add_values, value, name, valid_time, create_time);
    }
    template <class T, class = std::enable_if_t<detail::is_entity<T>::value>>
    Outcome add_blocking(const T& value, std::string_view name, Time valid_time,
                         std::optional<Time> create_time = std::nullopt) {
        return add_values(esgm_add_values_blocking, value, name, valid_time, create_time);
    }
    Outcome create_at(std::string_view name, Time valid_time, Structure&& attributes) {
        std::int32_t o = 0;
        detail::check(esgm_create_at(h_.get(), detail::z(name).c_str(), valid_time,
                                     attributes.release(), &o));
        return static_cast<Outcome>(o);
    }
    Outcome create_at_blocking(std::string_view name, Time valid_time, Structure&& attributes) {
        std::int32_t o = 0;
        detail::check(esgm_create_at_blocking(h_.get(), detail::z(name).c_str(), valid_time,
                                              attributes.release(), &o));
        return static_cast<Outcome>(o);
    }
    Outcome create_at_now(std::string_view name, Structure&& attributes) {
        std::int32_t o = 0;
        detail::check(
            esgm_create_at_now(h_.get(), detail::z(name).c_str(), attributes.release(), &o));
        return static_cast<Outcome>(o);
    }
    Outcome create_at_now_blocking(std::string_view name, Structure&& attributes) {
        std::int32_t o = 0;
        detail::check(esgm_create_at_now_blocking(h_.get(), detail::z(name).c_str(),
                                                  attributes.release(), &o));
        return static_cast<Outcome>(o);
    }
    /// Typed create_at_now (ESGM_ENTITY).
    template <class T, class = std::enable_if_t<detail::is_entity<T>::value>>
    Outcome create_at_now(std::string_view name, const T& value) {
        return create_at_now(name, Entity<T>::to_frame(value));
    }

    /// A loan of the trajectory's memory for one image (its shared memory when this
    /// process writes it).
    ImageLoan image_loan(std::int64_t width, std::int64_t height,
                         ImageFormat format = ImageFormat::Rgb8) {
        esgm_image_loan_t l{};
        detail::check(esgm_trajectory_image_loan(h_.get(), width, height,
                                                 static_cast<std::int32_t>(format), &l));
        return ImageLoan(l);
    }

    // T5, E7
    void reset() { detail::check(esgm_trajectory_reset(h_.get())); }
    void reset_blocking() { detail::check(esgm_trajectory_reset_blocking(h_.get())); }
    esgm_trajectory_stats_t stats() const {
        esgm_trajectory_stats_t s{};
        detail::check(esgm_trajectory_stats(h_.get(), &s));
        return s;
    }
    std::string stats_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_trajectory_stats_json(h_.get(), b, c, l);
        });
    }

    esgm_trajectory_t get() const noexcept { return h_.get(); }

private:
    using Owned = detail::Owned<esgm_trajectory_t, esgm_trajectory_free>;
    Owned h_;

    esgm_trajectory_t clone() const {
        esgm_trajectory_t c{};
        detail::check(esgm_trajectory_clone(h_.get(), &c));
        return c;
    }
    template <class F>
    Sample one(F&& query) const {
        esgm_sample_t s{};
        detail::check(query(&s));
        return Sample(s);
    }
    template <class T>
    Outcome add_values(esgm_status (*f)(esgm_trajectory_t, const char*, std::int64_t,
                                        std::int64_t, const esgm_value_t*, size_t,
                                        std::int32_t*),
                       const T& value, std::string_view name, Time valid_time,
                       std::optional<Time> create_time) {
        detail::ValueList values;
        Entity<T>::put_values(value, values);
        std::int32_t o = 0;
        const std::string n(name);
        esgm_status st = f(h_.get(), n.c_str(), valid_time, create_time.value_or(valid_time),
                           values.data(), values.size(), &o);
        values.handed_over();
        detail::check(st);
        return static_cast<Outcome>(o);
    }
    Outcome added(esgm_status (*f)(esgm_trajectory_t, esgm_structure_t, std::int32_t*),
                  Structure&& s) {
        std::int32_t o = 0;
        detail::check(f(h_.get(), s.release(), &o));
        return static_cast<Outcome>(o);
    }
};

// ---------------------------------------------------------------------------------
// Specs: every kind of trajectory with every policy setting

/// C1: what must differ between consecutive samples.
enum class Change : std::int32_t {
    None = ESGM_CHANGE_NONE,
    AnyChange = ESGM_CHANGE_ANY_CHANGE,
    AnyUpdate = ESGM_CHANGE_ANY_UPDATE,
    SampleEvery = ESGM_CHANGE_SAMPLE_EVERY,
};
/// C5: how consecutive valid times relate.
enum class Order : std::int32_t {
    Any = ESGM_ORDER_ANY,
    Monotone = ESGM_ORDER_MONOTONE,
    StrictMonotone = ESGM_ORDER_STRICT_MONOTONE,
};

namespace detail {
inline std::vector<const char*> c_strings(const std::vector<std::string>& v) {
    std::vector<const char*> out;
    out.reserve(v.size());
    for (const std::string& s : v) {
        out.push_back(s.c_str());
    }
    return out;
}
}  // namespace detail

/// A trajectory described in full (its source and its policy), for
/// Esgm::create_trajectory. Setters chain.
class Spec {
public:
    /// Pushed by programs (E2).
    static Spec primitive(std::string_view name, std::string_view type_name) {
        esgm_spec_t s{};
        detail::check(esgm_spec_primitive(detail::z(name).c_str(), detail::z(type_name).c_str(), &s));
        return Spec(s);
    }
    /// Sampled from `sensor` every `period` (E3).
    static Spec sampled(std::string_view name, std::string_view sensor, Time period) {
        esgm_spec_t s{};
        detail::check(
            esgm_spec_sampled(detail::z(name).c_str(), detail::z(sensor).c_str(), period, &s));
        return Spec(s);
    }
    /// Computed by `unit` from `inputs` (E4).
    static Spec computed(std::string_view name, std::string_view unit,
                         const std::vector<std::string>& inputs) {
        auto in = detail::c_strings(inputs);
        esgm_spec_t s{};
        detail::check(esgm_spec_computed(detail::z(name).c_str(), detail::z(unit).c_str(),
                                         in.data(), in.size(), &s));
        return Spec(s);
    }
    /// States of one sample of each input valid at the same time (G2): exact, or within
    /// `tolerance` ("approximate" as ROS message_filters, or "epsilon").
    static Spec sync(std::string_view name, const std::vector<std::string>& inputs,
                     std::optional<Time> tolerance = std::nullopt,
                     const char* policy = nullptr, std::size_t queue = 10) {
        auto in = detail::c_strings(inputs);
        esgm_spec_t s{};
        detail::check(esgm_spec_sync(detail::z(name).c_str(), in.data(), in.size(), policy,
                                     tolerance.value_or(-1), queue, &s));
        return Spec(s);
    }
    /// Every sample of `inputs` (G3).
    static Spec merge(std::string_view name, const std::vector<std::string>& inputs) {
        auto in = detail::c_strings(inputs);
        esgm_spec_t s{};
        detail::check(esgm_spec_merge(detail::z(name).c_str(), in.data(), in.size(), &s));
        return Spec(s);
    }
    /// Sampled every `period` from fluent generators "TRAJ[:APPROXIMATION[:MERGE]]" (G4),
    /// through `unit`'s temporal function if given.
    static Spec generated(std::string_view name, const std::vector<std::string>& generators,
                          Time period, std::optional<std::string> unit = std::nullopt) {
        auto in = detail::c_strings(generators);
        esgm_spec_t s{};
        detail::check(esgm_spec_generated(detail::z(name).c_str(), in.data(), in.size(), period,
                                          unit ? unit->c_str() : nullptr, &s));
        return Spec(s);
    }

    Spec& cache(std::size_t n) { return ok(esgm_spec_cache_count(h_.get(), n)); }
    Spec& cache_all() { return ok(esgm_spec_cache_all(h_.get())); }
    Spec& cache_for(Time span) { return ok(esgm_spec_cache_duration(h_.get(), span)); }
    Spec& change(Change c, Time period = 0) {
        return ok(esgm_spec_change(h_.get(), static_cast<std::int32_t>(c), period));
    }
    Spec& filter(std::string_view expression) {
        return ok(esgm_spec_filter(h_.get(), detail::z(expression).c_str()));
    }
    Spec& duration(Time from, Time to) { return ok(esgm_spec_duration(h_.get(), from, to)); }
    Spec& order(Order o) {
        return ok(esgm_spec_order(h_.get(), static_cast<std::int32_t>(o)));
    }
    Spec& delay(Time max_delay) { return ok(esgm_spec_delay(h_.get(), max_delay)); }
    Spec& reorder(bool on) { return ok(esgm_spec_reorder(h_.get(), on)); }
    Spec& readers(std::size_t n) { return ok(esgm_spec_readers(h_.get(), n)); }
    Spec& replace(bool on = true) { return ok(esgm_spec_replace(h_.get(), on)); }
    Spec& between(Time from, Time to) { return ok(esgm_spec_between(h_.get(), from, to)); }
    Spec& lag(Time lag) { return ok(esgm_spec_lag(h_.get(), lag)); }

    esgm_spec_t get() const noexcept { return h_.get(); }

private:
    explicit Spec(esgm_spec_t h) : h_(h) {}
    Spec& ok(esgm_status st) {
        detail::check(st);
        return *this;
    }
    detail::Owned<esgm_spec_t, esgm_spec_free> h_;
};

// ---------------------------------------------------------------------------------
// Computational units and sensors

/// The inputs of a unit's call: one sample per input trajectory, in input order.
using Inputs = std::vector<Sample>;

/// A computational unit as a class (seed 2.3): compute returns the output, or nullopt
/// (or throws ValueNotAvailable) for none this time. Any other exception is a failed
/// call: logged and counted, never fatal.
class CompUnit {
public:
    virtual ~CompUnit() = default;
    virtual std::optional<Structure> compute(const Inputs& inputs, Time qtime) = 0;
    /// A temporal function for generated trajectories (optional).
    virtual std::optional<Structure> compute_at(const Inputs& inputs, Time t) {
        (void)inputs;
        (void)t;
        throw OperationNotSupported("compute_at");
    }
};

/// What a sensor's call may use: loans of the sampled trajectory's memory.
class SensorContext {
public:
    explicit SensorContext(esgm_sensor_context_t h) noexcept : h_(h) {}
    /// A loan for one image: render the frame into it, set it as the structure's image.
    ImageLoan image_loan(std::int64_t width, std::int64_t height,
                         ImageFormat format = ImageFormat::Rgb8) const {
        esgm_image_loan_t l{};
        detail::check(esgm_sensor_image_loan(h_, width, height,
                                             static_cast<std::int32_t>(format), &l));
        return ImageLoan(l);
    }

private:
    esgm_sensor_context_t h_;
};

/// A pull sensor as a class (seed 2.2): called at each sample time with the scheduled
/// time (stamp the structure's valid time with it).
class SensorInterface {
public:
    virtual ~SensorInterface() = default;
    virtual Structure get_current_value(Time qtime, SensorContext& context) = 0;
};

namespace detail {

/// Runs a user's callback for the C ABI: its answer becomes `*out` and a status; no
/// exception crosses into C.
template <class F>
std::int32_t answer(esgm_structure_t* out, F&& call) noexcept {
    try {
        std::optional<Structure> result = call();
        if (!result) {
            return ESGM_VALUE_NOT_AVAILABLE;
        }
        *out = result->release();
        return ESGM_OK;
    } catch (const ValueNotAvailable&) {
        return ESGM_VALUE_NOT_AVAILABLE;
    } catch (const Error& e) {
        esgm_set_last_error_message(e.what());
        return e.status() == ESGM_OK ? ESGM_ERROR : e.status();
    } catch (const std::exception& e) {
        esgm_set_last_error_message(e.what());
        return ESGM_ERROR;
    } catch (...) {
        esgm_set_last_error_message("an exception that is not a std::exception");
        return ESGM_ERROR;
    }
}

inline Inputs borrowed(const esgm_sample_t* inputs, size_t n) {
    Inputs in;
    in.reserve(n);
    for (size_t i = 0; i < n; i++) {
        in.push_back(Sample::borrow(inputs[i]));
    }
    return in;
}

/// A unit's result as optional: a Structure, or an optional of one.
template <class R>
std::optional<Structure> optional_of(R&& r) {
    if constexpr (std::is_same_v<std::decay_t<R>, Structure>) {
        return std::optional<Structure>(std::forward<R>(r));
    } else {
        return std::forward<R>(r);
    }
}

struct UnitBox {
    std::function<std::optional<Structure>(const Inputs&, Time)> compute;
    std::function<std::optional<Structure>(const Inputs&, Time)> compute_at;
};

extern "C" inline std::int32_t esgm_cpp_compute(void* user, const esgm_sample_t* inputs,
                                                size_t n, std::int64_t time,
                                                esgm_structure_t* out) {
    auto* box = static_cast<UnitBox*>(user);
    return answer(out, [&] { return box->compute(borrowed(inputs, n), time); });
}
extern "C" inline std::int32_t esgm_cpp_compute_at(void* user, const esgm_sample_t* inputs,
                                                   size_t n, std::int64_t time,
                                                   esgm_structure_t* out) {
    auto* box = static_cast<UnitBox*>(user);
    return answer(out, [&] { return box->compute_at(borrowed(inputs, n), time); });
}
extern "C" inline void esgm_cpp_free_unit(void* user) { delete static_cast<UnitBox*>(user); }

struct SensorBox {
    std::function<Structure(Time, SensorContext&)> get;
};

extern "C" inline std::int32_t esgm_cpp_sensor(void* user, std::int64_t qtime,
                                               esgm_sensor_context_t ctx,
                                               esgm_structure_t* out) {
    auto* box = static_cast<SensorBox*>(user);
    return answer(out, [&] {
        SensorContext context(ctx);
        return std::optional<Structure>(box->get(qtime, context));
    });
}
extern "C" inline void esgm_cpp_free_sensor(void* user) { delete static_cast<SensorBox*>(user); }

}  // namespace detail

// ---------------------------------------------------------------------------------
// The ESGM

/// Log levels for Esgm::set_log_level.
enum class LogLevel : std::int32_t {
    Error = ESGM_LOG_ERROR,
    Warn = ESGM_LOG_WARN,
    Info = ESGM_LOG_INFO,
    Debug = ESGM_LOG_DEBUG,
    Trace = ESGM_LOG_TRACE,
};

/// The ESGM (the seed's Esgm interface): a system of processes joined through shared
/// memory, or one in this process. Freed (left) when it goes: its units' and sensors'
/// calls end first.
class Esgm {
public:
    /// Joins the system of `domain` (empty: ESGM_DOMAIN from the environment, else
    /// "esgm"); Unavailable when no coordinator answers (`esgm up`).
    static Esgm connect(std::string_view domain = {}) {
        esgm_t e{};
        const std::string d(domain);
        detail::check(esgm_connect(domain.empty() ? nullptr : d.c_str(), &e));
        return Esgm(e);
    }
    /// Joins the system a supervisor started this process for (a program a system file
    /// declares): domain and name from the environment.
    static Esgm connect_from_env() {
        esgm_t e{};
        detail::check(esgm_connect_from_env(&e));
        return Esgm(e);
    }
    /// An ESGM in this process.
    static Esgm in_process() {
        esgm_t e{};
        detail::check(esgm_in_process(&e));
        return Esgm(e);
    }
    /// The name a supervisor declared this program's unit or sensor under
    /// (ESGM_NAME), or `fallback`.
    static std::string declared_name(std::string_view fallback) {
        const char* n = std::getenv("ESGM_NAME");
        return n != nullptr && *n != '\0' ? std::string(n) : std::string(fallback);
    }
    /// Logs esgm's messages to stderr (RUST_LOG, default warnings).
    static void init_logging() { detail::check(esgm_init_logging()); }

    // E1
    void create_entity_structure_type(std::string_view type_name, const Type& type) {
        auto t = type.to_c();
        detail::check(esgm_create_entity_structure_type(h_.get(), detail::z(type_name).c_str(), t.get()));
    }
    void create_type(const Type& type) {
        auto t = type.to_c();
        detail::check(esgm_create_type(h_.get(), t.get()));
    }
    /// Registers a typed struct's type (ESGM_ENTITY). The same type registered already
    /// (by this program earlier, another process or esgm's library) is fine; another
    /// definition under its name is EntityStructureTypeAlreadyExists.
    template <class T>
    void create_type() {
        const Type wanted = Entity<T>::type();
        try {
            create_type(wanted);
        } catch (const EntityStructureTypeAlreadyExists&) {
            const Type there = get_entity_structure_type(wanted.name());
            const auto& a = wanted.attributes();
            const auto& b = there.attributes();
            const bool same = a.size() == b.size() &&
                std::equal(a.begin(), a.end(), b.begin(), [](const Attribute& x, const Attribute& y) {
                    return x.name == y.name && x.sort == y.sort && x.element_type == y.element_type;
                });
            if (!same) throw;
        }
    }
    void destroy_entity_structure_type(std::string_view type_name) {
        detail::check(esgm_destroy_entity_structure_type(h_.get(), detail::z(type_name).c_str()));
    }
    Type get_entity_structure_type(std::string_view type_name) const {
        esgm_type_t t{};
        detail::check(esgm_get_entity_structure_type(h_.get(), detail::z(type_name).c_str(), &t));
        detail::Owned<esgm_type_t, esgm_type_free> owned(t);
        return Type::from_c(t);
    }

    // E2–E5
    Trajectory create_primitive_entity_trajectory_structure(std::string_view name,
                                                            std::string_view type_name) {
        esgm_trajectory_t t{};
        detail::check(esgm_create_primitive_entity_trajectory_structure(
            h_.get(), detail::z(name).c_str(), detail::z(type_name).c_str(), &t));
        return Trajectory(t);
    }
    Trajectory create_entity_trajectory_structure(std::string_view name, std::string_view sensor,
                                                  Time from, Time to, Time sample_period,
                                                  Time delay, std::int64_t cache_size) {
        esgm_trajectory_t t{};
        detail::check(esgm_create_entity_trajectory_structure(
            h_.get(), detail::z(name).c_str(), detail::z(sensor).c_str(), from, to,
            sample_period, delay, cache_size, &t));
        return Trajectory(t);
    }
    Trajectory create_computed_entity_trajectory_structure(
        std::string_view name, std::string_view cu, const std::vector<std::string>& inputs) {
        auto in = detail::c_strings(inputs);
        esgm_trajectory_t t{};
        detail::check(esgm_create_computed_entity_trajectory_structure(
            h_.get(), detail::z(name).c_str(), detail::z(cu).c_str(), in.data(), in.size(), &t));
        return Trajectory(t);
    }
    Trajectory create_trajectory(const Spec& spec) {
        esgm_trajectory_t t{};
        detail::check(esgm_create_trajectory(h_.get(), spec.get(), &t));
        return Trajectory(t);
    }
    Trajectory get_entity_trajectory_structure(std::string_view name) const {
        esgm_trajectory_t t{};
        detail::check(esgm_get_entity_trajectory_structure(h_.get(), detail::z(name).c_str(), &t));
        return Trajectory(t);
    }
    Type get_entity_trajectory_structure_type(std::string_view name) const {
        esgm_type_t t{};
        detail::check(
            esgm_get_entity_trajectory_structure_type(h_.get(), detail::z(name).c_str(), &t));
        detail::Owned<esgm_type_t, esgm_type_free> owned(t);
        return Type::from_c(t);
    }
    void destroy_entity_trajectory_structure(std::string_view name) {
        detail::check(esgm_destroy_entity_trajectory_structure(h_.get(), detail::z(name).c_str()));
    }
    /// Every trajectory, as JSON.
    std::string trajectories_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_trajectories_json(h_.get(), b, c, l);
        });
    }

    // E6: units and sensors, as lambdas or classes.
    /// A unit from a callable `(const Inputs&, Time) -> Structure | std::optional<Structure>`
    /// (throw ValueNotAvailable, or return nullopt, for no output).
    template <class F, class = std::enable_if_t<std::is_invocable_v<F&, const Inputs&, Time>>>
    void add_comp_unit(std::string_view name, std::string_view type_name,
                       const std::vector<std::string>& input_types, F compute) {
        auto box = std::make_unique<detail::UnitBox>();
        box->compute = [f = std::move(compute)](const Inputs& in, Time t) mutable {
            return detail::optional_of(f(in, t));
        };
        box->compute_at = [](const Inputs&, Time) -> std::optional<Structure> {
            throw OperationNotSupported("compute_at");
        };
        register_unit(name, type_name, input_types, std::move(box), false);
    }
    /// A unit from a class (shared: esgm keeps it while it may call it).
    void add_comp_unit(std::string_view name, std::string_view type_name,
                       const std::vector<std::string>& input_types,
                       std::shared_ptr<CompUnit> unit) {
        auto box = std::make_unique<detail::UnitBox>();
        box->compute = [unit](const Inputs& in, Time t) { return unit->compute(in, t); };
        box->compute_at = [unit](const Inputs& in, Time t) { return unit->compute_at(in, t); };
        register_unit(name, type_name, input_types, std::move(box), true);
    }
    void remove_comp_unit(std::string_view name) {
        detail::check(esgm_remove_comp_unit(h_.get(), detail::z(name).c_str()));
    }
    /// A sensor from a callable `(Time qtime, SensorContext&) -> Structure` or
    /// `(Time qtime) -> Structure`.
    template <class F, class = std::enable_if_t<std::is_invocable_v<F&, Time, SensorContext&> ||
                                                std::is_invocable_v<F&, Time>>>
    void add_sensor_interface(std::string_view name, std::string_view type_name, F get) {
        auto box = std::make_unique<detail::SensorBox>();
        if constexpr (std::is_invocable_v<F&, Time, SensorContext&>) {
            box->get = std::move(get);
        } else {
            box->get = [f = std::move(get)](Time q, SensorContext&) mutable { return f(q); };
        }
        register_sensor(name, type_name, std::move(box));
    }
    /// A sensor from a class.
    void add_sensor_interface(std::string_view name, std::string_view type_name,
                              std::shared_ptr<SensorInterface> sensor) {
        auto box = std::make_unique<detail::SensorBox>();
        box->get = [sensor](Time q, SensorContext& c) { return sensor->get_current_value(q, c); };
        register_sensor(name, type_name, std::move(box));
    }
    void remove_sensor_interface(std::string_view name) {
        detail::check(esgm_remove_sensor_interface(h_.get(), detail::z(name).c_str()));
    }

    // E7
    bool ping() const {
        bool alive = false;
        detail::check(esgm_ping(h_.get(), &alive));
        return alive;
    }
    void reset() { detail::check(esgm_reset(h_.get())); }
    template <class Rep = std::int64_t, class Period = std::nano>
    void flush(std::chrono::duration<Rep, Period> timeout = std::chrono::seconds(10)) {
        detail::check(esgm_flush(h_.get(), to_time(timeout)));
    }
    std::string stats_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_stats_json(h_.get(), b, c, l);
        });
    }
    std::string memory_stats_json() const {
        return detail::copied([&](char* b, size_t c, size_t* l) {
            return esgm_memory_stats_json(h_.get(), b, c, l);
        });
    }
    void set_log_level(LogLevel level) {
        detail::check(esgm_set_log_level(h_.get(), static_cast<std::int32_t>(level)));
    }
    std::string domain_name() const {
        esgm_str_t n{};
        detail::check(esgm_domain_name(h_.get(), &n));
        return std::string(detail::view(n));
    }
    /// Serves this process's units and sensors until the system ends (its coordinator
    /// gone for `patience`): a worker's main loop.
    template <class Rep = std::int64_t, class Period = std::nano>
    void serve(std::chrono::duration<Rep, Period> patience = std::chrono::milliseconds(500)) {
        detail::check(esgm_serve(h_.get(), to_time(patience)));
    }

    esgm_t get() const noexcept { return h_.get(); }

private:
    explicit Esgm(esgm_t h) : h_(h) {}
    detail::Owned<esgm_t, esgm_free> h_;

    void register_unit(std::string_view name, std::string_view type_name,
                       const std::vector<std::string>& input_types,
                       std::unique_ptr<detail::UnitBox> box, bool with_compute_at) {
        auto in = detail::c_strings(input_types);
        // The C ABI owns the box from here on and deletes it when done, failure
        // included.
        detail::check(esgm_add_comp_unit(
            h_.get(), detail::z(name).c_str(), detail::z(type_name).c_str(), in.data(),
            in.size(), detail::esgm_cpp_compute,
            with_compute_at ? detail::esgm_cpp_compute_at : nullptr, box.release(),
            detail::esgm_cpp_free_unit));
    }
    void register_sensor(std::string_view name, std::string_view type_name,
                         std::unique_ptr<detail::SensorBox> box) {
        detail::check(esgm_add_sensor_interface(h_.get(), detail::z(name).c_str(),
                                                detail::z(type_name).c_str(),
                                                detail::esgm_cpp_sensor, box.release(),
                                                detail::esgm_cpp_free_sensor));
    }
};

}  // namespace esgm

#endif  // ESGM_ESGM_HPP
