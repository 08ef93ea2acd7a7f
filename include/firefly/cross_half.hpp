// firefly: rebuilding a pixel that is bad in one half only from the other half.
//
// A firefly (or a NaN) in half A at pixel p leaves half B's value at p untouched: B(p) is an
// unbiased estimate of the pixel with a known variance vB. The spatial estimate S, the
// Gaussian mean of A's neighbours, has a variance of its own (sum w_i^2 vA_i / W^2) and a
// bias wherever the image has detail. The bias can be judged without a reference: the same
// weights over B's neighbours give S_B, and B(p) - S_B has expectation -bias and variance
// vB + var(S_B), both halves being independent images of one scene. So
//
//   MSE(S) ~ var(S) + max(0, (S_B - B(p))^2 - vB - var(S_B))     (channel sums)
//
// The frame's final pixel is (A' + B) / 2. With A' = a S + (1 - a) B(p) its expected error is
// (a^2 MSE(S) + (2 - a)^2 vB) / 4, least at a = 2 vB / (MSE(S) + vB), clamped to [0, 1]:
// the spatial estimate is used where it lowers the expected error of the frame, and in
// detail and at edges A' is B(p) itself or close to it.
// The stored variance of A' is its own: a^2 MSE(S) + (1 - a)^2 vB (per channel). Note that
// A' and B are then correlated, so (vA + vB) / 4 understates the final pixel's variance
// there; the masks mark these pixels (mask_bits::other_half).
//
// Tried: vB floored where a half drew low from heavy-tailed samples (its variance then low
// too), by the neighbourhood's noise as the detector's noise_floor judges it: the Cycles
// interior 0.1130 -> 0.1125, the simulated interior 0.0185 -> 0.0184, the other scenes within
// 0.1%, for a neighbourhood's statistics per rebuilt pixel; not taken.
//
// Variances here are variances of the pixel mean: the renderer's variance times the frame's
// calibration factor (highlight.hpp), and back again when stored.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <type_traits>

#include "image_view.hpp"
#include "kernel.hpp"

namespace firefly {

// One half's colour and variance, read-only, for the estimate.
template <class C, class V>
struct half_views {
    image_view<const C> color;
    image_view<const V> variance;
};

namespace detail {

// The spatial weight a = 2 vB / (MSE(S) + vB), clamped to [0, 1], from the normalised sums
// (s, vs: the spatial half's channels, then the other half's) and the other half's pixel
// (xo, vo); bias_term: a^2 times the squared bias, per channel in renderer units.
inline double spatial_weight(const double* s, const double* vs, const double* xo, const double* vo, int nc, int nv,
                             double calibration, double& bias_term) noexcept {
    const int nd = nc < 3 ? nc : 3;  // colour channels that decide (a 4th is carried along)
    double v_other = 0, var_s = 0, miss = 0;  // channel sums, variances of the mean
    for (int c = 0; c < nd; ++c) {
        const int j = nv == 1 ? 0 : c;
        const double d = s[nc + c] - xo[c];
        v_other += calibration * vo[j];
        var_s += calibration * vs[j];
        miss += d * d - calibration * (vo[j] + vs[nv + j]);
    }
    const double mse_s = var_s + (std::max)(miss, 0.0);
    const double den = mse_s + v_other;
    double a = den > 0 && std::isfinite(den) ? (std::min)(1.0, 2.0 * v_other / den) : 0.0;
    if (!(a >= 0)) a = 0.0;
    // a^2 miss / (nd calibration), taken in this order: the squared bias alone may overflow (a
    // calibration of 1e-8, a bias of 1e151) where a is ~1e-186 and a^2 underflows, and 0 x Inf
    // was a NaN variance. a (a miss) <= miss, and a^2 miss <= v_other, so every step is finite.
    bias_term = a * (a * (std::max)(miss, 0.0)) / (nd * calibration);
    return a;
}

// The estimate of pixel (x, y) of half `own` from the other half. readable(xx, yy): the
// neighbour is a clean pixel in both halves; readable_other: in the other half. blend = false: the other half's value alone.
// out: colour channels, then variance channels. Returns the spatial weight a.
template <class C, class V, class Readable, class ReadableOther>
double cross_half_estimate(const half_views<C, V>& own, const half_views<C, V>& other, const gaussian_kernel& kernel,
                           double calibration, bool blend, int x, int y, Readable&& readable,
                           ReadableOther&& readable_other, double* out) {
    const int nc = own.color.channels(), nv = own.variance.channels();
    double xo[4], vo[4];
    for (int c = 0; c < nc; ++c) xo[c] = other.color.load(x, y, c);
    for (int c = 0; c < nv; ++c) vo[c] = (std::max)(other.variance.load(x, y, c), 0.0);
    double a = 0.0, bias_term = 0.0;  // bias_term: a^2 times the squared bias, per channel
    double s[8] = {}, vs[8] = {};  // [0, n): own half, [n, 2n): other half
    // Both halves' channels side by side; RGB (6 values) at compile time. `mine` is the half
    // the spatial estimate comes from: the own half, or the other one where no neighbour of
    // the own half is clean (a failed bucket): then S is the other half's S_B, independent
    // of B(p) all the same.
    // Each value times `scale` (unscaled, or overflow_scale where the plain sums overflowed).
    auto sums = [&](auto nc_const, auto nv_const, const half_views<C, V>& mine, auto&& can_read, auto scale) {
        constexpr int NC = decltype(nc_const)::value, NV = decltype(nv_const)::value;
        const int w = own.color.width(), h = own.color.height();
        return kernel_sum_1_2<NC, NV>(
            kernel, x, y, w, h, 2 * nc, 2 * nv, can_read,
            [&](int xx, int yy, double* v) {
                for (int c = 0; c < nc; ++c)
                    v[c] = mine.color.load(xx, yy, c) * scale, v[nc + c] = other.color.load(xx, yy, c) * scale;
            },
            [&](int xx, int yy, double* v) {
                for (int c = 0; c < nv; ++c)
                    v[c] = (std::max)(mine.variance.load(xx, yy, c), 0.0) * scale,
                    v[nv + c] = (std::max)(other.variance.load(xx, yy, c), 0.0) * scale;
            },
            s, vs);
    };
    auto sums_for = [&](const half_views<C, V>& mine, auto&& can_read, auto scale) {
        using I0 = std::integral_constant<int, 0>;
        using I2 = std::integral_constant<int, 2>;
        using I6 = std::integral_constant<int, 6>;
        return nc == 3 && nv == 3   ? sums(I6{}, I6{}, mine, can_read, scale)
               : nc == 3 && nv == 1 ? sums(I6{}, I2{}, mine, can_read, scale)
                                    : sums(I0{}, I0{}, mine, can_read, scale);
    };
    if (blend) {
        bool from_own = true;
        double wsum = sums_for(own, readable, unscaled{});
        if (!(wsum > 0)) from_own = false, wsum = sums_for(other, readable_other, unscaled{});
        if (wsum > 0) {
            const bool rescaled = !(all_finite(s, 2 * nc) && all_finite(vs, 2 * nv));
            if (rescaled) {  // double values near DBL_MAX
                std::fill(s, s + 8, 0.0);
                std::fill(vs, vs + 8, 0.0);
                if (from_own) (void)sums_for(own, readable, overflow_scale);
                else (void)sums_for(other, readable_other, overflow_scale);
            }
            for (int c = 0; c < 2 * nc; ++c) s[c] = rescaled ? from_overflow_scale(s[c] / wsum) : s[c] / wsum;
            for (int c = 0; c < 2 * nv; ++c)
                vs[c] = rescaled ? from_overflow_scale(vs[c] / (wsum * wsum)) : vs[c] / (wsum * wsum);
            a = spatial_weight(s, vs, xo, vo, nc, nv, calibration, bias_term);
        }
    }
    // (Held within the finite range: the blend of two values near DBL_MAX may round past it.)
    for (int c = 0; c < nc; ++c) out[c] = a > 0 ? std::clamp(a * s[c] + (1 - a) * xo[c], -DBL_MAX, DBL_MAX) : xo[c];
    for (int c = 0; c < nv; ++c)
        out[nc + c] = a > 0 ? (std::min)(a * a * vs[c] + bias_term + (1 - a) * (1 - a) * vo[c], DBL_MAX) : vo[c];
    return a;
}

}  // namespace detail
}  // namespace firefly
