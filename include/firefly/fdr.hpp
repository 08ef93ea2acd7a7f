// firefly: one promise per frame for the tests that run once per pixel.
//
// The local test and the K-buffer test each run a test at every pixel. At a fixed per-test
// level q, a frame of m tests without a single firefly still gets about q m flags (55 at
// 1024x540 and q = 1e-4), and every flag rebuilds a good pixel: the frame comes out worse
// than it went in. The generalized ESD makes its promise per frame instead (no detection in
// at least 1 - alpha of frames without outliers); these tests now do the same, by the step-up
// procedure of Benjamini and Hochberg (1995): with the p-values sorted, p_(1) <= ... <= p_(m),
// keep every flag with p <= p_(k), k the largest with p_(k) <= alpha k / m.
//
//   - without fireflies (every null hypothesis true) it flags nothing in at least 1 - alpha
//     of frames (Simes 1986), the ESD's promise;
//   - with fireflies, the expected share of flags that are not fireflies is at most alpha;
//   - a frame with many fireflies keeps its power: the threshold grows with the count.
//
// The tests screen at a cap level first (their false_alarm option) and hand over only the
// p-values at or below it, which are the smallest of all m: their ranks are the true ranks.
// The kept set is then BH's set intersected with p <= cap, so the cap can only make the
// procedure stricter. Independence across pixels is assumed (positive dependence, as
// between neighbours that share a noise estimate, keeps the promise: Benjamini and
// Yekutieli 2001). One pixel moves the threshold by at most one rank, alpha / m, but every
// p-value between the two levels turns with it: where many flags sit at the margin, one
// firefly far from them decides them all (20 equal local flags, none rebuilt without it and
// all 20 with it), as step-up procedures do. The promise is this family's: the implausible
// values, dropped pixels and pairs are decided at their own levels.
//
// p-values are carried as logarithms: a 1e30 firefly next to 1e-3 pixels has p far below
// the smallest double.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "student_t.hpp"

namespace firefly {

// The log of the largest p-value Benjamini-Hochberg keeps at level alpha among m tests, given
// the log p-values of the candidates (any order; sorted in place). -infinity when it keeps
// none (no candidate, m = 0, alpha <= 0 or NaN), and at least -DBL_MAX when it keeps any.
// NaN log p-values count as p = 1.
inline double bh_log_threshold(std::vector<double>& log_p, std::size_t m, double alpha) {
    const double none = -std::numeric_limits<double>::infinity();
    if (log_p.empty() || m == 0 || !(alpha > 0)) return none;
    for (double& l : log_p) {
        if (!(l <= 0)) l = 0;               // NaN or > 0: p = 1
        l = (std::max)(l, -DBL_MAX);          // p = 0 is a p-value too, not "none"
    }
    std::sort(log_p.begin(), log_p.end());
    const std::size_t n = (std::min)(log_p.size(), m);
    const double log_alpha_over_m = std::log((std::min)(alpha, 1.0)) - std::log(static_cast<double>(m));
    for (std::size_t k = n; k >= 1; --k)  // step up: the largest rank that passes
        if (log_p[k - 1] <= log_alpha_over_m + std::log(static_cast<double>(k))) return log_p[k - 1];
    return none;
}

// log P(Z > z) for a standard normal Z, z any real: log(erfc(z / sqrt 2) / 2), and past
// z = 30, where erfc nears underflow, Mills' ratio's asymptotic series
//     1 - 1/z^2 + 3/z^4 - 15/z^6 + ... + (-1)^k (2k-1)!!/z^2k
// taken until a term is below 1e-17 (at z = 30, nine terms; four were 1.6e-10 off in log p).
inline double normal_log_upper_tail(double z) noexcept {
    if (z < 30.0) return std::log(0.5 * std::erfc(z / std::sqrt(2.0)));
    const double z2 = z * z;
    double series = 1.0, term = 1.0;
    for (int k = 1; k < 40 && std::fabs(term) >= 1e-17; ++k) {  // terms fall while 2k - 1 < z^2
        term *= -(2.0 * k - 1.0) / z2;
        series += term;
    }
    return -0.5 * z2 - std::log(z) - 0.5 * std::log(2.0 * 3.141592653589793) + std::log(series);
}

// log P(T > t) for Student's t with df degrees of freedom (t >= 0, df >= 1). Above 1e7 degrees
// of freedom, where the incomplete beta function's own error grows (~1e-6 in log p at 1e10),
// and where t^4 <= 0.04 df: the normal tail corrected to first order in 1 / df,
//     log P(T > t) = log P(Z > t) + t^2 (t^2 + 2) / (4 df) + O(t^6 / df^2)
// (the plain normal tail was 2.5e-4 off in log p at t = 10, df = 1e7; the corrected one within
// 3e-8 of a 100-digit reference, test "fdr: log tails"); beyond that t the incomplete beta.
inline double student_t_log_upper_tail(double t, double df) noexcept {
    if (!(t > 0)) return t == 0 ? std::log(0.5) : std::numeric_limits<double>::quiet_NaN();
    const double t2 = t * t;
    if (df > 1e7 && t2 * t2 <= 0.04 * df) return normal_log_upper_tail(t) + t2 * (t2 + 2.0) / (4.0 * df);
    return detail::student_t_tail<double>(t, df).log_p;
}

}  // namespace firefly
