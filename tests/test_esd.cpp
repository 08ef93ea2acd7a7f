#include <firefly/bound.hpp>
#include <firefly/esd.hpp>
#include <firefly/statistics.hpp>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "catch.hpp"

using namespace firefly;

namespace {
// NIST/SEMATECH e-Handbook, section 1.3.5.17.3: the generalized ESD example.
const std::vector<double> nist = {
    -0.25, 0.68, 0.94, 1.15, 1.20, 1.26, 1.26, 1.34, 1.38, 1.43, 1.49, 1.49, 1.55, 1.56,
    1.58,  1.65, 1.69, 1.70, 1.76, 1.77, 1.81, 1.91, 1.94, 1.96, 1.99, 2.06, 2.09, 2.10,
    2.14,  2.15, 2.23, 2.24, 2.26, 2.35, 2.37, 2.40, 2.47, 2.54, 2.62, 2.64, 2.90, 2.92,
    2.92,  2.93, 3.21, 3.26, 3.30, 3.59, 3.68, 4.30, 4.64, 5.34, 5.42, 6.01};

std::vector<double> uniform_values(std::size_t n, unsigned seed) {
    std::mt19937_64 g(seed);
    std::vector<double> v(n);
    for (auto& x : v) x = static_cast<double>(g() >> 11) * 0x1.0p-53;
    return v;
}
}  // namespace

TEST_CASE("NIST generalized ESD example, two-sided", "[esd]") {
    esd_options o;
    o.max_outliers = 10;
    o.alpha = 0.05;
    o.two_sided = true;
    const esd_result r = generalized_esd(nist.data(), nist.size(), o);
    REQUIRE(r.error.ok());
    CHECK(r.outliers == 3);
    const double R[] = {3.118906, 2.942973, 3.179424, 2.810181, 2.815580,
                        2.848172, 2.279327, 2.310366, 2.101581, 2.067178};
    const double L[] = {3.158794, 3.151430, 3.143890, 3.136165, 3.128247,
                        3.120128, 3.111796, 3.103243, 3.094456, 3.085425};
    REQUIRE(r.r.size() == 10);
    for (int i = 0; i < 10; ++i) {
        CHECK(r.r[static_cast<std::size_t>(i)] == Approx(R[i]).margin(5e-7));
        CHECK(r.lambda[static_cast<std::size_t>(i)] == Approx(L[i]).margin(5e-7));
    }
    // removal order: 6.01, 5.42, 5.34 are the three outliers; -0.25 is removed fifth
    CHECK(r.indices[0] == 53);
    CHECK(r.indices[1] == 52);
    CHECK(r.indices[2] == 51);
    CHECK(r.indices[4] == 0);
}

TEST_CASE("one-sided Grubbs critical value and the one-sided test", "[esd]") {
    // One-sided Grubbs critical value, n = 8, alpha 0.05.
    CHECK(esd_lambda(8, 0.05, false) == Approx(2.031652).margin(5e-7));
    esd_options o;
    o.max_outliers = 10;
    const esd_result r = generalized_esd(nist.data(), nist.size(), o);
    // One-sided at the same alpha is less strict than two-sided: at least the same 3.
    CHECK(r.outliers >= 3);
    CHECK(r.indices[0] == 53);
    // the low value -0.25 is never tested on the upper side
    CHECK(std::find(r.indices.begin(), r.indices.end(), 0u) == r.indices.end());
}

TEST_CASE("the count is the LARGEST i with R_i > lambda_i", "[esd]") {
    // NIST: R_1, R_2 fail but R_3 passes, so 3 outliers (a first-failure rule would say 0).
    esd_options o;
    o.max_outliers = 10;
    o.two_sided = true;
    const esd_result r = generalized_esd(nist.data(), nist.size(), o);
    CHECK(r.r[0] < r.lambda[0]);
    CHECK(r.r[2] > r.lambda[2]);
    CHECK(r.outliers == 3);
}

TEST_CASE("lambda cache: keyed by k, shared across n and halves", "[esd]") {
    lambda_cache cache;
    CHECK(cache.get(1000, 0.05) == esd_lambda(1000, 0.05));
    CHECK(cache.computed() == 1);
    CHECK(cache.get(1000, 0.05) == esd_lambda(1000, 0.05));
    CHECK(cache.computed() == 1);
    CHECK(cache.hits() == 1);
    // another alpha or sidedness is another key
    CHECK(cache.get(1000, 0.01) == esd_lambda(1000, 0.01));
    CHECK(cache.get(1000, 0.05, true) == esd_lambda(1000, 0.05, true));
    CHECK(cache.computed() == 3);
    // a frame with n = 1000 then one with n = 999: the second reuses all but one lambda
    auto v = uniform_values(1000, 3);
    esd_options o;
    o.max_outliers = 20;
    lambda_cache c2;
    (void)generalized_esd(v.data(), 1000, o, c2);
    CHECK(c2.computed() == 20);
    (void)generalized_esd(v.data(), 999, o, c2);
    CHECK(c2.computed() == 21);
    // lambdas for neighbouring k at n = 1e8 differ in the 9th digit: the cache keeps them apart
    const double a = c2.get(100000000, 0.05), b = c2.get(99999999, 0.05);
    CHECK(a != b);
    CHECK(std::fabs(a - b) / a < 1e-8);
    CHECK(a > b);
}

TEST_CASE("lambda increases with k: more values, a stricter test", "[esd]") {
    double prev = 0;
    for (std::size_t k : {3u, 4u, 5u, 10u, 100u, 1000u, 100000u, 10000000u}) {
        const double l = esd_lambda(k, 0.05);
        CHECK(l > prev);
        prev = l;
    }
    CHECK(std::isnan(esd_lambda(2, 0.05)));
    CHECK(std::isnan(esd_lambda(10, 0.0)));
    // huge k: finite, no overflow; k = 3 (df 1)
    CHECK(std::isfinite(esd_lambda(std::size_t{1} << 40, 0.05)));
    CHECK(std::isfinite(esd_lambda(3, 1e-300)));
}

TEST_CASE("1e30 fireflies next to values in [0, 1): exact statistics", "[esd][hard]") {
    const std::size_t n = 1000000;
    auto v = uniform_values(n, 7);
    for (int j = 0; j < 10; ++j) v[static_cast<std::size_t>(j) * 99991] = 1e30 * (1 + j);  // ten huge values
    esd_options o;
    o.max_outliers = 20;
    const esd_result r = generalized_esd(v.data(), n, o);
    REQUIRE(r.r.size() == 20);
    CHECK(r.outliers >= 10);
    // R_i after the ten huge ones, against a long double two-pass over what remains
    std::vector<double> sorted = v;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t i = 10; i < 20; ++i) {  // step i+1 tests the data with the top i removed
        const std::size_t m = n - i;
        long double sum = 0;
        for (std::size_t j = 0; j < m; ++j) sum += sorted[j];
        const long double mean = sum / m;
        long double ss = 0;
        for (std::size_t j = 0; j < m; ++j) ss += (sorted[j] - mean) * (sorted[j] - mean);
        const long double sd = std::sqrt(ss / (m - 1));
        const long double R = (sorted[m - 1] - mean) / sd;
        INFO("step " << i + 1);
        CHECK(std::fabs(static_cast<double>((r.r[i] - R) / R)) < 1e-12);
    }
    // and the huge ones themselves come out first, largest first
    CHECK(v[r.indices[0]] == 1e31);
    CHECK(v[r.indices[9]] == 1e30);
}

// The kept values are summarised in heap order, nearly sorted: the sum of deviations that
// corrects the mean, added in one run, drifted by 1e-11 of the spread and put R_1 6e-12 off,
// by an amount that changed with max_outliers (the heap's order).
TEST_CASE("a million tightly spread floats: R_1 exact whatever the number of steps", "[esd][hard]") {
    const std::size_t n = 1000000;
    std::mt19937_64 g(11);
    std::vector<float> v(n);
    for (auto& x : v) x = static_cast<float>(0.5e-3 + 1e-3 * (static_cast<double>(g() >> 11) * 0x1.0p-53));
    long double sum = 0;
    for (float x : v) sum += x;
    const long double mean = sum / n;
    long double ss = 0;
    for (float x : v) ss += (x - mean) * (x - mean);
    const long double R = (*std::max_element(v.begin(), v.end()) - mean) / std::sqrt(ss / (n - 1));
    for (const std::size_t steps : {1, 2, 15}) {
        esd_options o;
        o.max_outliers = steps;
        const esd_result r = generalized_esd(v.data(), n, o);
        REQUIRE(r.r.size() == steps);
        INFO("steps " << steps << ": R_1 " << r.r[0] << " against " << static_cast<double>(R));
        CHECK(std::fabs(static_cast<double>((r.r[0] - R) / R)) < 1e-13);
    }
}

TEST_CASE("values near FLT_MAX, DBL_MAX and denormals", "[esd][hard]") {
    esd_options o;
    o.max_outliers = 3;
    std::vector<float> f(100);
    for (std::size_t i = 0; i < f.size(); ++i) f[i] = FLT_MAX * (0.5f + 0.001f * static_cast<float>(i % 7));
    f[42] = FLT_MAX;
    esd_result r = generalized_esd(f.data(), f.size(), o);
    for (double x : r.r) CHECK(std::isfinite(x));
    CHECK(r.indices[0] == 42);
    CHECK(r.outliers == 1);

    std::vector<double> d(100);
    for (std::size_t i = 0; i < d.size(); ++i) d[i] = DBL_MAX * (0.25 + 0.001 * static_cast<double>(i % 7));
    d[17] = DBL_MAX;
    r = generalized_esd(d.data(), d.size(), o);
    for (double x : r.r) CHECK(std::isfinite(x));
    CHECK(r.indices[0] == 17);
    CHECK(r.outliers == 1);

    // denormals: the same answer as the data scaled up by 2^1000 (scaling is exact)
    std::vector<double> tiny(100), big(100);
    for (std::size_t i = 0; i < tiny.size(); ++i) {
        tiny[i] = 4.9e-324 * static_cast<double>(1 + i % 5);
        big[i] = std::ldexp(tiny[i], 1000);
    }
    tiny[3] = 4.9e-324 * 1000;
    big[3] = std::ldexp(tiny[3], 1000);
    const esd_result rt = generalized_esd(tiny.data(), tiny.size(), o);
    const esd_result rb = generalized_esd(big.data(), big.size(), o);
    CHECK(rt.outliers == rb.outliers);
    CHECK(rt.outliers >= 1);
    for (std::size_t i = 0; i < rt.r.size(); ++i) CHECK(rt.r[i] == Approx(rb.r[i]).epsilon(1e-12));
}

TEST_CASE("degenerate inputs are defined cases", "[esd][hard]") {
    esd_options o;
    o.max_outliers = 5;
    std::vector<double> eq(50, 3.25);
    esd_result r = generalized_esd(eq.data(), eq.size(), o);
    CHECK(r.outliers == 0);
    for (double x : r.r) CHECK(x == 0.0);  // sd = 0 gives R = 0, not NaN
    for (std::size_t n = 0; n <= 3; ++n) {
        std::vector<double> v = {1.0, 2.0, 100.0};
        r = generalized_esd(v.data(), n, o);
        CHECK(r.error.ok());
        CHECK(r.r.size() == (n >= 3 ? 1u : 0u));  // at most n - 2 steps
        CHECK(r.outliers <= r.r.size());
        for (double x : r.r) CHECK(std::isfinite(x));
    }
    o.alpha = 1.5;
    CHECK(generalized_esd(eq.data(), eq.size(), o).error.code() == errc::invalid_argument);
}

TEST_CASE("NaN and Inf are outliers outright and stay out of the statistics", "[esd][hard]") {
    auto v = uniform_values(200, 11);
    auto clean = v;
    v[5] = std::numeric_limits<double>::quiet_NaN();
    v[9] = HUGE_VAL;
    v[13] = -HUGE_VAL;
    clean.erase(clean.begin() + 13);
    clean.erase(clean.begin() + 9);
    clean.erase(clean.begin() + 5);
    esd_options o;
    o.max_outliers = 5;
    const esd_result r = generalized_esd(v.data(), v.size(), o);
    const esd_result c = generalized_esd(clean.data(), clean.size(), o);
    CHECK(r.nonfinite == std::vector<std::size_t>{5, 9, 13});
    CHECK(r.n == 197);
    REQUIRE(r.r.size() == c.r.size());
    for (std::size_t i = 0; i < r.r.size(); ++i) CHECK(r.r[i] == Approx(c.r[i]).epsilon(1e-13));
    CHECK(r.outliers == c.outliers);
}

TEST_CASE("invariants: permutation, positive scale, the cap", "[esd][invariant]") {
    auto v = uniform_values(5000, 5);
    for (std::size_t j = 0; j < 12; ++j) v[j * 311] = 3.0 + static_cast<double>(j);
    esd_options o;
    o.max_outliers = 30;
    const esd_result base = generalized_esd(v.data(), v.size(), o);
    CHECK(base.outliers >= 12);
    CHECK(base.outliers <= o.max_outliers);
    std::mt19937 g(1);
    for (int t = 0; t < 3; ++t) {
        auto p = v;
        std::shuffle(p.begin(), p.end(), g);
        const esd_result r = generalized_esd(p.data(), p.size(), o);
        CHECK(r.outliers == base.outliers);
        for (std::size_t i = 0; i < r.r.size(); ++i) CHECK(r.r[i] == Approx(base.r[i]).epsilon(1e-12));
        std::vector<double> a, b;
        for (std::size_t i = 0; i < r.outliers; ++i) {
            a.push_back(p[r.indices[i]]);
            b.push_back(v[base.indices[i]]);
        }
        CHECK(a == b);  // the same values are the outliers
    }
    for (double s : {1e-20, 0.37, 1e25}) {
        auto sv = v;
        for (auto& x : sv) x *= s;
        CHECK(generalized_esd(sv.data(), sv.size(), o).outliers == base.outliers);
    }
    for (std::size_t cap : {0u, 1u, 5u, 13u}) {
        o.max_outliers = cap;
        CHECK(generalized_esd(v.data(), v.size(), o).outliers <= cap);
    }
}

TEST_CASE("modified Z-score bound", "[bound]") {
    const bound_result b = modified_zscore_bound(nist.data(), nist.size());
    std::vector<double> s = nist;
    std::sort(s.begin(), s.end());
    CHECK(b.median == 0.5 * (s[26] + s[27]));  // even count: mean of the two middle values
    CHECK(b.n == 54);
    std::vector<double> dev;
    for (double x : nist) dev.push_back(std::fabs(x - b.median));
    std::sort(dev.begin(), dev.end());
    CHECK(b.mad == 0.5 * (dev[26] + dev[27]));
    std::size_t count = 0;
    for (double x : nist) count += 0.6745 * (x - b.median) / b.mad > 3.5 ? 1 : 0;
    CHECK(b.count == count);
    // odd count, exact selection against a full sort, on many random sizes
    for (std::size_t n : {1u, 2u, 3u, 7u, 1000u, 4097u}) {
        auto v = uniform_values(n, static_cast<unsigned>(n));
        for (auto& x : v) x = std::pow(x, 8.0) * 1e3;  // skewed, many float buckets
        const bound_result r = modified_zscore_bound(v.data(), n);
        auto t = v;
        std::sort(t.begin(), t.end());
        const double med = n % 2 ? t[n / 2] : 0.5 * (t[n / 2 - 1] + t[n / 2]);
        CHECK(r.median == med);
    }
}

TEST_CASE("bound: one-sided, MAD = 0 fallback, constant data", "[bound]") {
    std::vector<double> v(101, 1.0);
    const bound_result c = modified_zscore_bound(v.data(), v.size());
    CHECK(c.count == 0);
    CHECK(c.mad == 0.0);
    v[0] = 50.0;  // MAD still 0 (more than half are equal): the mean-AD fallback finds it
    v[1] = -50.0; // below the median: never counted (one-sided)
    const bound_result f = modified_zscore_bound(v.data(), v.size());
    CHECK(f.mad_fallback);
    CHECK(f.count == 1);
    CHECK(f.scale == Approx(1.253314 * 100.0 / 101.0));
    std::vector<float> none;
    CHECK(modified_zscore_bound(none.data(), 0).count == 0);
    std::vector<double> with_nan = {1, 2, std::numeric_limits<double>::quiet_NaN(), 3};
    const bound_result wn = modified_zscore_bound(with_nan.data(), with_nan.size());
    CHECK(wn.n == 3);
    CHECK(wn.median == 2.0);
}

// alpha / k for a tiny alpha was 0 or a denormal: every lambda NaN (5e-324) and the test found
// nothing, or lambdas 6e-12 off. Such an alpha is refused, by the test and by the detectors.
TEST_CASE("an alpha whose alpha / n would underflow is refused", "[esd][errors]") {
    const std::vector<double> v = {1, 2, 3, 4, 100};
    for (const double a : {5e-324, 1e-300, 1e-281}) {
        esd_options o;
        o.alpha = a;
        const esd_result r = generalized_esd(v.data(), v.size(), o);
        INFO("alpha " << a);
        CHECK(r.error.code() == errc::invalid_argument);
        CHECK(r.lambda.empty());
    }
    esd_options o;
    o.alpha = min_alpha;
    const esd_result r = generalized_esd(v.data(), v.size(), o);
    CHECK(r.error.ok());
    CHECK(r.lambda.size() == 3);
    for (double l : r.lambda) CHECK(std::isfinite(l));
}

// An even count's median is (a + b) / 2 rounded once: halving each first rounded both at
// double denormals (the median of two least denormals was 0, of 3d and 3d 4d).
TEST_CASE("bound: even-count medians of double denormals", "[bound][hard]") {
    const double d = std::numeric_limits<double>::denorm_min();
    const std::vector<double> pair = {d, d}, six = {3 * d, 3 * d, 3 * d, 3 * d, 0, 1000 * d};
    CHECK(modified_zscore_bound(pair.data(), pair.size()).median == d);
    CHECK(modified_zscore_bound(six.data(), six.size()).median == 3 * d);
    const std::vector<double> huge = {DBL_MAX, DBL_MAX, -DBL_MAX, DBL_MAX};  // the sum overflows
    CHECK(modified_zscore_bound(huge.data(), huge.size()).median == DBL_MAX);
}

TEST_CASE("the detector's histogram median and MAD equal a full sort, bit for bit", "[bound][hard]") {
    std::mt19937_64 g(99);
    auto check = [](const std::vector<float>& v, const char* what) {
        std::vector<double> kept;
        for (float x : v)
            if (x >= 0) kept.push_back(x);
        if (kept.empty()) return;
        std::sort(kept.begin(), kept.end());
        const std::size_t n = kept.size();
        const double med = n % 2 ? kept[n / 2] : 0.5 * kept[n / 2 - 1] + 0.5 * kept[n / 2];
        std::vector<double> dev;
        for (double x : kept) dev.push_back(std::fabs(x - med));
        std::sort(dev.begin(), dev.end());
        const double mad = n % 2 ? dev[n / 2] : 0.5 * dev[n / 2 - 1] + 0.5 * dev[n / 2];
        sd_histogram h;
        h.build(v.data(), v.size());
        std::vector<float> sf;
        std::vector<double> sd;
        INFO(what << ", n = " << n);
        const double m = h.median(v.data(), v.size(), sf);
        CHECK(m == med);
        CHECK(h.mad(v.data(), v.size(), m, sd) == mad);
    };
    for (std::size_t n : {1u, 2u, 3u, 4u, 5u, 17u, 1000u, 100001u}) {
        std::vector<float> v(n);
        std::gamma_distribution<float> gam(2.0f, 0.05f);
        for (auto& x : v) x = gam(g);
        check(v, "gamma");
        for (std::size_t i = 0; i < n; i += 3) v[i] = 0.25f;  // heavy ties at one value
        check(v, "ties");
        for (std::size_t i = 1; i < n; i += 5) v[i] = -1.0f;  // ignored pixels
        for (std::size_t i = 2; i < n; i += 7) v[i] = std::numeric_limits<float>::quiet_NaN();
        check(v, "with ignored and NaN");
        for (std::size_t i = 0; i < n; i += 11) v[i] = FLT_MAX;
        for (std::size_t i = 4; i < n; i += 13) v[i] = 1e-45f;  // denormal
        for (std::size_t i = 5; i < n; i += 17) v[i] = 0.0f;
        check(v, "extremes");
        std::vector<float> c(n, 3.0f);
        check(c, "constant");
        std::vector<float> two(n);
        for (std::size_t i = 0; i < n; ++i) two[i] = i % 2 ? 1.0f : 1e30f;
        check(two, "two values far apart");
    }
}

// The order the detector visits its lists of pixels in (pixel index in the high word, the
// entry below): the radix sort against std::stable_sort on the high words, for sizes that need
// one, two and three passes, equal high words (kept in order), an empty list and one key.
TEST_CASE("sort_by_high_word orders by the high word, stably", "[bound]") {
    std::mt19937_64 rng(5);
    std::vector<std::uint64_t> tmp;
    for (const std::uint64_t top : {std::uint64_t{1000}, std::uint64_t{3000000}, std::uint64_t{0xffffffffu}})
        for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{5000}}) {
            std::vector<std::uint64_t> keys(n);
            for (std::size_t j = 0; j < n; ++j)
                keys[j] = ((rng() % (top + 1)) << 32) | static_cast<std::uint64_t>(j);  // repeats among the high words
            if (n > 1) keys[1] = (top << 32) | 1u;  // the largest high word present
            std::vector<std::uint64_t> want = keys;
            std::stable_sort(want.begin(), want.end(), [](std::uint64_t a, std::uint64_t b) { return (a >> 32) < (b >> 32); });
            firefly::detail::sort_by_high_word(keys, tmp);
            INFO("top " << top << ", n " << n);
            CHECK(keys == want);
        }
}
