#include <firefly/student_t.hpp>

#include <cfloat>
#include <cmath>
#include <limits>

#include "catch.hpp"

using namespace firefly;

namespace {
double rel(double a, double b) { return std::fabs(a - b) / std::fabs(b); }
const double q_grid[] = {1e-300, 1e-250, 1e-200, 1e-150, 1e-100, 1e-60, 1e-30, 1e-16, 1e-12, 1e-8,
                         1e-5,   1e-3,   0.01,   0.05,   0.1,    0.2,   0.249, 0.25,  0.26,  0.3,
                         0.4,    0.45,   0.49,   0.4999, 0.499999999};
}  // namespace

TEST_CASE("published Student-t points (R qt, upper tail)", "[student_t]") {
    CHECK(rel(student_t_upper_quantile(1e-8, 1), 31830988.618379056) < 1e-14);
    CHECK(rel(student_t_upper_quantile(1e-8, 5), 62.404506110967276) < 1e-14);
    CHECK(rel(student_t_upper_quantile(1e-8, 30), 7.5565346518854017) < 1e-14);
    CHECK(rel(student_t_upper_quantile(1e-16, 30), 16.264942502976727) < 1e-14);
    CHECK(rel(student_t_upper_quantile(0.025, 10), 2.2281388519862744) < 1e-14);
}

TEST_CASE("normal quantile: published points and the tail identity", "[student_t]") {
    CHECK(rel(normal_upper_quantile(0.025), 1.959963984540054) < 1e-15);
    CHECK(rel(normal_upper_quantile(0.05), 1.6448536269514722) < 1e-15);
    CHECK(rel(normal_upper_quantile(1e-10), 6.3613409024040557) < 1e-14);
    CHECK(normal_upper_quantile(0.5) == 0.0);
    // symmetry, on complements that are exact in binary
    CHECK(normal_upper_quantile(0.875) == -normal_upper_quantile(0.125));
    const double p = 1 - 1e-10;
    CHECK(normal_upper_quantile(p) == -normal_upper_quantile(1 - p));
    // 0.5 erfc(z / sqrt 2) = q; erfc's argument carries ~z^2 eps of relative error, so
    // the check's tolerance grows with z^2 while the quantile itself is ~1e-16.
    for (double q : q_grid) {
        const double z = normal_upper_quantile(q);
        const double back = 0.5 * std::erfc(z / std::sqrt(2.0));
        CHECK(rel(back, q) < 1e-14 * (1 + z * z));
    }
}

TEST_CASE("closed forms at df 1 and 2 agree with the general method", "[student_t]") {
    for (double q : q_grid) {
        if (q >= 0.5) continue;
        const double z = normal_upper_quantile(q);
        for (double df : {1.0, 2.0}) {
            const double closed = student_t_upper_quantile(q, df);
            const double general = detail::student_t_upper_quantile_refined<double>(q, df, z);
            INFO("q=" << q << " df=" << df);
            CHECK(rel(general, closed) < 2e-13);
        }
    }
    // df 1, q 1e-300 is ~3.18e299: finite, no overflow on the way.
    const double t = student_t_upper_quantile(1e-300, 1);
    CHECK(std::isfinite(t));
    CHECK(rel(t, 1.0 / (3.141592653589793 * 1e-300)) < 1e-15);
}

TEST_CASE("relative error <= 1e-13 against a long double oracle", "[student_t]") {
    // The oracle is the same general method in 64-bit-mantissa arithmetic; it is only
    // trustworthy where df * eps(long double) stays small, i.e. up to df ~1e6.
    const double dfs[] = {1.5, 2.5, 3, 4, 5, 7, 10, 30, 100, 1000, 1e4, 3e4, 1e5, 3e5, 1e6};
    double worst = 0;
    for (double df : dfs)
        for (double q : q_grid) {
            const double z = normal_upper_quantile(q);
            const long double o = detail::student_t_upper_quantile_refined<long double>(q, df, z);
            const double t = student_t_upper_quantile(q, df);
            const double e = static_cast<double>(std::fabs((static_cast<long double>(t) - o) / o));
            INFO("q=" << q << " df=" << df << " t=" << t);
            CHECK(e <= 1e-13);
            worst = std::max(worst, e);
        }
    INFO("worst relative error " << worst);
    CHECK(worst < 1e-13);
}

TEST_CASE("Cornish-Fisher region meets the general method where both apply", "[student_t]") {
    // max(z^2, 1) / df < 1e-3 selects the expansion; compare it with the general method
    // (long double) on both sides of the switch.
    for (double df : {2e3, 1e4, 1e5, 1e6})
        for (double q : {0.3, 0.1, 0.01, 1e-4, 1e-8}) {
            const double z = normal_upper_quantile(q);
            if (std::max(z * z, 1.0) >= 1e-3 * df) continue;
            const double cf = detail::cornish_fisher_t(z, df);
            const long double o = detail::student_t_upper_quantile_refined<long double>(q, df, z);
            INFO("q=" << q << " df=" << df);
            CHECK(static_cast<double>(std::fabs((cf - o) / o)) < 1e-13);
        }
}

TEST_CASE("huge degrees of freedom approach the normal quantile from above", "[student_t]") {
    for (double q : {1e-300, 1e-12, 0.01, 0.3}) {
        const double z = normal_upper_quantile(q);
        double prev = HUGE_VAL;
        for (double df : {1e6, 1e7, 1e8, 1e9, 1e10, 1e12}) {
            const double t = student_t_upper_quantile(q, df);
            CHECK(t >= z);
            CHECK(t <= prev);  // monotone in df
            prev = t;
        }
        CHECK(rel(student_t_upper_quantile(q, 1e12), z) < 1e-9);
        CHECK(student_t_upper_quantile(q, HUGE_VAL) == z);
    }
}

TEST_CASE("monotone in q and in df", "[student_t]") {
    const double dfs[] = {1, 1.5, 2, 3, 4.5, 10, 57, 1000, 123456, 1e9};
    for (double df : dfs) {
        double prev = HUGE_VAL;
        for (double q : q_grid) {
            const double t = student_t_upper_quantile(q, df);
            INFO("q=" << q << " df=" << df);
            CHECK(t < prev);  // decreasing in q
            CHECK(t > 0);
            prev = t;
        }
    }
    for (double q : q_grid) {
        double prev = HUGE_VAL;
        for (double df : dfs) {
            const double t = student_t_upper_quantile(q, df);
            INFO("q=" << q << " df=" << df);
            CHECK(t <= prev);  // decreasing in df
            prev = t;
        }
    }
}

TEST_CASE("domain: NaN outside, symmetry above one half", "[student_t]") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    CHECK(std::isnan(student_t_upper_quantile(0.0, 5)));
    CHECK(std::isnan(student_t_upper_quantile(1.0, 5)));
    CHECK(std::isnan(student_t_upper_quantile(-0.1, 5)));
    CHECK(std::isnan(student_t_upper_quantile(nan, 5)));
    CHECK(std::isnan(student_t_upper_quantile(0.1, 0.5)));
    CHECK(std::isnan(student_t_upper_quantile(0.1, nan)));
    CHECK(std::isnan(normal_upper_quantile(0.0)));
    CHECK(std::isnan(normal_upper_quantile(nan)));
    CHECK(student_t_upper_quantile(0.5, 7) == 0.0);
    CHECK(student_t_upper_quantile(0.875, 7) == -student_t_upper_quantile(0.125, 7));
    const double p = 1 - 1e-10;  // 1 - p is exact, and is what the upper half uses
    CHECK(student_t_upper_quantile(p, 3) == -student_t_upper_quantile(1 - p, 3));
    // the smallest normal q, and denormal q: finite or +inf, never NaN
    CHECK(std::isfinite(student_t_upper_quantile(DBL_MIN, 3)));
    CHECK(!std::isnan(student_t_upper_quantile(4.9e-324, 1)));
    CHECK(!std::isnan(student_t_upper_quantile(4.9e-324, 1.5)));
}
