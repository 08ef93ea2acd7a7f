// firefly: implausible pixels, values that the other half shows no Monte Carlo estimate holds.
//
// A render bucket can fail without NaN or black: memory never written, a worker that scaled its
// samples wrong, a fault that left 1e30 in a tile whose variance pass is sane. Such a pixel is
// no outlier of its half's standard deviations (its variance is ordinary), and inside a tile of
// them no pixel stands out from its neighbours either, so no test of the detector saw it; worse,
// its neighbours outside the tile read it as a clean source. Measured on cycles-caustics, a
// 64x64 tile of 1e30 in half A: the tile came out at 1e30 and the rebuilt pixels beside it at
// up to 1.6e29, though half B held good values for every one of them.
//
// Test. The two halves are independent estimates of one value, each with its variance, so at
// a pixel
//     z = |L_A - L_B| / sqrt(v_A + v_B)        (mean colour, reduced variance)
// is a two-sample t statistic. With normal samples, two or more per half, each variance has at
// least one degree of freedom and |z|'s tail is at most about that of Student's t with 1 (the
// Cauchy law: P(|z| > t) <= 2 / (pi t)). Bonferroni over the frame's m pixels: a pixel is
// implausible when z > 2 m / (pi alpha), so a frame of such halves loses no pixel to this test
// in at least 1 - alpha of cases (2.8e7 on a 2K frame at alpha = 0.05: only corruption reaches
// it). Samples far from normal can make both halves' variances tiny while their values differ
// (an emitter's edge at two samples a half: one half's samples all on the emitter, the other's
// all beside it), so the noise is taken at least the smaller level, min(|L_A|, |L_B|): a value
// must also dwarf the other half's level by the bound. The half of larger magnitude is the
// implausible one: a legitimate half carries its own variance, so z is that large only when
// the other half's value dwarfs it. It is rebuilt as a non-finite pixel is: from the other
// half, left out of every statistic, of the sources, and of the energy return. A variance of 0
// in either half says nothing (one sample a half, or no variance written): no test there; at
// one sample a half the level floor alone would call a bright emitter's edge (the sun's 1e5
// beside a sky of 1e-3) implausible.
// Not found: a tile whose variance is wrong with its colour (a tile scaled 10x with 100x the
// variance stays within the t's tail, and is judged as fireflies are); garbage where the other
// half is unusable too (NaN, black) at the same pixel: it is the only value there, and a NaN or
// black pixel of the other half is rebuilt from it.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "floating_point.hpp"

namespace firefly::detail {

// The frame's bound on z: 2 m / (pi alpha), m the pixels (or pixel-buffers) tested.
inline double implausible_bound(std::size_t pixels, double alpha) noexcept {
    const double a = alpha > 0 && alpha < 1 ? alpha : 0.05;
    return 2.0 * static_cast<double>(pixels > 0 ? pixels : 1) / (3.14159265358979323846 * a);
}

// Which half holds an implausible value at a pixel (0 or 1), or -1 for none. la, lb: the
// halves' mean colours (finite); va, vb: their reduced variances (finite, >= 0). Taken without
// overflow for values near DBL_MAX: the difference of halves against the noise, each halved.
inline int implausible_half(double la, double lb, double va, double vb, double bound) noexcept {
    if (!(va > 0) || !(vb > 0)) return -1;
    const double half_gap = std::fabs(0.5 * la - 0.5 * lb);
    const double v = va + vb;  // (hypot only where the sum overflows: it is slow)
    const double sd = v <= DBL_MAX ? std::sqrt(v) : std::hypot(std::sqrt(va), std::sqrt(vb));
    const double half_noise = 0.5 * (std::max)(sd, (std::min)(std::fabs(la), std::fabs(lb)));
    if (!(half_gap > bound * half_noise)) return -1;
    return std::fabs(la) >= std::fabs(lb) ? 0 : 1;
}

// K buffers (buffers.hpp): the same test of buffers against the others. The usable buffers
// (use[i]) ranked by magnitude, largest first (by value among equal magnitudes, then by
// variance: the same ranks in any buffer order); as in the step-down of buffers.hpp, for i
// from floor(u / 2) down to 1 the i-th, level l, against R, the ones ranked below it
// (n = |R| >= 2, mean m), where the i-th's magnitude is above the next one's (a tie cut in two
// would make the result depend on the buffers' order):
//     z = |l - m| / max(noise, |m|)
// the noise that of l - m: with the i-th buffer's variance known (rel_var[i] l^2, a variance of
// the mean), sqrt(v + mean_R(v) / n) over R's known variances, as for two halves (a firefly's
// own variance holds it, far below any bound); without it (seed renders: rel_var NaN), R's
// spread, s_R sqrt(1 + 1 / n) (nothing then holds a firefly's own noise, and over renders that
// agree to the bit a firefly would pass: the level floor |m| keeps it). Bound: `bound`
// (implausible_bound over pixels x K: the largest of K at each pixel; 2.3e8 for a 2K frame of 8
// buffers at alpha = 0.05) times C(u, i - 1), Bonferroni over the buffers set aside above the
// i-th (two tiles of the same garbage in two buffers are found together). The first i that
// passes takes the top i, returned as bits (0: none). A known variance of 0 of the i-th says
// nothing (as for two halves), and no noise at all (R in exact agreement at level 0): no test.
inline std::uint64_t implausible_buffers(const double* level, const double* rel_var, const bool* use, int k,
                                         double bound) noexcept {
    // Most pixels: levels of one sign within the bound of each other, where no step can pass
    // (the noise is at least R's level, which is at least the least level)
    double lo = HUGE_VAL, hi = 0;
    bool positive = true;
    for (int i = 0; i < k && i < 64; ++i)
        if (use[i]) lo = (std::min)(lo, level[i]), hi = (std::max)(hi, level[i]), positive = positive && level[i] > 0;
    if (positive && hi <= bound * lo) return 0;
    int rank[64], u = 0;
    auto above = [&](int a, int b) {  // a ranks before b
        const double ma = std::fabs(level[a]), mb = std::fabs(level[b]);
        if (ma != mb) return ma > mb;
        if (level[a] != level[b]) return level[a] > level[b];
        // Equal levels by variance, unknown first: the last of a tie (the i-th, whose variance
        // the test reads) has the largest known one, whatever the buffers' order.
        return std::isnan(rel_var[a]) ? !std::isnan(rel_var[b]) : rel_var[a] < rel_var[b];
    };
    for (int i = 0; i < k && i < 64; ++i) {  // insertion, largest first
        if (!use[i]) continue;
        int j = u++;
        for (; j > 0 && above(i, rank[j - 1]); --j) rank[j] = rank[j - 1];
        rank[j] = i;
    }
    auto half_var = [&](int i) { return rel_var[i] * (0.5 * level[i]) * (0.5 * level[i]); };  // of 0.5 l
    for (int i = u / 2; i >= 1; --i) {
        const int n = u - i;  // |R|
        const int c = rank[i - 1];
        const double vc = half_var(c);
        if (n < 2 || vc == 0 || !(std::fabs(level[c]) > std::fabs(level[rank[i]]))) continue;
        double sum = 0, ss = 0, vr = 0;  // of the halved levels of R (no overflow near DBL_MAX)
        int known = 0;
        for (int j = i; j < u; ++j) {
            sum += 0.5 * level[rank[j]];
            const double v = half_var(rank[j]);
            if (v >= 0) vr += v, ++known;
        }
        const double mean = sum / n;
        for (int j = i; j < u; ++j) ss += (0.5 * level[rank[j]] - mean) * (0.5 * level[rank[j]] - mean);
        const double noise = vc >= 0 ? std::sqrt(vc + (known > 0 ? vr / known / n : 0.0))
                                     : std::sqrt(ss / (n - 1)) * std::sqrt(1.0 + 1.0 / n);
        const double half_noise = (std::max)(noise, std::fabs(mean));
        double limit = bound;  // times C(u, i - 1)
        for (int j = 0; j < i - 1; ++j) limit *= static_cast<double>(u - j) / (j + 1);
        if (!(half_noise > 0) || !(std::fabs(0.5 * level[c] - mean) > limit * half_noise)) continue;
        std::uint64_t bits = 0;
        for (int j = 0; j < i; ++j) bits |= std::uint64_t{1} << rank[j];
        return bits;
    }
    return 0;
}

}  // namespace firefly::detail
