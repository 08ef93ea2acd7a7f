// firefly: opt-in adapters for glm::vec3 / glm::vec4 images (float or double).
// The core headers never include GLM; include this one where your buffers are GLM vectors.
#pragma once

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "image_view.hpp"

namespace firefly {

template <int N, class T, glm::qualifier Q>
struct pixel_traits<glm::vec<N, T, Q>> {
    static_assert(N == 3 || N == 4, "firefly/glm.hpp adapts glm::vec3 and glm::vec4");
    static constexpr bool is_specialized = true;
    using channel_type = T;
    static constexpr int channels = N;
};

// A view over a row-major array of glm::vec3 (3 channels) or glm::vec4 (4 channels:
// colour in 0..2, alpha or padding in 3). row_stride in bytes, auto_stride when packed.
template <int N, class T, glm::qualifier Q>
auto make_glm_view(glm::vec<N, T, Q>* pixels, int width, int height,
                   std::ptrdiff_t row_stride = auto_stride) noexcept {
    return make_pixel_view(pixels, width, height, row_stride);
}
template <int N, class T, glm::qualifier Q>
auto make_glm_view(const glm::vec<N, T, Q>* pixels, int width, int height,
                   std::ptrdiff_t row_stride = auto_stride) noexcept {
    return make_pixel_view(pixels, width, height, row_stride);
}

}  // namespace firefly
