// The K-buffer accumulator (accumulator.hpp): samples by index mod K, stable mean and
// variance of the mean at the numeric edges, lock-free tiles from two threads, views that
// go straight to the detector.
#include <firefly/accumulator.hpp>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <thread>
#include <vector>

#include "catch.hpp"

using namespace firefly;

TEST_CASE("accumulator: sample i goes to buffer i mod K; mean and variance of the mean", "[accumulator]") {
    sample_accumulator acc;
    REQUIRE(acc.reset(2, 1, 3, 1).ok());
    const float values[] = {1, 10, 100, 3, 20, 200, 5, 30, 300};  // indices 0..8
    for (int i = 0; i < 9; ++i) REQUIRE(acc.add(1, 0, static_cast<std::uint64_t>(i), &values[i]).ok());
    acc.finish();
    CHECK(acc.samples(0, 1, 0) == 3);
    CHECK(acc.samples(0, 0, 0) == 0);
    CHECK(acc.color(0)(1, 0) == Approx(3.0));    // 1, 3, 5
    CHECK(acc.color(1)(1, 0) == Approx(20.0));   // 10, 20, 30
    CHECK(acc.color(2)(1, 0) == Approx(200.0));  // 100, 200, 300
    CHECK(acc.variance(0)(1, 0) == Approx(4.0 / 3.0));     // sample variance 4, over 3
    CHECK(acc.variance(2)(1, 0) == Approx(10000.0 / 3.0));
    CHECK(std::isnan(acc.color(0)(0, 0)));  // no sample: no value (not black)
    CHECK(std::isnan(acc.variance(0)(0, 0)));
}

TEST_CASE("accumulator: a 1e30 sample next to 1e-3 samples", "[accumulator]") {
    sample_accumulator acc;
    REQUIRE(acc.reset(1, 1, 2, 3).ok());
    for (int i = 0; i < 64; ++i) {
        const float tiny[3] = {1e-3f, 1e-3f, 1e-3f};
        const float huge[3] = {1e30f, 1e-3f, 0.0f};
        REQUIRE(acc.add(0, 0, static_cast<std::uint64_t>(i), i == 11 ? huge : tiny).ok());
    }
    // Equal tiny samples after the huge one: the variance of buffer 1 stays >= 0.
    acc.finish();
    for (int b = 0; b < 2; ++b)
        for (int c = 0; c < 3; ++c) {
            const float v = acc.variance(b)(0, 0, c);
            CHECK(v >= 0.0f);
            CHECK(std::isfinite(v));
            CHECK(std::isfinite(acc.color(b)(0, 0, c)));
        }
    CHECK(acc.variance(1)(0, 0, 1) == Approx(0.0).margin(1e-20));  // all 1e-3: exactly none
    CHECK(acc.variance(0)(0, 0, 0) == Approx(0.0).margin(1e-20));
    CHECK(acc.color(0)(0, 0, 0) == Approx(1e-3));
    CHECK(acc.color(1)(0, 0, 0) == Approx(1e30 / 32));
    CHECK(acc.variance(1)(0, 0, 0) == FLT_MAX);  // 1e60 / 32^2 saturates, never Inf
    // The tiny buffer's mean is exact to float despite the huge one next to it.
    CHECK(acc.color(0)(0, 0, 1) == 1e-3f);
}

TEST_CASE("accumulator: constant samples give no variance; shifted data no cancellation", "[accumulator]") {
    sample_accumulator acc;
    REQUIRE(acc.reset(1, 1, 2, 1).ok());
    for (int i = 0; i < 2000; ++i) {
        const float v = 1e6f + static_cast<float>(i % 2 == 0 ? (i / 2) % 2 : 0) * 1e-1f;
        REQUIRE(acc.add(0, 0, static_cast<std::uint64_t>(i), &v).ok());
    }
    acc.finish();
    CHECK(acc.variance(1)(0, 0) == 0.0f);  // buffer 1: always 1e6
    // buffer 0: 1e6 and 1e6 + 0.1 alternately (as float): variance of the samples ~0.0025.
    const double d = static_cast<double>(1e6f + 1e-1f) - 1e6;
    CHECK(acc.variance(0)(0, 0) == Approx(d * d / 4 * 1000.0 / 999.0 / 1000.0).epsilon(1e-6));
}

TEST_CASE("accumulator: a NaN sample makes its buffer non-finite, the others stay", "[accumulator]") {
    sample_accumulator acc;
    REQUIRE(acc.reset(1, 1, 4, 1).ok());
    for (int i = 0; i < 16; ++i) {
        const float v = i == 5 ? std::numeric_limits<float>::quiet_NaN() : 1.0f;
        REQUIRE(acc.add(0, 0, static_cast<std::uint64_t>(i), &v).ok());
    }
    acc.finish();
    CHECK(std::isnan(acc.color(1)(0, 0)));
    CHECK(acc.color(0)(0, 0) == 1.0f);
    CHECK(acc.variance(0)(0, 0) == 0.0f);
}

TEST_CASE("accumulator: tiles from two threads without locks equal one thread", "[accumulator]") {
    const int w = 32, h = 16, k = 4, passes = 12;
    auto sample = [](int x, int y, int s, int c) {
        return static_cast<float>(0.1 + 0.01 * x + 0.02 * y + ((x * 7 + y * 13 + s * 29 + c * 3) % 17) * 0.05);
    };
    // Returns whether every tile was taken (Catch's assertions are not for other threads).
    auto render = [&](sample_accumulator& acc, int x0, int x1) {
        bool ok = true;
        std::vector<float> tile(static_cast<std::size_t>((x1 - x0) * h * 3));
        for (int s = 0; s < passes; ++s) {
            for (int y = 0; y < h; ++y)
                for (int x = x0; x < x1; ++x)
                    for (int c = 0; c < 3; ++c)
                        tile[static_cast<std::size_t>(((y * (x1 - x0)) + (x - x0)) * 3 + c)] = sample(x, y, s, c);
            ok &= acc.add_tile(x0, 0, static_cast<std::uint64_t>(s), *make_image_view(tile.data(), x1 - x0, h, 3)).ok();
        }
        return ok;
    };
    sample_accumulator one, two;
    REQUIRE(one.reset(w, h, k).ok());
    REQUIRE(two.reset(w, h, k).ok());
    REQUIRE(render(one, 0, w));
    bool ok_left = false, ok_right = false;
    {
        std::thread left([&] { ok_left = render(two, 0, w / 2); });
        std::thread right([&] { ok_right = render(two, w / 2, w); });
        left.join();
        right.join();
    }
    REQUIRE(ok_left);
    REQUIRE(ok_right);
    one.finish();
    two.finish();
    for (int b = 0; b < k; ++b)
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                CHECK(two.samples(b, x, y) == static_cast<std::uint32_t>(passes / k));
                for (int c = 0; c < 3; ++c) {
                    CHECK(two.color(b)(x, y, c) == one.color(b)(x, y, c));
                    CHECK(two.variance(b)(x, y, c) == one.variance(b)(x, y, c));
                }
            }
}

// Finite samples whose sums pass double's range: 1e308 and -1e308 gave a mean of -Inf with a
// variance of 0 (the difference overflowed, and a negative M2 was taken as 0); +-1e200 a mean
// of 0 with an infinite variance. No value now, as a NaN sample gives: the detector rebuilds it.
TEST_CASE("accumulator: sums past double's range leave no value, not a wrong one", "[accumulator][numerics]") {
    for (const double big : {1e308, 1e200, DBL_MAX}) {
        sample_accumulator acc;
        REQUIRE(acc.reset(2, 1, 2, 1).ok());
        std::vector<double> s{big, -big};
        for (int i = 0; i < 2; ++i) REQUIRE(acc.add_tile(0, 0, 0, *make_image_view(&s[static_cast<std::size_t>(i)], 1, 1, 1)).ok());
        double fine[2] = {0.25, 0.75};  // pixel 1: ordinary
        for (int i = 0; i < 2; ++i) REQUIRE(acc.add_tile(1, 0, 0, *make_image_view(&fine[i], 1, 1, 1)).ok());
        acc.finish();
        INFO("samples +-" << big);
        CHECK(std::isnan(acc.color(0)(0, 0)));
        CHECK(std::isnan(acc.variance(0)(0, 0)));
        CHECK(acc.color(0)(1, 0) == 0.5f);
        CHECK(acc.variance(0)(1, 0) == 0.0625f);
    }
}

TEST_CASE("accumulator: views go straight to the detector; errors as status", "[accumulator]") {
    sample_accumulator acc;
    CHECK(acc.reset(0, 4, 4).code() == errc::empty_image);
    CHECK(acc.reset(4, 4, 1).code() == errc::invalid_argument);
    CHECK(acc.reset(4, 4, 4, 5).code() == errc::channel_mismatch);
    REQUIRE(acc.reset(8, 8, 4).ok());
    const float v[3] = {1, 1, 1};
    CHECK(acc.add(8, 0, 0, v).code() == errc::invalid_argument);
    CHECK(acc.add(0, 0, 0, nullptr).code() == errc::null_data);  // (it said "outside the image")
    std::vector<float> tile(3 * 3 * 3, 0.5f);
    CHECK(acc.add_tile(6, 6, 0, *make_image_view(tile.data(), 3, 3, 3)).code() == errc::invalid_argument);
    for (int s = 0; s < 32; ++s)
        for (int y = 0; y < 8; ++y)
            for (int x = 0; x < 8; ++x) {
                float c[3] = {0.5f + 0.01f * static_cast<float>((s * 5 + x + y) % 7), 0.5f, 0.5f};
                if (x == 3 && y == 4 && s == 9) c[0] = c[1] = c[2] = 500.0f;  // buffer 1
                REQUIRE(acc.add(x, y, static_cast<std::uint64_t>(s), c).ok());
            }
    acc.finish();
    cross_buffer_detector d;
    const cross_buffer_report r = d.process(acc.views());
    REQUIRE(r.ok());
    CHECK(r.per_buffer[1] >= 1);
    CHECK(acc.color(1)(3, 4) < 1.0f);
    // The readers outside the buffers or the image: 0 samples, empty views (they read past
    // their vectors: AddressSanitizer, heap-buffer-overflow).
    CHECK(acc.samples(1, 3, 4) == 8);
    for (const int b : {-1, 4})
        for (const int x : {-1, 0, 8}) CHECK(acc.samples(b, x, 0) == 0);
    CHECK(acc.samples(0, 8, 0) == 0);
    CHECK(acc.samples(0, 0, -1) == 0);
    CHECK(acc.color(4).empty());
    CHECK(acc.variance(-1).empty());
    CHECK_FALSE(acc.color(3).empty());
    sample_accumulator unset;
    CHECK(unset.samples(0, 0, 0) == 0);
    CHECK(unset.color(0).empty());
    CHECK(unset.views().empty());
}

TEST_CASE("accumulator: fewer samples than buffers (adaptive sampling) lose no light", "[accumulator][buffers]") {
    // K = 8, 5 to 12 gamma samples a pixel. A buffer pixel without a sample is no value (NaN),
    // rebuilt by the detector from the buffers that have one: the output is the samples' mean.
    // Before, it read as black, and those pixels came out at 0.947 of their samples' mean.
    const int w = 32, h = 32, k = 8;
    sample_accumulator acc;
    REQUIRE(acc.reset(w, h, k).ok());
    std::mt19937 g(5);
    std::gamma_distribution<double> gamma(8.0, 1.0 / 8);
    std::uniform_int_distribution<int> count(5, 12);
    std::vector<double> truth(static_cast<std::size_t>(w * h));
    std::vector<int> spp(truth.size());
    for (std::size_t p = 0; p < truth.size(); ++p) {
        spp[p] = count(g);
        double sum = 0;
        for (int i = 0; i < spp[p]; ++i) {
            const float v = static_cast<float>(gamma(g)), c[3] = {v, v, v};
            sum += v;
            REQUIRE(acc.add(static_cast<int>(p) % w, static_cast<int>(p) / w, static_cast<std::uint64_t>(i), c).ok());
        }
        truth[p] = sum / spp[p];
    }
    acc.finish();
    CHECK(std::isnan(acc.color(7)(0, 0)) == (spp[0] < 8));
    cross_buffer_options o;
    o.return_energy = false;  // the rebuild alone
    cross_buffer_detector d(o);
    const cross_buffer_report r = d.process(acc.views());
    REQUIRE(r.ok());
    double out_few = 0, truth_few = 0;
    for (std::size_t p = 0; p < truth.size(); ++p) {
        if (spp[p] >= k) continue;
        double m = 0;
        for (int b = 0; b < k; ++b) m += acc.color(b)(static_cast<int>(p) % w, static_cast<int>(p) / w);
        out_few += m / k, truth_few += truth[p];
    }
    CHECK(out_few / truth_few == Approx(1.0).epsilon(0.01));
    // Fewer than half the buffers with a sample: left as they are, and said (not 0.38 of the
    // light, silently)
    REQUIRE(acc.reset(4, 4, 8).ok());
    for (int i = 0; i < 3; ++i)
        for (int p = 0; p < 16; ++p) {
            const float c[3] = {1, 1, 1};
            REQUIRE(acc.add(p % 4, p / 4, static_cast<std::uint64_t>(i), c).ok());
        }
    acc.finish();
    const cross_buffer_report few = d.process(acc.views());
    CHECK_FALSE(few.ok());
    CHECK(few.left == 16);
}

TEST_CASE("accumulator: a double tile's samples are summed as doubles", "[accumulator]") {
    // Before, each sample was narrowed to float first: 1e300 turned +inf, and 1 +- 1e-9 lost
    // its spread.
    sample_accumulator acc;
    REQUIRE(acc.reset(1, 1, 2, 1).ok());
    const double samples[4] = {1e300, 1.0 + 1e-9, 1e300, 1.0 - 1e-9};  // buffers 0, 1, 0, 1
    for (int i = 0; i < 4; ++i)
        REQUIRE(acc.add_tile(0, 0, static_cast<std::uint64_t>(i), *make_image_view(&samples[i], 1, 1, 1)).ok());
    acc.finish();
    CHECK(acc.color(0)(0, 0) == FLT_MAX);  // finite: held at the float range
    CHECK(acc.variance(0)(0, 0) == 0.0f);  // two equal samples
    CHECK(acc.color(1)(0, 0) == 1.0f);
    CHECK(acc.variance(1)(0, 0) == Approx(1e-18).epsilon(1e-6));  // (2e-18 / 1) / 2
}

// One sample's variance is its square: a double sample past 1.3e154 squared to Inf, and a
// finite sample read an infinite variance (found by fuzz_accumulator). It is held at the
// float range, as every finite value is.
TEST_CASE("accumulator: one sample past 1e154 has a variance of FLT_MAX, not Inf", "[accumulator][numerics]") {
    for (const double big : {2e154, 1e200, -1e300, DBL_MAX}) {
        sample_accumulator acc;
        REQUIRE(acc.reset(1, 1, 2, 1).ok());
        REQUIRE(acc.add_tile(0, 0, 0, *make_image_view(&big, 1, 1, 1)).ok());
        acc.finish();
        INFO("sample " << big);
        CHECK(acc.color(0)(0, 0) == (big > 0 ? FLT_MAX : -FLT_MAX));
        CHECK(acc.variance(0)(0, 0) == FLT_MAX);
    }
}

// Property: on random sample streams (magnitudes from denormals to 1e30, both signs, zeros,
// FLT_MAX, nearly constant runs), every buffer's mean and variance of the mean agree with a
// two-pass reference in long double: the mean to float rounding, the variance to float
// rounding plus Welford's own error (a few ulps of the sum of squares per sample); the
// variance is never negative, never NaN, and finite (FLT_MAX at most) for finite samples;
// a buffer without samples is NaN.
TEST_CASE("accumulator: random streams agree with a two-pass reference", "[accumulator][property]") {
    std::mt19937_64 next(99);
    auto uniform = [&next] { return static_cast<double>(next() >> 11) * 0x1.0p-53; };
    auto draw = [&](float base) -> float {
        switch (next() % 8) {
        case 0: return 0.0f;
        case 1: return std::numeric_limits<float>::denorm_min() * static_cast<float>(1 + next() % 1000);
        case 2: return static_cast<float>(std::pow(10.0, -30.0 + 60.0 * uniform()));
        case 3: return -static_cast<float>(std::pow(10.0, -5.0 + 10.0 * uniform()));
        case 4: return next() % 50 == 0 ? FLT_MAX : base;
        default: return base * static_cast<float>(1.0 + 1e-6 * (uniform() - 0.5));  // nearly constant
        }
    };
    for (int trial = 0; trial < 200; ++trial) {
        const int k = 2 + static_cast<int>(next() % 7), nc = 1 + static_cast<int>(next() % 4);
        const int samples = static_cast<int>(next() % 41);
        sample_accumulator acc;
        REQUIRE(acc.reset(1, 1, k, nc).ok());
        std::vector<std::vector<float>> by_buffer(static_cast<std::size_t>(k * nc));
        const float base = static_cast<float>(std::pow(10.0, -3.0 + 6.0 * uniform()));
        for (int s = 0; s < samples; ++s) {
            float v[4];
            for (int c = 0; c < nc; ++c) {
                v[c] = draw(base);
                by_buffer[static_cast<std::size_t>((s % k) * nc + c)].push_back(v[c]);
            }
            REQUIRE(acc.add(0, 0, static_cast<std::uint64_t>(s), v).ok());
        }
        acc.finish();
        for (int b = 0; b < k; ++b)
            for (int c = 0; c < nc; ++c) {
                const std::vector<float>& x = by_buffer[static_cast<std::size_t>(b * nc + c)];
                const long double n = static_cast<long double>(x.size());
                long double sum = 0, sq = 0, ss = 0;
                for (float v : x) sum += v;
                const long double mean = x.empty() ? 0 : sum / n;
                for (float v : x) {
                    sq += (v - mean) * (v - mean);
                    ss += static_cast<long double>(v) * v;
                }
                const long double want = x.size() >= 2 ? sq / (n - 1) / n : mean * mean;
                const double got_mean = acc.color(b)(0, 0, c), got_var = acc.variance(b)(0, 0, c);
                INFO("trial " << trial << " K " << k << " buffer " << b << " channel " << c << " n " << x.size());
                CHECK(acc.samples(b, 0, 0) == x.size());
                if (x.empty()) {  // no sample: no value
                    CHECK(std::isnan(got_mean));
                    CHECK(std::isnan(got_var));
                    continue;
                }
                CHECK(std::fabs(got_mean - static_cast<double>(mean)) <=
                      1e-6 * std::fabs(static_cast<double>(mean)) + 1e-12 * std::sqrt(static_cast<double>(ss / std::max(n, 1.0L))) + 1e-45);
                REQUIRE(std::isfinite(got_var));
                CHECK(got_var >= 0.0);
                const double expect = static_cast<double>(std::min(want, static_cast<long double>(FLT_MAX)));
                const double welford = x.size() >= 2 ? 16.0 * DBL_EPSILON * static_cast<double>(ss / (n - 1)) : 0.0;
                CHECK(std::fabs(got_var - expect) <= 1e-6 * expect + welford + 1e-45);
            }
    }
}
