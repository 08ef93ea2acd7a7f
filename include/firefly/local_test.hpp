// firefly: the local, brightness-invariant firefly test.
//
// Model. The two halves hold independent means of the same pixel's samples. Whatever the
// per-sample law, a half mean L is positive and, to its first two moments, a gamma variable
// of shape m = E[L]^2 / Var[L] (m = N k for N samples of a gamma(k) law; Satterthwaite's
// moment match otherwise).
//
// Pair test. For two independent gamma(m) means of one expected value, L_A / L_B ~ F(2m, 2m),
// and (Cacoullos 1965)
//
//     T = sqrt(m / 2) (sqrt(L_A / L_B) - sqrt(L_B / L_A))  ~  Student t, 2m degrees of freedom,
//
// exactly. T is a ratio, so brightness cancels: a pixel at 0.01 and one at 10 are judged
// alike, in one frame or across frames. Half A is flagged when T > t(q) (one-sided: a
// firefly adds light), half B when -T > t(q). A pixel is flagged in at most one half; an
// outlier in both halves is left to the global test and the highlight check.
//
// Spatial test (options.spatial). One other half is a poor yardstick when every pixel is
// noisy (m ~ 3-8): the n usable neighbours of both halves (16 in 3x3) estimate the level far
// better. Where they are gamma(m) means of the pixel's own value, L_A / mean ~ F(2m, 2nm)
// exactly. It is used only where the neighbourhood is homogeneous, by two checks at level
// options.homogeneity: the other half at the pixel agrees with the mean (two-sided, Paulson's
// normal approximation of F), and the levels' dispersion m sum (L / mean - 1)^2 is within
// chi-square(n - 1) (Wilson-Hilferty). Fine detail, edges and highlights fail one or both.
// Each test runs at q / 2 when both run.
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
// widens the pair test's t: df = 1 / (1/(2m) + 1/nu), nu = 4 n / (pi s^2) for a median of n.
//
// Assumptions: positive pixel values (a half whose mean colour is <= 0 is not tested); the
// given variance is that of the half's mean (else set variance_scale); light-tailed enough
// per-sample laws that the gamma moment match holds in the tail (gamma k >= 1 is measured;
// heavier, e.g. lognormal, flags more than q).
//
// Promise, per test. In a frame without fireflies, the expected share of tested pixel-halves
// flagged is at most q (options.false_alarm, default 1e-4). Each flag carries its p-value;
// the detector (pipeline.hpp) keeps what Benjamini-Hochberg keeps over the frame (fdr.hpp),
// which turns this into the per-frame promise of the generalized ESD. Test [local][calibration]: gamma(k)
// per-sample noise, k 1, 4, 16, 4 to 1024 samples per half, three decades, fine detail,
// highlights (25x, per-sample shape 0.16), black background, alpha; 534k pixel-halves:
//     q = 1e-3: 309 flagged (promise 534);  q = 1e-4: 49 flagged (promise 53)
//     at 4 samples per half, q = 1e-4: 40 of 306k (promise 31, within the binomial margin)
// The simulator's null scenes (bench/research/local_eval.cpp, 65k pixels each): 0.5-1.8 q.
//
// Measured with a stand-in rebuild (a pixel flagged in one half takes the other half's value;
// bench/research/README.md has the tables):
//     moderate fireflies 2-20x, 1% of pixels per half, 64 spp, gamma k = 4, dark frame:
//     recall 0.98 (test "recall"); 4-8x at 8 spp: recall 0.81, pair test alone 0.17
//     three decades with 30-1000x fireflies ("decades"): recall 1.000 (global ESD 0.987)
//     cycles-caustics: relMSE 0.062 alone; 0.0294 in union with the global ESD (0.0295)
//     cycles-interior: relMSE 0.399 alone; 0.1235 in union with the global ESD (0.1324)
//     Not seen: a pixel with fireflies in both halves; fireflies where every neighbour has
//     one too (the spatial test's homogeneity checks fail there).
//
// Cost: one read pass over both halves' colour and variance (level and r per pixel and
// half), then one pass over those arrays reading each pixel's 3x3 levels. The neighbourhood
// statistics (medians of r) are taken only for pixels that cheap bounds do not rule out: with
// r~ >= r_other the pair statistic at the other half's r bounds T from above and the
// threshold from below, and Paulson's z at m = 1 / r_other (less a margin of 1) bounds the
// spatial test. Thresholds come from a cache on a df grid rounded down. About 3x the global
// detection's time (bench/research/README.md). Deterministic, no scan order: medians and the
// sorted-level mean are order-free, so the flags are the same under the 8 flips and
// transposes of the frame.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "image_view.hpp"
#include "parallel.hpp"
#include "stddev.hpp"
#include "status.hpp"
#include "fdr.hpp"
#include "student_t.hpp"

namespace firefly {

struct local_test_options {
    double false_alarm = 1e-4;      // q: expected share of tested pixel-halves flagged in a
                                    // frame without fireflies
    int radius = 1;                 // neighbourhood (2 radius + 1)^2 - 1 pixels, both halves:
                                    // 16 values at 1 (measured as good as 48 at 2, 3x cheaper)
    int min_neighbours = 6;         // fewer usable neighbour values (2 per pixel): the pixel is
                                    // not tested (6: frame corners are, at radius 1)
    double variance_scale = 1.0;    // multiplies the given variance into the variance of the
                                    // half mean (1: it already is; 1 / N when the renderer
                                    // stores the variance of its N samples)
    bool spatial = true;            // also test each half against its neighbourhood's level
                                    // where that neighbourhood is homogeneous (q split evenly)
    double homogeneity = 0.01;      // level of the two homogeneity checks that gate it
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
    if (!(o.homogeneity > 0.0 && o.homogeneity < 1.0))
        return status{errc::invalid_argument, "local test: homogeneity must lie in (0, 1)"};
    return ok_status();
}

// Pixels flagged in one half at the per-test level q, in row-major order (sorted), with their
// scores (> 1: how far past the threshold): T / t(q) for the pair test, z(p) / z(q) for the
// spatial test; and their p-values (natural log; doubled when both tests run, Bonferroni),
// for the frame-level decision (fdr.hpp: bh_log_threshold over result.tested * 2 tests).
struct local_flags {
    std::vector<std::uint32_t> index;
    std::vector<float> score;
    std::vector<double> log_p;
};

struct local_test_result {
    std::size_t bytes() const noexcept {
        std::size_t n = 0;
        for (const local_flags& f : half)
            n += f.index.capacity() * sizeof(std::uint32_t) + f.score.capacity() * sizeof(float) +
                 f.log_p.capacity() * sizeof(double);
        return n;
    }
    local_flags half[2];
    std::size_t tested = 0;        // pixels tested (each tests both halves)
    std::size_t screened = 0;      // pixels whose neighbourhood statistics were computed
    std::size_t spatial = 0;       // flags the spatial test added (not the pair test's)
};

// What one band of rows needs of its own (bands run in parallel).
struct local_band_scratch {
    std::vector<float> pool;
    std::vector<double> levels;      // the neighbourhood's levels (spatial test)
    std::vector<std::ptrdiff_t> window;  // detail::window_offsets
    std::vector<double> column_sum[2];   // detail::window_columns: 3 rows, and the 2 outer rows
    std::vector<std::uint8_t> column_count[2];
    std::vector<double> row_sum[3];      // detail::row_levels, rows y mod 3
    std::vector<std::uint8_t> row_count[3];
    std::vector<double> thresholds;  // t_df(q) by df grid step (see detail::t_threshold)
    double thresholds_q = 0;
    local_test_result found;         // this band's flags and counts
    std::size_t bytes() const noexcept {
        std::size_t rows = 0;
        for (int t = 0; t < 3; ++t) rows += row_sum[t].capacity() * sizeof(double) + row_count[t].capacity();
        return rows +
               (levels.capacity() + thresholds.capacity() + column_sum[0].capacity() + column_sum[1].capacity()) *
                   sizeof(double) +
               column_count[0].capacity() + column_count[1].capacity() + pool.capacity() * sizeof(float) +
               window.capacity() * sizeof(std::ptrdiff_t) +
               (found.half[0].index.capacity() + found.half[1].index.capacity()) * 16;
    }
};

// Memory reused across frames.
struct local_test_scratch {
    std::vector<double> level[2];  // mean colour; NaN where the pixel does not count
    std::vector<float> rel_var[2]; // relative variance r of the half mean; NaN where unusable
    std::vector<local_band_scratch> bands;
    std::size_t bytes() const noexcept {
        std::size_t n = (level[0].capacity() + level[1].capacity()) * sizeof(double) +
                        (rel_var[0].capacity() + rel_var[1].capacity()) * sizeof(float);
        for (const auto& b : bands) n += b.bytes();
        return n;
    }
};

// One half buffer's views for the test; alpha may be empty. label (optional, pixel_count
// bytes, row-major): the stddev pass's labels, pixel_class in the low bits; when null the
// class is computed here (black: every colour channel 0; alpha <= 0; NaN/Inf in alpha or in
// the first three colour channels or their variances, the channels the test reads).
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

// Whether a pixel's r says something about its neighbourhood's noise: above the floor. A
// variance of 0 (one sample a half, no variance written, or one too small for its storage:
// half floats flush below 6e-8) sits at the floor; pooled, such pixels made the
// neighbourhood's noise near 0, so every difference of the halves was significant (half the
// pixel-halves of a noisy frame without fireflies flagged). The pixel's own r still bounds its
// other half's test from below and still flags a 1e30 beside ordinary pixels.
inline bool informative(float r) noexcept { return r > static_cast<float>(min_relative_variance); }

// Level (mean colour) and relative variance of one pixel; false when it does not count. NC > 0:
// the channel count known at compile time (the loop unrolled; the same operations in the same
// order as for nc = NC).
template <int NC = 0, class C, class V>
inline bool local_pixel(const C* pc, std::ptrdiff_t cs, const V* pv, std::ptrdiff_t vs, int nc_given, bool one_var,
                        double scale, double& level, float& rel_var) noexcept {
    using ctraits = channel_traits<std::remove_cv_t<C>>;
    using vtraits = channel_traits<std::remove_cv_t<V>>;
    const int nc = NC > 0 ? NC : nc_given;
    double sum = 0, sd = 0, fin = 0;
    bool black = true;
    for (int c = 0; c < nc; ++c) {
        const double v = ctraits::load(pc[c * cs]);
        const double var = vtraits::load(pv[one_var ? 0 : c * vs]);
        fin += (v - v) + (var - var);  // NaN for any NaN or Inf
        black &= v == 0.0;
        sum += v;
        sd += std::sqrt((std::max)(var, 0.0) * scale);
    }
    level = sum / nc;  // finite sums of floats up to FLT_MAX stay finite in double
    if (!(fin == 0.0) || black) return false;
    if (!(level > 0) || !std::isfinite(level)) {
        rel_var = std::numeric_limits<float>::quiet_NaN();
        return true;  // counts, but has no relative variance: neither tested nor pooled
    }
    const double rel = (sd / nc) / level;  // a ratio first: no overflow near FLT_MAX
    const double r = (std::max)(rel * rel, min_relative_variance);
    // float: r is an estimate good to a few per cent; r >= FLT_MAX means m ~ 0 anyway
    rel_var = static_cast<float>((std::min)(r, static_cast<double>(FLT_MAX)));
    return true;
}

#if defined(__SSE2__)
// local_pixel for two three-channel pixels (colour at c0 and c1, variance at v0 and v1) in
// the two lanes of SSE2 registers: each lane takes local_pixel's operations in its order
// (max(0, var) keeps var where it is NaN or -0, as std::max(var, 0.0) does), so the same
// bits. The pass is bound by its divisions and square roots, here two at a time.
template <class C, class V>
inline void local_pixel_pair(const C* c0, const C* c1, std::ptrdiff_t cs, const V* v0, const V* v1,
                             std::ptrdiff_t vs, double scale, double* level, float* rel_var, bool* counts) noexcept {
    using ctraits = channel_traits<std::remove_cv_t<C>>;
    using vtraits = channel_traits<std::remove_cv_t<V>>;
    const __m128d zero = _mm_setzero_pd(), three = _mm_set1_pd(3.0), sc = _mm_set1_pd(scale);
    __m128d sum = zero, sd = zero, fin = zero, black = _mm_cmpeq_pd(zero, zero);
    for (int c = 0; c < 3; ++c) {
        const __m128d v = _mm_set_pd(ctraits::load(c1[c * cs]), ctraits::load(c0[c * cs]));
        const __m128d var = _mm_set_pd(vtraits::load(v1[c * vs]), vtraits::load(v0[c * vs]));
        fin = _mm_add_pd(fin, _mm_add_pd(_mm_sub_pd(v, v), _mm_sub_pd(var, var)));
        black = _mm_and_pd(black, _mm_cmpeq_pd(v, zero));
        sum = _mm_add_pd(sum, v);
        sd = _mm_add_pd(sd, _mm_sqrt_pd(_mm_mul_pd(_mm_max_pd(zero, var), sc)));
    }
    const __m128d lv = _mm_div_pd(sum, three);
    double rel[2];
    _mm_storeu_pd(level, lv);
    _mm_storeu_pd(rel, _mm_div_pd(_mm_div_pd(sd, three), lv));
    const int usable = _mm_movemask_pd(_mm_andnot_pd(black, _mm_cmpeq_pd(fin, zero)));
    for (int k = 0; k < 2; ++k) {
        counts[k] = (usable >> k) & 1;
        if (!counts[k]) continue;
        if (!(level[k] > 0) || !std::isfinite(level[k])) {
            rel_var[k] = std::numeric_limits<float>::quiet_NaN();
            continue;
        }
        const double r = (std::max)(rel[k] * rel[k], min_relative_variance);
        rel_var[k] = static_cast<float>((std::min)(r, static_cast<double>(FLT_MAX)));
    }
}
#endif

// Level and relative variance of the pixels of row y of one half (NaN where unusable); NC as
// for local_pixel.
template <int NC, class C, class V, class A>
void local_levels_row(const local_half<C, V, A>& h, double scale, int y, const float* fc, const float* fv,
                      double* level, float* rel_var) noexcept {
    const int w = h.color.width();
    const int nc = colour_channels(h.color.channels());
    const bool one_var = h.variance.channels() == 1;
    const strided<const C> col(h.color);
    const strided<const V> var(h.variance);
    const strided<const A> al(h.alpha);
    using atraits = channel_traits<std::remove_cv_t<A>>;
    const auto valid = static_cast<std::uint8_t>(pixel_class::valid);
    const int cc = h.color.channels(), vc = h.variance.channels();
    const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    auto finish = [&](int x, bool counts) {
        const std::size_t i = row + static_cast<std::size_t>(x);
        if (h.label) {
            counts &= (h.label[i] & pixel_class_bits) == valid;
        } else if (!h.alpha.empty()) {
            const double a = atraits::load(al.p[y * al.y + x * al.x]);
            counts &= a > 0 && std::isfinite(a);
        }
        if (!counts) {
            level[x] = std::numeric_limits<double>::quiet_NaN();
            rel_var[x] = std::numeric_limits<float>::quiet_NaN();
        }
    };
    // (a row's offset in ptrdiff_t: x * channels overflows int past 2^29 RGBA pixels)
    auto at = [](int x, int channels) { return static_cast<std::ptrdiff_t>(x) * channels; };
    int x = 0;
#if defined(__SSE2__)
    if constexpr (NC == 3) {
        for (; x + 1 < w; x += 2) {
            bool counts[2];
            if (fc)
                local_pixel_pair(fc + at(x, cc), fc + at(x + 1, cc), 1, fv + at(x, vc), fv + at(x + 1, vc), one_var ? 0 : 1,
                                 scale, level + x, rel_var + x, counts);
            else
                local_pixel_pair(col.p + y * col.y + x * col.x, col.p + y * col.y + (x + 1) * col.x, col.c,
                                 var.p + y * var.y + x * var.x, var.p + y * var.y + (x + 1) * var.x,
                                 one_var ? 0 : var.c, scale, level + x, rel_var + x, counts);
            finish(x, counts[0]);
            finish(x + 1, counts[1]);
        }
    }
#endif
    for (; x < w; ++x) {
        const bool counts =
            fc ? local_pixel<NC>(fc + at(x, cc), 1, fv + at(x, vc), 1, nc, one_var, scale, level[x], rel_var[x])
               : local_pixel<NC>(col.p + y * col.y + x * col.x, col.c, var.p + y * var.y + x * var.x, var.c, nc,
                                 one_var, scale, level[x], rel_var[x]);
        finish(x, counts);
    }
}

// Level and relative variance of every pixel of one half (NaN where unusable).
template <class C, class V, class A>
void local_levels(const local_half<C, V, A>& h, double scale, std::vector<double>& level,
                  std::vector<float>& rel_var) {
    const int w = h.color.width(), ht = h.color.height();
    level.resize(h.color.pixel_count());
    rel_var.resize(h.color.pixel_count());
    // Packed rows of a converting type (a renderer's half) are read as float rows, converted
    // in bulk: the same values as loading one by one.
    constexpr bool convert = (float_rows_v<C> && float_rows_v<V>) &&
                             !(std::is_same_v<std::remove_cv_t<C>, float> && std::is_same_v<std::remove_cv_t<V>, float>);
    const bool rows = convert && h.color.is_packed() && h.variance.is_packed();
    const bool rgb = colour_channels(h.color.channels()) == 3;  // the common case, unrolled
    std::vector<float> crow, vrow;
    for (int y = 0; y < ht; ++y) {
        const float* fc = nullptr;
        const float* fv = nullptr;
        if constexpr (convert) {
            if (rows) {
                fc = float_row(h.color, y, crow);
                fv = float_row(h.variance, y, vrow);
            }
        }
        const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        if (rgb)
            local_levels_row<3>(h, scale, y, fc, fv, level.data() + i, rel_var.data() + i);
        else
            local_levels_row<0>(h, scale, y, fc, fv, level.data() + i, rel_var.data() + i);
    }
}

// Batcher's odd-even merge sort of 16 values: 63 compare-exchanges (checked on all 2^16 0-1
// inputs), branch-free, where insertion sort mispredicts about once per value.
inline constexpr unsigned char sort16_network[63][2] = {
    {0, 1}, {2, 3}, {0, 2}, {1, 3}, {1, 2}, {4, 5}, {6, 7}, {4, 6},
    {5, 7}, {5, 6}, {0, 4}, {2, 6}, {2, 4}, {1, 5}, {3, 7}, {3, 5},
    {1, 2}, {3, 4}, {5, 6}, {8, 9}, {10, 11}, {8, 10}, {9, 11}, {9, 10},
    {12, 13}, {14, 15}, {12, 14}, {13, 15}, {13, 14}, {8, 12}, {10, 14}, {10, 12},
    {9, 13}, {11, 15}, {11, 13}, {9, 10}, {11, 12}, {13, 14}, {0, 8}, {4, 12},
    {4, 8}, {2, 10}, {6, 14}, {6, 10}, {2, 4}, {6, 8}, {10, 12}, {1, 9},
    {5, 13}, {5, 9}, {3, 11}, {7, 15}, {7, 11}, {3, 5}, {7, 9}, {11, 13},
    {1, 2}, {3, 4}, {5, 6}, {7, 8}, {9, 10}, {11, 12}, {13, 14},
};

// a <= b after: min and max, one instruction each and no branch where the machine has them.
// Equal values come out as two copies of a: the same bits, but for zeros of both signs.
template <class T>
inline void compare_exchange(T& a, T& b) noexcept {
    const T lo = (std::min)(a, b), hi = (std::max)(a, b);
    a = lo;
    b = hi;
}

template <class T, std::size_t... I>
inline void sort16(T* v, std::index_sequence<I...>) noexcept {
    (compare_exchange(v[sort16_network[I][0]], v[sort16_network[I][1]]), ...);
}

// Sorts p[0..n) ascending, no NaN and no -0 among them: the same values as any sort. Up to 16
// values (a radius-1 window's two halves) through the network, padded with +Inf.
template <class T>
inline void sort_small(T* p, std::size_t n) noexcept {
    if (n <= 16) {
        T v[16];
        for (std::size_t i = 0; i < 16; ++i) v[i] = i < n ? p[i] : std::numeric_limits<T>::infinity();
        sort16(v, std::make_index_sequence<63>{});
        for (std::size_t i = 0; i < n; ++i) p[i] = v[i];
        return;
    }
    for (std::size_t i = 1; i < n; ++i) {
        const T v = p[i];
        std::size_t j = i;
        for (; j > 0 && p[j - 1] > v; --j) p[j] = p[j - 1];
        p[j] = v;
    }
}

// Median and median absolute deviation of p[0..n) (n >= 1, at most a few dozen values),
// reordering p; the mean of the two middle values when n is even. Sorted (sort_small), then the
// deviations, which run outwards from the median in two sorted sequences, are merged up to
// the middle (for these sizes several times faster than two selections).
inline void median_and_mad(float* p, std::size_t n, double& med, double& mad) noexcept {
    sort_small(p, n);
    const std::size_t k = n / 2;
    med = n % 2 ? static_cast<double>(p[k])
                : 0.5 * (static_cast<double>(p[k - 1]) + static_cast<double>(p[k]));
    std::size_t right = static_cast<std::size_t>(
        std::lower_bound(p, p + n, med, [](float a, double b) { return static_cast<double>(a) < b; }) - p);
    std::size_t left = right;  // deviations: p[left - 1] downwards, p[right] upwards
    double prev = 0, cur = 0;
    for (std::size_t t = 0; t <= k; ++t) {
        const double dl = left > 0 ? med - static_cast<double>(p[left - 1]) : HUGE_VAL;
        const double dr = right < n ? static_cast<double>(p[right]) - med : HUGE_VAL;
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

// f(j) for every pixel index j of the (2 radius + 1)^2 window around (x, y) inside the frame,
// the centre excluded.
template <class F>
inline void for_each_neighbour(int w, int h, int x, int y, int radius, F&& f) {
    const int x0 = (std::max)(x - radius, 0), x1 = (std::min)(x + radius, w - 1);
    const int y0 = (std::max)(y - radius, 0), y1 = (std::min)(y + radius, h - 1);
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx)
            if (xx != x || yy != y)
                f(static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(xx));
}

// r~ from the neighbourhood's log r values in both halves (centre excluded): exp(median +
// s^2 / 2), and the degrees of freedom of that estimate, 4 n / (pi s^2) (a median of n
// values has variance pi s^2 / (2 n), and log of a variance estimate with d degrees of
// freedom has variance 2 / d). nu is NaN when fewer than min_count values are usable.
struct pooled_estimate {
    double r = 0;
    double nu = std::numeric_limits<double>::quiet_NaN();
    double typical = 0;  // exp(median log r): the neighbourhood's typical r, uncorrected
};

// Room in pool for a value per half of every neighbour at this radius (written by index: these
// loops run per screened pixel and per outlier, and push_back checks capacity per value).
inline float* pool_room(std::vector<float>& pool, int radius) {
    const std::size_t side = 2 * static_cast<std::size_t>(radius) + 1;
    if (pool.size() < 2 * (side * side - 1)) pool.resize(2 * (side * side - 1));
    return pool.data();
}

inline pooled_estimate pooled_relative_variance(const std::vector<float> (&rel_var)[2], int w, int h, int x, int y,
                                                int radius, int min_count, std::vector<float>& pool) {
    float* p = pool_room(pool, radius);
    const float* rv[2] = {rel_var[0].data(), rel_var[1].data()};
    std::size_t count = 0;
    for_each_neighbour(w, h, x, y, radius, [&](std::size_t j) {
        for (int which = 0; which < 2; ++which)
            if (informative(rv[which][j])) p[count++] = std::log(rv[which][j]);
    });
    pooled_estimate e;
    if (count < static_cast<std::size_t>((std::max)(min_count, 1))) return e;
    const double n = static_cast<double>(count);
    double med = 0, mad = 0;
    median_and_mad(p, count, med, mad);
    const double s = mad / 0.6744897501960817;
    // The sample relative variance of a skewed law is biased low: E[r^] ~ r (1 - r) for a
    // gamma law (skewness 2 sqrt(r N)); 1 + r undoes it to first order.
    const double r = std::exp((std::min)(med + 0.5 * s * s, 700.0));
    e.typical = std::exp((std::min)(med, 700.0));
    e.r = r * (1.0 + (std::min)(r, 1.0));
    e.nu = s > 0 ? 4.0 * n / (3.141592653589793 * s * s) : HUGE_VAL;
    return e;
}

// The median (and MAD) over the neighbourhood (centre excluded) of value(j), a float per
// neighbour j that counts (NaN: it does not); NaN when fewer than min_count count. count: how
// many did.
template <class Value>
inline double neighbour_median(int w, int h, int x, int y, int radius, int min_count, std::vector<float>& pool,
                               Value&& value, std::size_t& count, double* mad_out = nullptr) {
    float* p = pool_room(pool, radius);
    count = 0;
    for_each_neighbour(w, h, x, y, radius, [&](std::size_t j) {
        const float v = value(j);
        if (v == v) p[count++] = v;
    });
    if (count < static_cast<std::size_t>((std::max)(min_count, 1))) return std::numeric_limits<double>::quiet_NaN();
    double med = 0, mad = 0;
    median_and_mad(p, count, med, mad);
    if (mad_out) *mad_out = mad;
    return med;
}

// The lower of pixel j's two half levels, NaN unless both are usable.
inline double lower_half_level(const std::vector<double> (&level)[2], std::size_t j) noexcept {
    const double a = level[0][j], b = level[1][j];
    return a == a && b == b ? (std::min)(a, b) : std::numeric_limits<double>::quiet_NaN();
}

// The median over the neighbourhood (centre excluded) of each neighbour's lower half level
// (mean colour): a firefly lands in one half of a pixel, rarely in both, so the lower half
// is clean where a quarter of the neighbours' halves carry one (a median over the halves
// themselves is pulled up there), at the cost of a known bias on clean pixels (the caller's).
// NaN when fewer than min_count neighbours have both halves usable.
inline double neighbourhood_lower_level(const std::vector<double> (&level)[2], int w, int h, int x, int y,
                                        int radius, int min_count, std::vector<float>& pool, double* mad_out = nullptr) {
    std::size_t count = 0;
    return neighbour_median(w, h, x, y, radius, min_count, pool, [&](std::size_t j) {
        return static_cast<float>(lower_half_level(level, j));  // NaN stays NaN
    }, count, mad_out);
}

// The level of a line through (x, y): over the four directions (the row, the column, both
// diagonals), the largest of the second smallest of lower(q) over the four pixels q at one and
// two steps on either side, lower(q) the lower of q's two halves. A line of detail one pixel
// wide has only two of its eight neighbours at its level, so the neighbourhood's median is the
// background's; a line runs on, and all four are at its level (one low draw among them is
// passed over). On a smooth region a lone bright pixel lifts no direction, and where fireflies
// are dense three of one direction's four pixels must carry one in both halves (at 30% per
// half, 0.3% of directions; both neighbours at one step alone: 0.8%). NaN when no direction has
// all four usable (the frame's edge, unusable pixels).
inline double neighbourhood_line_level(const std::vector<double> (&level)[2], int w, int h, int x, int y) noexcept {
    auto lower = [&](int xx, int yy) {
        if (xx < 0 || yy < 0 || xx >= w || yy >= h) return std::numeric_limits<double>::quiet_NaN();
        return lower_half_level(level, static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(xx));
    };
    static constexpr int dirs[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};
    double best = std::numeric_limits<double>::quiet_NaN();
    for (const auto& d : dirs) {
        double v[4] = {lower(x + d[0], y + d[1]), lower(x - d[0], y - d[1]), lower(x + 2 * d[0], y + 2 * d[1]),
                       lower(x - 2 * d[0], y - 2 * d[1])};
        if (!(v[0] == v[0] && v[1] == v[1] && v[2] == v[2] && v[3] == v[3])) continue;
        std::sort(v, v + 4);
        if (!(best >= v[1])) best = v[1];
    }
    return best;
}

// The median over the neighbourhood (centre excluded) of the relative variance of each
// neighbour's lower half (the half with the lower level): the neighbourhood's noise, clean
// where fireflies are dense (a firefly lands in one half and lifts that half's r with its
// level, so the median over both halves rises with them; of two halves at one level, the
// smaller r). NaN when fewer than min_count neighbours count; count: how many did (both
// halves' levels usable and the lower half's r informative).
inline double neighbourhood_lower_noise(const local_test_scratch& s, int w, int h, int x, int y, int radius,
                                        int min_count, std::vector<float>& pool, std::size_t& count) {
    return neighbour_median(w, h, x, y, radius, min_count, pool, [&](std::size_t j) {
        const double a = s.level[0][j], b = s.level[1][j];
        if (!(a == a && b == b)) return std::numeric_limits<float>::quiet_NaN();
        const float r = a < b ? s.rel_var[0][j] : b < a ? s.rel_var[1][j] : (std::min)(s.rel_var[0][j], s.rel_var[1][j]);
        return informative(r) ? r : std::numeric_limits<float>::quiet_NaN();
    }, count);
}

// The statistic for the half whose level is hi against lo (hi > lo > 0), with r~ = r:
// T = sqrt(m / 2) (sqrt(hi / lo) - sqrt(lo / hi)), m = 1 / r. The square roots are taken
// separately so that 1e30 against 1e-3 stays finite.
inline double pair_statistic(double hi, double lo, double r) noexcept {
    const double s = std::sqrt(hi) / std::sqrt(lo) - std::sqrt(lo) / std::sqrt(hi);
    return std::sqrt(0.5 / r) * s;
}

// Whether pair_statistic(hi, lo, r) may exceed z > 0: false only where it surely does not,
// from t^2 = (hi - lo)^2 / (hi lo) / (2 r) without the square roots and divisions of the
// exact form (every pixel's screen asks; the margin 1e-6 is far above either form's rounding,
// at most ~1e-9 with r >= 1e-14).
inline bool pair_may_exceed(double hi, double lo, double r, double z) noexcept {
    const double d = hi - lo, zm = z - 1e-6;
    return !(d * d / (hi * lo) * (0.5 / r) < zm * zm);
}

// Whether pair_may_exceed(hi, lo, r, z) is surely false (hi, lo, r, z > 0), multiplied
// through: no division. Its rounding (~1e-15 relatively) is far below the margin 1e-9.
inline bool pair_surely_below(double hi, double lo, double r, double z) noexcept {
    const double d = hi - lo, zm = z - 1e-6;
    return 0.5 * d * d < zm * zm * (hi * lo) * r * (1.0 - 1e-9);
}

// t_df(q) with df rounded down to a grid of 64 steps per octave (from 1 to 2^34): a lower df
// gives a higher threshold, so the rounding only makes the test a little stricter (df at most
// 1.1% low), and the Newton iterations run once per grid step and sequence of frames.
inline double t_threshold(local_band_scratch& s, double q, double df) {
    constexpr int steps = 64, octaves = 34;
    if (s.thresholds_q != q || s.thresholds.empty()) {
        s.thresholds.assign(steps * octaves + 1, 0.0);
        s.thresholds_q = q;
    }
    const double g = std::floor(std::log2((std::max)(df, 1.0)) * steps);
    const int k = static_cast<int>((std::min)(g, static_cast<double>(steps * octaves)));
    double& t = s.thresholds[static_cast<std::size_t>(k)];
    if (t == 0.0) t = student_t_upper_quantile(q, std::exp2(static_cast<double>(k) / steps));
    return t;
}

// Per-frame constants of the decision: the level each test runs at and its normal points.
struct local_levels_q {
    double q = 0, zq = 0;   // each test's level, and z_q
    double z_half_h = 0;    // z at homogeneity / 2 (two-sided gate)
    double z_h = 0;         // z at homogeneity (dispersion gate)
    double log_tests = 0;   // log of the number of tests a pixel runs (Bonferroni for p)
    explicit local_levels_q(const local_test_options& o)
        : q(o.spatial ? 0.5 * o.false_alarm : o.false_alarm),
          zq(normal_upper_quantile(q)),
          z_half_h(normal_upper_quantile(0.5 * o.homogeneity)),
          z_h(normal_upper_quantile(o.homogeneity)),
          log_tests(o.spatial ? std::log(2.0) : 0.0) {}
};

// Paulson's (1942) normal approximation of F(d1, d2) at f: cube roots of the two chi-square
// shares (Wilson-Hilferty). Screens and gates only; the decision uses the exact tail.
inline double paulson_z(double f, double d1, double d2) noexcept {
    const double c = std::cbrt(f), a1 = 2.0 / (9.0 * d1), a2 = 2.0 / (9.0 * d2);
    return ((1.0 - a2) * c - (1.0 - a1)) / std::sqrt(a2 * c * c + a1);
}

// Whether paulson_z(f, d1, d2) may exceed z, f > 0: false only where it surely does not. z
// grows with the cube root c where a1, a2 < 1 (dz/dc = ((1 - a2) a1 + a2 c (1 - a1)) / D^3),
// and c <= (f + 2) / 3 (the mean of f, 1, 1 bounds their geometric mean): no cube root. The
// margin 1e-6 is far above the rounding (~1e-8 where a1 is least).
inline bool paulson_may_exceed(double f, double d1, double d2, double z) noexcept {
    const double a1 = 2.0 / (9.0 * d1), a2 = 2.0 / (9.0 * d2);
    if (!(a1 < 1.0 && a2 < 1.0)) return true;
    const double c = (f + 2.0) / 3.0;
    return !(((1.0 - a2) * c - (1.0 - a1)) / std::sqrt(a2 * c * c + a1) < z - 1e-6);
}

// log Gamma(x) for x > 0 without touching the global `signgam`, which glibc's lgamma writes: the
// test runs in bands on the caller's threads, and ThreadSanitizer reports that write as a data
// race (in the threads workflow, and so in a host renderer's TSan build). lgamma_r computes the same value (glibc's lgamma is lgamma_r into
// signgam); elsewhere, or where <math.h> does not declare it (glibc declares it with its
// __USE_MISC features, on by default), std::lgamma.
inline double log_gamma_positive(double x) noexcept {
#if defined(__GLIBC__) && defined(__USE_MISC)
    int sign = 0;
    return ::lgamma_r(x, &sign);
#else
    return std::lgamma(x);
#endif
}

// P(F > f) for F(d1, d2), f > 0: I_y(d2/2, d1/2) with y = d2 / (d2 + d1 f), by the continued
// fraction on whichever side converges (the small tails the test asks for come out directly).
struct f_tail_terms {  // I_y(a, b) = front cf(a, b, y) / a, front = y^a y1^b / B(a, b)
    double a, b, y, y1, log_front;
    bool direct;  // the continued fraction converges on this side (else on 1 - y)
};
inline f_tail_terms f_tail_at(double f, double d1, double d2) noexcept {
    f_tail_terms t;
    t.a = 0.5 * d2, t.b = 0.5 * d1;
    t.y = d2 / (d2 + d1 * f), t.y1 = d1 * f / (d2 + d1 * f);
    t.log_front = t.a * std::log(t.y) + t.b * std::log(t.y1) - (log_gamma_positive(t.a) + log_gamma_positive(t.b) - log_gamma_positive(t.a + t.b));
    t.direct = t.y < (t.a + 1.0) / (t.a + t.b + 2.0);
    return t;
}
inline double f_upper_tail(double f, double d1, double d2) noexcept {
    const f_tail_terms t = f_tail_at(f, d1, d2);
    if (t.direct) return std::exp(t.log_front) * incbeta_cf(t.a, t.b, t.y) / t.a;
    return 1.0 - std::exp(t.log_front) * incbeta_cf(t.b, t.a, t.y1) / t.b;
}

// log P(F > f), f_upper_tail's continued fractions kept in logs: exact far below the
// smallest double (1e30 times the level at m = 4: -1374, where Paulson's point says -94).
inline double f_log_upper_tail(double f, double d1, double d2) noexcept {
    const f_tail_terms t = f_tail_at(f, d1, d2);
    if (t.direct) return t.log_front + std::log(incbeta_cf(t.a, t.b, t.y) / t.a);
    return std::log1p(-std::exp(t.log_front) * incbeta_cf(t.b, t.a, t.y1) / t.b);
}

// log P(level / around > f) for a pixel's mean over both halves, a gamma(2 m) mean when each
// half is a gamma(m) mean (m = 1 / r), against a neighbourhood level `around` taken from the
// median of n neighbours' lower halves: F(4 m, d2) with d2 = 2 (2 / pi) n m (a median of n
// values is worth 2 n / pi of them). 0 (p = 1) for f <= 1 or no m; above m = 1e4 the F is
// near normal and lgamma would cancel: Paulson's normal point, as spatial_score.
inline double pixel_level_log_p(double f, double m, std::size_t n) noexcept {
    if (!(f > 1.0) || !(m > 0) || n == 0) return 0.0;
    const double d1 = 4.0 * m, d2 = 4.0 / 3.141592653589793 * static_cast<double>(n) * m;
    if (m > 1e4) return normal_log_upper_tail(paulson_z(f, d1, d2));
    return (std::min)(f_log_upper_tail(f, d1, d2), 0.0);
}

// Sum and count of the usable neighbours' levels in both halves (centre excluded), in scan
// order: for the screen only, whose margin dwarfs any rounding. Every pixel's screen runs it,
// so it adds without branches (a usable level is > 0 (local_pixel) and the sum starts at +0:
// adding +0 for an unusable one gives the same bits as skipping it), and away from the
// frame's edges walks the window by `window` (window_offsets), without bounds.
inline double neighbour_sum(const local_test_scratch& s, int w, int h, int x, int y, int radius,
                            const std::vector<std::ptrdiff_t>& window, std::size_t& count) noexcept {
    const float* r0 = s.rel_var[0].data();
    const float* r1 = s.rel_var[1].data();
    const double* l0 = s.level[0].data();
    const double* l1 = s.level[1].data();
    double sum = 0;
    std::size_t n = 0;
    auto add = [&](std::size_t j) {
        const bool u0 = r0[j] == r0[j], u1 = r1[j] == r1[j];
        sum += u0 ? l0[j] : 0.0;
        sum += u1 ? l1[j] : 0.0;
        n += static_cast<std::size_t>(u0) + static_cast<std::size_t>(u1);
    };
    const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
    if (x >= radius && y >= radius && x + radius < w && y + radius < h)
        for (const std::ptrdiff_t d : window) add(static_cast<std::size_t>(static_cast<std::ptrdiff_t>(i) + d));
    else
        for_each_neighbour(w, h, x, y, radius, add);
    count = n;
    return sum;
}

// The offsets of the window's neighbours from its centre (row stride w), in scan order.
inline void window_offsets(int w, int radius, std::vector<std::ptrdiff_t>& out) {
    out.clear();
    for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx)
            if (dx != 0 || dy != 0) out.push_back(static_cast<std::ptrdiff_t>(dy) * w + dx);
}

// Row y's usable levels of both halves summed per pixel, and counted, into the ring slot
// y mod 3 (window_columns reads three consecutive rows: each is summed once).
inline void row_levels(const local_test_scratch& s, int w, int y, local_band_scratch& band) {
    const std::size_t n = static_cast<std::size_t>(w), slot = static_cast<std::size_t>(y % 3);
    band.row_sum[slot].resize(n);
    band.row_count[slot].resize(n);
    const std::size_t row = static_cast<std::size_t>(y) * n;
    const float* r0 = s.rel_var[0].data() + row;
    const float* r1 = s.rel_var[1].data() + row;
    const double* l0 = s.level[0].data() + row;
    const double* l1 = s.level[1].data() + row;
    double* sum = band.row_sum[slot].data();
    std::uint8_t* count = band.row_count[slot].data();
    for (std::size_t x = 0; x < n; ++x) {
        const bool u0 = r0[x] == r0[x], u1 = r1[x] == r1[x];
        sum[x] = (u0 ? l0[x] : 0.0) + (u1 ? l1[x] : 0.0);
        count[x] = static_cast<std::uint8_t>(u0 + u1);
    }
}

// Row y's window sums for the screen, radius 1 (rows y - 1, y and y + 1 in row_levels' ring):
// per column x, the usable levels of both halves over the three rows (column_sum[0]) and over
// the rows above and below (column_sum[1]), with their counts. Vectorizes, where
// neighbour_sum is a chain of dependent additions; the window's sum at x is
// column_sum[0][x - 1] + column_sum[1][x] + column_sum[0][x + 1], in another order than
// neighbour_sum's (within 15 2^-53 of it, relatively: spatial_screen_may allows for that).
inline void window_columns(int w, int y, local_band_scratch& band) {
    const std::size_t n = static_cast<std::size_t>(w);
    for (int t = 0; t < 2; ++t) {
        band.column_sum[t].resize(n);
        band.column_count[t].resize(n);
    }
    const double* a = band.row_sum[(y + 2) % 3].data();  // row y - 1
    const double* b = band.row_sum[y % 3].data();
    const double* c = band.row_sum[(y + 1) % 3].data();
    const std::uint8_t* na = band.row_count[(y + 2) % 3].data();
    const std::uint8_t* nb = band.row_count[y % 3].data();
    const std::uint8_t* nc = band.row_count[(y + 1) % 3].data();
    double* full = band.column_sum[0].data();
    double* outer = band.column_sum[1].data();
    std::uint8_t* full_n = band.column_count[0].data();
    std::uint8_t* outer_n = band.column_count[1].data();
    for (std::size_t x = 0; x < n; ++x) {
        outer[x] = a[x] + c[x];
        full[x] = (a[x] + c[x]) + b[x];
        outer_n[x] = static_cast<std::uint8_t>(na[x] + nc[x]);
        full_n[x] = static_cast<std::uint8_t>(na[x] + nc[x] + nb[x]);
    }
}

// Where a screen by Paulson's z at m = 1 / r_other bounds the exact test: z rises with the
// level ratio and with m while a1 = r_other / 9 < 1/2. Past that its z has a ceiling below z_q
// (1.9 at n = 6, r_other = 10) while the exact tail passes a firefly of 1e7 at p = 2e-7.
inline bool paulson_screen_holds(double r_other) noexcept { return r_other * (1.0 / 9.0) < 0.5; }

// Whether the spatial screen in local_score may pass, from a window sum `approx` of the same
// count usable levels in another order: false only where it surely fails. The levels are
// positive, so the two sums differ by less than 1e-12 relatively (16 values). Paulson's z at
// m = 1 / r (a1 = r / 9, a2 = a1 / n) rises with c = (f + 2) / 3 (paulson_may_exceed); at c
// = p / (3 approx), multiplied through by 3 n approx, it is M / sqrt(n a1 (p^2 + 9 n approx^2)):
// no division. The margin 1e-4 on z is far above what the sums' difference, this form's
// rounding and the exact screen's (~1e-8 where a1 is least) move it.
inline bool spatial_screen_may(double l_hi, double approx, std::size_t count, double r_other, double zq,
                               int min_neighbours) noexcept {
    const double n = static_cast<double>(count);
    if (count < static_cast<std::size_t>(min_neighbours) || !(approx > 0)) return false;
    if (!(l_hi * n > approx * (1.0 - 1e-12))) return false;
    const double z = zq - 1.0 - 1e-4, a1 = r_other * (1.0 / 9.0);
    if (!(z > 0 && paulson_screen_holds(r_other))) return true;  // z need not rise with c
    const double p = l_hi * n * (1.0 + 1e-12) + 2.0 * approx;
    const double m = (n - a1) * p - 3.0 * n * (1.0 - a1) * approx;
    return m > 0 && m * m >= z * z * n * a1 * (p * p + 9.0 * n * approx * approx);
}

// The same levels into out, sorted, and their mean summed in that order: the same bits under
// any flip or transpose of the frame.
inline double neighbour_levels(const local_test_scratch& s, int w, int h, int x, int y, int radius,
                               std::vector<double>& out) {
    out.clear();
    for (int yy = (std::max)(y - radius, 0); yy <= (std::min)(y + radius, h - 1); ++yy)
        for (int xx = (std::max)(x - radius, 0); xx <= (std::min)(x + radius, w - 1); ++xx) {
            if (xx == x && yy == y) continue;
            const std::size_t j = static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(xx);
            for (int half = 0; half < 2; ++half)
                if (s.rel_var[half][j] == s.rel_var[half][j]) out.push_back(s.level[half][j]);
        }
    sort_small(out.data(), out.size());
    double sum = 0;
    for (const double l : out) sum += l;
    return out.empty() ? 0.0 : sum / static_cast<double>(out.size());
}

// The spatial test of the brighter half (level hi; the other half lo) against the mean mu of
// n neighbour levels, all gamma(m) means of one value where the neighbourhood is homogeneous:
// hi / mu ~ F(2m, 2nm). Gated by two checks at level h that the neighbourhood is homogeneous:
// the other half agrees with mu (two-sided), and the levels' dispersion m sum (L/mu - 1)^2 is
// within chi-square(n - 1). Returns the score z(p) / z(q), > 1 when flagged, else 0.
inline double spatial_score(double hi, double lo, double m, const std::vector<double>& levels, double mu,
                            const local_levels_q& k, double& log_p) noexcept {
    const double n = static_cast<double>(levels.size());
    const double d1 = 2.0 * m, d2 = 2.0 * n * m;
    if (!(std::fabs(paulson_z(lo / mu, d1, d2)) < k.z_half_h)) return 0.0;
    double dispersion = 0;
    for (const double l : levels) dispersion += (l / mu - 1.0) * (l / mu - 1.0);
    const double dof = n - 1.0, c = 2.0 / (9.0 * dof);  // chi-square point by Wilson-Hilferty
    const double chi2_h = dof * std::pow(1.0 - c + k.z_h * std::sqrt(c), 3.0);
    if (!(m * dispersion <= chi2_h)) return 0.0;
    if (m > 1e4) {  // F near normal; lgamma would cancel
        const double z = paulson_z(hi / mu, d1, d2);
        log_p = normal_log_upper_tail(z);
        return z > k.zq ? z / k.zq : 0.0;
    }
    const double p = f_upper_tail(hi / mu, d1, d2);
    if (!(p <= k.q)) return 0.0;
    // Below the smallest double the tail's log is what the normal point says (Paulson).
    log_p = p > 0 ? std::log(p) : normal_log_upper_tail(paulson_z(hi / mu, d1, d2));
    return p > 0 ? normal_upper_quantile(p) / k.zq : static_cast<double>((std::numeric_limits<float>::max)());
}

// A window's sum and count of usable levels from window_columns (known: false where not taken).
struct window_sum {
    bool known = false;
    double sum = 0;
    std::size_t count = 0;
};

// One pixel, the brighter half hi: the pair test, then (options.spatial) the spatial test,
// each at q / 2 when both run; fast (when known) rules the spatial test out early. Returns the
// score (> 1: flagged), 0 otherwise.
inline double local_score(const local_test_options& o, const local_levels_q& k, const local_test_scratch& s,
                          local_band_scratch& band, int w, int h, int x, int y, int hi, const window_sum& fast,
                          bool& by_spatial, double& log_p) {
    local_test_result& res = band.found;
    const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
    const double l_hi = s.level[hi][i], l_lo = s.level[1 - hi][i];
    const double r_other = static_cast<double>(s.rel_var[1 - hi][i]);
    const double q = k.q, zq = k.zq;
    // Screens, from r~ >= r_other (m <= 1 / r_other): the pair statistic with the other half's
    // own r bounds T from above and the threshold from below; for the spatial test, the
    // level ratio must exceed 1 and Paulson's z at m = 1 / r_other must come near z_q.
    bool pair_may = !pair_surely_below(l_hi, l_lo, r_other, zq) && pair_may_exceed(l_hi, l_lo, r_other, zq);
    if (pair_may) {
        const double t_pair = pair_statistic(l_hi, l_lo, r_other);
        pair_may = t_pair > zq && t_pair > t_threshold(band, q, (std::min)(2.0 / r_other, 1e10));
    }
    double mu = 0;
    bool spatial_may = false;
    if (o.spatial && (!fast.known || spatial_screen_may(l_hi, fast.sum, fast.count, r_other, zq, o.min_neighbours))) {
        std::size_t count = 0;
        const double sum = neighbour_sum(s, w, h, x, y, o.radius, band.window, count);
        const double m_max = 1.0 / r_other, n = static_cast<double>(count);
        spatial_may = count >= static_cast<std::size_t>(o.min_neighbours) && sum > 0 && l_hi * n > sum &&
                      (!paulson_screen_holds(r_other) ||
                       (paulson_may_exceed(l_hi * n / sum, 2.0 * m_max, 2.0 * n * m_max, zq - 1.0) &&
                        paulson_z(l_hi * n / sum, 2.0 * m_max, 2.0 * n * m_max) > zq - 1.0));
        if (spatial_may) mu = neighbour_levels(s, w, h, x, y, o.radius, band.levels);
    }
    if (!pair_may && !spatial_may) return 0.0;
    ++res.screened;
    const pooled_estimate pooled = pooled_relative_variance(s.rel_var, w, h, x, y, o.radius, o.min_neighbours, band.pool);
    if (!(pooled.nu == pooled.nu)) return 0.0;
    const double r = (std::max)(pooled.r, r_other);
    if (pair_may) {
        const double t = pair_statistic(l_hi, l_lo, r);
        // t with 2m degrees of freedom for the gamma law, widened by the uncertainty of r~
        const double df = (std::min)((std::max)(1.0 / (0.5 * r + 1.0 / pooled.nu), 1.0), 1e10);
        const double threshold = t > zq ? t_threshold(band, q, df) : HUGE_VAL;
        if (t > threshold) {
            log_p = k.log_tests + student_t_log_upper_tail(t, df);
            return t / threshold;
        }
    }
    if (!spatial_may || !(mu > 0)) return 0.0;
    by_spatial = true;
    const double score = spatial_score(l_hi, l_lo, 1.0 / r, band.levels, mu, k, log_p);
    log_p += k.log_tests;
    return score;
}

// The pair test's p-value (log) for half hi at (x, y), with r~ as local_score takes it from
// `pooled` (pooled_relative_variance at the pixel: one estimate serves both halves), over the
// levels of a finished local_test: for a one-half outlier the global test found. NaN where the
// pixel is not tested (a half does not count, too few neighbours, hi not higher).
inline double pair_log_p(const local_test_scratch& s, int w, int x, int y, int hi,
                         const pooled_estimate& pooled) noexcept {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
    if (s.rel_var[0].size() <= i || s.rel_var[1].size() <= i) return nan;
    const double r_other = static_cast<double>(s.rel_var[1 - hi][i]);
    const double l_hi = s.level[hi][i], l_lo = s.level[1 - hi][i];
    if (!(r_other == r_other) || !(s.rel_var[hi][i] == s.rel_var[hi][i]) || !(l_hi > l_lo)) return nan;
    if (!(pooled.nu == pooled.nu)) return nan;
    const double r = (std::max)(pooled.r, r_other);
    const double df = (std::min)((std::max)(1.0 / (0.5 * r + 1.0 / pooled.nu), 1.0), 1e10);
    return student_t_log_upper_tail(pair_statistic(l_hi, l_lo, r), df);
}

// Rows [y0, y1) of the test into band.found.
inline void local_rows(const local_test_options& o, const local_levels_q& k, const local_test_scratch& s,
                       local_band_scratch& band, int w, int h, int y0, int y1) {
    local_test_result& found = band.found;
    for (auto& f : found.half) {
        f.index.clear();
        f.score.clear();
        f.log_p.clear();
    }
    found.tested = found.screened = found.spatial = 0;
    window_offsets(w, o.radius, band.window);
    int ready = -1;  // the last row in row_levels' ring
    for (int y = y0; y < y1; ++y) {
        const bool columns = o.spatial && o.radius == 1 && y >= 1 && y + 1 < h;
        if (columns) {
            for (int r = (std::max)(ready + 1, y - 1); r <= y + 1; ++r) row_levels(s, w, r, band);
            ready = y + 1;
            window_columns(w, y, band);
        }
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
            const float ra = s.rel_var[0][i], rb = s.rel_var[1][i];
            if (!(ra == ra) || !(rb == rb)) continue;  // one half does not count, or not > 0
            ++found.tested;
            const double la = s.level[0][i], lb = s.level[1][i];
            if (la == lb) continue;
            const int hi = la > lb ? 0 : 1;  // the half that could hold a firefly
            window_sum fast;
            if (columns && x >= 1 && x + 1 < w) {
                const std::size_t l = static_cast<std::size_t>(x - 1), c = l + 1, r = l + 2;
                fast.known = true;
                fast.sum = band.column_sum[0][l] + band.column_sum[1][c] + band.column_sum[0][r];
                fast.count = std::size_t{band.column_count[0][l]} + band.column_count[1][c] + band.column_count[0][r];
            }
            bool by_spatial = false;
            double log_p = 0;
            const double score = local_score(o, k, s, band, w, h, x, y, hi, fast, by_spatial, log_p);
            if (!(score > 1.0)) continue;
            found.half[hi].index.push_back(static_cast<std::uint32_t>(i));
            found.half[hi].score.push_back(static_cast<float>((std::min)(score, static_cast<double>(FLT_MAX))));
            found.half[hi].log_p.push_back((std::min)(log_p, 0.0));
            found.spatial += by_spatial;
        }
    }
}

}  // namespace detail

// Runs the local test on both halves. Views must share size, channel counts as for
// check_half_views. Returns the first problem found; result is then empty. exec runs the
// two halves' level passes and 16 bands of rows as tasks: the result is the same for any executor.
template <class C, class V, class A>
status local_test(const local_half<C, V, A>& a, const local_half<C, V, A>& b, const local_test_options& options,
                  local_test_scratch& scratch, local_test_result& result, const executor& exec = {}) {
    for (auto& f : result.half) {
        f.index.clear();
        f.score.clear();
        f.log_p.clear();
    }
    result.tested = result.screened = result.spatial = 0;
    if (status st = check_local_test_options(options); !st.ok()) return st;
    if (status st = check_half_views(a.color, a.variance, a.alpha); !st.ok()) return st;
    if (status st = check_half_views(b.color, b.variance, b.alpha); !st.ok()) return st;
    if (!same_size(a.color, b.color)) return status{errc::size_mismatch, "local test: the halves differ in size"};
    if (a.color.pixel_count() >= (std::size_t{1} << 32))
        return status{errc::size_overflow, "local test: more than 2^32 pixels"};
    const local_half<C, V, A>* halves[2] = {&a, &b};
    exec.run(2, [&](std::size_t hh) {
        detail::local_levels(*halves[hh], options.variance_scale, scratch.level[hh], scratch.rel_var[hh]);
    });
    // Bands of rows, each into its own list; joined in row order, so the result does not
    // depend on the executor (nor on the number of bands).
    const int w = a.color.width(), h = a.color.height();
    const detail::local_levels_q k(options);
    const std::size_t bands = static_cast<std::size_t>((std::min)(h, 16));
    scratch.bands.resize(bands);
    exec.run(bands, [&](std::size_t band) {
        const int y0 = static_cast<int>(band * static_cast<std::size_t>(h) / bands);
        const int y1 = static_cast<int>((band + 1) * static_cast<std::size_t>(h) / bands);
        detail::local_rows(options, k, scratch, scratch.bands[band], w, h, y0, y1);
    });
    for (const local_band_scratch& band : scratch.bands) {
        for (int hh = 0; hh < 2; ++hh) {
            const local_flags& f = band.found.half[hh];
            result.half[hh].index.insert(result.half[hh].index.end(), f.index.begin(), f.index.end());
            result.half[hh].score.insert(result.half[hh].score.end(), f.score.begin(), f.score.end());
            result.half[hh].log_p.insert(result.half[hh].log_p.end(), f.log_p.begin(), f.log_p.end());
        }
        result.tested += band.found.tested;
        result.screened += band.found.screened;
        result.spatial += band.found.spatial;
    }
    return ok_status();
}

}  // namespace firefly
