// libFuzzer target: firefly::cross_buffer_detector (K buffers, buffers.hpp) on small random
// frames: K = 2 to 6 buffers (K = 2 runs the half-buffer detector), 1..12 x 1..12 pixels, 1..4
// colour channels, variance per channel, on one channel or none (K >= 3), float and double,
// each buffer in its own storage with padded pixels and rows and sometimes flipped, values with
// raw bit patterns among them (NaN, Inf, -0, denormals, FLT_MAX); random options.
//
// Asserts: no crash; a frame the detector refuses is left as it was, masks included; otherwise
// a pixel-buffer whose mask has neither the firefly nor the nonfinite bit (or has left) keeps its variance
// and any fourth colour channel bit for bit, and its first three colour channels either stay
// or grow to a finite value (the energy return only adds light); a pixel-buffer whose input
// colour was finite never comes out NaN, nor does any value come out NaN or Inf when the whole
// input was finite; the
// report counts what the masks mark (left: report.left, or K = 2's unreachable); detect() on a
// copy reports the same and changes nothing.
#include <firefly/buffers.hpp>
#include <fuzzer/FuzzedDataProvider.h>

#include "../buffer_views.hpp"
#include "fuzz_values.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

using namespace firefly;

namespace {

[[noreturn]] void fail(const char* what) { fuzz_values::fail("fuzz_buffers", what); }
using firefly_test::masks_k;
using fuzz_values::same_bits;
using fuzz_values::value;

// One image of one buffer: interleaved, pixel stride nc + pad, row stride w (nc + pad) + rowpad.
template <class T>
struct image_storage {
    std::vector<T> data;
    int channels = 0;
    std::ptrdiff_t pixel = 0, row = 0;
    bool flip = false;
    T& at(int x, int y, int c) { return data[static_cast<std::size_t>(y * row + x * pixel + c)]; }
    const T& at(int x, int y, int c) const { return data[static_cast<std::size_t>(y * row + x * pixel + c)]; }
};

template <class T>
void lay_out(FuzzedDataProvider& p, int w, int h, int nc, image_storage<T>& s) {
    s.channels = nc;
    s.pixel = nc + p.ConsumeIntegralInRange<int>(0, 2);
    s.row = s.pixel * w + p.ConsumeIntegralInRange<int>(0, 3);
    s.flip = p.ConsumeBool();
    s.data.assign(static_cast<std::size_t>(s.row * h), T(0));
}

template <class T>
image_view<T> view_of(image_storage<T>& s, int w, int h) {
    const auto e = static_cast<std::ptrdiff_t>(sizeof(T));
    auto v = image_view<T>::create(s.data.data(), w, h, s.channels, s.pixel * e, s.row * e);
    if (!v.ok()) fail("a layout built by the target was refused by image_view::create");
    return s.flip ? v->flipped_vertically() : *v;
}

struct frame_shape {
    int k, w, h, nc, nv;
};

// The assertions on one pixel-buffer of a processed frame (see the top of the file). Views
// may be flipped: view row y is storage row h - 1 - y.
template <class T>
void check_pixel(const frame_shape& f, const image_storage<T>& col, const image_storage<T>& col0,
                 const image_storage<T>& var, const image_storage<T>& var0, int x, int y, std::uint8_t m,
                 bool finite) {
    const int sy = col.flip ? f.h - 1 - y : y, vy = var.flip ? f.h - 1 - y : y;
    const bool marked = (m & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped)) != 0 && !(m & mask_bits::left);
    bool pixel_finite = true;
    for (int c = 0; c < f.nc; ++c) pixel_finite = pixel_finite && std::isfinite(static_cast<double>(col0.at(x, sy, c)));
    for (int c = 0; c < f.nc; ++c) {
        const T now = col.at(x, sy, c), was = col0.at(x, sy, c);
        if ((pixel_finite || finite) && std::isnan(static_cast<double>(now))) fail("NaN out of finite colour");
        if (finite && std::isinf(static_cast<double>(now))) fail("Inf colour out of finite input");
        const bool grew = c < 3 && now >= was && std::isfinite(static_cast<double>(now));
        if (!marked && !same_bits(now, was) && !grew) {
            std::fprintf(stderr, "K %d %dx%d: pixel (%d, %d) channel %d: %.9g -> %.9g, mask %d\n", f.k, f.w, f.h, x, y,
                         c, static_cast<double>(was), static_cast<double>(now), m);
            fail("an unmarked pixel's colour changed");
        }
    }
    for (int c = 0; c < f.nv; ++c) {
        const T now = var.at(x, vy, c), was = var0.at(x, vy, c);
        if (!marked && !same_bits(now, was)) fail("an unmarked pixel's variance changed");
        if (finite && !std::isfinite(static_cast<double>(now))) fail("NaN or Inf variance out of finite input");
    }
}

// Every buffer's storage bit for bit as it was (padding included).
template <class T>
bool unchanged(const std::vector<image_storage<T>> (&s)[2], const std::vector<image_storage<T>> (&before)[2]) {
    for (int img = 0; img < 2; ++img)
        for (std::size_t i = 0; i < s[img].size(); ++i)
            if (!s[img][i].data.empty() &&
                std::memcmp(s[img][i].data.data(), before[img][i].data.data(), s[img][i].data.size() * sizeof(T)))
                return false;
    return true;
}

template <class T>
void check_frame(const frame_shape& f, const std::vector<image_storage<T>> (&s)[2],
                 const std::vector<image_storage<T>> (&before)[2], const std::vector<std::vector<std::uint8_t>>& mask,
                 const cross_buffer_report& r, bool finite) {
    if (!r.ok() && r.pixels == 0) {  // refused: nothing written
        if (!unchanged(s, before)) fail("a refused frame changed");
        for (int i = 0; i < f.k; ++i) {
            for (const std::uint8_t m : mask[static_cast<std::size_t>(i)])
                if (m) fail("a refused frame wrote a mask");
        }
        return;
    }
    // K = 2 counts what the pair detector found (left pixels too: its halves' unreachable);
    // K >= 3 what it rebuilt (left pixels: report.left)
    std::size_t marked = 0, left_pixels = 0;
    for (int y = 0; y < f.h; ++y)
        for (int x = 0; x < f.w; ++x) {
            bool left = false;
            for (int i = 0; i < f.k; ++i) left = left || (mask[static_cast<std::size_t>(i)][static_cast<std::size_t>(y * f.w + x)] & mask_bits::left);
            left_pixels += left;
        }
    for (int i = 0; i < f.k; ++i) {
        std::size_t in_buffer = 0, left_here = 0;
        for (int y = 0; y < f.h; ++y)
            for (int x = 0; x < f.w; ++x) {
                const std::uint8_t m = mask[static_cast<std::size_t>(i)][static_cast<std::size_t>(y * f.w + x)];
                const bool found = (m & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped)) != 0;
                if ((m & mask_bits::left) && !found) fail("a left mask without what was found");
                left_here += (m & mask_bits::left) != 0;
                in_buffer += found && (f.k == 2 || !(m & mask_bits::left));
                check_pixel(f, s[0][i], before[0][i], s[1][i], before[1][i], x, y, m, finite);
            }
        if (f.k == 2 && left_here != r.pair.half[i].unreachable) fail("left masks differ from unreachable");
        if (r.per_buffer.size() != static_cast<std::size_t>(f.k) || r.per_buffer[static_cast<std::size_t>(i)] != in_buffer) {
            std::fprintf(stderr, "K %d buffer %d of %dx%d: per_buffer %zu, masks %zu; %s\n", f.k, i, f.w, f.h,
                         r.per_buffer.size() == static_cast<std::size_t>(f.k) ? r.per_buffer[static_cast<std::size_t>(i)] : 0,
                         in_buffer, r.error.message());
            fail("per_buffer differs from the masks");
        }
        marked += in_buffer;
    }
    if (r.fireflies + r.nonfinite + r.dropped + r.implausible != marked)
        fail("fireflies + nonfinite + dropped + implausible differ from the masks");
    if (f.k > 2 && left_pixels != r.left) fail("left masks differ from report.left");
    if (f.k == 2 && r.left != std::max(r.pair.half[0].unreachable, r.pair.half[1].unreachable))
        fail("K = 2: report.left differs from the halves' unreachable");
}

template <class T>
void run(FuzzedDataProvider& p) {
    const int k = p.ConsumeIntegralInRange<int>(2, 6);
    const int w = p.ConsumeIntegralInRange<int>(1, 12), h = p.ConsumeIntegralInRange<int>(1, 12);
    const int nc = p.ConsumeIntegralInRange<int>(1, 4);
    const int var_kind = p.ConsumeIntegralInRange<int>(0, 2);  // per channel, one, none (K >= 3)
    const frame_shape f{k, w, h, nc, var_kind == 0 ? nc : var_kind == 1 ? 1 : k >= 3 ? 0 : 1};
    std::vector<image_storage<T>> s[2];  // colour, variance per buffer
    bool finite = true;
    for (int img = 0; img < 2; ++img) {
        s[img].resize(static_cast<std::size_t>(k));
        for (int i = 0; i < k; ++i) {
            image_storage<T>& st = s[img][static_cast<std::size_t>(i)];
            lay_out(p, w, h, img == 0 ? nc : f.nv, st);
            const bool constant = p.ConsumeIntegralInRange<int>(0, 7) == 0;  // degenerate statistics
            const T fixed = value<T>(p, img == 1);
            for (int y = 0; y < h; ++y)
                for (int x = 0; x < w; ++x)
                    for (int c = 0; c < st.channels; ++c) {
                        const T v = constant ? fixed : value<T>(p, img == 1);
                        st.at(x, y, c) = v;
                        finite = finite && std::isfinite(static_cast<double>(v));
                    }
        }
    }
    cross_buffer_options o;
    o.use_variance = p.ConsumeBool();
    o.return_energy = p.ConsumeBool();
    o.radius = p.ConsumeIntegralInRange<int>(1, 3);
    o.false_alarm = p.ConsumeBool() ? 1e-4 : 0.05;
    o.reconstruct = p.ConsumeIntegralInRange<int>(0, 3) != 0;

    std::vector<buffer_view<T>> views(static_cast<std::size_t>(k));
    for (int i = 0; i < k; ++i) {
        views[static_cast<std::size_t>(i)].color = view_of(s[0][static_cast<std::size_t>(i)], w, h);
        if (f.nv) views[static_cast<std::size_t>(i)].variance = view_of(s[1][static_cast<std::size_t>(i)], w, h);
    }
    const std::vector<image_storage<T>> before[2] = {s[0], s[1]};
    masks_k pm(f.k, f.w, f.h), dm(f.k, f.w, f.h);  // process()'s and detect()'s
    const auto &mask = pm.mem, &dmask = dm.mem;

    // Detection first, on const views of the input: it must change nothing, and process()
    // must report the same pixels.
    std::vector<buffer_view<const T>> cviews;
    for (const auto& v : views) cviews.push_back({image_view<const T>(v.color), image_view<const T>(v.variance)});
    static cross_buffer_detector serial, threaded(cross_buffer_options{}, executor::threads(2));
    cross_buffer_detector& d = p.ConsumeBool() ? threaded : serial;
    o.energy_density_evidence = p.ConsumeBool() ? 1.0 : 0.0;  // last: the corpus's inputs read as before
    d.set_options(o);
    const cross_buffer_report dr = d.detect(cviews, dm.views);
    if (!unchanged(s, before)) fail("detect() changed a buffer");

    const cross_buffer_report r = d.process(views, pm.views);
    check_frame(f, s, before, mask, r, finite);
    // (process() alone may add that pixels were left, and at K = 2 the bits of what it did:
    // energy added, rebuilt from the other half)
    const std::uint8_t decided = mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped | mask_bits::highlight | mask_bits::consistent;
    bool same_masks = true;
    for (std::size_t i = 0; i < mask.size(); ++i)
        for (std::size_t j = 0; j < mask[i].size(); ++j) same_masks = same_masks && ((mask[i][j] ^ dmask[i][j]) & decided) == 0;
    if ((dr.pixels == 0) != (r.pixels == 0) || dr.fireflies != r.fireflies || dr.nonfinite != r.nonfinite ||
        dr.implausible != r.implausible || !same_masks) {
        std::fprintf(stderr, "K %d %dx%d: detect %zu + %zu (%s), process %zu + %zu (%s), masks %s\n", k, w, h, dr.fireflies,
                     dr.nonfinite, dr.error.message(), r.fireflies, r.nonfinite, r.error.message(), same_masks ? "same" : "differ");
        fail("detect() and process() disagree");
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz_values::float_or_double(data, size, [](FuzzedDataProvider& p, auto t) { run<decltype(t)>(p); });
}
