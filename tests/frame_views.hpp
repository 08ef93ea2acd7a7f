// Test helper: a simulated frame with half_buffer views over its two halves.
#pragma once

#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

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

    // Both halves cleaned (process) or checked (detect) by d, each half's mask written into
    // mask[half] (frame-sized, zeroed first).
    std::vector<std::uint8_t> mask[2];
    template <class Detector>
    firefly::frame_report process(Detector& d) {
        return d.process(h[0], h[1], zeroed_mask(0), zeroed_mask(1));
    }
    template <class Detector>
    firefly::frame_report detect(Detector& d) {
        return d.detect(h[0], h[1], zeroed_mask(0), zeroed_mask(1));
    }

private:
    firefly::image_view<std::uint8_t> zeroed_mask(int half) {
        mask[half].assign(static_cast<std::size_t>(f.width) * static_cast<std::size_t>(f.height), 0);
        return *firefly::make_image_view(mask[half].data(), f.width, f.height, 1);
    }
};

}  // namespace firefly_test
