// Blob detection for the C++ tutorial: pixels whose luminance (ITU-R BT.601) is above a
// threshold, grouped into 4-connected components; each component is a blob (its centre
// and size in pixels). A plain version of cu-workers' BlobDetection.
#ifndef ESGM_EXAMPLES_BLOB_DETECTION_HPP
#define ESGM_EXAMPLES_BLOB_DETECTION_HPP

#include "driving_direction.hpp"

#include <cstdint>
#include <vector>

namespace tutorial {

/// The blobs of an RGB8 image: components of pixels whose luminance is above
/// `threshold`, at least `min_size` pixels each.
inline std::vector<Blob> detect_blobs(esgm::Span<const std::uint8_t> rgb, std::int64_t width,
                                      std::int64_t height, unsigned threshold = 127,
                                      std::int64_t min_size = 10) {
    const auto w = static_cast<std::size_t>(width), h = static_cast<std::size_t>(height);
    std::vector<Blob> blobs;
    if (rgb.size() != w * h * 3) {
        return blobs;
    }
    auto bright = [&](std::size_t i) {
        const unsigned luminance =
            (77u * rgb[3 * i] + 150u * rgb[3 * i + 1] + 29u * rgb[3 * i + 2] + 128u) >> 8;
        return luminance > threshold;
    };
    std::vector<bool> seen(w * h, false);
    std::vector<std::size_t> stack;
    for (std::size_t start = 0; start < w * h; start++) {
        if (seen[start] || !bright(start)) {
            continue;
        }
        std::int64_t size = 0, sum_x = 0, sum_y = 0;
        seen[start] = true;
        stack.push_back(start);
        while (!stack.empty()) {
            const std::size_t i = stack.back();
            stack.pop_back();
            const std::size_t x = i % w, y = i / w;
            size++;
            sum_x += static_cast<std::int64_t>(x);
            sum_y += static_cast<std::int64_t>(y);
            const std::size_t next[4] = {x > 0 ? i - 1 : i, x + 1 < w ? i + 1 : i,
                                         y > 0 ? i - w : i, y + 1 < h ? i + w : i};
            for (std::size_t n : next) {
                if (!seen[n] && bright(n)) {
                    seen[n] = true;
                    stack.push_back(n);
                }
            }
        }
        if (size >= min_size) {
            blobs.push_back({(sum_x + size / 2) / size, (sum_y + size / 2) / size, size});
        }
    }
    return blobs;
}

}  // namespace tutorial

#endif
