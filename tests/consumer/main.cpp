// A consumer of firefly: cleans a tiny frame with one firefly and checks the result.
#include <firefly/firefly.hpp>

#include <cstdio>
#include <vector>

int main() {
    const int w = 32, h = 24;
    std::vector<float> ca(w * h * 3), va(w * h * 3), cb, vb;
    unsigned s = 1;
    for (std::size_t i = 0; i < ca.size(); ++i) {
        s = s * 1664525u + 1013904223u;
        ca[i] = 0.5f + static_cast<float>(s >> 9) / 8388608.0f * 0.1f;
        va[i] = 0.001f * (1.0f + static_cast<float>(s >> 20) / 4096.0f);
    }
    cb = ca;
    vb = va;
    for (int c = 0; c < 3; ++c) {
        ca[(5 * w + 7) * 3 + c] = 250.0f;
        va[(5 * w + 7) * 3 + c] = 1000.0f;
    }
    firefly::half_buffer<float> a{*firefly::make_image_view(ca.data(), w, h, 3),
                                  *firefly::make_image_view(va.data(), w, h, 3), {}};
    firefly::half_buffer<float> b{*firefly::make_image_view(cb.data(), w, h, 3),
                                  *firefly::make_image_view(vb.data(), w, h, 3), {}};
    firefly::detector d;
    const firefly::frame_report r = d.process(a, b);
    std::printf("firefly %d.%d.%d: %s, fireflies %zu\n", FIREFLY_VERSION_MAJOR, FIREFLY_VERSION_MINOR,
                FIREFLY_VERSION_PATCH, r.error.message(), r.half[0].fireflies);
    return r.error.ok() && r.half[0].fireflies == 1 && ca[(5 * w + 7) * 3] < 1.0f ? 0 : 1;
}
