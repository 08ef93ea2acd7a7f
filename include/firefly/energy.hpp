// firefly: the energy a firefly removal takes away, returned where it belongs.
//
// A firefly is a rare, huge sample, but not a wrong one: its path carries real light, and a
// converged render holds that light as a smooth glow over the region where such paths land
// (a caustic, the bounce light of a small lamp). Removing fireflies lowers the noise and biases
// the image low by the fireflies' expected share. Where fireflies are dense, that share is
// large (half of a caustic's light can arrive as fireflies) and it can be estimated from the
// removed energy itself: spread over a neighbourhood, the removed excess is an estimate of the
// fireflies' local contribution, noisy where few fireflies fell and good where many did.
//
// Model: the fireflies' contribution at p is a local ratio times the pixel's radiance (light
// that arrives along rare paths lands where the image is bright, in proportion). With e the
// removed excess per pixel and channel, P the 3x3 median of the image the caller gives (the
// K-buffer detector gives the input's mean: the median drops lone fireflies and keeps where
// they fall densely, as in a caustic lit mostly by them), G a Gaussian of sigma pixels
// (normalised weights w):
//     M = G * e,  L = G * P,  ratio = min(M / L, 1),  returned(p) = s(p) ratio(p) P(p)
// s is the positive-part James-Stein factor of M: V = sum_q w_q^2 e_q^2 (channel sums) is the
// variance M would have if each e_q were one draw of a sparse process, so
//     s = max(0, 1 - V / |M|^2)
// keeps M where many fireflies agree on it and drops it where one or two make it up: a lone
// firefly (V = |M|^2) returns nothing, so no glow is painted around it. The sum over q of
// w_q^2 e_q^2 is an exact Gaussian blur at sigma / sqrt(2) of e^2, rescaled.
//
// Every blur sums opposite taps first (v[-i] + v[+i]): a flipped frame gives the flipped
// result bit for bit. Arithmetic in double: a 1e30 excess squared stays finite.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "image_view.hpp"
#include "parallel.hpp"

namespace firefly {

namespace detail {

// Normalised 1-D Gaussian weights w[0..r] (w[i] for offsets +-i); r = 3 sigma unless given.
inline std::vector<double> gaussian_weights(double sigma, int r = 0) {
    if (r <= 0) r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
    std::vector<double> w(static_cast<std::size_t>(r) + 1);
    double sum = 0;
    for (int i = 0; i <= r; ++i) {
        w[static_cast<std::size_t>(i)] = std::exp(-0.5 * i * i / (sigma * sigma));
        sum += i == 0 ? w[0] : 2.0 * w[static_cast<std::size_t>(i)];
    }
    for (double& v : w) v /= sum;
    return w;
}

// The pass along x: each row copied into a zero-padded line (outside the frame counts as 0),
// then k0 v[j] + sum over d of k_d (v[j - d] + v[j + d]) for every channel of the row at once
// (d outermost: the inner loop is contiguous and vectorises). Rows as tasks on the executor.
inline void blur_along_x(const double* in, double* out, int w, int h, int nch, const std::vector<double>& k,
                      const executor& exec) {
    const int r = static_cast<int>(k.size()) - 1;
    const std::size_t row = static_cast<std::size_t>(w) * static_cast<std::size_t>(nch);
    const std::size_t margin = static_cast<std::size_t>(r) * static_cast<std::size_t>(nch);
    exec.run(static_cast<std::size_t>(h), [&](std::size_t y) {
        const double* src = in + y * row;
        double* dst = out + y * row;
        std::vector<double> pad(row + 2 * margin, 0.0);
        std::copy(src, src + row, pad.begin() + static_cast<std::ptrdiff_t>(margin));
        const double* p = pad.data() + margin;
        for (std::size_t j = 0; j < row; ++j) dst[j] = k[0] * p[j];
        for (int d = 1; d <= r; ++d) {
            const std::size_t off = static_cast<std::size_t>(d) * static_cast<std::size_t>(nch);
            const double kd = k[static_cast<std::size_t>(d)];
            for (std::size_t j = 0; j < row; ++j) dst[j] += kd * (p[j - off] + p[j + off]);
        }
    });
}

// The pass along y, a whole row at a time (contiguous: it vectorises, where a column's
// stride would not); the same sums in the same order as along x.
inline void blur_along_y(const double* in, double* out, int w, int h, int nch, const std::vector<double>& k,
                      const executor& exec) {
    const int r = static_cast<int>(k.size()) - 1;
    const std::size_t row = static_cast<std::size_t>(w) * static_cast<std::size_t>(nch);
    exec.run(static_cast<std::size_t>(h), [&](std::size_t yy) {
        const int y = static_cast<int>(yy);
        double* dst = out + yy * row;
        const double* mid = in + yy * row;
        for (std::size_t i = 0; i < row; ++i) dst[i] = k[0] * mid[i];
        for (int d = 1; d <= r; ++d) {
            const double* lo = y - d >= 0 ? in + static_cast<std::size_t>(y - d) * row : nullptr;
            const double* hi = y + d < h ? in + static_cast<std::size_t>(y + d) * row : nullptr;
            const double kd = k[static_cast<std::size_t>(d)];
            if (lo && hi)
                for (std::size_t i = 0; i < row; ++i) dst[i] += kd * (lo[i] + hi[i]);
            else if (lo || hi) {
                const double* p = lo ? lo : hi;
                for (std::size_t i = 0; i < row; ++i) dst[i] += kd * (p[i] + 0.0);
            }
        }
    });
}

inline void gaussian_blur(std::vector<double>& v, std::vector<double>& tmp, int w, int h, int nch,
                          const std::vector<double>& k, const executor& exec) {
    tmp.resize(v.size());
    blur_along_x(v.data(), tmp.data(), w, h, nch, k, exec);
    blur_along_y(tmp.data(), v.data(), w, h, nch, k, exec);
}

// Median of 9 values by the 19-exchange network (Paeth): p[4] ends as the median.
inline double median9(double* p) noexcept {
    auto sort2 = [](double& a, double& b) {
        const double lo = std::min(a, b), hi = std::max(a, b);
        a = lo;
        b = hi;
    };
    sort2(p[1], p[2]), sort2(p[4], p[5]), sort2(p[7], p[8]), sort2(p[0], p[1]), sort2(p[3], p[4]);
    sort2(p[6], p[7]), sort2(p[1], p[2]), sort2(p[4], p[5]), sort2(p[7], p[8]), sort2(p[0], p[3]);
    sort2(p[5], p[8]), sort2(p[4], p[7]), sort2(p[3], p[6]), sort2(p[1], p[4]), sort2(p[2], p[5]);
    sort2(p[4], p[7]), sort2(p[4], p[2]), sort2(p[6], p[4]), sort2(p[4], p[2]);
    return p[4];
}

// 3x3 median of each of 3 interleaved channels (the frame's edge: the pixels inside it, the
// mean of the middle two where they are even in number). Values are finite.
inline void median3x3(const std::vector<double>& in, std::vector<double>& out, int w, int h, const executor& exec) {
    out.resize(in.size());
    auto at = [w](int x, int y, int c) {
        return (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c);
    };
    exec.run(static_cast<std::size_t>(h), [&](std::size_t row) {
        const int y = static_cast<int>(row);
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                double t[9] = {};
                int n = 0;
                for (int yy = std::max(0, y - 1); yy <= std::min(h - 1, y + 1); ++yy)
                    for (int xx = std::max(0, x - 1); xx <= std::min(w - 1, x + 1); ++xx) t[n++] = in[at(xx, yy, c)];
                if (n == 9) {
                    out[at(x, y, c)] = median9(t);
                    continue;
                }
                std::nth_element(t, t + n / 2, t + n);
                double m = t[n / 2];
                if (n % 2 == 0) m = 0.5 * (m + *std::max_element(t, t + n / 2));  // mean of the middle two
                out[at(x, y, c)] = m;
            }
    });
}

}  // namespace detail

// Frame-sized work arrays of the energy return, kept between frames.
struct energy_scratch {
    std::vector<double> profile, m, l, v, tmp;
    std::vector<double> excess, shape, returned;  // return_energy_to_image
    std::size_t bytes() const noexcept {
        return (profile.capacity() + m.capacity() + l.capacity() + v.capacity() + tmp.capacity() +
                excess.capacity() + shape.capacity() + returned.capacity()) *
               sizeof(double);
    }
};

// The energy to add back per pixel and channel (3 interleaved channels, w x h), from the
// removed excess `excess` (0 where nothing was removed) and the image whose 3x3 median shapes
// the return, `shape` (3 channels, finite, >= 0). Writes `returned` (same layout). sigma: the
// Gaussian's width in pixels.
inline void energy_return(const std::vector<double>& excess, const std::vector<double>& shape, int w, int h,
                          double sigma, std::vector<double>& returned, energy_scratch& s, const executor& exec) {
    const std::size_t np = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    const std::vector<double> k = detail::gaussian_weights(sigma);
    // the squared weights' kernel over the same support: V is then exact at every offset
    // where M is not 0 (a lone firefly: V = |M|^2 everywhere)
    const std::vector<double> k2 = detail::gaussian_weights(sigma / std::sqrt(2.0), static_cast<int>(k.size()) - 1);
    // sum w_q^2 x_q = (S2 / S^2)^2 (G' * x) in 2-D, S and S2 the unnormalised 1-D sums of
    // the two kernels (w = g / S, w^2 = g' / S^2 with g' the sigma / sqrt(2) kernel, = G' S2 / S^2).
    double s1 = 0, s2 = 0;
    for (std::size_t i = 0; i < k.size(); ++i) s1 += (i ? 2.0 : 1.0) * std::exp(-0.5 * double(i * i) / (sigma * sigma));
    for (std::size_t i = 0; i < k2.size(); ++i) s2 += (i ? 2.0 : 1.0) * std::exp(-double(i * i) / (sigma * sigma));
    const double scale = (s2 / (s1 * s1)) * (s2 / (s1 * s1));
    detail::median3x3(shape, s.profile, w, h, exec);
    s.m = excess;
    s.l = s.profile;
    s.v.resize(np);
    for (std::size_t p = 0; p < np; ++p)
        s.v[p] = excess[p * 3] * excess[p * 3] + excess[p * 3 + 1] * excess[p * 3 + 1] + excess[p * 3 + 2] * excess[p * 3 + 2];
    detail::gaussian_blur(s.m, s.tmp, w, h, 3, k, exec);
    detail::gaussian_blur(s.l, s.tmp, w, h, 3, k, exec);
    detail::gaussian_blur(s.v, s.tmp, w, h, 1, k2, exec);
    // The ratio is capped at 1: the return never exceeds the shape's own level. Where the
    // removed light outweighs the rest the fireflies are no longer rare, the shape (a median
    // of few noisy values) is mostly their noise, and scaling it up multiplies that noise
    // (simulated dense fireflies at 4 samples a buffer: 2.4x the error of no return).
    constexpr double max_ratio = 1.0;
    returned.assign(np * 3, 0.0);
    for (std::size_t p = 0; p < np; ++p) {
        const double* m = &s.m[p * 3];
        const double m2 = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
        const double keep = m2 > 0 ? 1.0 - s.v[p] * scale / m2 : 0.0;
        // a lone firefly gives keep = 0 up to rounding (1e-9: far above it, far below any
        // second firefly's share); nothing removed nearby gives m2 = 0
        if (!(keep > 1e-9) || !std::isfinite(m2)) continue;
        for (int c = 0; c < 3; ++c) {
            const double l = s.l[p * 3 + static_cast<std::size_t>(c)];
            const double add = l > 0 ? keep * std::min(m[c] / l, max_ratio) * s.profile[p * 3 + static_cast<std::size_t>(c)] : 0.0;
            returned[p * 3 + static_cast<std::size_t>(c)] = std::isfinite(add) && add > 0 ? add : 0.0;
        }
    }
}

// What one cleaned image gave and got back.
struct energy_totals {
    double removed = 0, returned = 0;  // sums over pixels of the mean colour channel
};

// The energy return on one cleaned image (the first three channels of `color`): pixel
// rebuilt[e] held before[3 e .. 3 e + 2] before it was rebuilt. The return is added where it
// exceeds the pixel's standard error, sqrt(variance_scale x the mean of its variance
// channels), and never where keep[p] is false (black background, alpha 0).
template <class C, class V>
energy_totals return_energy_to_image(const image_view<C>& color, const image_view<V>& variance, double variance_scale,
                                     const std::uint32_t* rebuilt, const float* before, std::size_t n,
                                     const std::uint8_t* keep, double sigma, energy_scratch& s, const executor& exec) {
    energy_totals t;
    const int w = color.width(), h = color.height();
    if (color.channels() < 3) return t;
    const std::size_t np = color.pixel_count();
    s.excess.assign(np * 3, 0.0);
    for (std::size_t e = 0; e < n; ++e) {
        const int x = static_cast<int>(rebuilt[e] % static_cast<std::uint32_t>(w));
        const int y = static_cast<int>(rebuilt[e] / static_cast<std::uint32_t>(w));
        for (int c = 0; c < 3; ++c) {
            const double d = static_cast<double>(before[e * 3 + static_cast<std::size_t>(c)]) - color.load(x, y, c);
            s.excess[static_cast<std::size_t>(rebuilt[e]) * 3 + static_cast<std::size_t>(c)] = std::isfinite(d) && d > 0 ? d : 0.0;
        }
    }
    s.shape.resize(np * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c);
                const double v = color.load(x, y, c) + s.excess[i];
                s.shape[i] = std::isfinite(v) && v > 0 ? v : 0.0;
            }
    energy_return(s.excess, s.shape, w, h, sigma, s.returned, s, exec);
    const int nv = variance.channels() == 1 ? 1 : 3;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t p = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
            const double* add = &s.returned[p * 3];
            t.removed += (s.excess[p * 3] + s.excess[p * 3 + 1] + s.excess[p * 3 + 2]) / 3.0;
            double var = 0;
            for (int c = 0; c < nv; ++c) var += std::max(static_cast<double>(variance.load(x, y, c)), 0.0) / nv;
            const double mean_add = (add[0] + add[1] + add[2]) / 3.0;
            if (!keep[p] || !(mean_add > std::sqrt(variance_scale * var))) continue;
            for (int c = 0; c < 3; ++c) color.store(x, y, c, color.load(x, y, c) + add[c]);
            t.returned += mean_add;
        }
    return t;
}

}  // namespace firefly
