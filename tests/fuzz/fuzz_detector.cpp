// libFuzzer target: firefly::detector::process on small random frames (1..16 x 1..16, 1..4
// colour channels, 1 or per-channel variance, optional alpha) in random layouts (interleaved
// in one buffer, planar, separate buffers with padded and flipped strides), float and double,
// with raw bit patterns among the values (NaN, Inf, -0, denormals, FLT_MAX).
//
// Asserts: no crash; pixels whose mask has neither the firefly nor the nonfinite bit, or has
// the left bit, are bit-identical to the input (colour, variance, alpha), except that the energy bit lets the
// first three colour channels grow (the energy return only adds light); alpha is never
// written; a frame whose inputs are all finite gives no NaN or Inf, and no pixel whose input
// colour was finite comes out NaN.
#include <firefly/firefly.hpp>
#include <fuzzer/FuzzedDataProvider.h>

#include "fuzz_values.hpp"

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

using namespace firefly;

namespace {

[[noreturn]] void fail(const char* what) { fuzz_values::fail("fuzz_detector", what); }
using fuzz_values::value;

// One image's placement inside a buffer: element offset and strides in elements.
struct placement {
    std::ptrdiff_t offset = 0, pixel = 0, row = 0, channel = 1;
};

// Storage of one half: one buffer, or one per image (colour, variance, alpha).
template <class T>
struct half_storage {
    std::vector<T> buf[3];
    placement where[3];
    int channels[3] = {0, 0, 0};
    int buffer_of[3] = {0, 1, 2};
};

// Chooses the layout of a half: 0 interleaved in one buffer, 1 planar per image, 2 separate
// interleaved buffers with padding. `flip` stores rows bottom-up (negative row stride).
template <class T>
void lay_out(FuzzedDataProvider& p, int w, int h, const int (&nch)[3], half_storage<T>& s, bool& flip) {
    const int mode = p.ConsumeIntegralInRange<int>(0, 2);
    flip = p.ConsumeBool();
    for (int k = 0; k < 3; ++k) s.channels[k] = nch[k];
    if (mode == 0) {
        const int pad = p.ConsumeIntegralInRange<int>(0, 2);
        const std::ptrdiff_t px = nch[0] + nch[1] + nch[2] + pad;
        const std::ptrdiff_t row = px * w + p.ConsumeIntegralInRange<int>(0, 3);
        s.buf[0].assign(static_cast<std::size_t>(row * h), T(0));
        std::ptrdiff_t off = 0;
        for (int k = 0; k < 3; ++k) {
            s.where[k] = {off, px, row, 1};
            s.buffer_of[k] = 0;
            off += nch[k];
        }
        return;
    }
    for (int k = 0; k < 3; ++k) {
        if (nch[k] == 0) continue;
        const std::ptrdiff_t rowpad = p.ConsumeIntegralInRange<int>(0, 3);
        if (mode == 1) {  // planar: channel c is a plane
            const std::ptrdiff_t row = w + rowpad, plane = row * h + p.ConsumeIntegralInRange<int>(0, 3);
            s.buf[k].assign(static_cast<std::size_t>(plane * nch[k]), T(0));
            s.where[k] = {0, 1, row, plane};
        } else {
            const std::ptrdiff_t px = nch[k] + p.ConsumeIntegralInRange<int>(0, 2), row = px * w + rowpad;
            s.buf[k].assign(static_cast<std::size_t>(row * h), T(0));
            s.where[k] = {0, px, row, 1};
        }
    }
}

template <class T>
T* element(half_storage<T>& s, int k, int x, int y, int c) {
    const placement& q = s.where[k];
    return s.buf[s.buffer_of[k]].data() + q.offset + y * q.row + x * q.pixel + c * q.channel;
}

template <class T>
result<image_view<T>> view_of(half_storage<T>& s, int k, int w, int h, bool flip) {
    const placement& q = s.where[k];
    const auto e = static_cast<std::ptrdiff_t>(sizeof(T));
    auto v = image_view<T>::create(element(s, k, 0, 0, 0), w, h, s.channels[k], q.pixel * e, q.row * e, q.channel * e);
    if (v.ok() && flip) return v->flipped_vertically();
    return v;
}

struct frame_shape {
    int w, h, nc, nv;
    bool alpha;
};

// The assertions on one processed frame (see the top of the file).
template <class T>
void check_frame(const frame_shape& f, const int (&nch)[3], half_storage<T> (&s)[2], half_storage<T> (&before)[2],
                 const bool (&flip)[2], const std::vector<std::uint8_t> (&mask)[2], const frame_report& r,
                 bool finite) {
    for (int i = 0; i < 2; ++i)
        for (int y = 0; y < f.h; ++y)
            for (int x = 0; x < f.w; ++x) {
                // Views may be flipped: mask row y is view row y, storage row h-1-y.
                const int sy = flip[i] ? f.h - 1 - y : y;
                const std::uint8_t m = mask[i][static_cast<std::size_t>(y * f.w + x)];
                // A refused frame writes no mask, so it may change nothing.
                // A left pixel (no usable value reached it) keeps its input.
                const bool may_change = (m & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped)) != 0 && !(m & mask_bits::left);
                if ((m & mask_bits::left) && !(m & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped)))
                    fail("a left mask without what was found");
                const bool may_grow = (m & mask_bits::energy) != 0;  // colour channels 0..2
                if (may_grow && f.alpha && !(static_cast<double>(*element(before[i], 2, x, sy, 0)) > 0))
                    fail("light added to a pixel with alpha <= 0");
                bool pixel_finite = true;  // the input colour of this pixel
                for (int c = 0; c < f.nc; ++c)
                    pixel_finite = pixel_finite && std::isfinite(static_cast<double>(*element(before[i], 0, x, sy, c)));
                for (int c = 0; c < f.nc; ++c)
                    if (pixel_finite && std::isnan(static_cast<double>(*element(s[i], 0, x, sy, c)))) {
                        std::fprintf(stderr, "half %d pixel (%d, %d) channel %d mask %d\n", i, x, y, c, m);
                        fail("NaN out of a pixel whose colour was finite");
                    }
                for (int k = 0; k < 3; ++k)
                    for (int c = 0; c < nch[k]; ++c) {
                        const T now = *element(s[i], k, x, sy, c);
                        const T was = *element(before[i], k, x, sy, c);
                        const bool same = std::memcmp(&now, &was, sizeof(T)) == 0;
                        const bool grew = k == 0 && c < 3 && may_grow && now >= was &&
                                          std::isfinite(static_cast<double>(now));  // light added, finite
                        if (!same && (k == 2 || !(may_change || grew))) {
                            std::fprintf(stderr, "half %d pixel (%d, %d) image %d channel %d mask %d; frame: %s\n", i, x,
                                         y, k, c, m, r.error.message());
                            fail("an unmarked pixel changed");
                        }
                        if (finite && !std::isfinite(static_cast<double>(now)))
                            fail("NaN or Inf out of finite input");
                    }
            }
}

template <class T>
void run(FuzzedDataProvider& p) {
    const frame_shape f{p.ConsumeIntegralInRange<int>(1, 16), p.ConsumeIntegralInRange<int>(1, 16),
                        p.ConsumeIntegralInRange<int>(1, 4), 0, p.ConsumeBool()};
    const int nv = p.ConsumeBool() ? 1 : f.nc;
    const int nch[3] = {f.nc, nv, f.alpha ? 1 : 0};
    half_storage<T> s[2];
    bool flip[2];
    for (int i = 0; i < 2; ++i) lay_out(p, f.w, f.h, nch, s[i], flip[i]);
    bool finite = true;
    for (int i = 0; i < 2; ++i)
        for (int k = 0; k < 3; ++k) {
            // Sometimes one value for a whole image (all -0, all FLT_MAX, ...): the
            // statistics' degenerate cases.
            const bool constant = p.ConsumeIntegralInRange<int>(0, 7) == 0;
            const T fixed = value<T>(p, k == 1);
            for (int y = 0; y < f.h; ++y)
                for (int x = 0; x < f.w; ++x)
                    for (int c = 0; c < nch[k]; ++c) {
                        const T v = constant ? fixed
                                    : k == 2 ? (p.ConsumeIntegralInRange<int>(0, 7) ? T(1) : value<T>(p, false))
                                             : value<T>(p, k == 1);
                        *element(s[i], k, x, y, c) = v;
                        finite = finite && std::isfinite(static_cast<double>(v));
                    }
        }
    detector_options o;
    o.highlight.rule = static_cast<highlight_rule>(p.ConsumeIntegralInRange<int>(0, 3));
    o.reduction = static_cast<variance_reduction>(p.ConsumeIntegralInRange<int>(0, 2));
    o.lambdas = static_cast<lambda_method>(p.ConsumeIntegralInRange<int>(0, 2));
    o.reconstruction.kernel_width = 3 + 2 * p.ConsumeIntegralInRange<int>(0, 2);
    o.reconstruction.max_iterations = p.ConsumeIntegralInRange<int>(0, 4);

    half_buffer<T> hb[2];
    for (int i = 0; i < 2; ++i) {
        auto c = view_of(s[i], 0, f.w, f.h, flip[i]);
        auto v = view_of(s[i], 1, f.w, f.h, flip[i]);
        if (!c.ok() || !v.ok()) fail("a layout built by the target was refused by image_view::create");
        hb[i].color = *c;
        hb[i].variance = *v;
        if (f.alpha) {
            auto a = view_of(s[i], 2, f.w, f.h, flip[i]);
            if (!a.ok()) fail("alpha layout refused");
            hb[i].alpha = *a;
        }
    }
    half_storage<T> before[2] = {s[0], s[1]};
    std::vector<std::uint8_t> mask[2];
    image_view<std::uint8_t> mv[2];
    for (int i = 0; i < 2; ++i) {
        mask[i].assign(static_cast<std::size_t>(f.w * f.h), 0);
        mv[i] = *make_image_view(mask[i].data(), f.w, f.h);
    }
    // One detector per thread count, reused like a sequence reuses it (scratch memory and
    // the lambda cache carry over; results must not depend on them), and much faster than a
    // fresh detector per input.
    static detector serial, threaded(detector_options{}, executor::threads(2));
    detector& d = p.ConsumeBool() ? threaded : serial;
    if (p.ConsumeBool()) o.energy_density_evidence = 1.0;  // last: the corpus's inputs read as before
    d.set_options(o);
    const frame_report r = d.process(hb[0], hb[1], mv[0], mv[1]);
    check_frame(f, nch, s, before, flip, mask, r, finite);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz_values::float_or_double(data, size, [](FuzzedDataProvider& p, auto t) { run<decltype(t)>(p); });
}
