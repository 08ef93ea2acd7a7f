// libFuzzer target: firefly::sample_accumulator (accumulator.hpp) fed a random stream of calls
// on small frames (1..8 x 1..8 pixels, 1..4 channels): single samples and float or double
// tiles at any sample index (2^64 - 1 included), calls it must refuse (no values, outside the
// image, a tile of other channels, a bad reset), and resets between frames; sample values with
// raw bit patterns among them (NaN, Inf, -0, denormals, 1e308). Then
// cross_buffer_detector::process() (buffers.hpp) on its views.
//
// Two input formats. An input that starts with "acc2" is read in the extended one: K = 2 to 17
// buffers (past 8 the dropped-buffer masks are 64-bit, past 16 the buffers are sorted by
// std::sort), now and then 18 to 64; tiles laid out with padded rows, padded pixels, planar or
// bottom-up, or of one colour (black among them: a dropped buffer); whole-frame passes at the
// next sample index (a few bytes fill every buffer); and calls between the adds that finish()
// and check, run process() on the views, or move the accumulator out and back. Any other
// input is read as the first format was (K = 2 to 6, packed tiles, one finish() at the end),
// so that the saved seeds and reproducers keep their meaning; every check below runs on both.
//
// Asserts: every refused call says why and changes no count; each buffer pixel counts the
// samples routed to it (sample index mod K); views read 0 before the first finish(); after
// finish() a buffer pixel with no sample or a non-finite one reads NaN, colour and variance;
// one whose samples are finite and whose sums stay in double's range (|sample| up to ~1e153)
// reads their mean, and its variance of the mean (the sample's square with one sample), as
// float, within Welford's rounding of a two-pass long double reference; no value reads Inf and
// no variance is negative. The same holds after more adds to a finished frame (finish() reads
// every sample since the reset); finish() twice gives the same bytes, and finish() after
// process() gives back the bytes process() cleaned (the sums are the accumulator's alone).
// Then process() on the views: a refused frame is left as it was; otherwise every colour and
// variance value of a pixel-buffer not marked left comes out finite, every variance >= 0, an
// input NaN or Inf is marked nonfinite, and the masks agree with the report's counts (see
// check_masks); a fresh detector gives the same bytes and counts as the one reused from input
// to input (its scratch must not carry over). Moved out and back, the accumulator keeps its
// sums and the moved-from one is empty.
#include <firefly/accumulator.hpp>
#include <fuzzer/FuzzedDataProvider.h>

#include "../buffer_views.hpp"
#include "fuzz_values.hpp"

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

using namespace firefly;

namespace {

[[noreturn]] void fail(const char* what) { fuzz_values::fail("fuzz_accumulator", what); }
using firefly_test::masks_k;
using fuzz_values::same_bits;
using fuzz_values::value;

// The extended format's tag (the first four bytes of an input).
constexpr char extended_tag[4] = {'a', 'c', 'c', '2'};

struct frame_shape {
    int w = 0, h = 0, k = 0, nc = 0;
    std::size_t pixels() const { return static_cast<std::size_t>(w * h); }
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

// One input: how it is read, the accumulator and what it should hold.
struct one_input {
    one_input(FuzzedDataProvider& provider, bool extended_format) : p(provider), extended(extended_format) {}
    FuzzedDataProvider& p;
    bool extended;          // the "acc2" format
    sample_accumulator acc;
    reference ref;
    bool finished = false;  // finish() called on this accumulator (before it, views read 0)
    int rounds = 0;         // process() rounds between the adds (each runs two detectors)
    std::uint64_t passes = 0;  // whole-frame passes since the reset (their sample indices)
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

// K: 2 to 6 in the first format; in the extended one up to 17 (the wide dropped-buffer masks
// past 8, std::sort past 16), and one time in eight 18 to 64 (the detector's limit).
int buffer_count(FuzzedDataProvider& p, bool extended) {
    if (!extended) return p.ConsumeIntegralInRange<int>(2, 6);
    return p.ConsumeIntegralInRange<int>(0, 7) != 0 ? p.ConsumeIntegralInRange<int>(2, 17)
                                                    : p.ConsumeIntegralInRange<int>(18, 64);
}

void expect_refused(const status& st, errc code, const char* what) {
    if (st.ok() || st.code() != code) {
        std::fprintf(stderr, "%s: %s\n", what, st.message());
        fail("a call was not refused as it should be");
    }
}

void add_one(one_input& s) {
    FuzzedDataProvider& p = s.p;
    const frame_shape& f = s.ref.f;
    const int x = p.ConsumeIntegralInRange<int>(-1, f.w), y = p.ConsumeIntegralInRange<int>(-1, f.h);
    const std::uint64_t index = sample_index(p);
    float v[4];
    double d[4];
    for (int c = 0; c < f.nc; ++c) d[c] = v[c] = sample_value<float>(p);
    if (p.ConsumeIntegralInRange<int>(0, 15) == 0) return expect_refused(s.acc.add(0, 0, index, nullptr), errc::null_data, "add(nullptr)");
    const status st = s.acc.add(x, y, index, v);
    if (x < 0 || y < 0 || x >= f.w || y >= f.h) return expect_refused(st, errc::invalid_argument, "add outside");
    if (!st.ok()) fail("a sample inside the image was refused");
    s.ref.add(x, y, index, d);
}

// Where a tile's values lie, in elements from the start of its memory: packed, or (extended
// format) rows padded, pixels padded, planar, or bottom-up (a negative row stride from the
// last row). The rest of the memory is NaN: a value read from it turns its cell NaN, which
// check_cell sees.
template <class T>
struct tile_memory {
    std::vector<T> memory;
    std::ptrdiff_t origin = 0, pixel = 0, row = 0, channel = 1;
    T& at(int i, int j, int c) { return memory[static_cast<std::size_t>(origin + j * row + i * pixel + c * channel)]; }
};

template <class T>
tile_memory<T> lay_out(FuzzedDataProvider& p, bool extended, int tw, int th, int nc) {
    enum { packed, padded_rows, padded_pixels, planar, bottom_up };
    const int layout = extended ? p.ConsumeIntegralInRange<int>(packed, bottom_up) : packed;
    const int pad = layout == packed ? 0 : p.ConsumeIntegralInRange<int>(1, 3);
    tile_memory<T> m;
    m.pixel = layout == planar ? 1 : layout == padded_pixels ? nc + pad : nc;
    m.row = layout == planar ? tw + pad : tw * m.pixel + (layout == padded_pixels ? 0 : pad);
    if (layout == planar) m.channel = m.row * th;
    const std::ptrdiff_t extent = (th - 1) * m.row + (tw - 1) * m.pixel + (nc - 1) * m.channel + 1;
    if (layout == bottom_up) m.origin = (th - 1) * m.row, m.row = -m.row;
    m.memory.assign(static_cast<std::size_t>(extent), std::numeric_limits<T>::quiet_NaN());
    return m;
}

// The tile's values: one per sample, or (extended format) one colour over the whole tile,
// or black (cheap whole-frame passes; a black buffer where the others are lit is a dropped one).
template <class T>
std::vector<T> tile_values(FuzzedDataProvider& p, bool extended, int tw, int th, int nc) {
    std::vector<T> tile(static_cast<std::size_t>(tw * th * nc));
    const int fill = extended ? p.ConsumeIntegralInRange<int>(0, 7) : 0;
    if (fill < 6) {
        for (T& t : tile) t = sample_value<T>(p);
        return tile;
    }
    for (int c = 0; c < nc; ++c) {
        const T v = fill == 6 ? sample_value<T>(p) : T(0);
        for (std::size_t i = static_cast<std::size_t>(c); i < tile.size(); i += static_cast<std::size_t>(nc)) tile[i] = v;
    }
    return tile;
}

// Where a tile goes: pixel (i, j) of a tw x th tile of nc channels is sample `index` of
// pixel (x0 + i, y0 + j).
struct tile_place {
    int tw = 0, th = 0, x0 = 0, y0 = 0, nc = 0;
    std::uint64_t index = 0;
};

// Anywhere, partly outside now and then, of other channels now and then.
tile_place any_place(FuzzedDataProvider& p, const frame_shape& f) {
    tile_place t;
    t.tw = p.ConsumeIntegralInRange<int>(1, f.w + 1), t.th = p.ConsumeIntegralInRange<int>(1, f.h + 1);
    t.x0 = p.ConsumeIntegralInRange<int>(-1, f.w), t.y0 = p.ConsumeIntegralInRange<int>(-1, f.h);
    t.nc = p.ConsumeIntegralInRange<int>(0, 7) == 0 ? p.ConsumeIntegralInRange<int>(1, 4) : f.nc;
    t.index = sample_index(p);
    return t;
}

// A renderer's pass (extended format): the whole frame at the next sample index, so that a
// few bytes fill K = 17 buffers or more at every pixel.
tile_place next_pass(one_input& s) {
    const frame_shape& f = s.ref.f;
    return {f.w, f.h, 0, 0, f.nc, s.passes++};
}

template <class T>
void add_tile(one_input& s, const tile_place& t) {
    FuzzedDataProvider& p = s.p;
    const frame_shape& f = s.ref.f;
    tile_memory<T> m = lay_out<T>(p, s.extended, t.tw, t.th, t.nc);
    const std::vector<T> tile = tile_values<T>(p, s.extended, t.tw, t.th, t.nc);
    for (int j = 0; j < t.th; ++j)
        for (int i = 0; i < t.tw; ++i)
            for (int c = 0; c < t.nc; ++c) m.at(i, j, c) = tile[static_cast<std::size_t>((j * t.tw + i) * t.nc + c)];
    constexpr auto e = static_cast<std::ptrdiff_t>(sizeof(T));
    const result<image_view<const T>> view =
        image_view<const T>::create(m.memory.data() + m.origin, t.tw, t.th, t.nc, m.pixel * e, m.row * e, m.channel * e);
    if (!view.ok()) fail("a tile's layout was refused");
    const status st = s.acc.add_tile(t.x0, t.y0, t.index, *view);
    if (t.nc != f.nc) return expect_refused(st, errc::channel_mismatch, "tile of other channels");
    if (t.x0 < 0 || t.y0 < 0 || t.x0 + t.tw > f.w || t.y0 + t.th > f.h) return expect_refused(st, errc::invalid_argument, "tile outside");
    if (!st.ok()) fail("a tile inside the image was refused");
    for (int j = 0; j < t.th; ++j)
        for (int i = 0; i < t.tw; ++i) {
            double d[4];
            for (int c = 0; c < t.nc; ++c) d[c] = static_cast<double>(tile[static_cast<std::size_t>((j * t.tw + i) * t.nc + c)]);
            s.ref.add(t.x0 + i, t.y0 + j, t.index, d);
        }
}

// A frame's shape, and a reset the accumulator must refuse now and then (nothing changes).
bool reset(one_input& s) {
    FuzzedDataProvider& p = s.p;
    frame_shape f{p.ConsumeIntegralInRange<int>(1, 8), p.ConsumeIntegralInRange<int>(1, 8), buffer_count(p, s.extended),
                  p.ConsumeIntegralInRange<int>(1, 4)};
    const int refuse = p.ConsumeIntegralInRange<int>(0, s.extended ? 15 : 9);
    switch (refuse) {
    case 0: return expect_refused(s.acc.reset(0, f.h, f.k, f.nc), errc::empty_image, "reset(0, ...)"), false;
    case 1: return expect_refused(s.acc.reset(f.w, f.h, 1, f.nc), errc::invalid_argument, "reset(k = 1)"), false;
    case 2: return expect_refused(s.acc.reset(f.w, f.h, f.k, 5), errc::channel_mismatch, "reset(5 channels)"), false;
    default: break;
    }
    if (s.extended && refuse == 3) return expect_refused(s.acc.reset(f.w, f.h, 65, f.nc), errc::invalid_argument, "reset(k = 65)"), false;
    if (s.extended && refuse == 4) return expect_refused(s.acc.reset(f.w, -f.h, f.k, f.nc), errc::empty_image, "reset(w, -h)"), false;
    if (!s.acc.reset(f.w, f.h, f.k, f.nc).ok()) fail("a valid reset was refused");
    s.ref.reset(f);
    s.passes = 0;
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

// The views' shape (K packed buffers of the frame, the ones color() and variance() give), and
// the queries documented to give nothing outside the buffers or the image.
void check_views(sample_accumulator& acc, const frame_shape& f) {
    const std::vector<buffer_view<float>> v = acc.views();
    if (static_cast<int>(v.size()) != f.k) fail("views() gave other than K buffers");
    for (int b = 0; b < f.k; ++b)
        for (const image_view<float>& i : {v[static_cast<std::size_t>(b)].color, v[static_cast<std::size_t>(b)].variance})
            if (i.width() != f.w || i.height() != f.h || i.channels() != f.nc || !i.is_packed())
                fail("a view is not the frame's shape, packed");
    if (v[0].color.data() != acc.color(0).data() || v[0].variance.data() != acc.variance(0).data())
        fail("views() and color()/variance() differ");
    if (!acc.color(-1).empty() || !acc.color(f.k).empty() || !acc.variance(-1).empty() || !acc.variance(f.k).empty())
        fail("a buffer outside [0, K) has a view");
    if (acc.samples(-1, 0, 0) != 0 || acc.samples(f.k, 0, 0) != 0 || acc.samples(0, -1, 0) != 0 ||
        acc.samples(0, f.w, 0) != 0 || acc.samples(0, 0, f.h) != 0)
        fail("samples() outside the buffers or the image is not 0");
}

// Every colour and variance value of the views, as bits (NaN payloads included).
std::vector<std::uint32_t> bits_of(sample_accumulator& acc, const frame_shape& f) {
    std::vector<std::uint32_t> bits;
    const std::size_t n = f.pixels() * static_cast<std::size_t>(f.nc);
    for (int b = 0; b < f.k; ++b)
        for (const float* v : {acc.color(b).data(), acc.variance(b).data()}) {
            const std::size_t at = bits.size();
            bits.resize(at + n);
            std::memcpy(bits.data() + at, v, n * sizeof(float));
        }
    return bits;
}

// finish() and every buffer pixel against its samples since the reset (before the first
// finish(), the views read 0); a second finish() reads the same sums: the same bytes.
void finish_and_check(one_input& s) {
    const frame_shape& f = s.ref.f;
    check_views(s.acc, f);
    if (!s.finished)
        for (const std::uint32_t b : bits_of(s.acc, f))
            if (b != 0) fail("a view does not read 0 before the first finish()");
    s.acc.finish();
    s.finished = true;
    for (int b = 0; b < f.k; ++b)
        for (int y = 0; y < f.h; ++y)
            for (int x = 0; x < f.w; ++x) check_cell(s.acc, s.ref, b, x, y);
    const std::vector<std::uint32_t> once = bits_of(s.acc, f);
    s.acc.finish();
    if (bits_of(s.acc, f) != once) fail("finish() twice gave other bytes");
}

// Moved out and back: the source is left a new, empty accumulator.
void move_out_and_back(sample_accumulator& acc) {
    sample_accumulator moved(std::move(acc));
    const float v[4] = {1, 1, 1, 1};
    if (acc.width() != 0 || acc.buffers() != 0 || acc.add(0, 0, 0, v).ok() || !acc.views().empty())
        fail("a moved-from accumulator is not empty");
    acc = std::move(moved);
}

// K buffers' colour and variance in memory of their own: the detectors' input as it was, and
// the reused detector's buffers.
struct buffer_copy {
    frame_shape f;
    std::vector<std::vector<float>> color, variance;
    std::vector<buffer_view<float>> views;
    buffer_copy(const std::vector<buffer_view<float>>& from, const frame_shape& shape) : f(shape) {
        const std::size_t n = f.pixels() * static_cast<std::size_t>(f.nc);
        for (const buffer_view<float>& b : from) {
            color.emplace_back(b.color.data(), b.color.data() + n);
            variance.emplace_back(b.variance.data(), b.variance.data() + n);
        }
        for (std::size_t b = 0; b < color.size(); ++b)
            views.push_back({*make_image_view(color[b].data(), f.w, f.h, f.nc), *make_image_view(variance[b].data(), f.w, f.h, f.nc)});
    }
    buffer_copy(const buffer_copy&) = delete;  // (the views point into this copy's vectors)
    float variance_at(std::size_t b, std::size_t p, int c) const {
        return variance[b][p * static_cast<std::size_t>(f.nc) + static_cast<std::size_t>(c)];
    }
    // Whether every colour and variance channel of buffer b at pixel p is finite.
    bool finite_at(std::size_t b, std::size_t p) const {
        for (int c = 0; c < f.nc; ++c)
            if (!std::isfinite(color[b][p * static_cast<std::size_t>(f.nc) + static_cast<std::size_t>(c)]) ||
                !std::isfinite(variance_at(b, p, c)))
                return false;
        return true;
    }
    // Bit for bit (NaN payloads included).
    bool same_bytes(const buffer_copy& o) const {
        for (std::size_t b = 0; b < color.size(); ++b)
            if (std::memcmp(color[b].data(), o.color[b].data(), color[b].size() * sizeof(float)) != 0 ||
                std::memcmp(variance[b].data(), o.variance[b].data(), variance[b].size() * sizeof(float)) != 0)
                return false;
        return true;
    }
};


// Everything a half's report says but its timings and the detector's memory.
bool same_half(const half_report& a, const half_report& b) {
    return a.pixels == b.pixels && a.valid == b.valid && a.ignored == b.ignored && a.nonfinite == b.nonfinite &&
           a.dropped == b.dropped && a.implausible == b.implausible && a.negative_variance == b.negative_variance &&
           same_bits(a.median, b.median) && same_bits(a.mad, b.mad) && a.bound == b.bound && a.outliers == b.outliers &&
           a.local == b.local && a.highlights == b.highlights && a.consistent == b.consistent &&
           a.frame_kept == b.frame_kept && a.fireflies == b.fireflies && a.repaired == b.repaired &&
           a.from_other_half == b.from_other_half && a.unreachable == b.unreachable &&
           a.phase1_rounds == b.phase1_rounds && a.phase2_iterations == b.phase2_iterations &&
           same_bits(a.final_change, b.final_change) && a.reconstruction.code() == b.reconstruction.code() &&
           same_bits(a.energy_removed, b.energy_removed) && same_bits(a.energy_returned, b.energy_returned);
}

// Two reports of one frame (lambda cache misses, memory and timings aside: a reused
// detector's differ by design).
bool same_report(const cross_buffer_report& a, const cross_buffer_report& b) {
    const frame_report &pa = a.pair, &pb = b.pair;
    return a.error.code() == b.error.code() && a.buffers == b.buffers && a.pixels == b.pixels && a.tested == b.tested &&
           a.candidates == b.candidates && same_bits(a.level, b.level) && a.fireflies == b.fireflies &&
           a.nonfinite == b.nonfinite && a.dropped == b.dropped && a.implausible == b.implausible && a.left == b.left &&
           a.per_buffer == b.per_buffer && same_bits(a.energy_removed, b.energy_removed) &&
           same_bits(a.energy_returned, b.energy_returned) && pa.error.code() == pb.error.code() &&
           same_half(pa.half[0], pb.half[0]) && same_half(pa.half[1], pb.half[1]) && pa.both_outliers == pb.both_outliers &&
           same_bits(pa.variance_calibration, pb.variance_calibration) && same_bits(pa.single_level, pb.single_level) &&
           same_bits(pa.single_log_level, pb.single_log_level);
}

// What the report's comments promise of an accepted frame: K buffers, the frame's pixels,
// tested and candidate pixels among them, per_buffer the sum of the four kinds, pixels left
// exactly when no_valid_pixels, the frame's level at most the cap.
void check_report(const cross_buffer_report& r, const frame_shape& f, const cross_buffer_options& o) {
    if (r.buffers != f.k || r.pixels != f.pixels() || r.per_buffer.size() != static_cast<std::size_t>(f.k))
        fail("the report's buffers, pixels or per_buffer are not the frame's");
    if (r.tested > r.pixels || r.candidates > r.pixels || r.left > r.pixels) fail("the report counts more pixels than the frame has");
    std::size_t per_buffer = 0;
    for (const std::size_t n : r.per_buffer) per_buffer += n;
    if (per_buffer != r.fireflies + r.nonfinite + r.dropped + r.implausible)
        fail("per_buffer does not add up to fireflies + nonfinite + dropped + implausible");
    if (!r.ok() && r.error.code() != errc::no_valid_pixels) {
        std::fprintf(stderr, "%s\n", r.error.message());
        fail("the accumulator's views were refused");
    }
    if ((r.left > 0) != (r.error.code() == errc::no_valid_pixels)) fail("pixels left, and no_valid_pixels, disagree");
    if (!(r.level >= 0 && r.level <= o.false_alarm)) fail("the frame's level is outside [0, false_alarm]");
}

// The masks against the input and the report. Every K: a pixel-buffer whose input held NaN
// or Inf says nonfinite; left comes with firefly, nonfinite or dropped. K >= 3 (buffers.hpp):
// a left pixel's masks are nonfinite | left or dropped | left on more than K / 2 buffers and 0
// on the others; any other pixel's are firefly, nonfinite, dropped or 0, on at most K / 2
// buffers, and they count what the report does (nonfinite: non-finite and implausible
// buffers). K = 2 (pipeline.hpp's half_report): per half, left on its unreachable pixels,
// nonfinite on its non-finite and implausible ones, dropped on its dropped ones.
void check_masks(const masks_k& m, const buffer_copy& input, const frame_shape& f, const cross_buffer_report& r) {
    constexpr std::uint8_t found = mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped;
    constexpr std::uint8_t nonfinite_left = mask_bits::nonfinite | mask_bits::left, dropped_left = mask_bits::dropped | mask_bits::left;
    const std::size_t k = static_cast<std::size_t>(f.k);
    std::vector<std::size_t> flagged(k), left(k), nonfinite(k), dropped(k);  // (the last three: K = 2)
    std::size_t left_pixels = 0, fireflies = 0, nonfinite_all = 0, dropped_all = 0;
    for (std::size_t p = 0; p < f.pixels(); ++p) {
        int on = 0, marked_left = 0;
        for (std::size_t b = 0; b < k; ++b) {
            const std::uint8_t v = m.mem[b][p];
            if (!input.finite_at(b, p) && !(v & mask_bits::nonfinite)) fail("a NaN or Inf input is not marked nonfinite");
            if ((v & mask_bits::left) && !(v & found)) fail("a mask says left without what was found");
            left[b] += (v & mask_bits::left) != 0;
            nonfinite[b] += (v & mask_bits::nonfinite) != 0;
            dropped[b] += (v & mask_bits::dropped) != 0;
            if (k == 2) continue;
            if (v != 0 && v != mask_bits::firefly && v != mask_bits::nonfinite && v != mask_bits::dropped &&
                v != nonfinite_left && v != dropped_left) {
                std::fprintf(stderr, "buffer %zu pixel %zu: mask %d\n", b, p, v);
                fail("a K-buffer mask holds other bits, or was not written");
            }
            on += v != 0;
            marked_left += (v & mask_bits::left) != 0;
            if (v == 0 || (v & mask_bits::left)) continue;
            ++flagged[b];
            fireflies += v == mask_bits::firefly;
            nonfinite_all += v == mask_bits::nonfinite;
            dropped_all += v == mask_bits::dropped;
        }
        if (k == 2) continue;
        left_pixels += marked_left > 0;
        if (marked_left > 0 && (marked_left != on || marked_left <= f.k / 2)) fail("a left pixel's masks are not its > K / 2 bad buffers");
        if (marked_left == 0 && on > f.k / 2) fail("more than K / 2 buffers of a pixel flagged");
    }
    for (std::size_t b = 0; b < k; ++b) {
        if (k == 2) {
            const half_report& h = r.pair.half[b];
            if (left[b] != h.unreachable || nonfinite[b] != h.nonfinite + h.implausible || dropped[b] != h.dropped) {
                std::fprintf(stderr, "half %zu masks: %zu left, %zu nonfinite, %zu dropped; report: %zu unreachable, %zu + %zu, %zu\n",
                             b, left[b], nonfinite[b], dropped[b], h.unreachable, h.nonfinite, h.implausible, h.dropped);
                fail("a half's masks and report disagree");
            }
        } else if (flagged[b] != r.per_buffer[b]) {
            fail("a buffer's masks and per_buffer disagree");
        }
    }
    if (k == 2) return;
    if (left_pixels != r.left || fireflies != r.fireflies || nonfinite_all != r.nonfinite + r.implausible || dropped_all != r.dropped) {
        std::fprintf(stderr, "masks: %zu left, %zu fireflies, %zu nonfinite, %zu dropped; report: %zu, %zu, %zu + %zu, %zu\n",
                     left_pixels, fireflies, nonfinite_all, dropped_all, r.left, r.fireflies, r.nonfinite, r.implausible, r.dropped);
        fail("the masks and the report's counts disagree");
    }
}

// process() on the accumulator's views by a fresh detector, and on a copy by the one reused
// from input to input (its scratch from every input before): the same bytes, masks and
// counts. The fresh one's result: refused and unchanged, or every colour and variance value
// of a pixel-buffer not marked left finite, each variance >= 0, masks and report as
// check_report and check_masks say.
void check_process(sample_accumulator& acc, const frame_shape& f, bool use_variance) {
    const buffer_copy input(acc.views(), f);
    buffer_copy reused_output(acc.views(), f);
    cross_buffer_options o;
    o.use_variance = use_variance;
    cross_buffer_detector fresh(o);
    // (filled with highlight first: no K >= 3 mask says highlight, so a mask pixel left
    // unwritten shows in check_masks)
    masks_k masks(f.k, f.w, f.h, mask_bits::highlight), reused_masks(f.k, f.w, f.h, mask_bits::highlight);
    const cross_buffer_report r = fresh.process(acc.views(), masks.views);
    static cross_buffer_detector reused;
    reused.set_options(o);
    const cross_buffer_report rr = reused.process(reused_output.views, reused_masks.views);
    const buffer_copy output(acc.views(), f);
    if (!output.same_bytes(reused_output) || masks.mem != reused_masks.mem || !same_report(r, rr)) {
        std::fprintf(stderr, "K %d %dx%d, %d channels: %s / %s\n", f.k, f.w, f.h, f.nc, r.error.message(), rr.error.message());
        fail("a reused detector gave other bytes than a fresh one");
    }
    if (!r.ok() && r.pixels == 0) {
        if (!output.same_bytes(input)) fail("a refused frame changed");
        return;
    }
    check_report(r, f, o);
    check_masks(masks, input, f, r);
    for (std::size_t b = 0; b < static_cast<std::size_t>(f.k); ++b)
        for (std::size_t p = 0; p < f.pixels(); ++p) {
            if (masks.mem[b][p] & mask_bits::left) continue;
            if (!output.finite_at(b, p)) {
                std::fprintf(stderr, "K %d %dx%d, %d channels: buffer %zu pixel %zu (%s)\n", f.k, f.w, f.h, f.nc, b, p,
                             r.error.message());
                fail("a value not marked left came out non-finite");
            }
            for (int c = 0; c < f.nc; ++c)
                if (output.variance_at(b, p, c) < 0) fail("a variance came out negative");
        }
}

// Between the adds (extended format): finish(), process() on the views, and finish() again,
// which must write the accumulator's own means back over what process() cleaned. At most two
// rounds an input (each runs two detectors).
void process_round(one_input& s) {
    if (s.rounds == 2) return;
    ++s.rounds;
    finish_and_check(s);
    const std::vector<std::uint32_t> finished = bits_of(s.acc, s.ref.f);
    check_process(s.acc, s.ref.f, s.p.ConsumeBool());
    s.acc.finish();
    if (bits_of(s.acc, s.ref.f) != finished) fail("finish() after process() did not give back the accumulator's means");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const bool extended = size >= sizeof extended_tag && std::memcmp(data, extended_tag, sizeof extended_tag) == 0;
    if (extended) data += sizeof extended_tag, size -= sizeof extended_tag;
    FuzzedDataProvider p(data, size);
    one_input s(p, extended);
    while (!reset(s))
        if (p.remaining_bytes() == 0) return 0;
    const int calls = p.ConsumeIntegralInRange<int>(0, 400);
    for (int i = 0; i < calls && p.remaining_bytes() > 0; ++i) {
        switch (p.ConsumeIntegralInRange<int>(0, extended ? 27 : 19)) {
        case 0: reset(s); break;
        case 1: case 2: add_tile<float>(s, any_place(p, s.ref.f)); break;
        case 3: add_tile<double>(s, any_place(p, s.ref.f)); break;
        case 20: finish_and_check(s); break;
        case 21: process_round(s); break;
        case 22: move_out_and_back(s.acc); break;
        case 23: case 24: case 25: case 26: case 27: add_tile<float>(s, next_pass(s)); break;
        default: add_one(s); break;
        }
    }
    if (p.ConsumeBool()) move_out_and_back(s.acc);
    finish_and_check(s);
    check_process(s.acc, s.ref.f, p.ConsumeBool());
    return 0;
}
