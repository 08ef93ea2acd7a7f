// Test helper: K simulated (or hand-made) buffers with views over them, and one mask per
// buffer, for the K-buffer detector's tests and fuzz targets.
#pragma once

#include <firefly/buffers.hpp>
#include <firefly/sim/types.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace firefly_test {

struct frame_k {
    int w = 0, h = 0;
    std::vector<std::vector<float>> color, variance;
    std::vector<firefly::buffer_view<float>> views(bool with_variance = true) {
        std::vector<firefly::buffer_view<float>> v;
        for (std::size_t b = 0; b < color.size(); ++b)
            v.push_back({*firefly::make_image_view(color[b].data(), w, h, 3),
                         with_variance ? *firefly::make_image_view(variance[b].data(), w, h, 3)
                                       : firefly::image_view<float>{}});
        return v;
    }
};

// One frame-sized mask per buffer, each byte `fill`, and the views the detector writes them
// through.
struct masks_k {
    std::vector<std::vector<std::uint8_t>> mem;
    std::vector<firefly::image_view<std::uint8_t>> views;
    masks_k(int k, int w, int h, std::uint8_t fill = 0)
        : mem(static_cast<std::size_t>(k), std::vector<std::uint8_t>(static_cast<std::size_t>(w * h), fill)) {
        for (auto& m : mem) views.push_back(*firefly::make_image_view(m.data(), w, h));
    }
    masks_k(const masks_k&) = delete;  // the views point into mem
    masks_k& operator=(const masks_k&) = delete;
};

inline frame_k from_sim(const firefly::sim::buffers& f) {
    frame_k r;
    r.w = f.width;
    r.h = f.height;
    r.color = f.color;
    r.variance = f.variance;
    return r;
}

}  // namespace firefly_test
