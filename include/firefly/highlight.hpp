// firefly: the half-buffer highlight check (paper, section 5).
//
// A pixel that is an outlier in BOTH halves is taken for a real highlight and keeps its
// values; an outlier in one half only is a firefly. Two unrelated fireflies can land on
// the same pixel by chance, though (at a 0.6% firefly rate per half, about 5 pixels in
// 120k), and every such pixel kept is a huge error. The stricter rules ask more of the pair:
//
//   same_pixel   the paper's rule: outlier in both halves
//   agree        and the halves' mean radiance agrees within a factor (max/min <= max_ratio)
//   confident    and the relative standard error of the pixel's mean over both halves,
//                sqrt(var(A) + var(B)) / |A + B| (variances of the half means), is at most
//                max_relative_error; with the detector's base (pair_rise), over the pair's
//                rise above its neighbourhood's level instead of |A + B|. A firefly is one
//                sample carrying the pixel's excess: one in each half gives at least
//                1/sqrt(2) = 0.71 of the rise, and 1 when one dominates. A highlight
//                is many samples that agree: c / sqrt(2N) for N samples per half of relative
//                spread c (0.22 for c = 2.5, N = 64). Both halves together halve the noise
//                of the estimate compared with a test per half.
//   confident_and_agree   both of the above
//
// Clusters: a highlight is spatially coherent (a spot, a streak, a disk), while two unrelated
// fireflies meeting on one pixel are an isolated coincidence; two such coincidences side by
// side are rarer still (about (pA pB)^2 per pixel). So a both-half outlier next to a strict
// highlight, or next to more both-half outliers than the frame's density of them explains (a
// binomial tail below 1e-3 over its 8 neighbours), is held to the looser
// cluster_relative_error, unless one-half fireflies around it say fireflies are dense there
// (pipeline.hpp, decide_pairs: they must be outnumbered by the strict neighbours, or more than
// twice by the pairs). (Tried: the density of the 15x15 window around the pixel where that
// is higher, since unrelated pairs meet side by side all the time where fireflies are dense,
// as in a caustic lit by them: the simulated caustics 0.033 -> 0.029, but a wide noisy
// highlight, every pixel a pair, then explains itself as chance: a 16x16 spot at relative
// error 0.6 kept 24 of its 256 pixels.) This keeps
// highlights at low sample counts, where even a real highlight's relative error passes 0.5
// (c / sqrt(2N) for N samples per half of relative spread c). Next to pixels that pass the
// strict limit (a spot whose level is known; cluster pass only), a pixel whose standard error
// is within the cluster limit's allowance (cluster / strict limit, 0.8 / 0.5) of the noisiest
// of them has the spot's noise, and its error is taken relative to the larger of its own
// rise (pair_rise: |A + B| where it has no base) and their mean (highlight_spot): a spot's
// pixel that drew low in both halves has a small sum and so a large error of its own (at 16
// samples per half and c = 2.5, 36 of 285 spot pixels failed at their own level, 2 at the
// spot's). Two fireflies that met beside a spot carry their own noise, one sample each (a
// standard error near their sum), far above a spot's many samples: judged at their own level
// as before. A spot without noise (a clamped emitter) or max_relative_error = 0 leaves every
// pixel at its own level, as before the rule.
// Measured, not yet taken: the cluster limit at 1/sqrt(2), the least standard error a pair of
// fireflies has against its rise (above it, a pair carried by one sample a half passes by
// construction): the simulated caustics' recall 0.905 -> 0.915 (relMSE 0.0275 -> 0.0267), the
// interior 0.0181 -> 0.0170, the Cycles renders unchanged; on the 36 held-out frames relMSE
// lower on 20 and higher on 1 (by 0.06%), but 11 lose highlight pixels (at 16 samples: 1 of 300 and
// 3 of 6,066 in the tables' frames).
//
// An outlier in ONE half only is a firefly in the paper. It must also stand out against the
// other half, though: a firefly makes its half exceed the other by many times the noise,
// while a bright, noisy but legitimate pixel (a thin line, a checker cell) that the global
// test flags in one half only agrees with the other half within the noise. With
// min_excess_z > 0 such an outlier is reconstructed only when
//     (L_out - L_other) / sqrt(2 var_other) > min_excess_z
// (variances calibrated to variances of the mean, as below; the detector's var_other is the
// other half's noise as its neighbourhood bounds it, pipeline.hpp noise_floor); 0 is the
// paper's behaviour.
// The frame's decision (fdr.hpp, Benjamini-Hochberg over every tested pixel-half) then keeps
// only what the frame's p-values support, so this is a cap, not the test: 3 (a normal tail of
// 1.3e-3) lets a frame dense with moderate fireflies reach them, where 4 had held the frame's
// level below its own (the Cycles interior's level is 1.2e-3: relMSE 0.1313 -> 0.1201), and a
// frame without fireflies is decided by the frame's level as before.
//
// "Variance" means different things in different renderers (of the samples, or of the
// pixel mean). The confident rule calibrates it from the data: for an ordinary pixel,
// (A - B)^2 / (vA + vB) follows a chi-square with one degree of freedom when v is the
// variance of the mean, whose median is 0.4549; the median of the observed ratios over
// ordinary pixels, divided by 0.4549, is the factor that turns the given variance into a
// variance of the mean. A median, so the few heavy-tailed pixels do not move it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "floating_point.hpp"

namespace firefly {

enum class highlight_rule : std::uint8_t { same_pixel, agree, confident, confident_and_agree };

struct highlight_options {
    highlight_rule rule = highlight_rule::confident;
    double max_ratio = 4.0;            // agree: max(LA, LB) / min(LA, LB)
    double max_relative_error = 0.5;   // confident: sqrt(vA + vB) / |A + B|, calibrated
    double min_excess_z = 3.0;         // one-half outliers: required excess over the other half
    double cluster_relative_error = 0.8;  // confident, for pixels with a both-half neighbour
};

// How far an outlier's half stands from the other half, in the outlier's direction: l_out -
// l_other, or its negation where l_out is below 0 (a firefly through a filter's negative lobe
// lowers its pixel; a pair of them is judged by magnitude too, in is_highlight).
inline double signed_excess(double l_out, double l_other) noexcept {
    return l_out < 0 ? l_other - l_out : l_out - l_other;
}

// Decide an outlier of one half only: true when it stands out against the other half.
// l_out, l_other: mean colour in the outlier's half and in the other; v_other: the other
// half's reduced variance; calibration as for is_highlight.
inline bool exceeds_other_half(const highlight_options& o, double l_out, double l_other,
                               double v_other, double calibration) noexcept {
    if (!(o.min_excess_z > 0)) return true;
    const double noise = std::sqrt(2.0 * (std::max)(v_other, 0.0) * calibration);
    return signed_excess(l_out, l_other) > o.min_excess_z * noise;
}

// The excess itself, in the other half's noise: signed_excess / sqrt(2 v_other calibration)
// (+infinity when that noise is 0 and the excess positive). Its normal tail is the p-value the
// frame-level decision ranks a one-half outlier by (fdr.hpp).
inline double excess_z(double l_out, double l_other, double v_other, double calibration) noexcept {
    const double noise = std::sqrt(2.0 * (std::max)(v_other, 0.0) * calibration);
    const double d = signed_excess(l_out, l_other);
    return noise > 0 ? d / noise : d > 0 ? HUGE_VAL : 0.0;
}

inline constexpr double chi2_1_median = 0.45493642311957184;

namespace detail {
// The least m with P(Binomial(n, q) >= m) < p: how many of n neighbours must share a property
// of density q before chance stops explaining it (n + 1 when no count is enough).
inline int binomial_tail_count(int n, double q, double p) noexcept {
    q = std::clamp(q, 0.0, 1.0);
    double tail = 0.0;  // P(M >= m), accumulated from m = n downwards
    for (int m = n; m >= 0; --m) {
        double term = 1.0;  // C(n, m) q^m (1 - q)^(n - m)
        for (int k = 0; k < m; ++k) term *= static_cast<double>(n - k) / static_cast<double>(k + 1) * q;
        for (int k = 0; k < n - m; ++k) term *= 1.0 - q;
        if (tail + term >= p) return m + 1;
        tail += term;
    }
    return 0;
}
}  // namespace detail

// The factor that turns the renderer's variance into a variance of the pixel mean: the
// median of (A_c - B_c)^2 / (vA_c + vB_c) over ordinary pixels, over chi2_1_median.
class variance_calibration {
public:
    void add(double a, double b, double va, double vb) {
        const double v = (std::max)(va, 0.0) + (std::max)(vb, 0.0);
        const double d = a - b;
        if (v > 0 && std::isfinite(v) && std::isfinite(d)) ratios_.push_back(d * d / v);
    }
    // 1 when there is too little to learn from; clamped to a sane range otherwise.
    double factor() {
        if (ratios_.size() < 32) return 1.0;
        const auto mid = ratios_.begin() + static_cast<std::ptrdiff_t>(ratios_.size() / 2);
        std::nth_element(ratios_.begin(), mid, ratios_.end());
        const double f = *mid / chi2_1_median;
        return f > 0 ? std::clamp(f, 1e-8, 1e8) : 1.0;
    }
    void clear() noexcept { ratios_.clear(); }
    std::size_t size() const noexcept { return ratios_.size(); }
    std::size_t bytes() const noexcept { return ratios_.capacity() * sizeof(double); }

private:
    std::vector<double> ratios_;
};

// sqrt(vA + vB) with the variances calibrated to variances of the mean: the standard error
// of A + B, which the confident rule compares with the pair's rise (pair_rise).
inline double pair_standard_error(double va, double vb, double calibration) noexcept {
    return std::sqrt(((std::max)(va, 0.0) + (std::max)(vb, 0.0)) * calibration);
}

// A highlight spot around a pixel, from its neighbours that passed the strict limit: the mean
// of their rises (pair_rise) and the largest of their standard errors, each as they were
// judged (a half carrying a firefly replaced by the other). A pixel whose noise is the spot's
// (within the cluster limit's allowance) is judged at the spot's level when that is higher
// than its own (is_highlight).
struct highlight_spot {
    double sum = 0.0;
    double se = 0.0;
};

// The share of the lower half's level a pair's base may take (pair_rise).
inline constexpr double max_base_share = 1.0 / 3.0;

// What the confident rule measures a pair's standard error against: its rise above its base,
// |A + B| - 2 base, where base is the level the pixel's ordinary samples give (its smooth
// neighbourhood's; 0: unknown, or detail). A firefly is one sample carrying a half's excess
// over that base, so a pair of them has a standard error of at least 1/sqrt(2) of the rise
// however bright the base; against |A + B| a moderate pair (each firefly 2-10 times the base,
// as where fireflies are dense) looks as confident as a highlight (0.47-0.65 of the level).
// The caller says where a base is known (the detector: both halves more than three standard
// deviations above a smooth neighbourhood; elsewhere 0). The base counts only where both
// halves are positive, and at most max_base_share of the lower one: the rise stays at least
// two thirds of the level, whatever the base. Non-finite levels or base: the level.
inline double pair_rise(double la, double lb, double base) noexcept {
    const double level = std::fabs(la + lb);
    if (!(base > 0) || !(la > 0 && lb > 0)) return level;
    const double b = (std::min)(base, max_base_share * (std::min)(la, lb));
    return std::isfinite(b) ? level - 2.0 * b : level;
}

// Decide one pixel that is an outlier in both halves. la, lb: mean colour of the pixel in
// each half; va, vb: its reduced variance in each half; calibration: variance_calibration::factor();
// in_cluster: another both-half outlier is among its 8 neighbours; spot (cluster only): what
// the strict highlights among them say of the spot (none: zeros); base: the level its
// ordinary samples give (pair_rise; 0: none).
inline bool is_highlight(const highlight_options& o, double la, double lb, double va, double vb,
                         double calibration, bool in_cluster = false, highlight_spot spot = {},
                         double base = 0.0) noexcept {
    const bool want_agree =
        o.rule == highlight_rule::agree || o.rule == highlight_rule::confident_and_agree;
    const bool want_conf =
        o.rule == highlight_rule::confident || o.rule == highlight_rule::confident_and_agree;
    if (want_agree) {
        if ((la < 0) != (lb < 0)) return false;  // halves of opposite sign agree on nothing
        const double lo = (std::min)(std::fabs(la), std::fabs(lb));
        const double hi = (std::max)(std::fabs(la), std::fabs(lb));
        if (!(hi <= o.max_ratio * lo)) return false;
    }
    if (want_conf) {
        const double limit = in_cluster ? (std::max)(o.max_relative_error, o.cluster_relative_error)
                                        : o.max_relative_error;
        const double se = pair_standard_error(va, vb, calibration);
        const bool spot_noise = se <= limit / o.max_relative_error * spot.se;  // (limit: cluster's)
        const double rise = pair_rise(la, lb, base);
        const double level = spot_noise ? (std::max)(rise, spot.sum) : rise;
        if (!(se <= limit * level)) return false;
    }
    return true;
}

}  // namespace firefly
