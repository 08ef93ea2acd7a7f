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
// K >= 3: more than one buffer can be black at a pixel (a tile that failed in two renders, or
// two failed tiles that overlap). A "partly black" pixel has j of its K buffers black,
// 1 <= j <= K - 1, the others finite and not black; exchangeability makes each buffer one of
// its j black ones with probability j / K. Around a partly black pixel and for each buffer k
// black there, n counts the window's partly black pixels and a those where k is black; each
// of the other n - 1, with j_q black buffers, is k's with probability j_q / K, independently:
// a - 1 is a Poisson-binomial count. Where every partly
// black pixel of the window is a lone black, that is the binomial above, exact. Elsewhere,
// with pbar the mean of the j_q / K, Hoeffding (1956, theorem 4) bounds its upper tail by the
// binomial's of the same mean,
//     P(a - 1 >= c) <= P(Binomial(n - 1, pbar) >= c)   for c >= (n - 1) pbar + 1,
// a valid p-value (1 below that point, far from any decision). Bonferroni's level is then over
// the m (pixel, black buffer) pairs. A tile black in the same two of eight renders: a = n,
// p = (1/4)^(n - 1), 2^-48 for a 5x5 region.
// Not found: a region dropped in every buffer alike (it is black background to any test), and
// a region smaller than a few pixels (indistinguishable from chance).
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
#include "scratch.hpp"

namespace firefly {

// A dropped pixel: `pixel` (row-major index) is black in buffer `buffer` (alone, or with
// others: K >= 3), and found.
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
    for (int c = 0; c < (std::min)(color.channels(), 3); ++c)
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
                const double v = pmf[static_cast<std::size_t>(a)], hi = (std::max)(acc, v);
                acc = hi == -HUGE_VAL ? hi : hi + std::log1p(std::exp((std::min)(acc, v) - hi));
                t[a] = (std::min)(acc, 0.0);
            }
        }
    }
    double log_tail(int n, int a) const noexcept { return tail_[row_[static_cast<std::size_t>(n)] + static_cast<std::size_t>(a)]; }
    std::size_t bytes() const noexcept { return row_.capacity() * sizeof(std::size_t) + tail_.capacity() * sizeof(double); }

private:
    reset_on_move<int> k_;  // (scratch.hpp: a moved-from table builds again)
    int n_max_ = -1;
    std::vector<std::size_t> row_;
    std::vector<double> tail_;
};

// The index of the lowest set bit of m (m != 0).
template <class Mask>
int lowest_bit(Mask m) noexcept {
    int b = 0;
    while (((static_cast<std::uint64_t>(m) >> b) & 1u) == 0u) ++b;
    return b;
}

// log P(Binomial(n, p) >= c) for c >= n p + 1 (so the terms fall from c on), 0 < p < 1,
// n <= the table's size: the terms summed in log space until they stop adding to a double.
inline double log_binomial_upper_tail(int n, int c, double p, const std::vector<double>& log_factorial) noexcept {
    if (c <= 0) return 0.0;
    if (c > n) return -HUGE_VAL;
    const double lp = std::log(p), lq = std::log1p(-p), odds = lp - lq;
    double term = log_factorial[static_cast<std::size_t>(n)] - log_factorial[static_cast<std::size_t>(c)] -
                  log_factorial[static_cast<std::size_t>(n - c)] + c * lp + (n - c) * lq;
    double acc = term;
    for (int t = c; t < n; ++t) {
        term += std::log(static_cast<double>(n - t) / (t + 1)) + odds;
        if (term < acc - 40.0) break;  // e^-40: below a double's precision of the sum
        acc += std::log1p(std::exp(term - acc));
    }
    return (std::min)(acc, 0.0);
}

// The number of set bits of each byte value.
struct byte_counts {
    unsigned char n[256] = {};
    constexpr byte_counts() {
        for (int v = 1; v < 256; ++v) n[v] = static_cast<unsigned char>(n[v >> 1] + (v & 1));
    }
};
inline constexpr byte_counts bits_in_byte{};

// The number of buffers black in a mask.
template <class Mask>
int blacks_in(Mask m) noexcept {
    int n = 0;
    for (std::size_t i = 0; i < sizeof(Mask); ++i) n += bits_in_byte.n[static_cast<unsigned>(m >> (8 * i)) & 255u];
    return n;
}

}  // namespace detail

// Work memory of find_dropped, kept between frames.
struct dropped_scratch {
    detail::binomial_tail_table table;                // at probability 1 / K (lone blacks)
    std::vector<double> log_factorial;                // log i!, i up to the window's size
    std::vector<std::uint8_t> lone;                   // black-buffer masks, K <= 8
    std::vector<std::uint64_t> wide;                  // black-buffer masks, K > 8
    std::vector<std::vector<dropped_pixel>> rows;     // candidates per row
    std::size_t bytes() const noexcept {
        std::size_t n = lone.capacity() + wide.capacity() * sizeof(std::uint64_t) +
                        rows.capacity() * sizeof(std::vector<dropped_pixel>);
        for (const auto& r : rows) n += r.capacity() * sizeof(dropped_pixel);
        return n + table.bytes() + log_factorial.capacity() * sizeof(double);
    }
};

namespace detail {

// The p-value (log) of c of the n other partly black pixels of a window having buffer k black,
// `blacks` the black buffers they hold in all: the lone-black binomial where they are all lone
// blacks (blacks = n), Hoeffding's bound otherwise.
inline double window_log_p(int n, int c, int blacks, int k, const dropped_scratch& s) noexcept {
    if (blacks == n) return s.table.log_tail(n, c);
    if (c * k < blacks + k) return 0.0;  // c < n pbar + 1, in integers: no bound there (p <= 1)
    return log_binomial_upper_tail(n, c, static_cast<double>(blacks) / (static_cast<double>(k) * n), s.log_factorial);
}

// The counts of a vertical strip of rows, per column: the partly black pixels, their black
// buffers, and per buffer the pixels where it is black. Slid down a band of rows (one row in,
// one out), so a window's counts cost its width, not its area: a half written black all over
// is as cheap a pixel as a lone black.
template <class Mask>
class strip_counts {
public:
    void reset(int w, int k) {
        w_ = w;
        lit_.assign(static_cast<std::size_t>(w), 0);
        blacks_.assign(static_cast<std::size_t>(w), 0);
        of_.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(k), 0);
    }
    // Row `row` of masks into the strip (sign 1) or out of it (sign -1).
    void add(const Mask* row, int sign) noexcept {
        for (int x = 0; x < w_; ++x) {
            const Mask m = row[x];
            if (m == 0) continue;
            lit_[static_cast<std::size_t>(x)] += sign;
            blacks_[static_cast<std::size_t>(x)] += sign * blacks_in(m);
            for (Mask rest = m; rest != 0; rest = static_cast<Mask>(rest & (rest - 1)))
                of_[column(lowest_bit(rest), x)] += sign;
        }
    }
    // Columns [i0, i1]: the window's partly black pixels, their black buffers, and buffer b's.
    int lit(int i0, int i1) const noexcept { return sum(lit_.data(), i0, i1); }
    int blacks(int i0, int i1) const noexcept { return sum(blacks_.data(), i0, i1); }
    int of(int b, int i0, int i1) const noexcept { return sum(&of_[column(b, 0)], i0, i1); }

private:
    static int sum(const int* v, int i0, int i1) noexcept {
        int n = 0;
        for (int i = i0; i <= i1; ++i) n += v[i];
        return n;
    }
    std::size_t column(int b, int x) const noexcept {
        return static_cast<std::size_t>(b) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
    }
    int w_ = 0;
    std::vector<int> lit_, blacks_, of_;
};

// The p-values of every (partly black pixel, black buffer) of row y into `row`, from the strip
// of rows [y - r, y + r] (counted in `strip`): black[p] is the mask of the buffers black at p
// (0: none, or not partly black), r the window's radius.
template <class Mask>
void dropped_row(const Mask* black, int w, int y, int r, int k, const strip_counts<Mask>& strip, const dropped_scratch& s,
                 std::vector<dropped_pixel>& row) {
    row.clear();
    const Mask* here = black + static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    std::size_t pairs = 0;  // reserved at once: a row black all over grows no vector step by step
    for (int x = 0; x < w; ++x) pairs += static_cast<std::size_t>(blacks_in(here[x]));
    row.reserve(pairs);
    for (int x = 0; x < w; ++x) {
        const Mask m = here[x];
        if (m == 0) continue;
        const int i0 = (std::max)(0, x - r), i1 = (std::min)(w - 1, x + r);
        const int n = strip.lit(i0, i1), blacks = strip.blacks(i0, i1) - blacks_in(m);  // the others' black buffers
        const std::uint32_t p = static_cast<std::uint32_t>(static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                                           static_cast<std::size_t>(x));
        for (Mask rest = m; rest != 0; rest = static_cast<Mask>(rest & (rest - 1))) {
            const int b = lowest_bit(rest);
            row.push_back({p, b, window_log_p(n - 1, strip.of(b, i0, i1) - 1, blacks, k, s)});
        }
    }
}

// Rows [y0, y1) of dropped_row's p-values into s.rows: the strip slid down the band.
template <class Mask>
void dropped_band(const Mask* black, int w, int h, int y0, int y1, int r, int k, dropped_scratch& s) {
    strip_counts<Mask> strip;
    strip.reset(w, k);
    const auto line = [&](int y) { return black + static_cast<std::size_t>(y) * static_cast<std::size_t>(w); };
    for (int j = (std::max)(0, y0 - r); j <= (std::min)(h - 1, y0 + r); ++j) strip.add(line(j), 1);
    for (int y = y0; y < y1; ++y) {
        if (y > y0) {
            if (y + r < h) strip.add(line(y + r), 1);
            if (y - r - 1 >= 0) strip.add(line(y - r - 1), -1);
        }
        dropped_row(black, w, y, r, k, strip, s, s.rows[static_cast<std::size_t>(y)]);
    }
}

// The dropped pixels from the black-buffer masks of a w x h frame of k buffers.
template <class Mask>
std::size_t find_dropped_in(const Mask* black, int w, int h, int k, double alpha, dropped_scratch& s,
                               const executor& exec, std::vector<dropped_pixel>& out) {
    out.clear();
    constexpr int r = dropped_radius, n_max = (2 * r + 1) * (2 * r + 1) - 1;
    s.table.build(k, n_max);
    if (s.log_factorial.size() != static_cast<std::size_t>(n_max + 1)) {
        s.log_factorial.assign(static_cast<std::size_t>(n_max + 1), 0.0);
        for (int i = 1; i <= n_max; ++i)
            s.log_factorial[static_cast<std::size_t>(i)] = s.log_factorial[static_cast<std::size_t>(i - 1)] + std::log(static_cast<double>(i));
    }
    s.rows.resize(static_cast<std::size_t>(h));
    constexpr int band = 32;  // rows a task slides its strip down (2 r of them read to start it)
    exec.run(static_cast<std::size_t>((h + band - 1) / band), [&](std::size_t i) {
        const int y0 = static_cast<int>(i) * band;
        dropped_band(black, w, h, y0, (std::min)(h, y0 + band), r, k, s);
    });
    std::size_t tested = 0;
    for (const auto& row : s.rows) tested += row.size();
    if (tested == 0) return 0;
    const double level = std::log(alpha) - std::log(static_cast<double>(tested));
    std::size_t found = 0;
    for (const auto& row : s.rows)
        for (const dropped_pixel& d : row) found += d.log_p <= level;
    out.reserve(found);
    for (const auto& row : s.rows)
        for (const dropped_pixel& d : row)
            if (d.log_p <= level) out.push_back(d);
    return tested;
}

// The masks black_at(x, y) gives (a std::uint64_t, bit i: buffer i black; 0 unless partly
// black) into `masks` across the executor; returns whether any pixel is partly black.
template <class Mask, class BlackAt>
bool fill_black_masks(int w, int h, BlackAt&& black_at, std::vector<Mask>& masks, const executor& exec) {
    const std::size_t row = static_cast<std::size_t>(w);
    masks.resize(row * static_cast<std::size_t>(h));
    std::vector<std::uint8_t> any(static_cast<std::size_t>(h), 0);
    exec.run(static_cast<std::size_t>(h), [&](std::size_t y) {
        for (int x = 0; x < w; ++x) {
            const Mask m = static_cast<Mask>(black_at(x, static_cast<int>(y)));
            masks[y * row + static_cast<std::size_t>(x)] = m;
            any[y] = any[y] || m != 0;
        }
    });
    return std::find(any.begin(), any.end(), std::uint8_t{1}) != any.end();
}

}  // namespace detail

// The dropped pixels of a w x h frame of k buffers (2 <= k <= 64), row-major into `out`, the
// black buffers given by black_at(x, y): a std::uint64_t whose bit i is set where buffer i is
// black at a partly black pixel (some buffers black, the others finite and not black), 0
// elsewhere (a bit past k, or all k set, counts as 0); taken row by row across the executor,
// no window pass where there is none.
// alpha: the frame's promise (Bonferroni's level over the pairs). Returns the pairs tested.
template <class BlackAt>
std::size_t find_dropped_masks(int w, int h, int k, double alpha, BlackAt&& black_at, dropped_scratch& s,
                               const executor& exec, std::vector<dropped_pixel>& out) {
    out.clear();
    // Bits past k name no buffer, and a pixel black in all k is not partly black: both are
    // taken out of what black_at gives (a stray bit was counted past the strip's arrays).
    const std::uint64_t all = k >= 64 ? ~std::uint64_t{0} : k <= 0 ? 0 : (std::uint64_t{1} << k) - 1;
    auto partly = [&](int x, int y) {
        const std::uint64_t m = static_cast<std::uint64_t>(black_at(x, y)) & all;
        return m == all ? std::uint64_t{0} : m;
    };
    if (k <= 8)
        return detail::fill_black_masks(w, h, partly, s.lone, exec)
                   ? detail::find_dropped_in(s.lone.data(), w, h, k, alpha, s, exec, out)
                   : 0;
    return detail::fill_black_masks(w, h, partly, s.wide, exec)
               ? detail::find_dropped_in(s.wide.data(), w, h, k, alpha, s, exec, out)
               : 0;
}

// The same for a frame whose partly black pixels are all lone blacks, given by lone_at(x, y):
// 0 where no buffer is, else 1 + the buffer that is (a value past k counts as 0).
template <class LoneAt>
std::size_t find_dropped(int w, int h, int k, double alpha, LoneAt&& lone_at, dropped_scratch& s, const executor& exec,
                         std::vector<dropped_pixel>& out) {
    auto black_at = [&](int x, int y) -> std::uint64_t {
        const int l = static_cast<int>(lone_at(x, y));
        return l >= 1 && l <= k && l <= 64 ? std::uint64_t{1} << (l - 1) : 0;
    };
    return find_dropped_masks(w, h, k, alpha, black_at, s, exec, out);
}

// The same from a frame of lone-black codes (lone[p] as lone_at's).
inline std::size_t find_dropped(const std::uint8_t* lone, int w, int h, int k, double alpha, dropped_scratch& s,
                                const executor& exec, std::vector<dropped_pixel>& out) {
    const std::size_t row = static_cast<std::size_t>(w);
    return find_dropped(
        w, h, k, alpha, [&](int x, int y) { return lone[static_cast<std::size_t>(y) * row + static_cast<std::size_t>(x)]; }, s,
        exec, out);
}

}  // namespace firefly
