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
// scales, which return the rest (1 - f) e. s is 0 where no light can land (an ignored or
// non-finite pixel: f counted light there that was never given); a kept outlier's share is
// withheld as given though it gets none, and a rebuilt pixel gets at most f e (below): but
// for those two, the total given back is the total removed.
// Measured (relMSE before a denoiser, then after NL-means): dense30 0.251 -> 0.076 and 0.109 ->
// 0.0070, recall 0.984 -> 0.991; dense10 0.0297 -> 0.0235; the simulated caustics 0.0275 ->
// 0.0314 but after NL-means 0.0664 -> 0.0465 (its cores are lit by fireflies, whose density is
// noisier than the wider scales, which a denoiser averages); the held-out bokeh render at 64
// and 8 samples a half 0.0149 -> 0.0132 and 0.0388 -> 0.0289; the Cycles caustics 0.02426 ->
// 0.02449; every other scene and the Cycles interior unchanged to 4 digits. Its cost is the
// window sums at every pixel of a dense frame: at 2K, dense30's rebuild stage ~1.2 s (1.8-2.6 s
// with the window's 81 taps summed pixel by pixel); at 1024x540, a fresh detector's first two
// frames of the simulated caustics 198 -> 253 ms, of sparse fireflies a pass of counts.
//
// The K-buffer detector (buffers.hpp) runs it on its mean image, each pixel's excess pooled
// over the buffers as one half's; off by default there (its wider scales' shape already keeps
// light where fireflies fall densely; buffers.hpp, give_density_back, says what it measured).
//
// A pixel gets no density light where either half kept an outlier (a highlight, or one within
// its noise: it holds its light already, and the wider scales must not give its share a second
// time: the simulated caustics 0.0310 -> 0.0313 when they did), where it is ignored (black,
// alpha 0, whose colour is no part of the level L either) or not finite (s = 0: the wider
// scales return that light), and a rebuilt pixel at most f e of what its rebuild took.
//
// Sums: the Gaussian is separable, and its sums are taken both ways, along rows then columns
// and along columns then rows, and averaged: a transpose swaps the two orders, and each axis'
// sum adds opposite taps first, which a flip swaps, so a flipped or transposed frame gives the
// flipped or transposed result bit for bit. In tiles of 128 x 32 pixels (one channel's buffers
// stay in a core's L2) the row and column passes cost ~45 ns a pixel for the 8 values; where few of
// a tile's pixels need them, each pixel's window is summed alone in the same order (the same
// bits, ~280 ns). A window with no more than c removed pixels cannot pass (|M|^2 <= N V for N
// terms, Cauchy-Schwarz): an integral image of the removed pixels skips those windows, and
// whole tiles, exactly, so a frame of sparse fireflies costs a pass of counts. The caller gives
// each pixel's values (its halves' excess and cleaned level) as they are read; memory: 5 bytes
// a pixel for the flags and counts; where some window passes, 4 for the factors, 4 for their
// sums and the list of pixels given light (the pipeline adds 8 for each pixel's list entries).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "fused.hpp"
#include "parallel.hpp"
#include "status.hpp"

namespace firefly {
namespace detail {

inline constexpr int density_radius = 4;  // 9 x 9, sigma 2

// The window's weights, separable: w(a, b) = g[|a|] g[|b|], g the Gaussian of sigma 2 over
// -4..4 normalised (w sums to 1 over the window); g2 = g^2, the weights of the variance's sums.
struct density_weights {
    double g[density_radius + 1] = {}, g2[density_radius + 1] = {};
    density_weights() {
        double z = 0;
        for (int a = -density_radius; a <= density_radius; ++a) z += std::exp(-a * a / 8.0);
        for (int a = 0; a <= density_radius; ++a) g[a] = std::exp(-a * a / 8.0) / z, g2[a] = g[a] * g[a];
    }
};

// The weighted sum of p[i step], |i| <= 4: opposite taps added first, then in a fixed order, so
// a flipped axis gives the same bits; the fusing written out where the target fuses (fused.hpp),
// so every loop that calls it gives the same bits too.
inline double axis_sum(const double* p, std::ptrdiff_t step, const double* g) noexcept {
    double s = g[0] * p[0];
    for (int a = 1; a <= density_radius; ++a) {
#ifdef FIREFLY_DETAIL_TARGET_FMA
        s = std::fma(g[a], p[-a * step] + p[a * step], s);
#else
        s += g[a] * (p[-a * step] + p[a * step]);
#endif
    }
    return s;
}

// The window sums of N values at every pixel of a tile (channel k weighted by g[k]: the
// density's weights or their squares), 0 outside the frame. A separable sum taken rows first
// and columns first gives the same value to round-off; the mean of both is the same bits under
// the frame's 8 flips and transposes (a transpose swaps the two orders, a flip the taps of a
// pair) and does not depend on the tiling. Buffers are kept between tiles.
template <int N>
class density_sums {
public:
    static constexpr int r = density_radius;
    static constexpr std::size_t n = N;  // N as the arrays' bound (an int one: GCC's sign warning)

    // The sums over the tile [x0, x0 + tw) x [y0, y0 + th) of a w x h frame, into out (N per
    // pixel, row-major in the tile); load(x, y, v) writes the N values of an in-frame pixel.
    template <class Load>
    void run(int w, int h, int x0, int y0, int tw, int th, const double* const (&g)[n], Load&& load, double* out) {
        const int pw = tw + 2 * r, ph = th + 2 * r;
        const std::size_t plane = static_cast<std::size_t>(pw) * static_cast<std::size_t>(ph);
        in_.assign(plane * N, 0.0);
        rows_.resize(static_cast<std::size_t>(tw) * static_cast<std::size_t>(ph) * N);
        cols_.resize(static_cast<std::size_t>(pw) * static_cast<std::size_t>(th) * N);
        double v[n];
        for (int j = (std::max)(0, r - y0); j < (std::min)(ph, h - y0 + r); ++j)
            for (int i = (std::max)(0, r - x0); i < (std::min)(pw, w - x0 + r); ++i) {
                load(x0 - r + i, y0 - r + j, v);
                for (int k = 0; k < N; ++k) in_[plane * static_cast<std::size_t>(k) + offset(i, j, pw)] = v[k];
            }
        for (std::size_t k = 0; k < static_cast<std::size_t>(N); ++k) {
            const double* in = &in_[plane * k];
            double* rows = &rows_[static_cast<std::size_t>(tw) * static_cast<std::size_t>(ph) * k];
            double* cols = &cols_[static_cast<std::size_t>(pw) * static_cast<std::size_t>(th) * k];
            for (int j = 0; j < ph; ++j)  // along rows, every row of the padded tile
                for (int i = 0; i < tw; ++i) rows[offset(i, j, tw)] = axis_sum(&in[offset(i + r, j, pw)], 1, g[k]);
            for (int j = 0; j < th; ++j)  // along columns, every column of the padded tile
                for (int i = 0; i < pw; ++i) cols[offset(i, j, pw)] = axis_sum(&in[offset(i, j + r, pw)], pw, g[k]);
            for (int j = 0; j < th; ++j)
                for (int i = 0; i < tw; ++i) {
                    const double rc = axis_sum(&rows[offset(i, j + r, tw)], tw, g[k]);  // rows, then columns
                    const double cr = axis_sum(&cols[offset(i + r, j, pw)], 1, g[k]);   // columns, then rows
                    out[offset(i, j, tw) * N + k] = (rc + cr) * 0.5;
                }
        }
    }

    // The sums at one pixel (x, y), the same bits as run() gives it: the same axis sums, in
    // the same order, over the pixel's window alone (cheaper where few pixels of a tile need
    // them); the N channels side by side, so that each step is one vector operation.
    template <class Load>
    void at(int w, int h, int x, int y, const double* const (&g)[n], Load&& load, double* out) const {
        constexpr int d = 2 * r + 1;
        double in[d * d][n], rows[d][n], cols[d][n], gw[r + 1][n];
        for (int a = 0; a <= r; ++a)
            for (int k = 0; k < N; ++k) gw[a][k] = g[k][a];
        const int j0 = (std::max)(0, r - y), j1 = (std::min)(d, h - y + r), i0 = (std::max)(0, r - x), i1 = (std::min)(d, w - x + r);
        if (j0 > 0 || i0 > 0 || j1 < d || i1 < d)  // at the frame's edge: 0 outside it
            for (auto& p : in)
                for (double& v : p) v = 0;
        for (int j = j0; j < j1; ++j)
            for (int i = i0; i < i1; ++i) load(x - r + i, y - r + j, in[j * d + i]);
        for (int b = 0; b < d; ++b) {
            axis_sums(in[b * d + r], 1, gw, rows[b]);
            axis_sums(in[r * d + b], d, gw, cols[b]);
        }
        double rc[n], cr[n];
        axis_sums(rows[r], 1, gw, rc);
        axis_sums(cols[r], 1, gw, cr);
        for (int k = 0; k < N; ++k) out[k] = (rc[k] + cr[k]) * 0.5;
    }

    // use(x, y, sums) at every pixel of the tile where need(x, y): the whole tile's sums
    // (run) or each needed pixel's alone (at), whichever costs less (the same bits).
    template <class Load, class Need, class Use>
    void each(int w, int h, int x0, int y0, int tw, int th, const double* const (&g)[n], Load&& load, Need&& need, Use&& use) {
        std::size_t needed = 0;
        for (int y = y0; y < y0 + th; ++y)
            for (int x = x0; x < x0 + tw; ++x) needed += need(x, y) ? 1u : 0u;
        const bool whole = whole_tile(needed, tw, th);
        if (whole) {
            tile_.resize(static_cast<std::size_t>(tw) * static_cast<std::size_t>(th) * N);
            run(w, h, x0, y0, tw, th, g, load, tile_.data());
        }
        double one[n];
        for (int j = 0; j < th; ++j)
            for (int i = 0; i < tw; ++i) {
                if (!need(x0 + i, y0 + j)) continue;
                if (!whole) at(w, h, x0 + i, y0 + j, g, load, one);
                use(x0 + i, y0 + j, whole ? &tile_[offset(i, j, tw) * N] : one);
            }
    }

    // Whether run() costs less than at() for `pixels` of a tile of tw x th: one pixel alone
    // costs about 6 pixels of a whole tile (at 1024x540: 280 and 45 ns a pixel for 8 values;
    // the one value of the shares takes the same rule). Only speed depends on it: the bits
    // are the same either way.
    static bool whole_tile(std::size_t pixels, int tw, int th) noexcept {
        return pixels * 6 > static_cast<std::size_t>(tw) * static_cast<std::size_t>(th);
    }

private:
    // axis_sum of each of N channels side by side: p[i step][k], weights gw[a][k].
    static void axis_sums(const double* p, std::ptrdiff_t step, const double (&gw)[r + 1][n], double* out) noexcept {
        const std::ptrdiff_t s = step * N;
        for (int k = 0; k < N; ++k) out[k] = gw[0][k] * p[k];
        for (int a = 1; a <= r; ++a)
            for (int k = 0; k < N; ++k) {
#ifdef FIREFLY_DETAIL_TARGET_FMA
                out[k] = std::fma(gw[a][k], p[k - a * s] + p[k + a * s], out[k]);
#else
                out[k] += gw[a][k] * (p[k - a * s] + p[k + a * s]);
#endif
            }
    }
    static std::size_t offset(int i, int j, int stride) noexcept {
        return static_cast<std::size_t>(j) * static_cast<std::size_t>(stride) + static_cast<std::size_t>(i);
    }
    std::vector<double> in_, rows_, cols_;  // N planes each
    std::vector<double> tile_;              // each(): the tile's sums, N per pixel
};

}  // namespace detail

// The evidence the finest scale asks (energy_density_evidence): 0 (none) or 1 to 1e6 removed
// pixels' worth.
inline status check_density_evidence(double evidence) noexcept {
    if (evidence == 0.0 || (evidence >= 1.0 && evidence <= 1e6)) return ok_status();
    return status{errc::invalid_argument, "energy_density_evidence must be 0 or lie in [1, 1e6]"};
}

// Work arrays of the density scale, kept between frames.
struct density_scratch {
    std::vector<std::uint8_t> removed;  // 1 where either half had excess removed
    std::vector<std::uint32_t> count;  // integral image of removed pixels, (w + 1) x (h + 1)
    std::vector<float> factor;         // s per pixel
    std::vector<float> share;          // G * s at removed pixels: the share f of their excess given
    std::size_t bytes() const noexcept {
        return removed.capacity() + (count.capacity() + factor.capacity() + share.capacity()) * 4;
    }
};

// The density return of both halves. The caller marks removed (1 per pixel, w x h, zeroed by
// prepare()) where either half had excess removed; where needed(), run() lists the light to
// give each half, reading each pixel's values through the caller's load(x, y, v): v[0..2] and
// v[3..5] what the rebuild removed from halves A and B (>= 0), v[6] |e_A + e_B|^2 and v[7] the
// cleaned halves' sum over the channels. taken(pixel) then is the share f of a removed pixel's
// excess given.
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

    // Whether any window holds more than `evidence` removed pixels (else nothing can pass):
    // run() is worth calling only then.
    bool needed(double evidence, density_scratch& s) {
        s_ = &s;
        return evidence > 0 && w_ > 0 && h_ > 0 && count_removed(evidence);
    }

    // The pixels that get light, row-major, in `out` (after needed() returned true for this
    // frame), and the share each removed pixel's excess gave (taken()); false when none.
    // receives(x, y): whether the pixel can take light; s is 0 where it cannot, so that the
    // shares count only light that is given.
    template <class Load, class Receives>
    bool run(double evidence, density_scratch& s, std::vector<light>& out, const executor& exec, const Load& load,
             const Receives& receives) {
        s_ = &s;
        out.clear();
        s.share.clear();  // taken() is 0 until the shares are summed
        const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
        if (!(evidence > 0) || n == 0 || s.count.size() != (static_cast<std::size_t>(w_) + 1) * (static_cast<std::size_t>(h_) + 1))
            return false;  // needed() has not counted this frame
        s.factor.assign(n, 0.0f);
        std::vector<std::vector<light>> bands(static_cast<std::size_t>((h_ + tile_h - 1) / tile_h));
        exec.run(bands.size(), [&](std::size_t b) { factor_band(static_cast<int>(b), evidence, load, receives, bands[b]); });
        for (const auto& b : bands) out.insert(out.end(), b.begin(), b.end());
        if (out.empty()) return false;
        s.share.assign(n, 0.0f);
        exec.run(bands.size(), [&](std::size_t b) { share_band(static_cast<int>(b)); });
        return true;
    }

    // The share of pixel q's removed excess that the density gave back: sum_p w_pq s(p)
    // (q the row-major pixel index; at a pixel marked removed, 0 elsewhere).
    double taken(std::size_t q) const {
        return s_ && !s_->share.empty() ? (std::min)(static_cast<double>(s_->share[q]), 1.0) : 0.0;
    }

private:
    static constexpr int tile_w = 128, tile_h = 32;  // one channel's buffers stay in a core's L2

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
    // Removed pixels in the window of (x, y), clipped to the frame, of the box [x0, x1) x [y0, y1)
    // grown by the radius.
    double box_count(int x0, int y0, int x1, int y1) const {
        const std::size_t W = static_cast<std::size_t>(w_) + 1;
        const int r = detail::density_radius;
        const std::size_t a0 = static_cast<std::size_t>((std::max)(0, x0 - r)), a1 = static_cast<std::size_t>((std::min)(w_, x1 + r));
        const std::size_t b0 = static_cast<std::size_t>((std::max)(0, y0 - r)), b1 = static_cast<std::size_t>((std::min)(h_, y1 + r));
        const std::vector<std::uint32_t>& c = s_->count;
        return static_cast<double>(c[b1 * W + a1] + c[b0 * W + a0] - c[b0 * W + a1] - c[b1 * W + a0]);
    }
    double window_count(int x, int y) const { return box_count(x, y, x + 1, y + 1); }

    // s at every pixel of band b whose window can pass, and the two halves' light where s > 0,
    // appended to out in row-major order.
    template <class Load, class Receives>
    void factor_band(int b, double evidence, const Load& load, const Receives& receives, std::vector<light>& out) {
        detail::density_sums<8> sums;
        const double* g[8] = {weights_.g, weights_.g, weights_.g, weights_.g, weights_.g, weights_.g, weights_.g2, weights_.g};
        const int y0 = b * tile_h, th = (std::min)(tile_h, h_ - y0);
        for (int x0 = 0; x0 < w_; x0 += tile_w) {
            const int tw = (std::min)(tile_w, w_ - x0);
            if (!(box_count(x0, y0, x0 + tw, y0 + th) > evidence)) continue;  // no window in it passes
            sums.each(w_, h_, x0, y0, tw, th, g, load,
                      [&](int x, int y) { return window_count(x, y) > evidence && receives(x, y); },
                      [&](int x, int y, const double* m) { pixel(x, y, evidence, m, out); });
        }
        std::sort(out.begin(), out.end(), [](const light& a, const light& c) { return a.pixel < c.pixel; });
    }

    // s and the two halves' light at (x, y) from its window sums m (M_A, M_B, V, L), appended
    // to out where s > 0.
    void pixel(int x, int y, double evidence, const double* m, std::vector<light>& out) {
        double m2 = 0, sum = 0;
        for (int k = 0; k < 3; ++k) m2 += (m[k] + m[3 + k]) * (m[k] + m[3 + k]), sum += m[k] + m[3 + k];
        const double js = m2 > 0 && std::isfinite(m2) ? 1.0 - evidence * m[6] / m2 : 0.0;
        // the part above the cleaned level: the wider scales return up to that level
        const double above = sum > 0 ? 1.0 - (std::max)(m[7], 0.0) / sum : 0.0;
        const double f = js > 0 && above > 0 ? js * above : 0.0;
        if (!(f > 0)) return;
        const std::size_t i = index(x, y);
        s_->factor[i] = static_cast<float>(f);
        light l{static_cast<std::uint32_t>(i), {}};
        for (int h = 0; h < 2; ++h)
            for (int k = 0; k < 3; ++k) l.add[h][k] = static_cast<float>((std::min)(f * m[3 * h + k], 3.0e38));
        out.push_back(l);
    }

    // G * s over band b, in tiles that some s > 0 reaches.
    void share_band(int b) {
        detail::density_sums<1> sums;
        const double* g[1] = {weights_.g};
        const int r = detail::density_radius, y0 = b * tile_h, th = (std::min)(tile_h, h_ - y0);
        for (int x0 = 0; x0 < w_; x0 += tile_w) {
            const int tw = (std::min)(tile_w, w_ - x0);
            bool any = false;
            for (int y = (std::max)(0, y0 - r); y < (std::min)(h_, y0 + th + r) && !any; ++y)
                for (int x = (std::max)(0, x0 - r); x < (std::min)(w_, x0 + tw + r) && !any; ++x) any = s_->factor[index(x, y)] > 0;
            if (!any) continue;
            sums.each(w_, h_, x0, y0, tw, th, g,
                      [&](int x, int y, double* v) { v[0] = static_cast<double>(s_->factor[index(x, y)]); },
                      [&](int x, int y) { return s_->removed[index(x, y)] != 0; },  // where taken() is asked
                      [&](int x, int y, const double* m) { s_->share[index(x, y)] = static_cast<float>(m[0]); });
        }
    }

    detail::density_weights weights_;
    density_scratch* s_ = nullptr;
    int w_ = 0, h_ = 0;
};

}  // namespace firefly
