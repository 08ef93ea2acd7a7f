// firefly: dropped pixels, black in one buffer where the others show it cannot be by chance.
//
// A render bucket that failed often comes back black rather than NaN: a tile never written, a
// crashed worker's zeroed memory, a seed render cut short. Black pixels are otherwise left out
// of every test (a black background), so such a bucket halves the frame's brightness there.
//
// Test. The buffers of one frame (two halves, or K renders) are exchangeable: their samples are
// drawn alike, so at a pixel where exactly one buffer is black and the others are not (a "lone
// black"), that buffer is any of the K with probability 1/K, whatever the scene, the sample
// count or the law of the samples, and independently from pixel to pixel. Around a lone black
// of buffer k, in the (2 radius + 1)^2 window centred on it, let n be the lone blacks of every
// buffer and a those of buffer k (both counting the pixel itself). Without a dropped region
// the other n - 1 are each buffer k's with probability 1/K, so
//     p = P(Binomial(n - 1, 1/K) >= a - 1)
// is an exact p-value (conditional on where the lone blacks are). A bucket dropped in buffer k
// makes every pixel of it a lone black of k (where the scene is not black in the others too):
// a = n, p = K^-(n - 1), 2^-24 for a 5x5 region at K = 2; a lone black in a dark, noisy
// region is among others of every buffer and keeps p near 1. The frame's decision is
// Bonferroni's at alpha over its m lone blacks, p <= alpha / m: a frame without a dropped region
// changes nothing in at least 1 - alpha of cases, and a frame with one gains at most alpha
// chance finds beyond it, expected (Benjamini-Hochberg would admit alpha of the region's size;
// the region's own pixels are far below either level: a corner's quarter window, 2^-63 at
// K = 2). Lone blacks of the same buffer within the radius of a dropped region share windows
// with it and are found with it (a legitimately black pixel there takes the other buffers'
// value: a halo at most `radius` wide, as dense as the lone blacks around the region).
// Not found: a region dropped in every buffer alike (it is black background to any test), a
// region smaller than a few pixels (indistinguishable from chance), and pixels of the region
// where another buffer is black too (K >= 3; not a lone black).
// The window is symmetric and every count is an integer: a flipped or transposed frame gives
// the flipped or transposed result, and the result does not depend on the executor.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "image_view.hpp"
#include "parallel.hpp"

namespace firefly {

// A dropped pixel: `pixel` (row-major index) is black in buffer `buffer` alone, and found.
struct dropped_pixel {
    std::uint32_t pixel = 0;
    int buffer = 0;
    double log_p = 0;  // its p-value (log)
};

namespace detail {

inline constexpr int dropped_radius = 7;  // the window: 15 x 15 pixels

// Whether pixel (x, y) is black: its colour channels (the first three) all 0.
template <class C>
bool colour_is_black(const image_view<C>& color, int x, int y) {
    for (int c = 0; c < std::min(color.channels(), 3); ++c)
        if (color.load(x, y, c) != 0) return false;
    return true;
}

// log P(Binomial(n, 1/k) >= a) for 0 <= a <= n <= n_max, one table per k.
class binomial_tail_table {
public:
    void build(int k, int n_max) {
        if (k == k_ && n_max == n_max_) return;
        k_ = k;
        n_max_ = n_max;
        row_.assign(static_cast<std::size_t>(n_max + 1), 0);
        tail_.clear();
        const double lp = std::log(1.0 / k), lq = std::log1p(-1.0 / k);
        std::vector<double> pmf;
        for (int n = 0; n <= n_max; ++n) {
            row_[static_cast<std::size_t>(n)] = tail_.size();
            pmf.assign(static_cast<std::size_t>(n + 1), 0.0);
            double log_c = 0;  // log C(n, a)
            for (int a = 0; a <= n; ++a) {
                pmf[static_cast<std::size_t>(a)] = log_c + a * lp + (n - a) * lq;
                log_c += std::log(static_cast<double>(n - a)) - std::log(static_cast<double>(a + 1));
            }
            tail_.resize(tail_.size() + static_cast<std::size_t>(n + 1));
            double* t = &tail_[row_[static_cast<std::size_t>(n)]];
            double acc = -HUGE_VAL;  // the tail from the top down: log-sum-exp of the terms
            for (int a = n; a >= 0; --a) {
                const double v = pmf[static_cast<std::size_t>(a)], hi = std::max(acc, v);
                acc = hi == -HUGE_VAL ? hi : hi + std::log1p(std::exp(std::min(acc, v) - hi));
                t[a] = std::min(acc, 0.0);
            }
        }
    }
    double log_tail(int n, int a) const noexcept { return tail_[row_[static_cast<std::size_t>(n)] + static_cast<std::size_t>(a)]; }

private:
    int k_ = 0, n_max_ = -1;
    std::vector<std::size_t> row_;
    std::vector<double> tail_;
};

}  // namespace detail

// Work memory of find_dropped, kept between frames.
struct dropped_scratch {
    detail::binomial_tail_table table;
    std::vector<std::uint8_t> lone;                // the lone blacks (find_dropped with lone_at)
    std::vector<std::vector<dropped_pixel>> rows;  // candidates per row
    std::size_t bytes() const noexcept {
        std::size_t n = lone.capacity() + rows.capacity() * sizeof(std::vector<dropped_pixel>);
        for (const auto& r : rows) n += r.capacity() * sizeof(dropped_pixel);
        return n;
    }
};

// The dropped pixels of a w x h frame of k buffers (k >= 2), row-major into `out`. lone[p]:
// 0 where no buffer is a lone black, else 1 + the buffer that is. alpha: the frame's promise
// (Bonferroni's level over the lone blacks). Returns the number of lone blacks tested.
inline std::size_t find_dropped(const std::uint8_t* lone, int w, int h, int k, double alpha, dropped_scratch& s,
                                const executor& exec, std::vector<dropped_pixel>& out) {
    out.clear();
    constexpr int r = detail::dropped_radius;
    s.table.build(k, (2 * r + 1) * (2 * r + 1) - 1);
    s.rows.resize(static_cast<std::size_t>(h));
    exec.run(static_cast<std::size_t>(h), [&](std::size_t yy) {
        const int y = static_cast<int>(yy);
        std::vector<dropped_pixel>& row = s.rows[yy];
        row.clear();
        const std::uint8_t* here = lone + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        for (int x = 0; x < w; ++x) {
            if (here[x] == 0) continue;
            int n = 0, a = 0;
            for (int j = std::max(0, y - r); j <= std::min(h - 1, y + r); ++j) {
                const std::uint8_t* l = lone + static_cast<std::size_t>(j) * static_cast<std::size_t>(w);
                for (int i = std::max(0, x - r); i <= std::min(w - 1, x + r); ++i) {
                    n += l[i] != 0;
                    a += l[i] == here[x];
                }
            }
            const std::uint32_t p = static_cast<std::uint32_t>(static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                                               static_cast<std::size_t>(x));
            row.push_back({p, here[x] - 1, s.table.log_tail(n - 1, a - 1)});
        }
    });
    std::size_t tested = 0;
    for (const auto& row : s.rows) tested += row.size();
    if (tested == 0) return 0;
    const double level = std::log(alpha) - std::log(static_cast<double>(tested));
    for (const auto& row : s.rows)
        for (const dropped_pixel& d : row)
            if (d.log_p <= level) out.push_back(d);
    return tested;
}

// The same, the lone blacks given by lone_at(x, y) (0, or 1 + the buffer black alone at the
// pixel), taken row by row across the executor into s.lone; no window pass where none is.
template <class LoneAt>
std::size_t find_dropped(int w, int h, int k, double alpha, LoneAt&& lone_at, dropped_scratch& s, const executor& exec,
                         std::vector<dropped_pixel>& out) {
    const std::size_t row = static_cast<std::size_t>(w);
    s.lone.resize(row * static_cast<std::size_t>(h));
    std::vector<std::uint8_t> any(static_cast<std::size_t>(h), 0);
    exec.run(static_cast<std::size_t>(h), [&](std::size_t y) {
        for (int x = 0; x < w; ++x) {
            const std::uint8_t l = lone_at(x, static_cast<int>(y));
            s.lone[y * row + static_cast<std::size_t>(x)] = l;
            any[y] = any[y] || l != 0;
        }
    });
    out.clear();
    if (std::find_if(any.begin(), any.end(), [](std::uint8_t a) { return a != 0; }) == any.end()) return 0;
    return find_dropped(s.lone.data(), w, h, k, alpha, s, exec, out);
}

}  // namespace firefly
