// firefly: the local, brightness-invariant firefly test (issues 15 and 17).
//
// Model. The two halves hold independent means of the same pixel's samples. Whatever the
// per-sample law, a half mean L is positive and, to its first two moments, a gamma variable
// of shape m = E[L]^2 / Var[L] (m = N k for N samples of a gamma(k) law; Satterthwaite's
// moment match otherwise). For two independent gamma(m) means of one expected value,
// L_A / L_B ~ F(2m, 2m), and (Cacoullos 1965)
//
//     T = sqrt(m / 2) (sqrt(L_A / L_B) - sqrt(L_B / L_A))  ~  Student t, 2m degrees of freedom,
//
// exactly. T is a ratio, so brightness cancels: a pixel at 0.01 and one at 10 are judged
// alike, in one frame or across frames. Half A is flagged when T > t(q) (one-sided: a
// firefly adds light), half B when -T > t(q). A pixel is flagged in at most one half; an
// outlier in both halves is left to the global test and the highlight check.
//
// The shape m. 1/m = r = Var[L] / E[L]^2, the relative variance of a half mean, given per
// pixel by the renderer's variance: r = (mean over channels of sd_c)^2 / (mean colour)^2
// (the channels of one sample move together). A firefly inflates its own half's r, so r is
// estimated without it, from the (2 radius + 1)^2 - 1 neighbours in both halves:
//     r~ = exp(median log r + s^2 / 2) (1 + r),   s = MAD(log r) / 0.6745
// exp(s^2 / 2): a median of variance estimates sits below their mean (lognormal mean over
// median); 1 + r: the sample relative variance of a skewed law is itself biased low, by
// E[r^] ~ r (1 - r) for gamma samples. r~ is never taken below the other half's own r at the
// pixel: a highlight or an edge is noisier than its surroundings, and the other half says so.
// Relative variances do not change across gradients, fine detail or texture that keep the
// noise's character, only where the light transport changes. The estimate's own uncertainty
// widens the t: df = 1 / (1/(2m) + 1/nu), nu = 4 n / (pi s^2) for a median of n values.
//
// Assumptions: positive pixel values (a half whose mean colour is <= 0 is not tested); the
// given variance is that of the half's mean (else set variance_scale); the neighbourhood's
// light transport is like the pixel's (else the other half's r takes over, conservatively).
//
// Promise. In a frame without fireflies, the expected share of tested pixel-halves flagged
// is at most q (options.false_alarm, default 1e-4). Test [local][calibration]: gamma(k)
// per-sample noise, k 1, 4, 16, 4 to 1024 samples per half, three decades, fine detail,
// highlights (25x, per-sample shape 0.16), black background, alpha; 534k pixel-halves:
//     q = 1e-3: 345 flagged (promise 534);  q = 1e-4: 30 flagged (promise 53)
//     at 4 samples per half, q = 1e-4: 24 of 306k (promise 31), a third on highlights
// On the simulator's null scenes (bench/research/local_eval.cpp) the share flagged follows q
// from 1e-4 to 0.05 within a factor 0.7-0.9.
//
// Measured with a stand-in rebuild (a pixel flagged in one half takes the other half's value;
// bench/research/README.md has the tables):
//     moderate fireflies (2-20x the pixel, 1% of pixels per half, 64 spp, gamma k = 4, dark
//     frame): recall 0.97, 1 false positive in 32k pixel-halves (test "recall")
//     three decades with 30-1000x fireflies ("decades"): recall 1.000 (global ESD 0.987)
//     cycles-caustics: relMSE 0.078 alone, 0.0295 in union with the global ESD (= global)
//     cycles-interior: relMSE 0.88 alone (the global ESD's flags: 0.132): every pixel there
//     has m ~ 2-6, so a pixel 3x its other half is ordinary noise under the model and the
//     test, calibrated, does not flag it. Pixels that both halves hold fireflies at are not
//     seen at all.
//
// Cost: one read pass over both halves' colour and variance (level and r per pixel and
// half), then one pass over those arrays. The neighbourhood is read only for pixels that the
// pair statistic with the other half's own r (an upper bound of T, with the threshold at
// that r a lower bound of the real one) does not clear; thresholds come from a cache on a df
// grid rounded down. Deterministic, no scan order: medians are order-free, so the flags are
// the same under the 8 flips and transposes of the frame.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#include "image_view.hpp"
#include "status.hpp"
#include "stddev.hpp"
#include "student_t.hpp"

namespace firefly {

struct local_test_options {
    double false_alarm = 1e-4;      // q: expected share of tested pixel-halves flagged in a
                                    // frame without fireflies
    int radius = 1;                 // neighbourhood (2 radius + 1)^2 - 1 pixels, both halves:
                                    // 16 values at 1 (measured as good as 48 at 2, 3x cheaper)
    int min_neighbours = 6;         // fewer usable neighbour values (2 per pixel): the pixel is
                                    // not tested (6: frame corners are, at radius 1)
    double variance_scale = 1.0;    // turns the given variance into the variance of the half
                                    // mean (1: it already is; the number of samples when the
                                    // renderer stores the variance of the samples)
};

inline status check_local_test_options(const local_test_options& o) noexcept {
    if (!(o.false_alarm > 0.0 && o.false_alarm < 0.5))
        return status{errc::invalid_argument, "local test: false_alarm must lie in (0, 0.5)"};
    if (o.radius < 1 || o.radius > 8)
        return status{errc::invalid_argument, "local test: radius must lie in [1, 8]"};
    if (o.min_neighbours < 1)
        return status{errc::invalid_argument, "local test: min_neighbours must be >= 1"};
    if (!(o.variance_scale > 0.0) || !std::isfinite(o.variance_scale))
        return status{errc::invalid_argument, "local test: variance_scale must be finite and > 0"};
    return ok_status();
}

// Pixels flagged in one half, in row-major order (sorted), with their scores T / t_{2m}(q)
// (> 1: how far past the threshold).
struct local_flags {
    std::vector<std::uint32_t> index;
    std::vector<float> score;
};

struct local_test_result {
    local_flags half[2];
    std::size_t tested = 0;        // pixels tested (each tests both halves)
    std::size_t screened = 0;      // pixels whose neighbourhood statistics were computed
};

// Memory reused across frames.
struct local_test_scratch {
    std::vector<double> level[2];  // mean colour; NaN where the pixel does not count
    std::vector<float> rel_var[2]; // relative variance r of the half mean; NaN where unusable
    std::vector<float> pool;
    std::vector<double> thresholds;  // t_df(q) by df grid step (see detail::t_threshold)
    double thresholds_q = 0;
    std::size_t bytes() const noexcept {
        return (level[0].capacity() + level[1].capacity() + thresholds.capacity()) * sizeof(double) +
               (rel_var[0].capacity() + rel_var[1].capacity() + pool.capacity()) * sizeof(float);
    }
};

// One half buffer's views for the test; alpha may be empty. label (optional, pixel_count
// bytes, row-major): the stddev pass's labels, pixel_class in the low bits; when null the
// class is computed here (black: every colour channel 0; alpha <= 0; NaN/Inf anywhere).
// Colour, variance and alpha may each have their own channel type, as in half_buffer.
template <class C, class V = C, class A = C>
struct local_half {
    image_view<const C> color;
    image_view<const V> variance;
    image_view<const A> alpha{};
    const std::uint8_t* label = nullptr;
};

namespace detail {

// Relative variances below this count as this: float colour carries ~1e-7 relative
// rounding, so a smaller relative sd is not information (and m stays finite).
inline constexpr double min_relative_variance = 1e-14;

// Level (mean colour) and relative variance of one pixel; false when it does not count.
template <class C, class V>
inline bool local_pixel(const C* pc, std::ptrdiff_t cs, const V* pv, std::ptrdiff_t vs, int nc, bool one_var,
                        double scale, double& level, float& rel_var) noexcept {
    using ctraits = channel_traits<std::remove_cv_t<C>>;
    using vtraits = channel_traits<std::remove_cv_t<V>>;
    double sum = 0, sd = 0, fin = 0;
    bool black = true;
    for (int c = 0; c < nc; ++c) {
        const double v = ctraits::load(pc[c * cs]);
        const double var = vtraits::load(pv[one_var ? 0 : c * vs]);
        fin += (v - v) + (var - var);  // NaN for any NaN or Inf
        black &= v == 0.0;
        sum += v;
        sd += std::sqrt(std::max(var, 0.0) * scale);
    }
    level = sum / nc;  // finite sums of floats up to FLT_MAX stay finite in double
    if (!(fin == 0.0) || black) return false;
    if (!(level > 0) || !std::isfinite(level)) {
        rel_var = std::numeric_limits<float>::quiet_NaN();
        return true;  // counts, but has no relative variance: neither tested nor pooled
    }
    const double rel = (sd / nc) / level;  // a ratio first: no overflow near FLT_MAX
    const double r = std::max(rel * rel, min_relative_variance);
    // float: r is an estimate good to a few per cent; r >= FLT_MAX means m ~ 0 anyway
    rel_var = static_cast<float>(std::min(r, static_cast<double>(FLT_MAX)));
    return true;
}

// Level and relative variance of every pixel of one half (NaN where unusable).
template <class C, class V, class A>
void local_levels(const local_half<C, V, A>& h, double scale, std::vector<double>& level,
                  std::vector<float>& rel_var) {
    const int w = h.color.width(), ht = h.color.height();
    const int nc = colour_channels(h.color.channels());
    const bool one_var = h.variance.channels() == 1;
    level.resize(h.color.pixel_count());
    rel_var.resize(h.color.pixel_count());
    const strided<const C> col(h.color);
    const strided<const V> var(h.variance);
    const strided<const A> al(h.alpha);
    using atraits = channel_traits<std::remove_cv_t<A>>;
    const auto valid = static_cast<std::uint8_t>(pixel_class::valid);
    for (int y = 0; y < ht; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
            const C* pc = col.p + y * col.y + x * col.x;
            const V* pv = var.p + y * var.y + x * var.x;
            bool counts = local_pixel(pc, col.c, pv, var.c, nc, one_var, scale, level[i], rel_var[i]);
            if (h.label) {
                counts &= (h.label[i] & pixel_class_bits) == valid;
            } else if (!h.alpha.empty()) {
                const double a = atraits::load(al.p[y * al.y + x * al.x]);
                counts &= a > 0 && std::isfinite(a);
            }
            if (!counts) {
                level[i] = std::numeric_limits<double>::quiet_NaN();
                rel_var[i] = std::numeric_limits<float>::quiet_NaN();
            }
        }
}

// Median and median absolute deviation of p[0..n) (n >= 1, at most a few dozen values),
// reordering p; the mean of the two middle values when n is even. Insertion sort, then the
// deviations, which run outwards from the median in two sorted sequences, are merged up to
// the middle (for these sizes several times faster than two selections).
inline void median_and_mad(float* p, std::size_t n, double& med, double& mad) noexcept {
    for (std::size_t i = 1; i < n; ++i) {
        const float v = p[i];
        std::size_t j = i;
        for (; j > 0 && p[j - 1] > v; --j) p[j] = p[j - 1];
        p[j] = v;
    }
    const std::size_t k = n / 2;
    med = n % 2 ? static_cast<double>(p[k]) : 0.5 * (static_cast<double>(p[k - 1]) + p[k]);
    std::size_t right = static_cast<std::size_t>(
        std::lower_bound(p, p + n, med, [](float a, double b) { return static_cast<double>(a) < b; }) - p);
    std::size_t left = right;  // deviations: p[left - 1] downwards, p[right] upwards
    double prev = 0, cur = 0;
    for (std::size_t t = 0; t <= k; ++t) {
        const double dl = left > 0 ? med - p[left - 1] : HUGE_VAL;
        const double dr = right < n ? p[right] - med : HUGE_VAL;
        prev = cur;
        if (dl <= dr) {
            cur = dl;
            --left;
        } else {
            cur = dr;
            ++right;
        }
    }
    mad = n % 2 ? cur : 0.5 * (prev + cur);
}

// r~ from the neighbourhood's log r values in both halves (centre excluded): exp(median +
// s^2 / 2), and the degrees of freedom of that estimate, 4 n / (pi s^2) (a median of n
// values has variance pi s^2 / (2 n), and log of a variance estimate with d degrees of
// freedom has variance 2 / d). nu is NaN when fewer than min_count values are usable.
struct pooled_estimate {
    double r = 0;
    double nu = std::numeric_limits<double>::quiet_NaN();
};

inline pooled_estimate pooled_relative_variance(const std::vector<float> (&rel_var)[2], int w, int h, int x, int y,
                                                int radius, int min_count, std::vector<float>& pool) {
    pool.clear();
    const int x0 = std::max(x - radius, 0), x1 = std::min(x + radius, w - 1);
    const int y0 = std::max(y - radius, 0), y1 = std::min(y + radius, h - 1);
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            if (xx == x && yy == y) continue;
            const std::size_t j = static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(xx);
            for (int half = 0; half < 2; ++half)
                if (rel_var[half][j] == rel_var[half][j]) pool.push_back(std::log(rel_var[half][j]));
        }
    pooled_estimate e;
    if (pool.size() < static_cast<std::size_t>(std::max(min_count, 1))) return e;
    const double n = static_cast<double>(pool.size());
    double med = 0, mad = 0;
    median_and_mad(pool.data(), pool.size(), med, mad);
    const double s = mad / 0.6744897501960817;
    // The sample relative variance of a skewed law is biased low: E[r^] ~ r (1 - r) for a
    // gamma law (skewness 2 sqrt(r N)); 1 + r undoes it to first order.
    const double r = std::exp(std::min(med + 0.5 * s * s, 700.0));
    e.r = r * (1.0 + std::min(r, 1.0));
    e.nu = s > 0 ? 4.0 * n / (3.141592653589793 * s * s) : HUGE_VAL;
    return e;
}

// The statistic for the half whose level is hi against lo (hi > lo > 0), with r~ = r:
// T = sqrt(m / 2) (sqrt(hi / lo) - sqrt(lo / hi)), m = 1 / r. The square roots are taken
// separately so that 1e30 against 1e-3 stays finite.
inline double pair_statistic(double hi, double lo, double r) noexcept {
    const double s = std::sqrt(hi) / std::sqrt(lo) - std::sqrt(lo) / std::sqrt(hi);
    return std::sqrt(0.5 / r) * s;
}

// t_df(q) with df rounded down to a grid of 64 steps per octave (from 1 to 2^34): a lower df
// gives a higher threshold, so the rounding only makes the test a little stricter (df at most
// 1.1% low), and the Newton iterations run once per grid step and sequence of frames.
inline double t_threshold(local_test_scratch& s, double q, double df) {
    constexpr int steps = 64, octaves = 34;
    if (s.thresholds_q != q || s.thresholds.empty()) {
        s.thresholds.assign(steps * octaves + 1, 0.0);
        s.thresholds_q = q;
    }
    const double g = std::floor(std::log2(std::max(df, 1.0)) * steps);
    const int k = static_cast<int>(std::min(g, static_cast<double>(steps * octaves)));
    double& t = s.thresholds[static_cast<std::size_t>(k)];
    if (t == 0.0) t = student_t_upper_quantile(q, std::exp2(static_cast<double>(k) / steps));
    return t;
}

}  // namespace detail

// Runs the local test on both halves. Views must share size, channel counts as for
// check_half_views. Returns the first problem found; result is then empty.
template <class C, class V, class A>
status local_test(const local_half<C, V, A>& a, const local_half<C, V, A>& b, const local_test_options& options,
                  local_test_scratch& scratch, local_test_result& result) {
    for (auto& f : result.half) {
        f.index.clear();
        f.score.clear();
    }
    result.tested = result.screened = 0;
    if (status st = check_local_test_options(options); !st.ok()) return st;
    if (status st = check_half_views(a.color, a.variance, a.alpha); !st.ok()) return st;
    if (status st = check_half_views(b.color, b.variance, b.alpha); !st.ok()) return st;
    if (!same_size(a.color, b.color)) return status{errc::size_mismatch, "local test: the halves differ in size"};
    if (a.color.pixel_count() >= (std::size_t{1} << 32))
        return status{errc::size_overflow, "local test: more than 2^32 pixels"};
    detail::local_levels(a, options.variance_scale, scratch.level[0], scratch.rel_var[0]);
    detail::local_levels(b, options.variance_scale, scratch.level[1], scratch.rel_var[1]);
    const int w = a.color.width(), h = a.color.height();
    const double zq = normal_upper_quantile(options.false_alarm);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
            const double la = scratch.level[0][i], lb = scratch.level[1][i];
            const float ra = scratch.rel_var[0][i], rb = scratch.rel_var[1][i];
            if (!(ra == ra) || !(rb == rb)) continue;  // one half does not count, or not > 0
            ++result.tested;
            if (la == lb) continue;
            const int hi = la > lb ? 0 : 1;  // the half that could hold a firefly
            const double l_hi = hi == 0 ? la : lb, l_lo = hi == 0 ? lb : la;
            const double r_other = hi == 0 ? rb : ra;
            // Screen: r~ >= r_other bounds T from above and df from above (so the threshold
            // from below): most pixels are decided without the neighbourhood.
            const double t_pair = detail::pair_statistic(l_hi, l_lo, r_other);
            if (!(t_pair > zq)) continue;
            if (!(t_pair > detail::t_threshold(scratch, options.false_alarm, std::min(2.0 / r_other, 1e10)))) continue;
            ++result.screened;
            const detail::pooled_estimate pooled = detail::pooled_relative_variance(
                scratch.rel_var, w, h, x, y, options.radius, options.min_neighbours, scratch.pool);
            if (!(pooled.nu == pooled.nu)) continue;
            const double r = std::max(pooled.r, r_other);
            const double t = detail::pair_statistic(l_hi, l_lo, r);
            if (!(t > zq)) continue;
            // t with 2m degrees of freedom for the gamma law, widened by the uncertainty of r~
            const double df = std::min(std::max(1.0 / (0.5 * r + 1.0 / pooled.nu), 1.0), 1e10);
            const double threshold = detail::t_threshold(scratch, options.false_alarm, df);
            if (!(t > threshold)) continue;
            const double score = std::min(t / threshold, static_cast<double>(std::numeric_limits<float>::max()));
            result.half[hi].index.push_back(static_cast<std::uint32_t>(i));
            result.half[hi].score.push_back(static_cast<float>(score));
        }
    return ok_status();
}

}  // namespace firefly
