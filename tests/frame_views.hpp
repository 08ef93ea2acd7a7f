// Test helper: a simulated frame with half_buffer views over its two halves.
#pragma once

#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>

#include <cstddef>
#include <utility>

namespace firefly_test {

struct frame_views {
    firefly::sim::frame f;
    firefly::half_buffer<float> h[2];
    explicit frame_views(firefly::sim::frame fr) : f(std::move(fr)) {
        using firefly::make_image_view;
        for (int i = 0; i < 2; ++i) {
            h[i].color = *make_image_view(f.color[i].data(), f.width, f.height, 3);
            h[i].variance = *make_image_view(f.variance[i].data(), f.width, f.height, 3);
            if (!f.alpha.empty())
                h[i].alpha = *make_image_view(static_cast<const float*>(f.alpha.data()), f.width, f.height, 1);
        }
    }
    frame_views(const frame_views&) = delete;
    std::size_t at(int x, int y) const {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(f.width) + static_cast<std::size_t>(x);
    }
    // Every colour channel of pixel (x, y) in one half to `value`, its variance to `variance`.
    void set(int half, int x, int y, float value, float variance) {
        for (std::size_t c = 0; c < 3; ++c) {
            f.color[half][at(x, y) * 3 + c] = value;
            f.variance[half][at(x, y) * 3 + c] = variance;
        }
    }
    float col(int half, int x, int y, int c = 0) const { return f.color[half][at(x, y) * 3 + static_cast<std::size_t>(c)]; }
    float var(int half, int x, int y, int c = 0) const { return f.variance[half][at(x, y) * 3 + static_cast<std::size_t>(c)]; }
};

}  // namespace firefly_test
