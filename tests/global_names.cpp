// The library's entry points instantiated where a renderer's global names are visible: Imath's
// half.h (OpenEXR 3) declares `using half = Imath::half;` at global scope, and a local named
// `half` inside a firefly template then broke -Wshadow -Werror builds of any file including both.
// Compiled (not run) with the header checks' flags; see tests/CMakeLists.txt.
#include "half_float.hpp"

using half = firefly_examples::half16;  // a global `half`, as Imath's half.h declares one

#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/scenes.hpp>

#include <cstdint>
#include <vector>

namespace {

template <class C, class V>
bool two_halves(std::vector<C>& ca, std::vector<V>& va, std::vector<C>& cb, std::vector<V>& vb, int w, int h) {
    using namespace firefly;
    half_buffer<C, V> a{*make_image_view(ca.data(), w, h, 3), *make_image_view(va.data(), w, h, 3), {}};
    half_buffer<C, V> b{*make_image_view(cb.data(), w, h, 3), *make_image_view(vb.data(), w, h, 3), {}};
    std::vector<std::uint8_t> ma(ca.size() / 3), mb(ma.size());
    detector d(detector_options{}, executor::threads(2));
    const frame_report r = d.process(a, b, *make_image_view(ma.data(), w, h), *make_image_view(mb.data(), w, h));
    const frame_report s = d.detect(half_buffer<const C, const V>{a.color, a.variance, {}},
                                    half_buffer<const C, const V>{b.color, b.variance, {}});
    std::vector<C> out(ca.size());
    return r.ok() && s.ok() && combine_halves(a.color, b.color, *make_image_view(out.data(), w, h, 3)).ok();
}

template <class T>
bool k_buffers(std::vector<std::vector<T>>& colour, std::vector<std::vector<T>>& variance, int w, int h) {
    using namespace firefly;
    std::vector<buffer_view<T>> views;
    for (std::size_t i = 0; i < colour.size(); ++i)
        views.push_back({*make_image_view(colour[i].data(), w, h, 3), *make_image_view(variance[i].data(), w, h, 3)});
    cross_buffer_detector det;
    sample_accumulator acc;
    return det.process(views).error.ok() && acc.reset(w, h, 4).ok();
}

}  // namespace

#ifndef FIREFLY_GLOBAL_NAMES_TU
#define FIREFLY_GLOBAL_NAMES_TU firefly_global_names_tu
#endif
int FIREFLY_GLOBAL_NAMES_TU() {
    const int w = 8, h = 8;
    std::vector<float> c(w * h * 3, 0.5f), v(c.size(), 0.01f), c2 = c, v2 = v;
    std::vector<double> dc(c.begin(), c.end()), dv(v.begin(), v.end()), dc2 = dc, dv2 = dv;
    std::vector<half> hv(c.size(), firefly_examples::to_half(0.01f)), hv2 = hv;
    std::vector<std::vector<float>> kc(4, c), kv(4, v);
    std::vector<std::vector<double>> kdc(4, dc), kdv(4, dv);
    const firefly::sim::frame f = firefly::sim::simulate(firefly::sim::named_scene("production", 16, 16));
    return two_halves(c, v, c2, v2, w, h) + two_halves(dc, dv, dc2, dv2, w, h) + two_halves(c, hv, c2, hv2, w, h) +
           k_buffers(kc, kv, w, h) + k_buffers(kdc, kdv, w, h) + f.width;
}
