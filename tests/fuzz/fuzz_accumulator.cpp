// libFuzzer target: firefly::sample_accumulator (accumulator.hpp) fed a random stream of calls
// on small frames (K = 2 to 6 buffers, 1..8 x 1..8 pixels, 1..4 channels): single samples and
// float or double tiles at any sample index (2^64 - 1 included), calls it must refuse (no
// values, outside the image, a tile of other channels, a bad reset), and resets between
// frames; sample values with raw bit patterns among them (NaN, Inf, -0, denormals, 1e308).
//
// Asserts: every refused call says why and changes no count; each buffer pixel counts the
// samples routed to it (sample index mod K); after finish() a buffer pixel with no sample or
// a non-finite one reads NaN, colour and variance; one whose samples are finite and whose sums
// stay in double's range (|sample| up to ~1e153) reads their mean, and its variance of the mean (the sample's square
// with one sample), as float, within Welford's rounding of a two-pass long double reference;
// no value reads Inf and no variance is negative. Then cross_buffer_detector::process() on the
// views: a refused frame is left as it was; otherwise every colour value of a pixel-buffer not
// marked left comes out finite. Moved out and back before finish(), the accumulator keeps its
// sums and the moved-from one is empty.
#include <firefly/accumulator.hpp>
#include <fuzzer/FuzzedDataProvider.h>

#include "fuzz_values.hpp"

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <utility>
#include <vector>

using namespace firefly;

namespace {

[[noreturn]] void fail(const char* what) { fuzz_values::fail("fuzz_accumulator", what); }
using fuzz_values::value;

struct frame_shape {
    int w = 0, h = 0, k = 0, nc = 0;
    std::size_t cells() const { return static_cast<std::size_t>(w * h * k); }
    std::size_t cell(int x, int y, std::uint64_t index) const {
        return static_cast<std::size_t>((y * w + x) * k) + static_cast<std::size_t>(index % static_cast<std::uint64_t>(k));
    }
};

// What the accumulator should hold: every sample of every buffer pixel, in double.
struct reference {
    frame_shape f;
    std::vector<std::vector<double>> samples;  // per cell, channel-interleaved
    void reset(const frame_shape& shape) {
        f = shape;
        samples.assign(f.cells(), {});
    }
    void add(int x, int y, std::uint64_t index, const double* v) {
        auto& s = samples[f.cell(x, y, index)];
        s.insert(s.end(), v, v + f.nc);
    }
};

// A sample: the fuzz values, or an ordinary one most of the time (so that cells fill up).
template <class T>
T sample_value(FuzzedDataProvider& p) {
    if (p.ConsumeIntegralInRange<int>(0, 3) != 0) return static_cast<T>(p.ConsumeIntegralInRange<int>(0, 2000) / 100.0);
    return value<T>(p, false);
}

std::uint64_t sample_index(FuzzedDataProvider& p) {
    return p.ConsumeIntegralInRange<int>(0, 7) == 0 ? p.ConsumeIntegral<std::uint64_t>()
                                                   : p.ConsumeIntegralInRange<std::uint64_t>(0, 40);
}

void expect_refused(const status& st, errc code, const char* what) {
    if (st.ok() || st.code() != code) {
        std::fprintf(stderr, "%s: %s\n", what, st.message());
        fail("a call was not refused as it should be");
    }
}

void add_one(FuzzedDataProvider& p, sample_accumulator& acc, reference& ref) {
    const frame_shape& f = ref.f;
    const int x = p.ConsumeIntegralInRange<int>(-1, f.w), y = p.ConsumeIntegralInRange<int>(-1, f.h);
    const std::uint64_t index = sample_index(p);
    float v[4];
    double d[4];
    for (int c = 0; c < f.nc; ++c) d[c] = v[c] = sample_value<float>(p);
    if (p.ConsumeIntegralInRange<int>(0, 15) == 0) return expect_refused(acc.add(0, 0, index, nullptr), errc::null_data, "add(nullptr)");
    const status st = acc.add(x, y, index, v);
    if (x < 0 || y < 0 || x >= f.w || y >= f.h) return expect_refused(st, errc::invalid_argument, "add outside");
    if (!st.ok()) fail("a sample inside the image was refused");
    ref.add(x, y, index, d);
}

template <class T>
void add_tile(FuzzedDataProvider& p, sample_accumulator& acc, reference& ref) {
    const frame_shape& f = ref.f;
    const int tw = p.ConsumeIntegralInRange<int>(1, f.w + 1), th = p.ConsumeIntegralInRange<int>(1, f.h + 1);
    const int x0 = p.ConsumeIntegralInRange<int>(-1, f.w), y0 = p.ConsumeIntegralInRange<int>(-1, f.h);
    const int nc = p.ConsumeIntegralInRange<int>(0, 7) == 0 ? p.ConsumeIntegralInRange<int>(1, 4) : f.nc;
    const std::uint64_t index = sample_index(p);
    std::vector<T> tile(static_cast<std::size_t>(tw * th * nc));
    for (T& t : tile) t = sample_value<T>(p);
    const status st = acc.add_tile(x0, y0, index, *make_image_view(static_cast<const T*>(tile.data()), tw, th, nc));
    if (nc != f.nc) return expect_refused(st, errc::channel_mismatch, "tile of other channels");
    if (x0 < 0 || y0 < 0 || x0 + tw > f.w || y0 + th > f.h) return expect_refused(st, errc::invalid_argument, "tile outside");
    if (!st.ok()) fail("a tile inside the image was refused");
    for (int j = 0; j < th; ++j)
        for (int i = 0; i < tw; ++i) {
            double d[4];
            for (int c = 0; c < nc; ++c) d[c] = static_cast<double>(tile[static_cast<std::size_t>((j * tw + i) * nc + c)]);
            ref.add(x0 + i, y0 + j, index, d);
        }
}

// A frame's shape, and a reset the accumulator must refuse now and then (nothing changes).
bool reset(FuzzedDataProvider& p, sample_accumulator& acc, reference& ref) {
    frame_shape f{p.ConsumeIntegralInRange<int>(1, 8), p.ConsumeIntegralInRange<int>(1, 8),
                  p.ConsumeIntegralInRange<int>(2, 6), p.ConsumeIntegralInRange<int>(1, 4)};
    switch (p.ConsumeIntegralInRange<int>(0, 9)) {
    case 0: return expect_refused(acc.reset(0, f.h, f.k, f.nc), errc::empty_image, "reset(0, ...)"), false;
    case 1: return expect_refused(acc.reset(f.w, f.h, 1, f.nc), errc::invalid_argument, "reset(k = 1)"), false;
    case 2: return expect_refused(acc.reset(f.w, f.h, f.k, 5), errc::channel_mismatch, "reset(5 channels)"), false;
    default: break;
    }
    if (!acc.reset(f.w, f.h, f.k, f.nc).ok()) fail("a valid reset was refused");
    ref.reset(f);
    return true;
}

// The two-pass mean and variance of the mean of one channel of a cell, in long double.
struct moments {
    long double mean = 0, var = 0, largest = 0;
    bool finite = true;
};
moments moments_of(const std::vector<double>& s, int nc, int c) {
    moments m;
    const std::size_t n = s.size() / static_cast<std::size_t>(nc);
    for (std::size_t i = 0; i < n; ++i) {
        const double v = s[i * static_cast<std::size_t>(nc) + static_cast<std::size_t>(c)];
        m.finite = m.finite && std::isfinite(v);
        m.largest = std::fmax(m.largest, std::fabs(static_cast<long double>(v)));
        m.mean += v;
    }
    if (!m.finite) return m;
    m.mean /= static_cast<long double>(n);
    for (std::size_t i = 0; i < n; ++i) {
        const long double d = s[i * static_cast<std::size_t>(nc) + static_cast<std::size_t>(c)] - m.mean;
        m.var += d * d;
    }
    m.var = n >= 2 ? m.var / static_cast<long double>(n - 1) / static_cast<long double>(n) : m.mean * m.mean;
    return m;
}

// float's view of a long double, as the accumulator stores it (saturating at FLT_MAX).
double as_float(long double v) {
    return static_cast<double>(v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : static_cast<float>(v));
}

void check_value(double got, long double want, long double tolerance, const char* what) {
    const double w = as_float(want);
    const long double tol = tolerance + std::fabs(static_cast<long double>(w)) * 1.2e-7L + 1e-44L;
    if (!(std::fabs(static_cast<long double>(got) - w) <= tol) &&
        !(std::fabs(static_cast<long double>(got) - want) <= tol)) {  // (past FLT_MAX: the limit)
        std::fprintf(stderr, "%s: %.9g, expected %.9Lg (tolerance %.3Lg)\n", what, got, want, tol);
        fail("a buffer pixel's value differs from its samples'");
    }
}

void check_cell(sample_accumulator& acc, const reference& ref, int b, int x, int y) {
    const frame_shape& f = ref.f;
    const auto& s = ref.samples[f.cell(x, y, static_cast<std::uint64_t>(b))];
    const std::size_t n = s.size() / static_cast<std::size_t>(f.nc);
    if (acc.samples(b, x, y) != n) fail("a buffer pixel's count differs from the samples added");
    for (int c = 0; c < f.nc; ++c) {
        const double col = acc.color(b).load(x, y, c), var = acc.variance(b).load(x, y, c);
        if (std::isinf(col) || std::isinf(var)) {
            std::fprintf(stderr, "buffer %d (%d, %d) channel %d of %zu samples: %g, variance %g\n", b, x, y, c, n, col, var);
            fail("a value reads Inf");
        }
        if (var < 0) fail("a negative variance");
        if (std::isnan(col) != std::isnan(var)) fail("colour and variance disagree on having a value");
        const moments m = moments_of(s, f.nc, c);
        if (n == 0 || !m.finite) {
            if (!std::isnan(col)) fail("a buffer pixel without a finite sample has a value");
            continue;
        }
        // Welford's sums may pass double's range only where the squared deviations can: M2
        // adds n of them, each at most (2 largest)^2
        const long double n_l = static_cast<long double>(n), eps = 1.2e-16L * n_l;
        if (std::isnan(col)) {
            if (4 * n_l * m.largest * m.largest <= DBL_MAX) fail("finite samples in range gave no value");
            continue;
        }
        check_value(col, m.mean, eps * m.largest, "mean");
        check_value(var, m.var, (n >= 2 ? 16 * eps * m.largest * m.largest / (n_l - 1) : 0), "variance");
    }
}

// process() on the accumulator's views: refused and unchanged, or every value not left finite.
void check_process(sample_accumulator& acc, const frame_shape& f, bool use_variance) {
    std::vector<std::vector<float>> before;
    for (int b = 0; b < f.k; ++b) {
        const image_view<float> v = acc.color(b);
        before.emplace_back(v.data(), v.data() + f.w * f.h * f.nc);
    }
    std::vector<std::vector<std::uint8_t>> mem(static_cast<std::size_t>(f.k), std::vector<std::uint8_t>(static_cast<std::size_t>(f.w * f.h)));
    std::vector<image_view<std::uint8_t>> masks;
    for (auto& m : mem) masks.push_back(*make_image_view(m.data(), f.w, f.h));
    static cross_buffer_detector d;
    cross_buffer_options o;
    o.use_variance = use_variance;
    d.set_options(o);
    const cross_buffer_report r = d.process(acc.views(), masks);
    for (int b = 0; b < f.k; ++b)
        for (int p = 0; p < f.w * f.h; ++p)
            for (int c = 0; c < f.nc; ++c) {
                const float v = acc.color(b).data()[p * f.nc + c];  // (packed: pixel p, channel c)
                const float was = before[static_cast<std::size_t>(b)][static_cast<std::size_t>(p * f.nc + c)];
                const bool left = (mem[static_cast<std::size_t>(b)][static_cast<std::size_t>(p)] & mask_bits::left) != 0;
                if (!r.ok() && r.pixels == 0 && !(v == was || (std::isnan(v) && std::isnan(was))))
                    fail("a refused frame changed");
                if ((r.ok() || r.pixels != 0) && !left && !std::isfinite(v)) {
                    std::fprintf(stderr, "K %d %dx%d, %d channels: buffer %d pixel %d: %g (%s)\n", f.k, f.w, f.h, f.nc, b, p,
                                 static_cast<double>(v), r.error.message());
                    fail("a value not marked left came out non-finite");
                }
            }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    FuzzedDataProvider p(data, size);
    sample_accumulator acc;
    reference ref;
    while (!reset(p, acc, ref))
        if (p.remaining_bytes() == 0) return 0;
    const int calls = p.ConsumeIntegralInRange<int>(0, 400);
    for (int i = 0; i < calls && p.remaining_bytes() > 0; ++i) {
        switch (p.ConsumeIntegralInRange<int>(0, 19)) {
        case 0: reset(p, acc, ref); break;
        case 1: case 2: add_tile<float>(p, acc, ref); break;
        case 3: add_tile<double>(p, acc, ref); break;
        default: add_one(p, acc, ref); break;
        }
    }
    if (p.ConsumeBool()) {  // moved out and back: the source is left a new, empty accumulator
        sample_accumulator moved(std::move(acc));
        const float v[4] = {1, 1, 1, 1};
        if (acc.width() != 0 || acc.buffers() != 0 || acc.add(0, 0, 0, v).ok() || !acc.views().empty())
            fail("a moved-from accumulator is not empty");
        acc = std::move(moved);
    }
    acc.finish();
    for (int b = 0; b < ref.f.k; ++b)
        for (int y = 0; y < ref.f.h; ++y)
            for (int x = 0; x < ref.f.w; ++x) check_cell(acc, ref, b, x, y);
    check_process(acc, ref.f, p.ConsumeBool());
    return 0;
}
