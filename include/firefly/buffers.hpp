// firefly: fireflies found and removed across K >= 2 independent buffers of one frame (a
// renderer's sample-index-split buffers, accumulator.hpp, or N renders with different seeds).
//
// Model. Buffer k holds, per pixel, the mean x_k of its own n_k samples (n_k equal to within
// one: sample i goes to buffer i mod K). Without fireflies the x_k are independent draws of
// one law around the pixel's value. A firefly is a rare, huge sample: it sits in one buffer
// (or a few) and lifts that buffer far above the others; a highlight is many samples that
// agree, so every buffer is high together. The other buffers then give an unbiased value
// with a known variance, so a buffer is judged against the others at its own pixel.
//
// Test. Levels L_k: the mean of the colour channels (the first three). Each is moved to
// y_k = cbrt(L_k), the Wilson-Hilferty transform that makes a gamma-like (positive, right
// skewed) mean close to normal (odd: a negative pixel's law is taken as a positive one's
// mirror); every statistic is a ratio of y's, so brightness cancels (a pixel at 0.01 and one
// at 10 are judged alike, as in local_test.hpp).
//   Noise. v = Var[y] / E[y]^2 of one buffer, pooled: each pixel's own estimate (the spread
//   of its K y's, K - 1 degrees of freedom; with use_variance, the larger of that and the
//   median over its buffers of Var[x_k] / x_k^2 / 9, the delta method on cbrt), then the
//   median over the neighbours in the (2 radius + 1)^2 window that sit at the pixel's level
//   (its law: a small highlight noisier than its surroundings is judged by its own pixels;
//   levels are the lower half's mean y, which fireflies do not move; see pooled_noise),
//   scaled from a median to a mean of chi-square(K - 1) / (K - 1) values (without
//   use_variance). Never below the spread of the buffers the candidate is tested against.
//   Where most pixels carry a firefly (dense ones), a neighbour's own spread is a firefly's
//   and so is the median: the pixels flagged at the cap level give the spread of their
//   buffers below the flagged ones instead (a firefly's other buffers are an unbiased sample
//   of the pixel's law), and the pixels next to them are judged again (refine_noise).
//   Step-down (Rosner's order): sorted y_(1) >= ... >= y_(K); for i from floor(K / 2) down
//   to 1, the i-th highest against R, the buffers below it (never itself, nor the ones above):
//       T_i = (y_(i) - mean_R y) / (mean_R y sqrt(v (1 + 1 / |R|)))
//   the largest i with T_i > t_df(q / C(K, i - 1)) flags the top i buffers (a second firefly
//   above the tested one cannot mask it; C(K, i - 1): Bonferroni over the buffers set aside).
//   df = (2 / pi) n (K - 1), the pooled median's degrees of freedom over its n estimates
//   (thresholds per n). Where some buffer is black, mean_R y is never taken below the
//   neighbourhood's level (the median of its pixels' mean y): where light is sparse (a dark
//   room at a few samples a buffer) half the buffers catch no path, and a black R says only
//   that (before: any buffer above a black R was flagged; a Cycles exterior's doorway at 4
//   samples a buffer, K = 8, came out black, relMSE 0.0203 -> 0.0286, now 0.0182). Black
//   includes a hair below 0 (-1e-20). Where most neighbours are black too, a buffer above a
//   black R is flagged only if the light is absent rather than sparse: no two lit pixels among
//   the 80 around in 9 x 9 (a firefly on a black background, also with no neighbour at all);
//   where light is that sparse, a lit buffer above black ones is what it looks like (before,
//   with 95% of the buffers black, K = 4 at one sample a buffer lost 93% of its light).
// Promise, per frame (fdr.hpp): a frame without fireflies gets no flag at all in at least
// 1 - alpha of cases (the generalized ESD's promise), and with fireflies at most alpha of the
// flagged pixels are expected clean. Each pixel's p-value is the smallest over its steps of
// C(K, i - 1) P(t_df > T_i); the pixels at or below the cap q (false_alarm) go to Benjamini-
// Hochberg over the tested pixels, and the kept ones are judged again at the frame's level to
// say how many buffers go. The cap alone promises at most q of the pixel-buffers flagged (the
// first step's maximum of K is flagged with probability <= K q). Tests [buffers][calibration],
// simulator null scenes (gamma samples, shape 1 and 4, 8-16 samples per buffer): at the cap,
// q = 1e-3, three seeds: K = 4 0.31 q (spread) / 0.17 q (variance), K = 8 0.30 q / 0.29 q;
// per frame, 80 frames of 64x64 at alpha = 0.1: K = 4 and 8, with and without variance.
// Frames with fireflies run at the cap (the renders and simulated scenes below: the same
// numbers as the cap alone); a frame without them is left exactly as it was (1024x540,
// K = 4 and 8: no flag; the cap alone flagged 43 and 89 pixels, 39 and 72 of them made worse,
// as any change driven by the spread alone must be on average: the mean of normal buffers is
// independent of their differences). With use_variance at 8 samples per buffer of a
// renderer's mixed per-sample laws (the tiny renderer example) 0.44% of the pixel-buffers are
// rebuilt, the spread alone 0.19% (its caustic fireflies included).
// Measured, relMSE against the reference (../shared/data/cycles-caustics-seeds, 8 Cycles
// renders of 16 samples, no variance; 128 samples in all): mean 0.496; K = 4 (2 renders per
// buffer): median of means 0.0326, G-MoN (best threshold) 0.0321, this 0.0197 (0.0249 without
// the energy return, before the noise was pooled by level); K = 8: median of means 0.0242,
// G-MoN 0.0230, this 0.0182 (0.0234). The simulator, 1024x540 (docs/accuracy.md), this /
// G-MoN at its best: caustics K = 4 0.032 / 0.133, K = 8 0.032 / 0.086; interior K = 4
// 0.037 / 0.061, K = 8 0.019 / 0.042; a frame
// without fireflies: unchanged, the mean's 0.00093582 at K = 4. How the result grows with K
// and what each K costs: docs/k_study.md.
// Highlights: a firefly on a highlight is rebuilt, rightly (the energy return then adds to
// it); highlight pixels not lowered below their input less their fireflies: 0.99-1.0 on the
// simulated caustics, highlights and production scenes at K = 4 and 8 (0.977-0.99 before the
// noise was pooled by level; tests: small noisy highlights kept).
// Not promised: heavy-tailed (lognormal) per-sample laws, as local_test.hpp: the interior
// scene changes 0.1-0.26% of its clean pixel-buffers at q = 1e-4 (its bright patch: 0.973 not
// lowered at K = 8, yet those pixels' relative squared error fell 1.3 -> 0.030: a draw 5-40
// times the other buffers is a firefly in all but the simulator's name; q = 1e-6 keeps 0.993
// of the patch but leaves the frame at relMSE 0.0284 against 0.0186); pixels whose buffers
// straddle 0 (the cube root is steep there: 2-3% of such pixel-buffers flagged in the tests).
//
// The paper's rules for two halves, for K:
//   "an outlier in both halves is a highlight, kept"  -> a pixel where all buffers, or all
//       but a few, are high together is never flagged: the test is against the pixel's own
//       other buffers, so agreement is the null. Nothing to do, nothing changed.
//   "an outlier in one half is rebuilt"               -> a flagged buffer (a minority, at
//       most floor(K / 2)) is rebuilt from the others.
//   "rebuilt from the other half at the same pixel"   -> from the mean of the clean buffers
//       at that pixel (colour and every channel; variance: the mean of their variances, what
//       a clean buffer holds), so the mean of the K buffers equals the mean of the clean ones;
//       then (return_energy, K >= 3) the removed energy is given back where many fireflies
//       agree on it, the same amount to every buffer (energy.hpp).
//   "NaN/Inf in a half are repaired"                   -> a buffer with NaN/Inf in colour or
//       variance at a pixel is left out of the test and rebuilt like a firefly.
//   "black pixels are ignored"                         -> unless some buffers are black (one, or
//       several: a tile that failed in two renders) where the others show it cannot be by
//       chance (dropped.hpp, find_dropped): then they are left out of the test and rebuilt like
//       non-finite ones (mask_bits::dropped, report.dropped).
//   (beyond the paper)                                 -> a buffer's finite value that the others
//       show no estimate holds (a tile of 1e30, implausible.hpp, find_implausible): left out
//       of the test and rebuilt like a non-finite one (mask_bits::nonfinite, report.implausible).
//   "bad in both halves: spatial reconstruction"       -> a pixel with more than floor(K / 2)
//       non-finite buffers is left as it is and counted (report.left, error no_valid_pixels);
//       its non-finite buffers' masks say nonfinite | left (found, not repaired), the others 0.
//       Buffers found dropped or implausible count as non-finite: the few left could not be
//       told from their own fireflies (masks: dropped | left, nonfinite | left).
//   K = 2 is the paper's method: the two buffers go to firefly::detector unchanged (variance
//       required), with its global ESD, highlight check and spatial reconstruction.
// Variance: that of each buffer's mean (accumulator.hpp gives it). Required for K = 2;
// optional for K >= 3, where the spread of the buffers estimates the noise (K = 3: 2 degrees of
// freedom a pixel, pooled over the neighbourhood; used instead of given variances only for
// K >= 4 with use_variance off).
//
// Deterministic and independent of the order of the buffers: the per-pixel statistics are
// taken in the order of the sorted levels (ties by colour), and buffers of equal level are
// flagged together or not at all, so a permutation of the buffers permutes the output, bit
// for bit.
#pragma once

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "density.hpp"
#include "dropped.hpp"
#include "energy.hpp"
#include "fdr.hpp"
#include "image_view.hpp"
#include "implausible.hpp"
#include "parallel.hpp"
#include "pipeline.hpp"
#include "scratch.hpp"
#include "status.hpp"
#include "student_t.hpp"

namespace firefly {

// One buffer: colour (1 to 4 channels; the first three are colour, a 4th is carried along)
// and the variance of its mean (1 channel or one per colour channel; empty in every buffer
// or in none, and only when K >= 3). Given variances are rebuilt and checked for NaN/Inf
// even when use_variance is off.
template <class C, class V = C>
struct buffer_view {
    image_view<C> color;
    image_view<V> variance;
};

struct cross_buffer_options {
    double alpha = 0.05;         // the frame's promise: without fireflies, no flag in at least
                                 // 1 - alpha of frames; with them, at most alpha of the flagged
                                 // pixels expected clean (fdr.hpp)
    double false_alarm = 1e-4;   // q: the per-pixel level's cap (a frame dense with fireflies
                                 // runs at q: the expected share of flagged clean pixels)
    bool use_variance = false;   // K >= 4: the noise from the given variances instead of the
                                 // spread of the buffer means (K = 3 always uses them); the
                                 // spread measured better at 8-16 samples per buffer
    bool reconstruct = true;     // false: detect and report only
    bool find_dropped = true;    // a buffer black where the others show it cannot be by chance
                                 // (a failed bucket or render written black, dropped.hpp) is
                                 // left out of the test and rebuilt as a non-finite one
    bool find_implausible = true;  // a buffer's finite value that the others show no estimate
                                   // holds (a tile of 1e30, implausible.hpp): the same
    bool refine_noise = true;    // neighbours flagged at the cap pool their noise without their flagged buffers
    int radius = 1;              // the noise is pooled over (2 radius + 1)^2 pixels (1 to 8)
    bool return_energy = true;   // K >= 3, 3 or 4 channels: the removed fireflies' energy is
                                 // returned where many agree on it (energy.hpp)
    double energy_sigma = 8.0;   // its Gaussian's width in pixels (1 to 64)
    double energy_coarse_sigma = 32.0;  // the wider scale (0 or not above energy_sigma:
                                        // none; else 2 to 256)
    double energy_density_evidence = 0.0;  // the finest scale (density.hpp): removed pixels'
                                           // light given back where more than this many agree
                                           // (0: none, the default; else 1 to 1e6; 8 is the
                                           // two halves' default)
    detector_options pair{};     // K = 2: firefly::detector's options (its own
                                 // return_energy, on by default too)
};

inline status check_cross_buffer_options(const cross_buffer_options& o) noexcept {
    if (!(o.false_alarm > 0.0 && o.false_alarm < 0.5))
        return status{errc::invalid_argument, "false_alarm must lie in (0, 0.5)"};
    if (const status e = check_alpha(o.alpha); !e.ok()) return e;
    // 0 is refused: a pixel's own noise is left out of its pool (its fireflies inflate it), so
    // with no neighbour nothing was judged but a firefly on black (no flag otherwise, K 3-16)
    if (o.radius < 1 || o.radius > 8) return status{errc::invalid_argument, "radius must lie in [1, 8]"};
    if (!(o.energy_sigma >= 1.0 && o.energy_sigma <= 64.0))
        return status{errc::invalid_argument, "energy_sigma must lie in [1, 64]"};
    if (status st = check_density_evidence(o.energy_density_evidence); !st.ok()) return st;
    return check_energy_coarse(o.energy_coarse_sigma);
}

struct [[nodiscard]] cross_buffer_report {
    bool ok() const noexcept { return error.ok(); }
    status error{};
    int buffers = 0;
    std::size_t pixels = 0;
    std::size_t tested = 0;      // pixels with at least 3 usable buffers (K >= 3)
    std::size_t candidates = 0;  // pixels flagged or non-finite at the cap level, false_alarm
    double level = 0;            // the per-pixel level the frame's decision ran at (fdr.hpp)
    std::size_t fireflies = 0;   // pixel-buffers flagged as fireflies (rebuilt if reconstruct)
    std::size_t nonfinite = 0;   // pixel-buffers with NaN/Inf, rebuilt from the others
    std::size_t dropped = 0;     // pixel-buffers black where the others show they cannot be
                                 // (find_dropped), rebuilt from the others
    std::size_t implausible = 0; // pixel-buffers whose finite value the others show no
                                 // estimate holds (find_implausible), rebuilt from the others
    std::size_t left = 0;        // pixels with more than K / 2 non-finite buffers, unchanged
                                 // (K = 2: those no usable value reached, the pair detector's
                                 // unreachable; its counts above are what it found)
    std::vector<std::size_t> per_buffer;  // fireflies, non-finite, dropped and implausible, per buffer
    double energy_removed = 0;   // sum over pixels of the mean colour the fireflies took from
    double energy_returned = 0;  // the frame's mean image, and of what energy.hpp gave back
    frame_report pair{};         // K = 2: firefly::detector's report
};

namespace detail {

inline constexpr int max_buffers = 64;

// One pixel across the buffers: level, transform, relative variance, finiteness.
struct pixel_buffers {
    int k = 0;
    std::array<double, max_buffers> level{}, y{}, rel_var{};
    std::array<bool, max_buffers> finite{}, flagged{};
    std::array<int, max_buffers> order{};  // usable buffers, highest y first
    int usable = 0;
    std::uint64_t implausible = 0;  // bit i: buffer i's value implausible (implausible.hpp)
    double around = std::numeric_limits<double>::quiet_NaN();  // the neighbourhood's level, where
                                                               // some buffer is black (NaN: unknown)
    bool lit_around = false;  // where `around` is 0: light sparse there, not absent (set_around)
    // y of the j-th highest usable buffer
    double ranked_y(int j) const noexcept { return y[static_cast<std::size_t>(order[static_cast<std::size_t>(j)])]; }
};

// Thresholds of the step-down: step i tests the i-th highest buffer against the ones below
// it, at level q / C(K, i - 1) (Bonferroni over the i - 1 buffers set aside above it), with
// df the pooled noise estimate's degrees of freedom.
struct cross_thresholds {
    std::array<double, max_buffers / 2 + 1> step{};
    double q = 0, df = 0;
    int k = 0;
    void fill(double q_, int k_, double df_) noexcept {
        q = q_;
        k = k_;
        df = df_;
        double binom = 1;  // C(k, i - 1)
        for (int i = 1; i <= k / 2; ++i) {
            step[static_cast<std::size_t>(i)] = student_t_upper_quantile(q / binom, df);
            binom = binom * (k - i + 1) / i;
        }
    }
};

// The pooled estimate's degrees of freedom: a median of n estimates of K - 1 degrees of
// freedom each (efficiency 2 / pi against their mean).
inline double pooled_df(int n, int k) noexcept { return (std::max)(1.0, 2.0 / pi * n * (k - 1)); }

// The step thresholds for every pool size n = 1..pool (the pixels that joined a pixel's
// pooled noise), each at its own degrees of freedom; only the sizes asked for are filled.
struct threshold_table {
    std::vector<cross_thresholds> by_n;  // index n - 1
    std::vector<std::uint8_t> filled;
    double q = -1;
    int k = 0;
    void fill(double q_, int k_, int pool, const std::vector<std::uint8_t>& wanted) {
        if (q_ != q || k_ != k || static_cast<int>(by_n.size()) != pool) {
            q = q_;
            k = k_;
            by_n.assign(static_cast<std::size_t>(pool), cross_thresholds{});
            filled.assign(static_cast<std::size_t>(pool), 0);
        }
        for (int n = 1; n <= pool; ++n)
            if (wanted[static_cast<std::size_t>(n - 1)] && !filled[static_cast<std::size_t>(n - 1)]) {
                by_n[static_cast<std::size_t>(n - 1)].fill(q, k, pooled_df(n, k));
                filled[static_cast<std::size_t>(n - 1)] = 1;
            }
    }
    const cross_thresholds& at(int n) const noexcept { return by_n[static_cast<std::size_t>(n - 1)]; }
};

// A pixel's level: the mean y of the lower half of its usable buffers (the highest first:
// the last ceil(usable / 2)), which the step-down never flags, so its fireflies do not move
// it. NaN without a usable buffer.
inline double lower_level(const pixel_buffers& p) noexcept {
    const int u = p.usable, upper = (u + 1) / 2;
    if (u == 0) return std::numeric_limits<double>::quiet_NaN();
    double sum = 0;
    for (int j = u - upper; j < u; ++j) sum += p.ranked_y(j);
    return sum / upper;
}

// The mean y of the usable buffers from the i-th highest down (R of step i + 1; i = 0: all).
inline double rest_mean(const pixel_buffers& p, int i) noexcept {
    double sum = 0;
    for (int j = i; j < p.usable; ++j) sum += p.ranked_y(j);
    return sum / (p.usable - i);
}

inline double median_of(double* v, int n) noexcept {
    std::sort(v, v + n);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The relative variance of y among order[i..usable) (R, mean given): their spread, or with
// variance the median of their Var[x] / x^2 / 9. NaN when R cannot tell (fewer than 2).
inline double rest_noise(const pixel_buffers& p, int i, double mean, bool with_variance) noexcept {
    const int n = p.usable - i;
    std::array<double, max_buffers> r;  // (only the entries written are read)
    int m = 0;
    double ss = 0;
    for (int j = i; j < p.usable; ++j) {
        const std::size_t b = static_cast<std::size_t>(p.order[static_cast<std::size_t>(j)]);
        const double d = p.y[b] - mean;
        ss += d * d;
        if (std::isfinite(p.rel_var[b])) r[static_cast<std::size_t>(m++)] = p.rel_var[b];
    }
    if (with_variance) return m == 0 ? std::numeric_limits<double>::quiet_NaN() : median_of(r.data(), m) / 9.0;
    return n >= 2 && mean != 0 ? ss / (n - 1) / (mean * mean) : std::numeric_limits<double>::quiet_NaN();
}

// The pixel's own noise: the relative variance of one buffer's y, var(y) / mean(y)^2, over
// its usable buffers from the from-th highest down (from > 0: without flagged ones); from
// their spread, or (with variance) the larger of that and the median of Var[x] / x^2 / 9 (the
// delta method on cbrt; few-sample variances of skewed samples mostly sit low). NaN when
// unknown (fewer than 2 buffers, or a black pixel).
inline double pixel_noise(const pixel_buffers& p, bool with_variance, int from = 0) noexcept {
    const double mean = p.usable > from ? rest_mean(p, from) : 0.0;  // 0: no buffer, both NaN
    const double spread = rest_noise(p, from, mean, false);
    if (!with_variance) return spread;
    const double given = rest_noise(p, from, mean, true);
    return std::isnan(given) ? spread : std::isnan(spread) ? given : (std::max)(given, spread);
}

// Step i of the step-down: the i-th highest buffer against the mean of the ones below it, in
// noise standard deviations (noise: the pooled relative variance of y). NaN when it does not
// stand above them; +infinity when they are black at level 0 (no noise: any excess stands out).
// Where light is sparse (a dark room at a few samples a buffer) many buffers catch no path at
// all, and R's mean, black or nearly, says little of the pixel's level: where some buffer is
// black the candidate is never judged below the neighbourhood's level (p.around,
// set_around), with R's spread kept as a floor. It stands out of nothing only where that is
// black too (a firefly on a black background), or unknown (not ruled out before it is known).
inline double step_statistic(const pixel_buffers& p, int i, double noise, bool with_variance) noexcept {
    const int n = p.usable - i;  // |R|
    const double mean = rest_mean(p, i);
    const double yc = p.ranked_y(i - 1);
    if (!(yc > mean)) return std::numeric_limits<double>::quiet_NaN();
    const double level = p.around > mean ? p.around : mean;
    if (level == 0) {
        // Most neighbours black but light around: sparse light, where a lit buffer above black
        // ones is what the light looks like (a firefly there cannot be told from it by level).
        if (p.lit_around) return std::numeric_limits<double>::quiet_NaN();
        for (int j = i; j < p.usable; ++j)  // R black (or below, as -1e-20 is): nothing to stand out of
            if (p.ranked_y(j) > 0) return std::numeric_limits<double>::quiet_NaN();
        return HUGE_VAL;
    }
    if (!(yc > level)) return std::numeric_limits<double>::quiet_NaN();
    // Never below R's own noise: an edge or a highlight is noisier than its surroundings,
    // and the buffers below the candidate say so. Its spread is relative to R's mean, so taken
    // to the level by (mean / level)^2 (1 exactly where the level is R's own; with variance a
    // buffer's own relative variance, the same at any level).
    const double own = rest_noise(p, i, mean, with_variance);
    const double r = mean / level, own_at_level = own >= 0 ? (with_variance ? own : own * r * r) : 0.0;
    const double s = std::fabs(level) * std::sqrt((std::max)(noise, own_at_level) * (1.0 + 1.0 / n));
    return s > 0 ? (yc - level) / s : HUGE_VAL;
}

// Whether some usable buffer of p is black, or below (its lowest y <= 0): then the candidate is
// judged at the neighbourhood's level too (set_around, step_statistic).
inline bool black_below(const pixel_buffers& p) noexcept {
    return p.usable > 0 && p.ranked_y(p.usable - 1) <= 0;
}

// The steps a pixel can take: at most floor(K / 2) buffers flagged, and one must stay clean.
inline int step_limit(const pixel_buffers& p) noexcept {
    return (std::min)(p.k / 2 - (p.k - p.usable), p.usable - 1);
}

// Rosner-style step-down of one pixel: the largest i whose step statistic exceeds step[i]
// flags the top i (a second firefly above the tested one cannot mask it), but never splits
// buffers of equal y (a renderer's clamp, or bit-identical buffers): a buffer equal to one left
// clean is clean, so the output does not depend on the order of the buffers. Returns the
// number flagged (p.flagged set).
inline int judge_pixel(pixel_buffers& p, double noise, bool with_variance, const cross_thresholds& th) noexcept {
    if (!(noise >= 0)) return 0;
    for (int i = step_limit(p); i >= 1; --i) {
        const double t = step_statistic(p, i, noise, with_variance);
        if (t > th.step[static_cast<std::size_t>(i)]) {
            while (i > 0 && p.ranked_y(i - 1) == p.ranked_y(i)) --i;  // (i < usable: one stays clean)
            for (int j = 0; j < i; ++j) p.flagged[static_cast<std::size_t>(p.order[static_cast<std::size_t>(j)])] = true;
            return i;
        }
    }
    return 0;
}

// Whether judge_pixel flags nothing at (p) whatever the pooled noise: each step's statistic
// without it (the noise of the buffers below the candidate alone) bounds the statistic with it
// from above (the pooled noise only raises the denominator, and every operation is monotone),
// so where each bound is at most the step's smallest threshold over the pool sizes (lowest[i]),
// no step can pass. NaN (the candidate not above the rest) passes no step either.
inline bool cannot_flag(const pixel_buffers& p, bool with_variance, const std::array<double, max_buffers / 2 + 1>& lowest) noexcept {
    // A lit buffer above black ones is judged with its neighbourhood's level, which the bound
    // does not know (R's mean may be exactly 0 with buffers of both signs, its statistic NaN)
    if (black_below(p) && p.ranked_y(0) > 0) return false;
    for (int i = step_limit(p); i >= 1; --i) {
        const double t = step_statistic(p, i, 0.0, with_variance);
        if (t > lowest[static_cast<std::size_t>(i)]) return false;
    }
    return true;
}

// The pixel's p-value (log) for "no firefly here": the smallest over its steps of
// C(K, i - 1) P(t_df > T_i), the level at which judge_pixel would first flag it.
inline double pixel_log_p(const pixel_buffers& p, double noise, bool with_variance, double df) noexcept {
    double best = 0;
    double log_binom = 0;  // log C(K, i - 1)
    double highest = 0;    // the largest statistic of the steps before
    const int limit = step_limit(p);
    for (int i = 1; i <= limit; ++i) {
        const double t = step_statistic(p, i, noise, with_variance);
        // A step whose statistic is not above an earlier one's cannot give the smallest: its
        // tail is not smaller and C(K, i - 1) grows with i (by at least (K + 4) / (K - 2) a
        // step, far past any rounding of the tail), so its tail is not computed: the same minimum.
        if (t > highest) {
            highest = t;
            // no noise to judge by (R agree exactly): the smallest p a double's log can carry
            const double l = t == HUGE_VAL ? -DBL_MAX : log_binom + student_t_log_upper_tail(t, df);
            best = (std::min)(best, l);
        }
        log_binom += std::log(static_cast<double>(p.k - i + 1) / i);
    }
    return best;
}


// The K-buffer detector's scratch, kept apart from its options, executor and pair detector so
// that a move leaves the source a fresh one (take_scratch, scratch.hpp).
struct cross_buffer_scratch {
    threshold_table thresholds_{};  // at the cap level, false_alarm, every pool size
    std::array<double, max_buffers / 2 + 1> lowest_step_{};  // each step's smallest of those
    threshold_table frame_{};       // at the frame's level (fdr.hpp)
    double frame_log_p_ = 0;                 // log of the largest p-value kept
    double frame_q_ = 0;                     // the frame's level (0: nothing kept)
    double implausible_bound_ = HUGE_VAL;    // find_implausible's bound for this frame
    std::vector<double> log_p_;              // the candidates' p-values (log), for the level
    std::vector<double> noise_;  // per pixel: its own relative variance of y (NaN: unknown)
    std::vector<float> level_;   // per pixel: lower_level, its buffers' lower half (NaN: none usable)
    std::vector<float> mean_level_;  // per pixel: the mean y of its usable buffers (NaN: none)
    std::vector<std::uint8_t> refined_;  // per pixel: its noise pooled without the buffers flagged at the cap
    std::vector<double> excess_;        // energy return: what was removed, 3 channels per pixel
    std::vector<std::uint8_t> no_return_;  // energy return: pixels that get none (fewer than 3 usable
                                           // buffers; a rebuild that took nothing)
    std::vector<std::uint64_t> dropped_at_;  // the buffers found dropped at a pixel, bit i buffer i (empty: none)
    dropped_scratch dropped_scratch_;
    std::vector<dropped_pixel> dropped_found_;

    energy_scratch energy_;
    density_scratch density_;  // energy return: the finest scale's arrays
    std::vector<density_return::light> density_light_;  // and the light it gives
};
}  // namespace detail

class cross_buffer_detector : private detail::cross_buffer_scratch {
public:
    // exec and lambdas: for the K = 2 firefly::detector (and the K >= 3 rows).
    explicit cross_buffer_detector(cross_buffer_options options = {}, executor exec = {},
                                   std::shared_ptr<lambda_cache> lambdas = nullptr)
        : options_(options), exec_(exec), pair_(options.pair, exec, std::move(lambdas)) {}
    // A moved-from detector stays usable, as a moved-from firefly::detector does.
    cross_buffer_detector(const cross_buffer_detector&) = default;
    cross_buffer_detector& operator=(const cross_buffer_detector&) = default;
    cross_buffer_detector(cross_buffer_detector&& o) noexcept
        : detail::cross_buffer_scratch(detail::take_scratch<detail::cross_buffer_scratch>(o)), options_(o.options_),
          exec_(std::move(o.exec_)), pair_(std::move(o.pair_)) {}
    cross_buffer_detector& operator=(cross_buffer_detector&& o) noexcept {
        if (this == &o) return *this;
        static_cast<detail::cross_buffer_scratch&>(*this) = detail::take_scratch<detail::cross_buffer_scratch>(o);
        options_ = o.options_;
        exec_ = std::move(o.exec_);
        pair_ = std::move(o.pair_);
        return *this;
    }

    const cross_buffer_options& options() const noexcept { return options_; }
    void set_options(const cross_buffer_options& o) {
        options_ = o;
        pair_.set_options(o.pair);
    }
    detector& pair_detector() noexcept { return pair_; }
    // Work memory kept between frames, bytes (the K = 2 detector's included).
    std::size_t scratch_bytes() const noexcept {
        return (noise_.capacity() + log_p_.capacity() + excess_.capacity()) *
                   sizeof(double) + (level_.capacity() + mean_level_.capacity()) * sizeof(float) + refined_.capacity() + no_return_.capacity() +
               dropped_at_.capacity() * sizeof(std::uint64_t) + dropped_scratch_.bytes() +
               dropped_found_.capacity() * sizeof(dropped_pixel) +
               energy_.bytes() + density_.bytes() + density_light_.capacity() * sizeof(density_return::light) +
               pair_.scratch_bytes();
    }

    // Cleans the k buffers in place. masks (optional, k views of 1 channel, frame-sized)
    // receive mask_bits::firefly / nonfinite per pixel and buffer.
    template <class C, class V>
    cross_buffer_report process(const buffer_view<C, V>* buffers, int k,
                                const image_view<std::uint8_t>* masks = nullptr) {
        static_assert(!std::is_const_v<C> && !std::is_const_v<V>,
                      "process() cleans the buffers in place: use detect() on const views");
        return run(buffers, k, masks, options_.reconstruct);
    }
    template <class C, class V>
    cross_buffer_report process(const std::vector<buffer_view<C, V>>& buffers,
                                const std::vector<image_view<std::uint8_t>>& masks = {}) {
        if (!masks.empty() && masks.size() != buffers.size()) return mask_count_mismatch();
        return process(buffers.data(), static_cast<int>(buffers.size()), masks.empty() ? nullptr : masks.data());
    }
    // Detection only: report and masks, the buffers unchanged (they may be const).
    template <class C, class V>
    cross_buffer_report detect(const buffer_view<C, V>* buffers, int k,
                               const image_view<std::uint8_t>* masks = nullptr) {
        return run(buffers, k, masks, false);
    }
    template <class C, class V>
    cross_buffer_report detect(const std::vector<buffer_view<C, V>>& buffers,
                               const std::vector<image_view<std::uint8_t>>& masks = {}) {
        if (!masks.empty() && masks.size() != buffers.size()) return mask_count_mismatch();
        return detect(buffers.data(), static_cast<int>(buffers.size()), masks.empty() ? nullptr : masks.data());
    }

private:
    // Masks are one per buffer or none: with fewer, the checks and the writes read past the
    // list (a vector of 2 masks for 4 buffers was read, then written, out of bounds).
    static cross_buffer_report mask_count_mismatch() {
        cross_buffer_report r;
        r.error = status{errc::size_mismatch, "masks: one per buffer, or none"};
        return r;
    }

    template <class C, class V>
    status check_inputs(const buffer_view<C, V>* b, int k, const image_view<std::uint8_t>* masks) const {
        if (status st = check_cross_buffer_options(options_); !st.ok()) return st;
        if (b == nullptr || k < 2) return status{errc::invalid_argument, "at least 2 buffers are needed"};
        if (k > detail::max_buffers) return status{errc::invalid_argument, "at most 64 buffers"};
        const bool has_var = !b[0].variance.empty();
        if (k <= 2 && !has_var) return status{errc::invalid_argument, "2 buffers need variance"};
        for (int i = 0; i < k; ++i) {
            if (b[i].color.empty()) return status{errc::empty_image, "a buffer's colour is empty"};
            if (b[i].color.channels() > 4) return status{errc::channel_mismatch, "colour needs 1 to 4 channels"};
            if (!same_size(b[i].color, b[0].color)) return status{errc::size_mismatch, "the buffers differ in size"};
            if (b[i].color.channels() != b[0].color.channels())
                return status{errc::channel_mismatch, "the buffers differ in channels"};
            if (b[i].variance.empty() == has_var)
                return status{errc::invalid_argument, "every buffer or none needs variance"};
            if (has_var) {
                if (status st = check_half_views(b[i].color, b[i].variance, image_view<const C>{}); !st.ok())
                    return st;
                if (b[i].variance.channels() != b[0].variance.channels())
                    return status{errc::channel_mismatch, "the buffers differ in variance channels"};
            }
            if (masks && (!same_size(masks[i], b[0].color) || masks[i].channels() != 1))
                return status{errc::size_mismatch, "a mask must be 1 channel, frame-sized"};
        }
        if (status st = detail::check_frame_extent(b[0].color); !st.ok()) return st;
        return check_apart(b, k, masks, has_var);
    }

    // Every view written must be apart from every other view.
    template <class C, class V>
    static status check_apart(const buffer_view<C, V>* b, int k, const image_view<std::uint8_t>* masks, bool var) {
        for (int i = 0; i < k; ++i)
            for (int j = i; j < k; ++j) {
                if ((i != j && views_may_overlap(b[i].color, b[j].color)) ||
                    (var && (views_may_overlap(b[i].color, b[j].variance) ||
                             views_may_overlap(b[i].variance, b[j].color) ||
                             (i != j && views_may_overlap(b[i].variance, b[j].variance)))))
                    return status{errc::aliased_views, "the buffers' views must not share memory"};
                if (masks && i != j && views_may_overlap(masks[i], masks[j]))
                    return status{errc::aliased_views, "two masks share memory"};
            }
        for (int i = 0; masks && i < k; ++i)  // every mask against every buffer, before it too
            for (int j = 0; j < k; ++j)
                if (views_may_overlap(masks[i], b[j].color) || (var && views_may_overlap(masks[i], b[j].variance)))
                    return status{errc::aliased_views, "a mask shares memory with a buffer"};
        return ok_status();
    }

    template <class C, class V>
    cross_buffer_report run(const buffer_view<C, V>* b, int k, const image_view<std::uint8_t>* masks, bool clean) {
        cross_buffer_report rep;
        rep.buffers = k;
        if (status st = check_inputs(b, k, masks); !st.ok()) {
            rep.error = st;
            return rep;
        }
        rep.pixels = b[0].color.pixel_count();
        rep.per_buffer.assign(static_cast<std::size_t>(k), 0);
        if (k == 2) return run_pair(b, masks, clean, rep);
        const bool has_var = !b[0].variance.empty();
        const bool with_var = has_var && (k <= 3 || options_.use_variance);
        const int window = 2 * options_.radius + 1, pool = window * window;
        thresholds_.fill(options_.false_alarm, k, pool, std::vector<std::uint8_t>(static_cast<std::size_t>(pool), 1));
        lowest_step_.fill(HUGE_VAL);
        for (int n = 1; n <= pool; ++n)
            for (int i = 1; i <= k / 2; ++i)
                lowest_step_[static_cast<std::size_t>(i)] =
                    (std::min)(lowest_step_[static_cast<std::size_t>(i)], thresholds_.at(n).step[static_cast<std::size_t>(i)]);
        const int h = b[0].color.height();
        noise_.resize(rep.pixels);
        level_.resize(rep.pixels);
        mean_level_.resize(rep.pixels);
        if (returns_energy(b, k, clean)) excess_.assign(rep.pixels * 3, 0.0), no_return_.assign(rep.pixels, 0);
        else excess_.clear(), no_return_.clear();
        implausible_bound_ = detail::implausible_bound(b[0].color.pixel_count() * static_cast<std::size_t>(k), options_.alpha);
        find_dropped_buffers(b, k, has_var);
        exec_.run(static_cast<std::size_t>(h), [&](std::size_t y) {
            noise_row(b, k, has_var, with_var, static_cast<int>(y));
        });
        std::vector<row_counts> counts(static_cast<std::size_t>(h), row_counts(k));
        exec_.run(static_cast<std::size_t>(h), [&](std::size_t y) {
            find_row(b, k, masks, has_var, with_var, static_cast<int>(y), counts[y]);
        });
        if (refine_noise(b, k, has_var, with_var, counts)) {
            std::vector<row_counts> again(static_cast<std::size_t>(h), row_counts(k));
            exec_.run(static_cast<std::size_t>(h), [&](std::size_t y) {
                find_row(b, k, masks, has_var, with_var, static_cast<int>(y), again[y], &counts[y]);
            });
            counts.swap(again);
        }
        rep.tested = 0;
        for (const row_counts& c : counts) rep.tested += c.tested;
        set_frame_level(counts, rep.tested, k, pool);
        exec_.run(static_cast<std::size_t>(h), [&](std::size_t y) {
            decide_row(b, k, masks, clean, has_var, with_var, static_cast<int>(y), counts[y]);
        });
        if (returns_energy(b, k, clean)) return_energy(b, k, rep);
        for (const row_counts& c : counts) {
            rep.candidates += c.found.size();
            rep.fireflies += c.fireflies;
            rep.nonfinite += c.nonfinite;
            rep.dropped += c.dropped;
            rep.implausible += c.implausible;
            rep.left += c.left;
            for (int i = 0; i < k; ++i) rep.per_buffer[static_cast<std::size_t>(i)] += c.per_buffer[static_cast<std::size_t>(i)];
        }
        rep.level = frame_q_;
        if (clean && rep.left > 0)
            rep.error = status{errc::no_valid_pixels, "pixels with more than half of the buffers non-finite were left"};
        return rep;
    }

    template <class C, class V>
    cross_buffer_report& run_pair(const buffer_view<C, V>* b, const image_view<std::uint8_t>* masks, bool clean,
                                  cross_buffer_report& rep) {
        const half_buffer<C, V> a{b[0].color, b[0].variance, {}};
        const half_buffer<C, V> o{b[1].color, b[1].variance, {}};
        const image_view<std::uint8_t> none{};
        const image_view<std::uint8_t>& ma = masks ? masks[0] : none;
        const image_view<std::uint8_t>& mb = masks ? masks[1] : none;
        if (clean) {
            if constexpr (!std::is_const_v<C> && !std::is_const_v<V>) rep.pair = pair_.process(a, o, ma, mb);
        } else {
            rep.pair = pair_.detect(a, o, ma, mb);
        }
        rep.error = rep.pair.error;
        for (int i = 0; i < 2; ++i) {
            const half_report& hr = rep.pair.half[i];
            rep.fireflies += hr.fireflies;
            rep.nonfinite += hr.nonfinite;
            rep.dropped += hr.dropped;
            rep.implausible += hr.implausible;
            rep.per_buffer[static_cast<std::size_t>(i)] = hr.found();
            rep.left = (std::max)(rep.left, hr.unreachable);  // pixels: the larger half's count
        }
        rep.tested = rep.pair.half[0].valid;
        return rep;
    }

    // A pixel of a row that needs the second pass: flagged at the cap level (log p, for the
    // frame-level decision) or with non-finite buffers to rebuild (log p = 0).
    struct candidate {
        int x = 0;
        double log_p = 0;
        int pool = 0;  // the pixels its pooled noise came from
        int flagged = 0;  // buffers flagged at the cap level
    };
    struct row_counts {
        explicit row_counts(int k) : per_buffer(static_cast<std::size_t>(k), 0) {}
        std::size_t tested = 0, fireflies = 0, nonfinite = 0, dropped = 0, implausible = 0, left = 0;
        std::vector<std::size_t> per_buffer;
        std::vector<candidate> found;
    };

    // Level, relative variance and finiteness of buffer i at (x, y).
    template <class C, class V>
    static void read_buffer(const buffer_view<C, V>& b, int x, int y, bool has_var, int i, detail::pixel_buffers& p) {
        const int nc = b.color.channels(), ncol = colour_channels(nc);
        double sum = 0, fin = 0, sd = 0;
        for (int c = 0; c < nc; ++c) {
            const double v = b.color.load(x, y, c);
            fin += v - v;
            if (c < ncol) sum += v;
        }
        const std::size_t s = static_cast<std::size_t>(i);
        p.level[s] = sum / ncol;
        if (fin == 0.0 && !std::isfinite(sum)) {  // finite double channels near DBL_MAX (kernel.hpp)
            sum = 0;
            for (int c = 0; c < ncol; ++c) sum += b.color.load(x, y, c) * detail::overflow_scale;
            p.level[s] = detail::from_overflow_scale(sum / ncol);
        }
        p.rel_var[s] = std::numeric_limits<double>::quiet_NaN();
        if (has_var) {
            const int nv = b.variance.channels();
            for (int c = 0; c < nv; ++c) {  // every channel checked, as the colour's (alpha's too)
                const double v = b.variance.load(x, y, c);
                fin += v - v;
                if (c < ncol) sd += std::sqrt((std::max)(v, 0.0));
            }
            if (nv == 1) sd *= ncol;  // one variance for every colour channel (exact: ncol <= 3)
            const double rel = (sd / ncol) / std::fabs(p.level[s]);
            if (p.level[s] != 0 && std::isfinite(rel)) p.rel_var[s] = rel * rel;
        }
        p.finite[s] = fin == 0.0 && std::isfinite(p.level[s]);
        p.y[s] = std::cbrt(p.level[s]);  // odd: a negative pixel's law is a positive one's mirror
        p.flagged[s] = !p.finite[s];
    }

    // Usable buffers sorted highest first; ties by colour, then by variance (a rebuild sums the
    // clean buffers' variances in this order: buffers of one clamped colour and different
    // variances gave other bits when permuted), then by nothing (equal pixels).
    template <class C, class V>
    static void sort_buffers(const buffer_view<C, V>* b, int x, int y, bool has_var, detail::pixel_buffers& p) {
        p.usable = 0;
        for (int i = 0; i < p.k; ++i)
            if (p.finite[static_cast<std::size_t>(i)]) p.order[static_cast<std::size_t>(p.usable++)] = i;
        const int nc = b[0].color.channels(), nv = has_var ? b[0].variance.channels() : 0;
        auto colour_above = [&](int i, int j) {  // (a usable buffer's values are finite)
            for (int c = 0; c < nc; ++c) {
                const double a = b[i].color.load(x, y, c), o = b[j].color.load(x, y, c);
                if (a != o) return a > o;
            }
            for (int c = 0; c < nv; ++c) {
                const double a = b[i].variance.load(x, y, c), o = b[j].variance.load(x, y, c);
                if (a != o) return a > o;
            }
            return false;
        };
        if (p.usable > 16) {
            std::sort(p.order.begin(), p.order.begin() + p.usable, [&](int i, int j) {
                if (p.y[static_cast<std::size_t>(i)] != p.y[static_cast<std::size_t>(j)])
                    return p.y[static_cast<std::size_t>(i)] > p.y[static_cast<std::size_t>(j)];
                return colour_above(i, j);
            });
            return;
        }
        // Up to 16 buffers: a stable insertion sort on local (y, buffer) keys (no indirection
        // through the order in the inner loop), the order libstdc++'s std::sort gives there and
        // the same on every standard library (fully equal buffers keep their index order).
        struct key {
            double y;
            int i;
        };
        std::array<key, 16> keys;
        for (int a = 0; a < p.usable; ++a) {
            const int i = p.order[static_cast<std::size_t>(a)];
            keys[static_cast<std::size_t>(a)] = {p.y[static_cast<std::size_t>(i)], i};
        }
        for (int a = 1; a < p.usable; ++a) {
            const key v = keys[static_cast<std::size_t>(a)];
            int j = a;
            for (; j > 0; --j) {
                const key& u = keys[static_cast<std::size_t>(j - 1)];
                if (!(v.y > u.y || (v.y == u.y && colour_above(v.i, u.i)))) break;
                keys[static_cast<std::size_t>(j)] = u;
            }
            keys[static_cast<std::size_t>(j)] = v;
        }
        for (int a = 0; a < p.usable; ++a) p.order[static_cast<std::size_t>(a)] = keys[static_cast<std::size_t>(a)].i;
    }

    // The K buffers of pixel (x, y), read and sorted; a dropped buffer counts as non-finite.
    template <class C, class V>
    void gather(const buffer_view<C, V>* b, int k, int x, int y, bool has_var, detail::pixel_buffers& p) const {
        for (int i = 0; i < k; ++i) read_buffer(b[i], x, y, has_var, i, p);
        const std::uint64_t d = dropped_buffers(x, y, b[0].color.width());
        for (int i = 0; i < k; ++i)
            if ((d >> i) & 1u) p.finite[static_cast<std::size_t>(i)] = false, p.flagged[static_cast<std::size_t>(i)] = true;
        p.implausible = options_.find_implausible
                            ? detail::implausible_buffers(p.level.data(), p.rel_var.data(), p.finite.data(), k, implausible_bound_) : 0;
        for (int i = 0; i < k; ++i)
            if ((p.implausible >> i) & 1u) p.finite[static_cast<std::size_t>(i)] = false, p.flagged[static_cast<std::size_t>(i)] = true;
        sort_buffers(b, x, y, has_var, p);
        p.around = std::numeric_limits<double>::quiet_NaN();  // set where needed (set_around)
        p.lit_around = false;
    }

    // The buffers found dropped at (x, y): bit i for buffer i (0: none).
    std::uint64_t dropped_buffers(int x, int y, int w) const noexcept {
        return dropped_at_.empty() ? 0 : dropped_at_[index(x, y, w)];
    }

    // find_dropped (dropped.hpp): a partly black pixel is one where some buffers are black
    // (their colour channels 0) and every other one finite and not black (a lone black: one
    // buffer); those the window test finds are marked in dropped_at_ (empty: none).
    template <class C, class V>
    void find_dropped_buffers(const buffer_view<C, V>* b, int k, bool has_var) {
        dropped_at_.clear();
        if (!options_.find_dropped) return;
        const int w = b[0].color.width(), h = b[0].color.height();
        auto black_at = [&](int x, int y) -> std::uint64_t {
            std::uint64_t black = 0;
            for (int i = 0; i < k; ++i)
                if (detail::colour_is_black(b[i].color, x, y)) black |= std::uint64_t{1} << i;
            if (black == 0 || black == (k == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << k) - 1)) return 0;
            detail::pixel_buffers p;  // every buffer finite (colour and variance)
            for (int i = 0; i < k; ++i) {
                read_buffer(b[i], x, y, has_var, i, p);
                if (!p.finite[static_cast<std::size_t>(i)]) return 0;
            }
            return black;
        };
        (void)find_dropped_masks(w, h, k, options_.alpha, black_at, dropped_scratch_, exec_, dropped_found_);
        if (dropped_found_.empty()) return;
        dropped_at_.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
        for (const dropped_pixel& d : dropped_found_) dropped_at_[d.pixel] |= std::uint64_t{1} << d.buffer;
    }

    // Pass 1: every pixel's own noise and level (before anything is rebuilt; NaN where they
    // cannot be told).
    template <class C, class V>
    void noise_row(const buffer_view<C, V>* b, int k, bool has_var, bool with_var, int y) {
        detail::pixel_buffers p;
        p.k = k;
        const int w = b[0].color.width();
        for (int x = 0; x < w; ++x) {
            gather(b, k, x, y, has_var, p);
            const std::size_t i = index(x, y, w);
            noise_[i] = detail::pixel_noise(p, with_var);
            level_[i] = static_cast<float>(detail::lower_level(p));
            mean_level_[i] = p.usable > 0 ? static_cast<float>(detail::rest_mean(p, 0)) : std::numeric_limits<float>::quiet_NaN();
        }
    }

    // A neighbour's own noise is a firefly's spread where it carries one. Pixels flagged at
    // the cap level get the spread of their buffers below the flagged ones (for a firefly,
    // the others are an unbiased sample of the pixel's law; a clean pixel flagged by chance,
    // at most q of them, only lowers its neighbours' medians by one rank). True when any
    // noise changed (the find pass is run again).
    template <class C, class V>
    bool refine_noise(const buffer_view<C, V>* b, int k, bool has_var, bool with_var,
                      const std::vector<row_counts>& counts) {
        if (!options_.refine_noise) return false;
        const int w = b[0].color.width();
        const bool any = std::any_of(counts.begin(), counts.end(), [](const row_counts& c) {
            return std::any_of(c.found.begin(), c.found.end(), [](const candidate& f) { return f.flagged > 0; });
        });
        if (!any) return false;
        refined_.assign(noise_.size(), 0);
        exec_.run(counts.size(), [&](std::size_t y) {
            detail::pixel_buffers p;
            p.k = k;
            for (const candidate& f : counts[y].found) {
                if (f.flagged == 0) continue;
                gather(b, k, f.x, static_cast<int>(y), has_var, p);
                const std::size_t i = index(f.x, static_cast<int>(y), w);
                noise_[i] = detail::pixel_noise(p, with_var, f.flagged);
                refined_[i] = 1;
            }
        });
        return true;
    }

    // A median of relative variances scaled to a mean of chi-square(K - 1) / (K - 1)
    // estimates (Wilson-Hilferty median; with variance they have many degrees of freedom:
    // no scale).
    static double median_noise(double* v, int n, int k, bool with_var) noexcept {
        const double med = detail::median_of(v, n);
        if (with_var) return med;
        const double d = 2.0 / (9.0 * (k - 1)), m = 1.0 - d;
        return med / (m * m * m);
    }

    // The pixel's own noise without its highest buffer (a firefly there would inflate it): the
    // relative variance of the others (0 when unknown).
    static double own_rest(const detail::pixel_buffers& p, bool with_var) {
        if (p.usable < 3) return 0.0;
        const double v = detail::rest_noise(p, 1, detail::rest_mean(p, 1), with_var);
        return v >= 0 ? v : 0.0;
    }

    struct pooled {
        double noise = 0;
        int n = 0;  // the estimates it came from
    };

    // The pooled noise at (x, y). A pixel's noise is that of its own law, which a neighbour
    // shares only at the same level: the median of the known estimates of the neighbours at
    // the pixel's level (a small highlight, noisier than its surroundings, is judged by its own
    // pixels' spread). Its own estimate is left out (its fireflies inflate it; the step-down
    // floors the noise at the spread of the buffers below the candidate instead). A neighbour
    // joins when its level m_q (lower_level) is within 3 standard deviations of the pixel's
    // m_p: (m_q - m_p)^2 <= 9 (pi / 2) (v_p m_p^2 + v_q m_q^2) / K (a median of K varies ~pi / 2
    // times their mean; the lower half's mean alike), v_q the neighbour's estimate, v_p the
    // pixel's without its highest buffer (vp), each at least the window's (the median of all
    // its estimates). In a smooth region almost every neighbour joins. With fewer than 2 (a
    // pixel unlike its neighbours) its law is unknown: the window's noise.
    pooled pooled_noise(int x, int y, int w, int h, int k, bool with_var, double vp) const {
        std::array<double, 17 * 17> all, nearby;  // (only the entries written are read)
        int n = 0, joined = 0;
        const int r = options_.radius;
        const std::size_t self = index(x, y, w);
        for (int j = (std::max)(0, y - r); j <= (std::min)(h - 1, y + r); ++j)
            for (int i = (std::max)(0, x - r); i <= (std::min)(w - 1, x + r); ++i)
                if (noise_[index(i, j, w)] >= 0) all[static_cast<std::size_t>(n++)] = noise_[index(i, j, w)];
        if (n == 0) return {std::numeric_limits<double>::quiet_NaN(), 0};
        const double window_noise = median_noise(all.data(), n, k, with_var);
        const double mp = static_cast<double>(level_[self]);
        const double sp = (std::max)(window_noise, vp) * mp * mp;  // m_p's variance x K / (pi / 2)
        auto same_level = [&](std::size_t q) {
            const double mq = static_cast<double>(level_[q]), d = mq - mp;
            return d * d <= 9.0 * (detail::pi / 2.0) / k * (sp + (std::max)(window_noise, noise_[q]) * mq * mq);
        };
        for (int j = (std::max)(0, y - r); j <= (std::min)(h - 1, y + r); ++j)
            for (int i = (std::max)(0, x - r); i <= (std::min)(w - 1, x + r); ++i) {
                const std::size_t q = index(i, j, w);
                if (q != self && noise_[q] >= 0 && same_level(q)) nearby[static_cast<std::size_t>(joined++)] = noise_[q];
            }
        if (joined < 2) return {window_noise, n};
        return {median_noise(nearby.data(), joined, k, with_var), joined};
    }

    // p.around where some buffer of (x, y) is black, or below (a buffer at -1e-20 is black too:
    // step_statistic): the median over the window of the neighbours' mean y (their fireflies
    // raise a mean; the median of the window does not follow one); NaN without a neighbour.
    // Where that is black, p.lit_around says whether the light is sparse rather than absent: at
    // least two lit pixels among the 80 around in 9 x 9 (a lone firefly on a black background
    // has none; light with 2% of its samples lit, 4 buffers of one sample, leaves 1.5% of its
    // lit pixels without two such neighbours, and 52% without one in 3 x 3).
    void set_around(detail::pixel_buffers& p, int x, int y, int w, int h) const {
        if (!detail::black_below(p)) return;
        std::array<double, 17 * 17> v;
        int n = 0;
        detail::for_each_neighbour(w, h, x, y, options_.radius, [&](std::size_t q) {
            const float m = mean_level_[q];
            if (m == m) v[static_cast<std::size_t>(n++)] = static_cast<double>(m);
        });
        if (n > 0) p.around = detail::median_of(v.data(), n);
        if (!(p.around > 0)) p.lit_around = lit_pixels_around(x, y, w, h) >= 2;
    }

    // The lit pixels (mean y > 0) among the 80 around (x, y) in 9 x 9.
    int lit_pixels_around(int x, int y, int w, int h) const {
        int lit = 0;
        detail::for_each_neighbour(w, h, x, y, 4, [&](std::size_t q) { lit += mean_level_[q] > 0; });
        return lit;
    }

    // The noise p is judged with (and p.around set). Where some buffer is black, no pixel of the
    // window has a known noise and no neighbour is lit (a firefly on a black background, its own
    // noise refined to that of its black buffers; or no neighbour at all: radius 0, a 1x1
    // frame), there is none: any excess stands out.
    pooled judging_noise(detail::pixel_buffers& p, int x, int y, int w, int h, int k, bool with_var) const {
        set_around(p, x, y, w, h);
        const pooled pn = pooled_noise(x, y, w, h, k, with_var, own_rest(p, with_var));
        return pn.n == 0 && detail::black_below(p) && !(p.around > 0) && !p.lit_around ? pooled{0.0, 1} : pn;
    }

    // Pass 2: every pixel judged at the cap level (false_alarm); those flagged, with their
    // p-values, and those with non-finite buffers are kept for pass 3. Masks are written
    // here for the pixels pass 3 does not visit.
    template <class C, class V>
    void find_row(const buffer_view<C, V>* b, int k, const image_view<std::uint8_t>* masks, bool has_var,
                  bool with_var, int y, row_counts& rc, const row_counts* before = nullptr) {
        detail::pixel_buffers p;
        p.k = k;
        const int w = b[0].color.width(), h = b[0].color.height();
        rc.found.clear();
        std::size_t next = 0;  // before's next candidate
        if (before) {  // which pixels are tested or left does not depend on the noise
            rc.tested = before->tested;
            rc.left = before->left;
        }
        for (int x = 0; x < w; ++x) {
            if (before) {
                while (next < before->found.size() && before->found[next].x < x) ++next;
                const bool was = next < before->found.size() && before->found[next].x == x;
                if (!near_refined(x, y, w, h)) {  // the same noise around: pass 1's verdict stands
                    if (was) rc.found.push_back(before->found[next]);
                    continue;
                }
            }
            gather(b, k, x, y, has_var, p);
            const int bad = k - p.usable;
            // left as it is where more than half are non-finite, dropped or implausible (its masks say so): the
            // few left cannot be told from their own fireflies (a tile black in two of three
            // Cycles seed renders, rebuilt from the third: relMSE in the tile 2.2, 0.043 intact)
            if (bad > k / 2) {
                rc.left += before ? 0 : 1;
                write_left_masks(masks, p, x, y);
                if (!no_return_.empty()) no_return_[index(x, y, w)] = 1;
                continue;
            }
            if (p.usable >= 3 && !before) ++rc.tested;
            int flagged = 0;
            pooled pn{};
            if (!detail::cannot_flag(p, with_var, lowest_step_)) {  // most pixels: no pooled noise needed
                pn = judging_noise(p, x, y, w, h, k, with_var);
                flagged = pn.n > 0 ? detail::judge_pixel(p, pn.noise, with_var, thresholds_.at(pn.n)) : 0;
            }
            if (flagged > 0)
                rc.found.push_back({x, detail::pixel_log_p(p, pn.noise, with_var, detail::pooled_df(pn.n, k)), pn.n, flagged});
            else if (bad > 0)
                rc.found.push_back({x, 0.0, 0});
            else
                write_masks(masks, p, x, y);
        }
    }

    // Whether a pixel of (x, y)'s window had its noise refined.
    bool near_refined(int x, int y, int w, int h) const noexcept {
        const int r = options_.radius;
        for (int j = (std::max)(0, y - r); j <= (std::min)(h - 1, y + r); ++j)
            for (int i = (std::max)(0, x - r); i <= (std::min)(w - 1, x + r); ++i)
                if (refined_[index(i, j, w)]) return true;
        return false;
    }

    // The frame's level (fdr.hpp): Benjamini-Hochberg at alpha over the tested pixels, never
    // above the cap. Thresholds for pass 3 at that level, for the kept candidates' pool sizes.
    void set_frame_level(const std::vector<row_counts>& counts, std::size_t tested, int k, int pool) {
        log_p_.clear();
        for (const row_counts& c : counts)
            for (const candidate& f : c.found)
                if (f.log_p < 0) log_p_.push_back(f.log_p);
        frame_log_p_ = bh_log_threshold(log_p_, tested, options_.alpha);
        frame_q_ = 0;
        if (frame_log_p_ == -HUGE_VAL) return;  // nothing kept: pass 3 judges no candidate
        std::vector<std::uint8_t> wanted(static_cast<std::size_t>(pool), 0);
        for (const row_counts& c : counts)
            for (const candidate& f : c.found)
                if (f.log_p < 0 && f.log_p <= frame_log_p_) wanted[static_cast<std::size_t>(f.pool - 1)] = 1;
        // Below 1e-300 the thresholds stop growing; every candidate kept is far past them. A
        // hair above the kept p-value: the quantile and the tail invert each other only to
        // rounding, and the candidate at the level itself must pass.
        const double q = (std::max)((std::min)(std::exp(frame_log_p_) * (1 + 1e-6), options_.false_alarm), 1e-300);
        frame_.fill(q, k, pool, wanted);
        frame_q_ = q;
    }

    // Pass 3: the candidates again, judged at the frame's level, masks written, rebuilt.
    template <class C, class V>
    void decide_row(const buffer_view<C, V>* b, int k, const image_view<std::uint8_t>* masks, bool clean,
                    bool has_var, bool with_var, int y, row_counts& rc) {
        detail::pixel_buffers p;
        p.k = k;
        const int w = b[0].color.width();
        for (const candidate& f : rc.found) {
            const int x = f.x;
            gather(b, k, x, y, has_var, p);
            const int bad = k - p.usable;
            const bool kept = f.log_p < 0 && f.log_p <= frame_log_p_;
            const pooled pn = kept ? judging_noise(p, x, y, w, b[0].color.height(), k, with_var) : pooled{};
            const int flags = kept ? detail::judge_pixel(p, pn.noise, with_var, frame_.at(pn.n)) : 0;
            const int dropped = detail::blacks_in(dropped_buffers(x, y, w));
            const int implausible = detail::blacks_in(p.implausible);
            rc.fireflies += static_cast<std::size_t>(flags);
            rc.nonfinite += static_cast<std::size_t>(bad - dropped - implausible);
            rc.dropped += static_cast<std::size_t>(dropped);
            rc.implausible += static_cast<std::size_t>(implausible);
            for (int i = 0; i < k; ++i) rc.per_buffer[static_cast<std::size_t>(i)] += p.flagged[static_cast<std::size_t>(i)];
            write_masks(masks, p, x, y);
            if (!no_return_.empty() && p.usable < 3) no_return_[index(x, y, w)] = 1;
            if (clean && (flags > 0 || bad > 0)) rebuild(b, p, x, y, has_var, excess_.empty() ? nullptr : &excess_[index(x, y, w) * 3]);
            if (clean && flags > 0 && !excess_.empty()) {  // a rebuild that took nothing gets nothing back
                const double* e = &excess_[index(x, y, w) * 3];
                if (!(e[0] > 0 || e[1] > 0 || e[2] > 0)) no_return_[index(x, y, w)] = 1;
            }
        }
    }

    // A pixel left as it is (more than K / 2 non-finite, dropped or implausible buffers): nonfinite | left,
    // or dropped | left, on those.
    void write_left_masks(const image_view<std::uint8_t>* masks, const detail::pixel_buffers& p, int x, int y) const {
        if (!masks) return;
        const std::uint64_t d = dropped_buffers(x, y, masks[0].width());
        for (int i = 0; i < p.k; ++i)
            masks[i](x, y) = p.finite[static_cast<std::size_t>(i)] ? std::uint8_t{0}
                             : (d >> i) & 1u ? static_cast<std::uint8_t>(mask_bits::dropped | mask_bits::left)
                                             : static_cast<std::uint8_t>(mask_bits::nonfinite | mask_bits::left);
    }

    void write_masks(const image_view<std::uint8_t>* masks, const detail::pixel_buffers& p, int x, int y) const {
        if (!masks) return;
        const std::uint64_t d = dropped_buffers(x, y, masks[0].width());
        for (int i = 0; i < p.k; ++i) {
            const std::size_t s = static_cast<std::size_t>(i);
            masks[i](x, y) = !p.flagged[s]     ? 0
                             : p.finite[s]     ? mask_bits::firefly
                             : (d >> i) & 1u   ? mask_bits::dropped
                                               : mask_bits::nonfinite;
        }
    }

    // Flagged buffers take the mean of the clean ones (in sorted order: no buffer order).
    // excess (3 channels, or null): what the finite flagged buffers lose, over K.
    template <class C, class V>
    static void rebuild(const buffer_view<C, V>* b, const detail::pixel_buffers& p, int x, int y, bool has_var,
                        double* excess) {
        if constexpr (!std::is_const_v<C> && !std::is_const_v<V>) {
            const int nc = b[0].color.channels();
            const int nv = has_var ? b[0].variance.channels() : 0;
            std::array<double, 8> sum{};  // colour channels, then variance channels
            int n = 0;
            auto add_clean = [&](auto scale) {  // unscaled, or overflow_scale (kernel.hpp)
                n = 0;
                for (int j = 0; j < p.usable; ++j) {
                    const int i = p.order[static_cast<std::size_t>(j)];
                    if (p.flagged[static_cast<std::size_t>(i)]) continue;
                    ++n;
                    for (int c = 0; c < nc; ++c) sum[static_cast<std::size_t>(c)] += b[i].color.load(x, y, c) * scale;
                    for (int c = 0; c < nv; ++c)
                        sum[static_cast<std::size_t>(nc + c)] += (std::max)(b[i].variance.load(x, y, c), 0.0) * scale;
                }
            };
            add_clean(detail::unscaled{});
            std::array<double, 8> mean{};
            const bool rescaled = !detail::all_finite(sum.data(), nc + nv);  // double values near DBL_MAX
            if (rescaled) sum.fill(0.0), add_clean(detail::overflow_scale);
            for (int c = 0; c < nc + nv; ++c)
                mean[static_cast<std::size_t>(c)] = rescaled ? detail::from_overflow_scale(sum[static_cast<std::size_t>(c)] / n)
                                                             : sum[static_cast<std::size_t>(c)] / n;
            for (int j = 0; j < p.usable && excess; ++j) {  // sorted order, finite buffers only
                const int i = p.order[static_cast<std::size_t>(j)];
                if (!p.flagged[static_cast<std::size_t>(i)]) continue;
                for (int c = 0; c < 3; ++c)  // (a difference of two values near DBL_MAX: held finite)
                    excess[c] += std::clamp((b[i].color.load(x, y, c) - mean[static_cast<std::size_t>(c)]) / p.k,
                                            -DBL_MAX / detail::max_buffers, DBL_MAX / detail::max_buffers);
            }
            for (int i = 0; i < p.k; ++i) {
                if (!p.flagged[static_cast<std::size_t>(i)]) continue;
                for (int c = 0; c < nc; ++c) b[i].color.store(x, y, c, mean[static_cast<std::size_t>(c)]);
                for (int c = 0; c < nv; ++c) b[i].variance.store(x, y, c, mean[static_cast<std::size_t>(nc + c)]);
            }
        }
    }

    static std::size_t index(int x, int y, int w) noexcept {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
    }

    template <class C, class V>
    bool returns_energy(const buffer_view<C, V>* b, int k, bool clean) const noexcept {
        return clean && options_.return_energy && k >= 3 && b[0].color.channels() >= 3 && !std::is_const_v<C>;
    }

    // After the rebuild: the clean mean image, the energy to return (energy.hpp), added to
    // every buffer alike (the same value: the buffers' order still does not matter).
    template <class C, class V>
    void return_energy(const buffer_view<C, V>* b, int k, cross_buffer_report& rep) {
        const int w = b[0].color.width(), h = b[0].color.height();
        // The shape: the input's mean (the clean mean plus what was removed), whose 3x3
        // median keeps where fireflies fall densely (a caustic lit mostly by them) and drops
        // the lone ones; the clean mean alone misplaces that light at high K (few samples a
        // buffer: most of a caustic's light is then flagged). Made row by row as needed.
        auto shape_row = [&](int y, double* row) {
            for (int x = 0; x < w; ++x)
                for (int c = 0; c < 3; ++c) {
                    const std::size_t i = index(x, y, w) * 3 + static_cast<std::size_t>(c);
                    row[static_cast<std::size_t>(x) * 3 + static_cast<std::size_t>(c)] = positive_mean(b, k, x, y, c) + excess_[i];
                }
        };
        for (std::size_t i = 0; i < excess_.size(); ++i) rep.energy_removed += excess_[i] / 3.0;
        if constexpr (!std::is_const_v<C>) rep.energy_returned += give_density_back(b, k);  // the finest scale, first
        energy_model_rows(excess_, shape_row, w, h, energy_scales(options_.energy_sigma, options_.energy_coarse_sigma),
                          energy_, exec_);
        energy_.row_returned.assign(static_cast<std::size_t>(h), 0.0);
        if constexpr (!std::is_const_v<C>)
            detail::for_each_energy_row(energy_, w, h, exec_, [&](int y, const double* add) { give_back_row(b, k, y, add); });
        for (const double r : energy_.row_returned) rep.energy_returned += r;
        // (double buffers: excess up to DBL_MAX / 64 a pixel-buffer sums past the range)
        rep.energy_removed = (std::min)(rep.energy_removed, DBL_MAX);
        rep.energy_returned = (std::min)(rep.energy_returned, DBL_MAX);
    }

    // return_energy's finest scale (density.hpp), on the mean image: each pixel's removed
    // excess is one half's, the other's none (the buffers' excess is pooled at the pixel
    // already: a cluster of fireflies counts its pixels once, as one half's chance cluster
    // does). Its light is added to every buffer alike, at most f e where e was removed, and
    // each pixel's excess is lowered to (1 - f) e: the wider scales return the rest. Returns
    // the light given (mean colour, summed over the pixels).
    // Off by default (energy_density_evidence 0): the wider scales' shape here, the 3x3 median
    // of the input's mean, already keeps light where fireflies fall densely, and the window's
    // blur (sigma 2) spreads a thin caustic's light beyond it: the simulated caustics at 128
    // samples (512x270, 3 seeds) 0.0354 -> 0.0437 at K = 8 and 0.0327 -> 0.0662 at K = 16, while
    // dense10 0.0519 -> 0.0456 (K = 8) and the bokeh render as 8 renders of 16 samples 0.0166 ->
    // 0.0156; 16 and above change nothing measurable.
    template <class C, class V>
    double give_density_back(const buffer_view<C, V>* b, int k) {
        const int w = b[0].color.width(), h = b[0].color.height();
        if (!(options_.energy_density_evidence > 0)) return 0.0;
        density_return d;
        d.prepare(w, h, density_);
        for (std::size_t p = 0; p < density_.removed.size(); ++p)
            density_.removed[p] = (excess_[p * 3] > 0 || excess_[p * 3 + 1] > 0 || excess_[p * 3 + 2] > 0) && !no_return_[p];
        if (!d.needed(options_.energy_density_evidence, density_)) return 0.0;
        auto load = [&](int x, int y, double* v) {  // the excess, none, |e|^2, the cleaned mean's level
            const std::size_t p = index(x, y, w);
            v[6] = v[7] = 0;
            for (int c = 0; c < 3; ++c) {
                v[c] = density_.removed[p] ? excess_[p * 3 + static_cast<std::size_t>(c)] : 0.0;
                v[3 + c] = 0;
#ifdef FIREFLY_DETAIL_TARGET_FMA
                v[6] = std::fma(v[c], v[c], v[6]);  // fused the one way (fused.hpp)
#else
                v[6] += v[c] * v[c];
#endif
                v[7] += positive_mean(b, k, x, y, c);
            }
        };
        // none where a pixel's own fireflies could not be told: none removed there
        auto receives = [&](int x, int y) { return !no_return_[index(x, y, w)]; };
        if (!d.run(options_.energy_density_evidence, density_, density_light_, exec_, load, receives)) return 0.0;
        double given = 0;
        for (const density_return::light& l : density_light_) {
            const int x = detail::column_of(l.pixel, w), y = detail::row_of(l.pixel, w);
            const double f = d.taken(l.pixel);  // (0 where nothing was removed)
            double add[3];
            for (int c = 0; c < 3; ++c) {
                // (none in a channel whose excess is negative, as a red firefly's on grey:
                // light is only added, and the total counts what was)
                add[c] = (std::max)(static_cast<double>(l.add[0][c]), 0.0);
                if (density_.removed[l.pixel])
                    add[c] = (std::min)(add[c], f * (std::max)(excess_[l.pixel * 3 + static_cast<std::size_t>(c)], 0.0));
            }
            if (add_to_every_buffer(b, k, x, y, add)) given += (add[0] + add[1] + add[2]) / 3.0;
        }
        for (std::size_t p = 0; p < density_.removed.size(); ++p) {
            if (!density_.removed[p]) continue;
            const double f = d.taken(p);
            for (int c = 0; c < 3; ++c) excess_[p * 3 + static_cast<std::size_t>(c)] *= 1.0 - f;
        }
        return given;
    }

    // The mean of the k buffers' channel c at (x, y) where positive and finite, else 0. Summed
    // in ascending order, not the buffers' (values of very different magnitudes round
    // differently in another order): a permutation of the buffers gives the same bits.
    template <class C, class V>
    static double positive_mean(const buffer_view<C, V>* b, int k, int x, int y, int c) {
        double v[detail::max_buffers];
        for (int i = 0; i < k; ++i) {
            v[i] = b[i].color.load(x, y, c);
            if (!std::isfinite(v[i])) return 0.0;  // (the sum would not be finite either)
        }
        detail::sort_small(v, static_cast<std::size_t>(k));
        double sum = 0;
        for (int i = 0; i < k; ++i) sum += v[i];
        const double m = sum / k;
        return std::isfinite(m) && m > 0 ? m : 0.0;
    }

    // add (3 channels) to pixel (x, y) of every buffer alike, or to none where a sum does not
    // fit a buffer's type; whether it was added.
    template <class C, class V>
    static bool add_to_every_buffer(const buffer_view<C, V>* b, int k, int x, int y, const double* add) {
        if (!(add[0] + add[1] + add[2] > 0)) return false;
        double old[detail::max_buffers][3];
        bool fits = true;
        for (int i = 0; i < k; ++i) fits = add_light(b[i].color, x, y, add, old[i]) && fits;
        if (!fits)
            for (int i = 0; i < k; ++i) restore_light(b[i].color, x, y, old[i], add);
        return fits;
    }

    // Row y's return (3 per pixel) added to every buffer alike, or to none where a sum does
    // not fit a buffer's type. Where something was removed, at most that (the pixel's mean
    // ends above its input's by float rounding at most: as in return_energy_to_image); none
    // where a flagged buffer's rebuild took nothing (no channel's excess above 0, as two
    // halves' untaken pixels), or where fewer than 3 buffers were usable, whose own fireflies
    // could not be told apart and are all still there (at K = 4, a tile black in two renders
    // came out 1.44x its expected light on the simulated caustics).
    template <class C, class V>
    void give_back_row(const buffer_view<C, V>* b, int k, int y, const double* returned) {
        const int w = b[0].color.width();
        const std::size_t row = static_cast<std::size_t>(y);
        double capped[3];
        for (int x = 0; x < w; ++x) {
            const double* add = returned + static_cast<std::size_t>(x) * 3;
            const double* removed = &excess_[index(x, y, w) * 3];
            if (removed[0] > 0 || removed[1] > 0 || removed[2] > 0) add = detail::at_most(add, removed, capped);
            if (!(add[0] + add[1] + add[2] > 0)) continue;  // wherever positive (energy.hpp)
            if (no_return_[index(x, y, w)]) continue;  // its fireflies could not be told, or none were removed
            if (add_to_every_buffer(b, k, x, y, add)) energy_.row_returned[row] += (add[0] + add[1] + add[2]) / 3.0;
        }
    }

    cross_buffer_options options_;
    executor exec_;
    detector pair_;
};

}  // namespace firefly
