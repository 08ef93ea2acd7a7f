// Inputs and edge cases that broke earlier versions, each pinned by a test.
#include <firefly/firefly.hpp>
#include <firefly/accumulator.hpp>
#include <firefly/buffers.hpp>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "catch.hpp"
#include "frame_views.hpp"
#include "moves.hpp"

using namespace firefly;

namespace {
// A noisy flat frame of w x h pixels with `ch` interleaved channels, deterministic.
template <class T>
std::vector<T> noisy(int w, int h, int ch, unsigned seed, double level = 1.0) {
    std::vector<T> v(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(ch));
    std::uint32_t s = seed * 2654435761u + 1u;
    for (auto& x : v) {
        s = s * 1664525u + 1013904223u;
        x = static_cast<T>(level * (0.75 + 0.5 * (s >> 8) / 16777216.0));
    }
    return v;
}
}  // namespace

TEST_CASE("double variance of -0 does not reach the histogram's sign bucket", "[reliability][hard]") {
    // More than half the pixels with variance -0.0 once read past the histogram's end.
    const int w = 32, h = 32;
    std::vector<double> col[2], var[2];
    for (int k = 0; k < 2; ++k) {
        col[k] = noisy<double>(w, h, 3, 1u + static_cast<unsigned>(k));
        var[k] = noisy<double>(w, h, 3, 7u + static_cast<unsigned>(k), 0.01);
        for (std::size_t i = 0; i < var[k].size() * 3 / 4; ++i) var[k][i] = -0.0;
    }
    half_buffer<double> a{*make_image_view(col[0].data(), w, h, 3), *make_image_view(var[0].data(), w, h, 3), {}};
    half_buffer<double> b{*make_image_view(col[1].data(), w, h, 3), *make_image_view(var[1].data(), w, h, 3), {}};
    detector d;
    const frame_report r = d.process(a, b);
    REQUIRE(r.error.ok());
    // Three quarters of the standard deviations are exactly 0: so are the median and MAD.
    CHECK(r.half[0].median == 0.0);
    CHECK(r.half[0].mad == 0.0);
    CHECK(r.half[0].valid == static_cast<std::size_t>(w * h));
}

TEST_CASE("the histogram files -0 with +0", "[reliability][bound]") {
    CHECK(sd_histogram::bucket(-0.0f) == sd_histogram::bucket(0.0f));
    std::vector<float> v = {-0.0f, -0.0f, -0.0f, 1.0f, 2.0f};
    sd_histogram hist;
    hist.build(v.data(), v.size());
    std::vector<float> sf;
    std::vector<double> sd;
    const double med = hist.median(v.data(), v.size(), sf);
    CHECK(med == 0.0);
    CHECK(hist.mad(v.data(), v.size(), med, sd) == 0.0);
}

// +Inf is >= 0 and counted; its bucket is the last, whose next edge holds a NaN's bits. Before,
// a median there collected nothing and read past its scratch (a crash at -O2).
TEST_CASE("the histogram's median where it falls on +Inf", "[reliability][bound]") {
    const float inf = std::numeric_limits<float>::infinity();
    for (const std::vector<float>& v : {std::vector<float>{1.0f, inf, inf}, std::vector<float>{inf}, std::vector<float>{2.0f, inf}}) {
        sd_histogram hist;
        hist.build(v.data(), v.size());
        std::vector<float> sf;
        const double med = hist.median(v.data(), v.size(), sf);
        CHECK(med == (v.size() == 2 ? inf : inf));
    }
}

// The MAD counts the deviations within its bracket's lower end without collecting them; a value
// one float past that end (med + d_lo rounded twice) was counted among them, and the MAD came
// out one ulp low (2 of 197k adversarial arrays).
TEST_CASE("the histogram's MAD where a bound rounds outwards", "[reliability][bound]") {
    const std::vector<float> v = {0x1.42c95ep-10f, 0x1.21799p-12f, 0x1.e564e2p+51f, 0x1.a93b6ep+42f};
    sd_histogram hist;
    hist.build(v.data(), v.size());
    std::vector<float> sf;
    std::vector<double> sd;
    const double med = hist.median(v.data(), v.size(), sf);
    std::vector<double> dev;
    for (const float x : v) dev.push_back(std::fabs(static_cast<double>(x) - med));
    std::sort(dev.begin(), dev.end());
    CHECK(hist.mad(v.data(), v.size(), med, sd) == 0.5 * dev[1] + 0.5 * dev[2]);
}

// Sides past 2^30 are refused (the energy return's half-pixel positions, 2 x + 1, are ints),
// before a pixel is read: the views here have one real pixel.
TEST_CASE("a side longer than 2^30 pixels is refused", "[reliability][errors]") {
    float px[2][4] = {};
    const int side = detail::max_side + 1;
    for (const bool wide : {true, false}) {
        half_buffer<float> h[2];
        for (int k = 0; k < 2; ++k) {
            // pixel and row strides of one float: every pixel the same (never read)
            h[k].color = image_view<float>::unchecked(px[k], wide ? side : 1, wide ? 1 : side, 1, 0, 0, 4);
            h[k].variance = image_view<float>::unchecked(px[k] + 2, wide ? side : 1, wide ? 1 : side, 1, 0, 0, 4);
        }
        detector d;
        CHECK(d.detect(h[0], h[1]).error.code() == errc::size_overflow);
        buffer_view<float> b[3];
        for (int k = 0; k < 3; ++k) b[k].color = h[k % 2].color;
        cross_buffer_detector kd;
        CHECK(kd.detect(b, 3).error.code() == errc::size_overflow);
    }
}

TEST_CASE("NaN or Inf in a 4th channel makes the pixel non-finite and never spreads", "[reliability]") {
    const int w = 16, h = 16;
    for (const bool in_variance : {false, true}) {
        std::vector<float> col[2], var[2];
        for (int k = 0; k < 2; ++k) {
            col[k] = noisy<float>(w, h, 4, 3u + static_cast<unsigned>(k));
            var[k] = noisy<float>(w, h, 4, 5u + static_cast<unsigned>(k), 0.01);
        }
        // a firefly next to a pixel whose 4th channel is NaN, in half A
        const std::size_t bad = (8 * w + 8) * 4 + 3, fly = (8 * w + 9) * 4;
        (in_variance ? var[0] : col[0])[bad] = std::numeric_limits<float>::quiet_NaN();
        for (int c = 0; c < 4; ++c) {
            col[0][fly + static_cast<std::size_t>(c)] = 500.0f;
            var[0][fly + static_cast<std::size_t>(c)] = 250000.0f;
        }
        half_buffer<float> a{*make_image_view(col[0].data(), w, h, 4), *make_image_view(var[0].data(), w, h, 4), {}};
        half_buffer<float> b{*make_image_view(col[1].data(), w, h, 4), *make_image_view(var[1].data(), w, h, 4), {}};
        detector d;
        const frame_report r = d.process(a, b);
        REQUIRE(r.error.ok());
        CHECK(r.half[0].nonfinite == 1);
        CHECK(r.half[0].repaired == 1);
        for (const float x : col[0]) REQUIRE(std::isfinite(x));
        for (const float x : var[0]) REQUIRE(std::isfinite(x));
    }
}

TEST_CASE("more than 4 colour channels is an error, not a silent no-op", "[reliability][errors]") {
    const int w = 8, h = 8, ch = 9;
    std::vector<float> col[2], var[2];
    for (int k = 0; k < 2; ++k) {
        col[k] = noisy<float>(w, h, ch, 1u);
        var[k] = noisy<float>(w, h, 1, 2u);
    }
    half_buffer<float> a{*make_image_view(col[0].data(), w, h, ch), *make_image_view(var[0].data(), w, h, 1), {}};
    half_buffer<float> b{*make_image_view(col[1].data(), w, h, ch), *make_image_view(var[1].data(), w, h, 1), {}};
    detector d;
    const frame_report r = d.process(a, b);
    CHECK(r.error.code() == errc::channel_mismatch);
    CHECK_FALSE(r.ok());
}

TEST_CASE("overlapping views are refused before anything is written", "[reliability][errors]") {
    const int w = 8, h = 8;
    std::vector<float> col = noisy<float>(w, h, 3, 1u), var = noisy<float>(w, h, 3, 2u, 0.01);
    std::vector<float> col2 = noisy<float>(w, h, 3, 3u), var2 = noisy<float>(w, h, 3, 4u, 0.01);
    const std::vector<float> before = col;
    auto view = [&](std::vector<float>& v) { return *make_image_view(v.data(), w, h, 3); };
    detector d;
    SECTION("the same buffer as both halves") {
        half_buffer<float> a{view(col), view(var), {}};
        const frame_report r = d.process(a, a);
        CHECK(r.error.code() == errc::aliased_views);
    }
    SECTION("colour and variance overlap") {
        half_buffer<float> a{view(col), view(col), {}};
        half_buffer<float> b{view(col2), view(var2), {}};
        CHECK(d.process(a, b).error.code() == errc::aliased_views);
    }
    SECTION("a mask over a colour buffer") {
        half_buffer<float> a{view(col), view(var), {}};
        half_buffer<float> b{view(col2), view(var2), {}};
        auto* bytes = reinterpret_cast<std::uint8_t*>(col2.data());
        CHECK(d.process(a, b, *make_image_view(bytes, w, h, 1)).error.code() == errc::aliased_views);
    }
    SECTION("alpha that is a written channel") {
        half_buffer<float> a{view(col), view(var), {}};
        half_buffer<float> b{view(col2), view(var2), {}};
        a.alpha = *image_view<const float>::create(col2.data(), w, h, 1, 12);
        CHECK(d.process(a, b).error.code() == errc::aliased_views);
    }
    CHECK(col == before);
}

TEST_CASE("colour and variance interleaved in one 6-channel image are not an overlap", "[reliability]") {
    // channels [0, 3) colour and [3, 6) variance of one buffer per half (OpenImageIO's layout)
    const int w = 16, h = 12;
    std::vector<float> px[2];
    for (int k = 0; k < 2; ++k) {
        px[k] = noisy<float>(w, h, 6, 11u + static_cast<unsigned>(k));
        for (std::size_t i = 0; i < px[k].size(); i += 6)
            for (int c = 3; c < 6; ++c) px[k][i + static_cast<std::size_t>(c)] *= 0.01f;
    }
    px[0][(5 * w + 7) * 6] = 400.0f;
    px[0][(5 * w + 7) * 6 + 3] = 160000.0f;
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        const image_view<float> all = *make_image_view(px[k].data(), w, h, 6);
        hb[k].color = *all.channel_range(0, 3);
        hb[k].variance = *all.channel_range(3, 3);
        CHECK_FALSE(views_may_overlap(hb[k].color, hb[k].variance));
    }
    CHECK(views_may_overlap(*make_image_view(px[0].data(), w, h, 6), hb[0].variance));
    detector d;
    const frame_report r = d.process(hb[0], hb[1]);
    REQUIRE(r.error.ok());
    CHECK(r.half[0].fireflies >= 1);
}

TEST_CASE("buffers interleaved element by element are not an overlap", "[reliability][image_view]") {
    // K = 4 buffers stacked innermost: memory (H, W, C, K), buffer k a view with channel stride
    // K floats and pixel stride C K floats (numpy's np.stack(buffers, -1).transpose(3, 0, 1, 2))
    const int w = 10, h = 6, c = 3, k = 4;
    std::vector<float> mem(static_cast<std::size_t>(w * h * c * k));
    std::vector<image_view<float>> v;
    for (int i = 0; i < k; ++i)
        v.push_back(*image_view<float>::create(mem.data() + i, w, h, c, c * k * 4, w * c * k * 4, k * 4));
    for (int i = 0; i < k; ++i)
        for (int j = 0; j < k; ++j) CHECK(views_may_overlap(v[static_cast<std::size_t>(i)], v[static_cast<std::size_t>(j)]) == (i == j));
    // a view two bytes off shares bytes with its neighbours; a double view spans two floats
    auto* bytes = reinterpret_cast<unsigned char*>(mem.data());
    const auto off = *image_view<float>::create(reinterpret_cast<float*>(bytes + 2), w, h, c, c * k * 4, w * c * k * 4, k * 4);
    CHECK(views_may_overlap(v[0], off));
    CHECK(views_may_overlap(off, v[1]));
    std::vector<double> dmem(static_cast<std::size_t>(w * h * c * 2));
    const auto d0 = *image_view<double>::create(dmem.data(), w, h, c, c * 2 * 8, w * c * 2 * 8, 2 * 8);
    const auto f1 = *image_view<float>::create(reinterpret_cast<float*>(dmem.data()) + 1, w, h, c, c * 2 * 8, w * c * 2 * 8, 2 * 8);
    const auto f2 = *image_view<float>::create(reinterpret_cast<float*>(dmem.data()) + 2, w, h, c, c * 2 * 8, w * c * 2 * 8, 2 * 8);
    CHECK(views_may_overlap(d0, f1));  // inside the double
    CHECK_FALSE(views_may_overlap(d0, f2));
    // the detector takes them: K buffers cleaned in place, the same bits as separate buffers
    std::vector<std::vector<float>> sep(static_cast<std::size_t>(k));
    for (int i = 0; i < k; ++i) {
        sep[static_cast<std::size_t>(i)] = noisy<float>(w, h, c, 70u + static_cast<unsigned>(i));
        for (int p = 0; p < w * h * c; ++p) mem[static_cast<std::size_t>(p * k + i)] = sep[static_cast<std::size_t>(i)][static_cast<std::size_t>(p)];
    }
    sep[1][static_cast<std::size_t>((2 * w + 3) * c)] = mem[static_cast<std::size_t>((2 * w + 3) * c * k + 1)] = 500.0f;
    std::vector<buffer_view<float>> inter, apart;
    for (int i = 0; i < k; ++i) {
        inter.push_back({v[static_cast<std::size_t>(i)], {}});
        apart.push_back({*make_image_view(sep[static_cast<std::size_t>(i)].data(), w, h, c), {}});
    }
    cross_buffer_detector d1, d2;
    const cross_buffer_report r1 = d1.process(inter), r2 = d2.process(apart);
    REQUIRE(r1.error.ok());
    CHECK(r1.fireflies == r2.fireflies);
    CHECK(r1.fireflies >= 1);
    for (int i = 0; i < k; ++i)
        for (int p = 0; p < w * h * c; ++p)
            CHECK(mem[static_cast<std::size_t>(p * k + i)] == sep[static_cast<std::size_t>(i)][static_cast<std::size_t>(p)]);
}

TEST_CASE("a stride of PTRDIFF_MIN is refused, not negated", "[reliability][image_view]") {
    float px[16] = {};
    const std::ptrdiff_t lowest = std::numeric_limits<std::ptrdiff_t>::min();
    CHECK(image_view<float>::create(px, 2, 2, 1, lowest).error().code() == errc::size_overflow);
    CHECK(image_view<float>::create(px, 2, 2, 1, 4, lowest).error().code() == errc::size_overflow);
    CHECK(image_view<float>::create(px, 2, 2, 2, auto_stride, auto_stride, lowest).error().code() ==
          errc::size_overflow);
}

// Property: double frames full of values from 1e280 to DBL_MAX of both signs (their sums
// overflow where their means do not) come out finite from both detectors, with and without
// the energy return, and K buffers whose inputs are all finite are never called non-finite.
TEST_CASE("finite double frames near DBL_MAX come out finite from both detectors", "[reliability][numerics]") {
    std::mt19937_64 next(12345);
    auto uniform = [&next] { return static_cast<double>(next() >> 11) * 0x1.0p-53; };
    auto value = [&](bool variance) {
        const double u = uniform(), sign = variance || next() % 2 ? 1.0 : -1.0;
        switch (next() % 8) {
        case 0: case 1: case 2: return variance ? u * u : 2 * u;
        case 3: case 4: return sign * DBL_MAX * (0.5 + 0.5 * u);
        case 5: case 6: return sign * std::pow(10.0, 280 + 28 * u);
        default: return variance ? u : 1e6 * u;
        }
    };
    for (int trial = 0; trial < 400; ++trial) {
        const int w = 1 + static_cast<int>(next() % 10), h = 1 + static_cast<int>(next() % 10);
        const int k = 2 + static_cast<int>(next() % 4);
        const bool with_variance = k == 2 || next() % 2;
        std::vector<std::vector<double>> col(static_cast<std::size_t>(k)), var(static_cast<std::size_t>(k));
        std::vector<buffer_view<double>> views;
        for (int b = 0; b < k; ++b) {
            auto& c = col[static_cast<std::size_t>(b)];
            auto& v = var[static_cast<std::size_t>(b)];
            for (int i = 0; i < w * h * 3; ++i) c.push_back(value(false)), v.push_back(value(true));
            views.push_back({*make_image_view(c.data(), w, h, 3),
                             with_variance ? *make_image_view(v.data(), w, h, 3) : image_view<double>{}});
        }
        cross_buffer_options o;
        o.return_energy = o.pair.return_energy = next() % 2 == 0;
        cross_buffer_detector d(o);
        const cross_buffer_report r = d.process(views);
        INFO("trial " << trial << ", K " << k << ", " << w << "x" << h << ": " << r.error.message());
        CHECK(r.nonfinite == 0);
        CHECK(r.left == 0);
        bool finite = true;
        for (int b = 0; b < k; ++b)
            for (int i = 0; i < w * h * 3; ++i)
                finite = finite && std::isfinite(col[static_cast<std::size_t>(b)][static_cast<std::size_t>(i)]) &&
                         std::isfinite(var[static_cast<std::size_t>(b)][static_cast<std::size_t>(i)]);
        CHECK(finite);
    }
}

TEST_CASE("the narrowest kernel allowed still reads its neighbours", "[reconstruct]") {
    // sigma 0.1: the nearest ring's weight is exp(-50), its square exp(-100); both halves NaN at
    // the centre, so the spatial rule must rebuild it from the eight valid neighbours.
    const int w = 8, h = 8;
    std::vector<float> a(w * h * 3), b(w * h * 3), va(w * h * 3, 0.01f), vb(w * h * 3, 0.01f);
    for (int i = 0; i < w * h * 3; ++i)
        a[static_cast<std::size_t>(i)] = 1.0f + 0.01f * static_cast<float>(i % 7),
        b[static_cast<std::size_t>(i)] = 1.0f + 0.01f * static_cast<float>(i % 5);
    const int centre = (4 * w + 4) * 3;
    for (int c = 0; c < 3; ++c) a[centre + c] = b[centre + c] = std::numeric_limits<float>::quiet_NaN();
    detector_options o;
    o.reconstruction.sigma = 0.1;
    REQUIRE(check_options(o).ok());
    half_buffer<float> A{*make_image_view(a.data(), w, h, 3), *make_image_view(va.data(), w, h, 3), {}};
    half_buffer<float> B{*make_image_view(b.data(), w, h, 3), *make_image_view(vb.data(), w, h, 3), {}};
    detector d(o);
    const frame_report r = d.process(A, B);
    CHECK(r.ok());
    for (int c = 0; c < 3; ++c) {
        CHECK(a[centre + c] > 0.9f);
        CHECK(a[centre + c] < 1.1f);
        CHECK(va[centre + c] > 0.0f);  // the variance's weights, squared, did not underflow
        CHECK(std::isfinite(va[centre + c]));
    }
}

TEST_CASE("a variance of 0 says nothing: a noisy frame without fireflies is left alone", "[reliability][local]") {
    // One sample a half, no variance written, or variances below what half floats store
    // (6e-8): the local test once took 0 as an exact estimate, so every difference between the
    // halves was significant and half the pixel-halves of a clean frame were rebuilt.
    sim::scene s;
    s.name = "zero_variance";
    s.width = 64;
    s.height = 48;
    s.seed = 4;
    s.spp = 16;
    s.effects = sim::gradient;
    s.samples = sim::distribution::gamma;
    firefly_test::frame_views hv(sim::simulate(s));
    for (int h = 0; h < 2; ++h) std::fill(hv.f.variance[h].begin(), hv.f.variance[h].end(), 0.0f);
    const sim::frame before = hv.f;
    for (const bool local : {true, false}) {
        detector_options o;
        o.local_test = local;
        detector d(o);
        hv.f = before;
        const frame_report r = hv.process(d);
        REQUIRE(r.error.ok());
        CHECK(r.half[0].fireflies + r.half[1].fireflies == 0);
        CHECK(hv.f.color[0] == before.color[0]);
        CHECK(hv.f.color[1] == before.color[1]);
    }
    // A firefly there carries its own variance: still found and rebuilt.
    hv.f = before;
    const float e = hv.f.expected[hv.at(20, 20) * 3];
    hv.set(0, 20, 20, 200.0f * e, 200.0f * e * 200.0f * e);
    detector d;
    REQUIRE(hv.process(d).error.ok());
    CHECK((hv.mask[0][hv.at(20, 20)] & mask_bits::firefly) != 0);
    CHECK(hv.col(0, 20, 20) < 5.0f * e);
}

TEST_CASE("a firefly whose variance overflowed to Inf is rebuilt, in one half or both", "[reliability][reconstruct]") {
    // Above ~1.3e19 a firefly's variance of the mean does not fit a float: its finite colour
    // with an Inf variance is a firefly, rebuilt whether the other half stands in (its value)
    // or not (NaN there: spatially), under either rebuild rule.
    const int w = 24, h = 16;
    auto at = [&](int x, int y) { return (static_cast<std::size_t>(y) * w + static_cast<std::size_t>(x)) * 3; };
    for (const rebuild_source rule : {rebuild_source::other_half, rebuild_source::spatial})
        for (const bool other_nan : {false, true}) {
            std::vector<float> col[2], var[2];
            for (int k = 0; k < 2; ++k) {
                col[k] = noisy<float>(w, h, 3, 3u + static_cast<unsigned>(k), 0.5);
                var[k] = noisy<float>(w, h, 3, 9u + static_cast<unsigned>(k), 0.01);
            }
            for (std::size_t c = 0; c < 3; ++c) {
                col[0][at(5, 5) + c] = 1e25f;
                var[0][at(5, 5) + c] = std::numeric_limits<float>::infinity();
                if (other_nan) col[1][at(5, 5) + c] = std::numeric_limits<float>::quiet_NaN();
            }
            half_buffer<float> a{*make_image_view(col[0].data(), w, h, 3), *make_image_view(var[0].data(), w, h, 3), {}};
            half_buffer<float> b{*make_image_view(col[1].data(), w, h, 3), *make_image_view(var[1].data(), w, h, 3), {}};
            detector_options o;
            o.rebuild = rule;
            detector d(o);
            const frame_report r = d.process(a, b);
            INFO("rule " << static_cast<int>(rule) << ", other half NaN " << other_nan);
            REQUIRE(r.error.ok());
            for (int k = 0; k < 2; ++k)
                for (std::size_t c = 0; c < 3; ++c) {
                    CHECK(col[k][at(5, 5) + c] < 2.0f);
                    CHECK(std::isfinite(var[k][at(5, 5) + c]));
                }
        }
}

namespace {
// The bytes a detector leaves in a frame (colour, variance, masks) and its report's counts.
template <class Detector>
std::vector<std::uint8_t> cleaned_bytes(Detector& d, const sim::frame& f, frame_report* report = nullptr) {
    firefly_test::frame_views v(f);
    const frame_report r = v.process(d);
    if (report) *report = r;
    std::vector<std::uint8_t> out;
    auto add = [&out](const auto& vec) {
        const auto* p = reinterpret_cast<const std::uint8_t*>(vec.data());
        out.insert(out.end(), p, p + vec.size() * sizeof(vec[0]));
    };
    for (int h = 0; h < 2; ++h) add(v.f.color[h]), add(v.f.variance[h]), add(v.mask[h]);
    return out;
}
}  // namespace

TEST_CASE("a detector reused after options change gives a fresh detector's bits", "[reliability][pipeline]") {
    // A frame with a dropped bucket, then find_dropped turned off and a caustics frame: the
    // first frame's dropped list was never cleared, and the masks of the next got its 256
    // pixels' dropped bits (written past the mask where the next frame was smaller).
    sim::scene bucket = sim::named_scene("dropped_bucket", 64, 64, 5);
    bucket.bucket_size = 0.25;
    const sim::frame first = sim::simulate(bucket);
    detector_options no_drop;
    no_drop.find_dropped = false;
    for (const int side : {64, 16}) {
        const sim::frame next = sim::simulate(sim::named_scene("caustics", side, side, 4));
        detector fresh(no_drop), reused;
        frame_report r0;
        (void)cleaned_bytes(reused, first, &r0);
        REQUIRE(r0.half[0].dropped > 0);
        reused.set_options(no_drop);
        INFO("next frame " << side << "x" << side);
        CHECK(cleaned_bytes(reused, next) == cleaned_bytes(fresh, next));
    }
    // The local test skipped (its variance scale times the calibration past DBL_MAX) reads no
    // earlier frame's scratch: before, the frame after a tested one kept 0 of 188 fireflies.
    detector_options huge;
    huge.local.variance_scale = 1e301;
    sim::frame calm = sim::simulate(sim::named_scene("caustics", 64, 64, 4)), faint = calm;
    for (int h = 0; h < 2; ++h)
        for (float& v : faint.variance[h]) v *= 1e-10f;  // calibrated far up: the scale overflows
    detector fresh(huge), reused(huge);
    (void)cleaned_bytes(reused, calm);
    CHECK(cleaned_bytes(reused, faint) == cleaned_bytes(fresh, faint));
}

// Objects that keep a table between calls keep a key next to it (a kernel's width and sigma,
// a binomial table's K, a histogram's count, an accumulator's size). Moved member-wise, the
// key stayed and the storage went: a moved-from reconstruct_scratch rebuilt nothing
// (no_valid_pixels, the firefly kept), a moved-from dropped_scratch and histogram read past
// empty vectors (ASan SEGV), a moved-from accumulator indexed empty sums in add(). Now the key
// goes with the move (scratch.hpp), so each source works as a new object would.
TEST_CASE("moved-from scratch and accumulators work as new ones", "[reliability]") {
    SECTION("reconstruct_scratch") {
        auto rebuild = [](reconstruct_scratch& s) {
            std::vector<float> img(16 * 12, 1.0f);
            std::vector<std::uint8_t> mask(img.size(), 0);
            img[5 * 16 + 7] = 1000.0f;
            mask[5 * 16 + 7] = 1;
            const reconstruct_report r = reconstruct(*make_image_view(img.data(), 16, 12, 1), image_view<float>{},
                                                     mask.data(), reconstruct_options{}, s);
            return r.error.ok() && img[5 * 16 + 7] == 1.0f;
        };
        reconstruct_scratch a;
        REQUIRE(rebuild(a));
        firefly_test::check_moves(a, rebuild);
    }
    SECTION("dropped_scratch") {
        const int w = 24, h = 24, k = 4;
        std::vector<std::uint8_t> lone(static_cast<std::size_t>(w * h), 0);
        for (int y = 4; y < 14; ++y)
            for (int x = 4; x < 14; ++x) lone[static_cast<std::size_t>(y * w + x)] = 2;  // buffer 1 black
        auto found = [&](dropped_scratch& s) {
            std::vector<dropped_pixel> out;
            (void)find_dropped(lone.data(), w, h, k, 0.05, s, executor{}, out);
            return out.size();
        };
        dropped_scratch a;
        const std::size_t fresh = found(a);
        REQUIRE(fresh > 0);
        firefly_test::check_moves(a, [&](dropped_scratch& s) { return found(s) == fresh; });
    }
    SECTION("sd_histogram") {
        const std::vector<float> v = {1.0f, 2.0f, 3.0f};
        sd_histogram a;
        a.build(v.data(), v.size());
        sd_histogram b = std::move(a);
        std::vector<float> sf;
        CHECK(b.median(v.data(), v.size(), sf) == 2.0);
        CHECK(a.total() == 0);  // as a new histogram: nothing counted
        CHECK(a.median(v.data(), v.size(), sf) == 0.0);
    }
    SECTION("sample_accumulator") {
        sample_accumulator a;
        REQUIRE(a.reset(8, 8, 4).ok());
        const float s[3] = {1, 2, 3};
        REQUIRE(a.add(3, 3, 0, s).ok());
        sample_accumulator b = std::move(a);
        CHECK(b.samples(0, 3, 3) == 1);
        CHECK(a.width() == 0);
        CHECK(a.buffers() == 0);
        CHECK(a.add(3, 3, 0, s).code() == errc::invalid_argument);  // outside its 0 x 0 image
        CHECK(a.samples(0, 3, 3) == 0);
        a.finish();
        CHECK(a.views().empty());
        REQUIRE(a.reset(4, 4, 2).ok());  // usable again
        CHECK(a.add(1, 1, 0, s).ok());
        sample_accumulator c;
        c = std::move(b);
        CHECK(b.buffers() == 0);
        CHECK(c.samples(0, 3, 3) == 1);
    }
}
