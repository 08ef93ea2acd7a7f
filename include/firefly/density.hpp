// firefly: the finest scale of the energy return: the removed light given back where it fell,
// as the density of the removed samples themselves, where both halves' samples agree on it.
//
// Light that reaches a region through rare paths only (a small light far out of focus seen as
// a bokeh disc, a caustic lit by fireflies, fireflies dense enough to be most of the light)
// arrives as single samples far above their pixel: sample by sample such a region is made of
// fireflies, and they are removed. The energy return (energy.hpp) gives their light back over
// its wider scales in the shape of the image, at most that image's own level: where the rare
// light is most of it, the light comes back as a faint halo, and a disc lit through 1% of its
// samples lost 0.2 of its light at 64 samples a half and 0.9 at 8 (bench/renders/README.md).
// Where such samples are dense, their own density is the region's shape: with e_h the excess
// removed from half h per pixel, G a Gaussian of sigma 2 (9 x 9, normalised), E = e_A + e_B
// the two halves' excess pooled and C the cleaned halves' sum,
//     M_h = G * e_h,  M = M_A + M_B,  V = G^2 * |E|^2,  L = G * C
//     s = max(0, 1 - c V / |M|^2) max(0, 1 - sum(L) / sum(M))
// and half h gets s M_h at every pixel. The first factor is the return's James-Stein factor
// with the evidence c asked of it: |M|^2 / V is the number of equal removed samples the
// window's sum is worth, so it is > 0 only where more than c of them agree (c = 8). Pooled over
// both halves, light that both halves see counts its samples twice, while a chance cluster of
// fireflies in one half counts once. The second keeps the part above the cleaned level, which
// the wider scales cannot give back (their ratio is capped at 1); below it they do, with less
// noise (with the first factor alone, dense10 after NL-means 0.00046 -> 0.0031). The part of
// each removed sample the density took, f(q) = sum_p w_pq s(p), is withheld from the wider
// scales, which return the rest (1 - f) e: the total given back is the total removed.
// Measured (relMSE before a denoiser, then after NL-means): dense30 0.251 -> 0.076 and 0.109 ->
// 0.0070, recall 0.984 -> 0.991; dense10 0.0297 -> 0.0235; the simulated caustics 0.0275 ->
// 0.0314 but after NL-means 0.0664 -> 0.0465 (its cores are lit by fireflies, whose density is
// noisier than the wider scales, which a denoiser averages); the held-out bokeh render at 64
// and 8 samples a half 0.0149 -> 0.0132 and 0.0388 -> 0.0289; the Cycles caustics 0.02426 ->
// 0.02449; every other scene and the Cycles interior unchanged to 4 digits. Its cost is
// the 9 x 9 sums at every pixel of a dense frame: dense30 755 -> 1281 ms at 1024x540.
//
// A pixel gets no density light where either half kept an outlier (a highlight, or one within
// its noise: it holds its light already), where it is ignored (black, alpha 0), and a rebuilt
// pixel at most f e of what its rebuild took (the wider scales' cap takes the rest).
//
// Sums: the window's 81 taps fall into orbits of the frame's 8 flips and transposes (offsets
// (a, b), (b, a) and their signs share one weight), and each orbit's values are added in a tree
// that every symmetry maps onto itself, so a flipped or transposed frame gives the flipped or
// transposed result bit for bit; orbits are added in a fixed order. A window with no more than
// c removed pixels cannot pass (|M|^2 <= N V for N terms, Cauchy-Schwarz): an integral image of
// the removed pixels skips those windows exactly, so a frame of sparse fireflies costs a pass
// of counts. Memory: 5 bytes a pixel for the flags and counts; where some window passes, 28
// more (both halves' excess, the level, the factors) and the list of pixels given light.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "parallel.hpp"

namespace firefly {
namespace detail {

inline constexpr int density_radius = 4;  // 9 x 9, sigma 2

// The orbit weights w(a, b), 0 <= b <= a <= radius, normalised over the whole window.
struct density_weights {
    double w[density_radius + 1][density_radius + 1] = {};
    density_weights() {
        double z = 0;
        for (int dy = -density_radius; dy <= density_radius; ++dy)
            for (int dx = -density_radius; dx <= density_radius; ++dx) z += std::exp(-(dx * dx + dy * dy) / 8.0);
        for (int a = 0; a <= density_radius; ++a)
            for (int b = 0; b <= a; ++b) w[a][b] = std::exp(-(a * a + b * b) / 8.0) / z;
    }
};

// The sum of v over the orbit of offset (a, b), 0 <= b <= a, in a tree each of the 8
// symmetries maps onto itself. v(dx, dy, out) writes N values (0 outside the frame); out: N.
template <int N, class V>
inline void orbit_sum(int a, int b, V&& v, double* out) {
    double t[8][N];
    auto pair = [&](int i, int j, double* r) {
        for (int k = 0; k < N; ++k) r[k] = t[i][k] + t[j][k];
    };
    if (a == 0) {
        v(0, 0, out);
        return;
    }
    double p[4][N];
    if (b == 0 || a == b) {
        // (a, 0): x pair and y pair; (a, a): the two diagonals
        if (b == 0) v(a, 0, t[0]), v(-a, 0, t[1]), v(0, a, t[2]), v(0, -a, t[3]);
        else v(a, a, t[0]), v(-a, -a, t[1]), v(-a, a, t[2]), v(a, -a, t[3]);
        pair(0, 1, p[0]), pair(2, 3, p[1]);
        for (int k = 0; k < N; ++k) out[k] = p[0][k] + p[1][k];
        return;
    }
    v(a, b, t[0]), v(-a, b, t[1]), v(a, -b, t[2]), v(-a, -b, t[3]);  // S: pairs by the sign of x
    v(b, a, t[4]), v(b, -a, t[5]), v(-b, a, t[6]), v(-b, -a, t[7]);  // T: by the sign of y
    pair(0, 1, p[0]), pair(2, 3, p[1]), pair(4, 5, p[2]), pair(6, 7, p[3]);
    for (int k = 0; k < N; ++k) out[k] = (p[0][k] + p[1][k]) + (p[2][k] + p[3][k]);
}

// The Gaussian-weighted sums over the window of (x, y): values v (N of them) with weight w,
// and, when SQ >= 0, value SQ with weight w^2 instead.
template <int N, int SQ, class V>
inline void window_sums(const density_weights& dw, V&& v, double* out) {
    for (int k = 0; k < N; ++k) out[k] = 0;
    double o[N];
    for (int a = 0; a <= density_radius; ++a)
        for (int b = 0; b <= a; ++b) {
            orbit_sum<N>(a, b, v, o);
            for (int k = 0; k < N; ++k) out[k] += (k == SQ ? dw.w[a][b] * dw.w[a][b] : dw.w[a][b]) * o[k];
        }
}

}  // namespace detail

// Work arrays of the density scale, kept between frames.
struct density_scratch {
    std::vector<std::uint8_t> removed;  // 1 where either half had excess removed
    std::vector<std::uint32_t> count;  // integral image of removed pixels, (w + 1) x (h + 1)
    std::vector<float> excess[2];      // per half, 3 per pixel
    std::vector<float> level;          // the cleaned halves' sum, 3 per pixel
    std::vector<float> factor;         // s per pixel
    std::size_t bytes() const noexcept {
        return removed.capacity() + count.capacity() * sizeof(std::uint32_t) +
               (excess[0].capacity() + excess[1].capacity() + level.capacity() + factor.capacity()) * sizeof(float);
    }
};

// The density return of both halves. The caller marks removed (1 per pixel, w x h, zeroed by
// prepare()) where either half had excess removed; where needed() (the arrays sized then)
// fills excess[h] (3 per pixel, >= 0) with what the rebuild removed from half h and level (3
// per pixel) with the cleaned halves' sum. run() lists the light to give each half;
// taken(x, y) then is the share f of the pixel's removed excess given.
class density_return {
public:
    // removed zeroed, w x h.
    void prepare(int w, int h, density_scratch& s) {
        w_ = w, h_ = h;
        s.removed.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
    }

    // One pixel's light for each half (in renderer units, >= 0).
    struct light {
        std::uint32_t pixel;
        float add[2][3];
    };

    // Whether any window holds more than `evidence` removed pixels (else nothing can pass),
    // from the excess filled in; the level is needed, and run() worth calling, only then.
    bool needed(double evidence, density_scratch& s) {
        s_ = &s;
        if (!(evidence > 0 && w_ > 0 && h_ > 0 && count_removed(evidence))) return false;
        const std::size_t n = s.removed.size() * 3;
        for (auto& e : s.excess) e.assign(n, 0.0f);
        s.level.assign(n, 0.0f);
        return true;
    }

    // The pixels that get light, row-major, in `out` (after needed() and the level filled in);
    // false when none.
    bool run(double evidence, density_scratch& s, std::vector<light>& out, const executor& exec) {
        s_ = &s;
        out.clear();
        if (!(evidence > 0) || w_ <= 0 || h_ <= 0) return false;
        s.factor.assign(static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_), 0.0f);
        constexpr int band = 16;
        std::vector<std::vector<light>> bands(static_cast<std::size_t>((h_ + band - 1) / band));
        exec.run(bands.size(), [&](std::size_t bi) {
            for (int y = static_cast<int>(bi) * band; y < std::min(h_, static_cast<int>(bi + 1) * band); ++y)
                for (int x = 0; x < w_; ++x) pixel(x, y, evidence, bands[bi]);
        });
        for (const auto& b : bands) out.insert(out.end(), b.begin(), b.end());
        return !out.empty();
    }

    // The share of pixel (x, y)'s removed excess that the density gave back: sum_p w_pq s(p).
    double taken(int x, int y) const {
        double f = 0;
        detail::window_sums<1, -1>(weights_, [&](int dx, int dy, double* v) {
            const int xx = x + dx, yy = y + dy;
            v[0] = inside(xx, yy) ? s_->factor[index(xx, yy)] : 0.0;
        }, &f);
        return std::min(f, 1.0);
    }

private:
    bool inside(int x, int y) const noexcept { return x >= 0 && y >= 0 && x < w_ && y < h_; }
    std::size_t index(int x, int y) const noexcept {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
    }

    // The integral image of pixels with removed excess in either half; false when no window
    // holds more than `evidence` of them (nothing can pass).
    bool count_removed(double evidence) {
        const std::size_t W = static_cast<std::size_t>(w_) + 1;
        std::vector<std::uint32_t>& c = s_->count;
        c.assign(W * (static_cast<std::size_t>(h_) + 1), 0);
        for (int y = 0; y < h_; ++y) {
            std::uint32_t row = 0;
            for (int x = 0; x < w_; ++x) {
                row += s_->removed[index(x, y)] != 0;
                c[(static_cast<std::size_t>(y) + 1) * W + static_cast<std::size_t>(x) + 1] =
                    c[static_cast<std::size_t>(y) * W + static_cast<std::size_t>(x) + 1] + row;
            }
        }
        for (int y = 0; y < h_; ++y)
            for (int x = 0; x < w_; ++x)
                if (window_count(x, y) > evidence) return true;
        return false;
    }
    double window_count(int x, int y) const {
        const std::size_t W = static_cast<std::size_t>(w_) + 1;
        const int r = detail::density_radius;
        const std::size_t x0 = static_cast<std::size_t>(std::max(0, x - r)), x1 = static_cast<std::size_t>(std::min(w_, x + r + 1));
        const std::size_t y0 = static_cast<std::size_t>(std::max(0, y - r)), y1 = static_cast<std::size_t>(std::min(h_, y + r + 1));
        const std::vector<std::uint32_t>& c = s_->count;
        return static_cast<double>(c[y1 * W + x1] + c[y0 * W + x0] - c[y0 * W + x1] - c[y1 * W + x0]);
    }

    // s and the two halves' light at (x, y), appended to out where s > 0.
    void pixel(int x, int y, double evidence, std::vector<light>& out) {
        if (!(window_count(x, y) > evidence)) return;
        double m[8];  // M_A (3), M_B (3), V, L
        detail::window_sums<8, 6>(weights_, [&](int dx, int dy, double* v) {
            const int xx = x + dx, yy = y + dy;
            if (!inside(xx, yy)) {
                for (int k = 0; k < 8; ++k) v[k] = 0;
                return;
            }
            const std::size_t i = index(xx, yy) * 3;
            v[6] = v[7] = 0;
            for (int k = 0; k < 3; ++k) {
                v[k] = s_->excess[0][i + static_cast<std::size_t>(k)];
                v[3 + k] = s_->excess[1][i + static_cast<std::size_t>(k)];
                v[6] += (v[k] + v[3 + k]) * (v[k] + v[3 + k]);
                v[7] += s_->level[i + static_cast<std::size_t>(k)];
            }
        }, m);
        double m2 = 0, sum = 0;
        for (int k = 0; k < 3; ++k) m2 += (m[k] + m[3 + k]) * (m[k] + m[3 + k]), sum += m[k] + m[3 + k];
        const double js = m2 > 0 && std::isfinite(m2) ? 1.0 - evidence * m[6] / m2 : 0.0;
        // the part above the cleaned level: the wider scales return up to that level
        const double above = sum > 0 ? 1.0 - std::max(m[7], 0.0) / sum : 0.0;
        const double f = js > 0 && above > 0 ? js * above : 0.0;
        if (!(f > 0)) return;
        const std::size_t i = index(x, y);
        s_->factor[i] = static_cast<float>(f);
        light l{static_cast<std::uint32_t>(i), {}};
        for (int h = 0; h < 2; ++h)
            for (int k = 0; k < 3; ++k) l.add[h][k] = static_cast<float>(std::min(f * m[3 * h + k], 3.0e38));
        out.push_back(l);
    }

    detail::density_weights weights_;
    density_scratch* s_ = nullptr;
    int w_ = 0, h_ = 0;
};

}  // namespace firefly
