// The tutorial's synthetic camera scene in C++: bright discs moving over a noisy dark
// background, a pure function of its seed and the time, so any process can rebuild
// the frame (and its ground truth) for any time. The same scene, pixel for pixel, as
// the Rust camera-publisher's SyntheticScene (same generator, same arithmetic), so
// `esgm demo --config tutorial_cpp.toml` checks a C++ camera against the same truth.
#ifndef ESGM_EXAMPLES_SYNTHETIC_SCENE_HPP
#define ESGM_EXAMPLES_SYNTHETIC_SCENE_HPP

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace tutorial {

/// SplitMix64's finaliser: spreads a seed over all bits.
inline std::uint64_t mix(std::uint64_t z) {
    z += 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/// xorshift64*: a small, fast, reproducible generator.
class XorShift64 {
public:
    explicit XorShift64(std::uint64_t seed) {
        std::uint64_t s = mix(seed);
        state_ = s == 0 ? 0x2545F4914F6CDD1DULL : s;
    }
    std::uint64_t next_u64() {
        std::uint64_t x = state_;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        state_ = x;
        return x * 0x2545F4914F6CDD1DULL;
    }
    /// Uniform in [0, 1).
    double next_unit() {
        return static_cast<double>(next_u64() >> 11) * (1.0 / static_cast<double>(1ULL << 53));
    }

private:
    std::uint64_t state_;
};

/// A blob the scene shows: its centre and size in pixels.
struct TrueBlob {
    std::int64_t x, y, size;
};

class SyntheticScene {
public:
    static constexpr double TAU = 6.283185307179586476925286766559;

    SyntheticScene(std::uint32_t width, std::uint32_t height, std::size_t blobs,
                   std::uint64_t seed)
        : width_(width), height_(height), seed_(seed) {
        if (width < 1 || width > 8192 || height < 1 || height > 8192) {
            throw std::invalid_argument("a " + std::to_string(width) + "x" +
                                        std::to_string(height) +
                                        " frame is not supported: each side must be 1..=8192 pixels");
        }
        const double w = width, h = height;
        std::size_t cols = 1;
        if (blobs > 0) {
            cols = static_cast<std::size_t>(std::ceil(std::sqrt(static_cast<double>(blobs) * w / h)));
            cols = std::clamp<std::size_t>(cols, 1, blobs);
        }
        const std::size_t rows = std::max<std::size_t>((blobs + cols - 1) / cols, 1);
        const double cell_w = w / static_cast<double>(cols), cell_h = h / static_cast<double>(rows);
        if (blobs > 0 && std::min(cell_w, cell_h) < MIN_CELL_SIDE) {
            throw std::invalid_argument(std::to_string(blobs) +
                                        " blobs do not fit the frame: each needs 16x16 pixels");
        }
        const double room = (std::min(cell_w, cell_h) - 1.0) / 2.0 - CELL_MARGIN;
        XorShift64 rng(seed);
        for (std::size_t i = 0; i < blobs; i++) {
            const double col = static_cast<double>(i % cols), row = static_cast<double>(i / cols);
            Disc d{};
            d.base_radius = room * (0.3 + 0.3 * rng.next_unit());
            const double max_radius = d.base_radius * (1.0 + BREATHING);
            for (auto& p : d.periods) {
                p = static_cast<std::int64_t>(4.0e9 + 12.0e9 * rng.next_unit());
            }
            for (auto& p : d.phases) {
                p = rng.next_unit() * TAU;
            }
            d.colour = PALETTE[rng.next_u64() % PALETTE.size()];
            d.home_x = col * cell_w + (cell_w - 1.0) / 2.0;
            d.home_y = row * cell_h + (cell_h - 1.0) / 2.0;
            d.amplitude_x = std::max((cell_w - 1.0) / 2.0 - CELL_MARGIN - max_radius, 0.0);
            d.amplitude_y = std::max((cell_h - 1.0) / 2.0 - CELL_MARGIN - max_radius, 0.0);
            discs_.push_back(d);
        }
    }

    std::uint32_t width() const { return width_; }
    std::uint32_t height() const { return height_; }
    std::size_t frame_len() const { return std::size_t{width_} * height_ * 3; }

    /// Paints the frame at `t` (ns) into `out` (RGB8, frame_len() bytes).
    void render_into(std::int64_t t, std::uint8_t* out, std::size_t len) const {
        if (len != frame_len()) {
            throw std::invalid_argument("a frame of " + std::to_string(frame_len()) +
                                        " bytes does not fit a buffer of " + std::to_string(len));
        }
        XorShift64 noise(mix(seed_) ^ static_cast<std::uint64_t>(t));
        for (std::size_t i = 0; i < len; i += 8) {
            const std::uint64_t word = noise.next_u64();
            for (std::size_t b = 0; b < 8 && i + b < len; b++) {
                const auto n = static_cast<std::uint8_t>(word >> (8 * b));
                out[i + b] = static_cast<std::uint8_t>(BACKGROUND_BASE + (n & BACKGROUND_NOISE_MASK));
            }
        }
        for (const Disc& d : discs_) {
            spans(d.at(t), [&](std::size_t row, std::size_t x0, std::size_t x1) {
                std::uint8_t* px = out + (row * width_ + x0) * 3;
                for (std::size_t x = x0; x <= x1; x++, px += 3) {
                    for (std::size_t c = 0; c < 3; c++) {
                        const int v = d.colour[c] - (px[c] & BLOB_NOISE_MASK);
                        px[c] = static_cast<std::uint8_t>(std::max(v, 0));
                    }
                }
            });
        }
    }

    /// The blobs the frame at `t` shows.
    std::vector<TrueBlob> truth(std::int64_t t) const {
        std::vector<TrueBlob> out;
        for (const Disc& d : discs_) {
            const Circle c = d.at(t);
            std::int64_t size = 0;
            spans(c, [&](std::size_t, std::size_t x0, std::size_t x1) {
                size += static_cast<std::int64_t>(x1 - x0 + 1);
            });
            out.push_back({static_cast<std::int64_t>(std::round(c.x)),
                           static_cast<std::int64_t>(std::round(c.y)), size});
        }
        return out;
    }

private:
    static constexpr std::uint8_t BACKGROUND_BASE = 8;
    static constexpr std::uint8_t BACKGROUND_NOISE_MASK = 0x1F;
    static constexpr std::uint8_t BLOB_NOISE_MASK = 0x0F;
    static constexpr double CELL_MARGIN = 2.0;
    static constexpr double MIN_CELL_SIDE = 16.0;
    static constexpr double BREATHING = 0.2;
    static constexpr std::array<std::array<std::uint8_t, 3>, 6> PALETTE{{
        {255, 255, 255}, {255, 255, 64}, {64, 255, 255},
        {128, 255, 128}, {255, 180, 220}, {255, 200, 80},
    }};

    struct Circle {
        double x, y, r;
    };
    struct Disc {
        double home_x, home_y, amplitude_x, amplitude_y;
        std::array<std::int64_t, 3> periods;
        std::array<double, 3> phases;
        double base_radius;
        std::array<std::uint8_t, 3> colour;

        Circle at(std::int64_t t) const {
            auto wave = [&](std::size_t k) {
                const std::int64_t period = periods[k];
                std::int64_t rem = t % period;
                if (rem < 0) {
                    rem += period;  // Euclidean remainder, as the Rust scene's rem_euclid
                }
                return std::sin(TAU * (static_cast<double>(rem) / static_cast<double>(period)) +
                                phases[k]);
            };
            return {home_x + amplitude_x * wave(0), home_y + amplitude_y * wave(1),
                    base_radius * (1.0 + BREATHING * wave(2))};
        }
    };

    /// Calls `f(row, x0, x1)` for each row of the disc `c` inside the frame.
    template <class F>
    void spans(Circle c, F&& f) const {
        const double last_col = static_cast<double>(width_) - 1.0;
        const double first_row = std::max(std::ceil(c.y - c.r), 0.0);
        const double last_row = std::min(std::floor(c.y + c.r), static_cast<double>(height_) - 1.0);
        const auto end = static_cast<std::size_t>(std::max(last_row + 1.0, first_row));
        for (auto row = static_cast<std::size_t>(first_row); row < end; row++) {
            const double dy = static_cast<double>(row) - c.y;
            const double half = std::sqrt(c.r * c.r - dy * dy);
            if (std::isnan(half)) {
                continue;
            }
            const double x0 = std::max(std::ceil(c.x - half), 0.0);
            const double x1 = std::min(std::floor(c.x + half), last_col);
            if (x0 <= x1) {
                f(row, static_cast<std::size_t>(x0), static_cast<std::size_t>(x1));
            }
        }
    }

    std::uint32_t width_, height_;
    std::uint64_t seed_;
    std::vector<Disc> discs_;
};

}  // namespace tutorial

#endif
