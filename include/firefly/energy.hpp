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
// they fall densely, as in a caustic lit mostly by them; two halves take the median twice,
// which drops windows where fireflies crowd by chance: shape_profile), G a Gaussian of sigma
// pixels (normalised weights w):
//     M = G * e,  L = G * P,  ratio = min(M / L, 1),  returned(p) = s(p) ratio(p) P(p)
// s is the positive-part James-Stein factor of M: V = sum_q w_q^2 e_q^2 (channel sums) is the
// variance M would have if each e_q were one draw of a sparse process, so
//     s = max(0, 1 - V / |M|^2)
// keeps M where many fireflies agree on it and drops it where one or two make it up: a lone
// firefly (V = |M|^2) returns nothing, so no glow is painted around it.
//
// Two scales: where fireflies are sparse (one or two in a fine window), the fine sums are mostly
// noise and s drops them, yet their light was spread evenly and the frame still comes out low
// (after a denoiser, that bias is most of what is left). A second Gaussian, sigma_c wide (32 by
// default), sees enough of them; a node takes it where the fine sums agree with what its ratio
// predicts for them, within the noise the fine sums would have if the coarse window's relative
// excess |e| / |P| were spread evenly (Lepski's rule: the widest scale the narrow one cannot
// tell apart), so a caustic's clustered light stays where it fell. The return is added
// wherever it is positive: most of it is far below a pixel's noise, but it is a bias, which a
// denoiser's averaging leaves whole. At a pixel whose rebuild took light (a firefly's) it is
// at most that, channel by channel (return_energy_to_image): the return never brings a
// firefly back.
//
// Tried (1024x540 simulated scenes, relMSE): the cleaned image's median as the shape, with the
// ratio uncapped or the part of M above L added as a smooth field, returns the light of
// uniformly dense fireflies in full (dense10 0.030 -> 0.0025, dense30 0.29 -> 0.035-0.05), but
// smears clustered light off a caustic's edge onto the dark pixels beside it (the simulated
// caustics 0.032 -> 0.08-0.23), also with the James-Stein factor taken on M - L; the input's
// median with the cap at 4: caustics 0.051, dense30 0.53. No return onto pixels kept as both-half
// outliers: the Cycles interior 0.1154 -> 0.1152, the simulated interior 0.019 -> 0.024 (its
// bright region's share of the light is then never returned). Taken: none onto a half's pixel
// kept as a one-half outlier within its noise (pipeline.hpp leaves it out): that half
// kept its high draw and the rare light in it, so a return counted that light twice (1024x540:
// dense30 0.279 -> 0.267, the simulated interior 0.0190 -> 0.0185, the Cycles interior 0.1152
// -> 0.1130, the Cycles caustics 0.0248 -> 0.0244). Its other half gets the rest of the pair's
// share (within_share): the Cycles interior 0.1130 -> 0.1114, caustics 0.02441 -> 0.02429,
// the simulated interior 0.0185 -> 0.0182, dense30 0.267 -> 0.266. Tried: none onto that half
// either (the Cycles renders 0.1114 and 0.02426 alike, but the simulated caustics 1% higher on
// all seven frames measured: in a caustic lit by fireflies the kept half's excess is often
// below the pair's share). And a half of a kept pair that stands above a smooth neighbourhood
// holds its rise above it, of its own share (were they fireflies that met, the rise is their
// light; a highlight spot takes no glow onto its own light): the simulated caustics 0.02820 ->
// 0.02747, dense30 0.266 -> 0.259, the simulated interior 0.01817 -> 0.01808, the Cycles
// caustics 0.02429 -> 0.02426, interior unchanged (0.1114); the highlight scenes' spots
// unchanged to 4 digits. Tried: the return shaped by the pixel's own value, a pixel above P
// taking only what lifts it to P plus its share (the least-squares step toward its expected
// value within [0, share]): relMSE far lower (the Cycles interior 0.1114 -> 0.0954, caustics
// 0.0243 -> 0.0223, the simulated interior 0.0181 -> 0.0136), but the frame keeps 1-6% less
// light, and after NL-means 14 of 23 frames came out worse (the simulated interior 0.00018 ->
// 0.0020); with the light it withheld given to the other pixels (one scale per frame, the
// totals kept) still 15 of 23 (dense fireflies 5.2e-5 -> 1.2e-4, fine detail 4.4e-4 ->
// 7.5e-4): a denoiser averages away the noise this removes and keeps the bias it moves.
//
// Evaluation: s ratio is smooth at the Gaussian's scale, so M, L and V are summed exactly (the
// separable Gaussian, taps to 3 sigma, V with the squared taps) only at nodes every
// node_step(sigma) pixels (sigma / 2, a power of two), and s ratio is interpolated bilinearly
// between nodes: a fraction of the work of full blurs, and a lone firefly still has s = 0 at
// every node. Nodes are placed symmetrically, every sum adds opposite taps first
// (v[-i] + v[+i]), and the separable sums run along the frame's shorter axis first (a
// transposed frame's shorter axis is the other one: it takes the same sums in the same order),
// on a square frame in both orders, averaged; the interpolation is the mean of both orders:
// a flipped or transposed frame gives the flipped or transposed result bit for bit. (Both
// orders on every frame cost ~15% more of a 2K frame's pipeline for no accuracy.)
// The coarse sums are box sums over odd cells (a quarter of sigma_c, symmetric about the
// frame's centre) and a Gaussian over the cells, read at the nodes with integer bilinear
// weights, in the same orders. Arithmetic in double: a 1e30 excess squared stays finite.
#pragma once

#include <algorithm>
#include <cfloat>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#endif

#include "fused.hpp"
#include "image_view.hpp"
#include "parallel.hpp"
#include "status.hpp"

// The flip and transpose invariants hold where multiply and add are fused within an expression
// (fused.hpp). Clang's -ffp-contract=fast fuses across statements too, differently in the
// two orders' loops (transposed frames then differed in the last bit at -O3): this header asks
// for contraction within expressions, Clang's default, and gives the includer's setting back at
// its end. (GCC's fusing across statements keeps the invariants: the energy_fma test.)
#ifdef FIREFLY_DETAIL_CLANG_FP_PRAGMAS
#pragma float_control(push)
#pragma clang fp contract(on)
#endif

namespace firefly {

namespace detail {

// The order of the separable sums on a w x h frame: along the shorter axis first (y first on a
// landscape frame: a 2K pipeline 2.5-3.5% faster than x first, in alternated runs), both (their
// mean) on a square frame. A transpose swaps the axes and the order with them.
enum class sum_order : unsigned char { both, x_first, y_first };
inline sum_order sum_order_for(int w, int h) noexcept {
    return w == h ? sum_order::both : w > h ? sum_order::y_first : sum_order::x_first;
}

// The nodes the return is evaluated at along one axis of n pixels: every `step` pixels (a
// power of two), symmetric about the axis' centre, the first at or before pixel 0 and the last
// at or after pixel n - 1. Positions are kept doubled (pos2 = 2 x), so a node between two
// pixels (half-integer) is exact.
struct node_axis {
    int pixels = 1, count = 1, step = 1;
    int pos2(int j) const noexcept { return (pixels - 1) + (2 * j - (count - 1)) * step; }
};

inline node_axis make_node_axis(int pixels, int step) {
    node_axis a;
    a.pixels = pixels;
    a.step = step;
    a.count = (pixels - 1 + step - 1) / step + 1;  // (count - 1) step >= pixels - 1
    return a;
}

// Cells of an odd `width` along an axis of n pixels, centred on pixels and symmetric about the
// axis' centre; centre of cell j at pixel c(j) = ((n - 1) + (2 j - (count - 1)) width) / 2.
struct cell_axis {
    int pixels = 1, count = 1, width = 1;
    int centre2(int j) const noexcept { return (pixels - 1) + (2 * j - (count - 1)) * width; }  // doubled
};

inline cell_axis make_cell_axis(int pixels, int width) {
    cell_axis a;
    a.pixels = pixels;
    a.width = width;
    a.count = (pixels + width - 1) / width;
    if ((a.count - pixels) % 2 != 0) ++a.count;  // same parity: centres on pixels
    return a;
}

// The largest power of two at most sigma / 2 (at least 1): a Gaussian of that width varies
// little between nodes that far apart (linear interpolation's error at a peak ~ step^2 /
// (8 sigma^2) <= 1/32), and a power of two keeps the interpolation weights exact.
inline int node_step(double sigma) {
    int s = 1;
    while (2.0 * s <= sigma / 2.0) s *= 2;
    return s;
}

// The record of the model's sums at a pixel or node: M (3 channels), L (3), V, and (coarse
// scale only, else 0) the relative V: the sum of w^2 |e|^2 / |P|^2.
inline constexpr int record = 8;

// Gaussian tap weights for one node parity: offsets d (integer node) or d + 1/2 (a node
// between pixels), d = 0..r; normalised so that the taps on both sides sum to 1. `sq`: the
// weights squared, for the sum of squared weights of the James-Stein factor. `rec`: each tap's
// weights of a record's values (w on M and L, sq on V and the relative V), record after record:
// one weight per value lets the sums run on whole records at a time (they vectorise).
// `profile`, `excess`: the same for a record's parts summed apart, L (3 values: w) and M, V (4
// values: w, w, w, sq; see excess_map).
struct tap_weights {
    std::vector<double> w, sq, rec, profile, excess;
    bool half = false;
};

inline void set_record_weights(tap_weights& t) {
    t.rec.resize(t.w.size() * record);
    t.profile.resize(t.w.size() * 3);
    t.excess.resize(t.w.size() * 4);
    for (std::size_t d = 0; d < t.w.size(); ++d) {
        for (std::size_t k = 0; k < record; ++k) t.rec[d * record + k] = k < 6 ? t.w[d] : t.sq[d];
        for (std::size_t k = 0; k < 3; ++k) t.profile[d * 3 + k] = t.excess[d * 4 + k] = t.w[d];
        t.excess[d * 4 + 3] = t.sq[d];
    }
}

inline tap_weights make_taps(double sigma, int r, bool offset_half) {
    tap_weights t;
    t.half = offset_half;
    t.w.resize(static_cast<std::size_t>(r) + 1);
    double sum = 0;
    for (int d = 0; d <= r; ++d) {
        const double o = d + (offset_half ? 0.5 : 0.0);
        t.w[static_cast<std::size_t>(d)] = std::exp(-0.5 * o * o / (sigma * sigma));
        sum += (d == 0 && !offset_half) ? t.w[0] : 2.0 * t.w[static_cast<std::size_t>(d)];
    }
    t.sq.resize(t.w.size());
    for (std::size_t d = 0; d < t.w.size(); ++d) {
        t.w[d] /= sum;
        t.sq[d] = t.w[d] * t.w[d];
    }
    set_record_weights(t);
    return t;
}

// The positions a node's tap d reads (doubled position p2): lo and hi pixel, -1 outside.
struct tap_pair {
    int lo, hi;
};
inline tap_pair taps_at(int p2, int d, bool offset_half, int n) noexcept {
    const int o2 = 2 * d + (offset_half ? 1 : 0);
    const int lo = (p2 - o2) / 2, hi = (p2 + o2) / 2;  // p2 -+ o2 is even
    return {p2 - o2 >= 0 && lo < n ? lo : -1, hi >= 0 && hi < n ? hi : -1};
}

// std::min and std::max of four floats a lane, with their operand order (so the same value
// whichever of a tie, -0 or NaN it meets): std::min(a, b) is b < a ? b : a, SSE2's min(b, a);
// std::max(a, b) is a < b ? b : a, SSE2's max(b, a). Where the target has neither SSE2 nor
// NEON, the scalar loops do the work.
#if defined(__SSE2__) || defined(_M_X64)
#define FIREFLY_DETAIL_LANES4 1
using f4 = __m128;
inline f4 load4(const float* p) noexcept { return _mm_loadu_ps(p); }
inline void store4(float* p, f4 v) noexcept { _mm_storeu_ps(p, v); }
inline f4 min4(f4 a, f4 b) noexcept { return _mm_min_ps(b, a); }
inline f4 max4(f4 a, f4 b) noexcept { return _mm_max_ps(b, a); }
#elif defined(__ARM_NEON) && defined(__aarch64__)
#define FIREFLY_DETAIL_LANES4 1
using f4 = float32x4_t;
inline f4 load4(const float* p) noexcept { return vld1q_f32(p); }
inline void store4(float* p, f4 v) noexcept { vst1q_f32(p, v); }
inline f4 min4(f4 a, f4 b) noexcept { return vbslq_f32(vcltq_f32(b, a), b, a); }
inline f4 max4(f4 a, f4 b) noexcept { return vbslq_f32(vcltq_f32(a, b), b, a); }
#endif

// The median of the 3x3 windows of three rows of n values (3 interleaved channels: the window
// of value i takes i - 3, i, i + 3 of each row), at i in [3, n - 3), into o. Each column of 3 is
// sorted once and the median of the 9 is the median of (the largest column minimum, the median
// column median, the smallest column maximum): min and max only select, so the value is the
// 9's median exactly. lo, mid, hi: scratch of n values. (Loops split so that each vectorises
// where the compiler does it, -O3; float, the profile's type, by hand four lanes at a time, so
// that -O2 builds, whose cost model leaves these loops scalar, select as fast.)
template <class M>
inline void median3x3_columns(const M* up, const M* here, const M* down, std::size_t i, std::size_t n, M* lo, M* hi) {
    for (; i < n; ++i) {
        lo[i] = (std::min)((std::min)(up[i], here[i]), down[i]);
        hi[i] = (std::max)((std::max)(up[i], here[i]), down[i]);
    }
}
template <class M>
inline void median3x3_middles(const M* up, const M* here, const M* down, std::size_t i, std::size_t n, M* mid) {
    for (; i < n; ++i) mid[i] = (std::max)((std::min)(up[i], here[i]), (std::min)((std::max)(up[i], here[i]), down[i]));
}
template <class M>
inline void median3x3_rows_of(const M* lo, const M* mid, const M* hi, std::size_t i, std::size_t n, M* o) {
    for (; i + 3 < n; ++i) {
        const M l = (std::max)((std::max)(lo[i - 3], lo[i]), lo[i + 3]);
        const M u = (std::min)((std::min)(hi[i - 3], hi[i]), hi[i + 3]);
        const M m0 = mid[i - 3], m1 = mid[i], m2 = mid[i + 3];
        const M m = (std::max)((std::min)(m0, m1), (std::min)((std::max)(m0, m1), m2));
        o[i] = (std::max)((std::min)(l, m), (std::min)((std::max)(l, m), u));
    }
}
template <class M>
inline void median3x3_interior(const M* up, const M* here, const M* down, std::size_t n, M* lo, M* mid, M* hi,
                               M* o) {
    std::size_t i = 0;  // where the scalar loops start
#if defined(FIREFLY_DETAIL_LANES4)
    if constexpr (std::is_same_v<M, float>)
        for (; i + 4 <= n; i += 4) {
            const f4 u = load4(up + i), h = load4(here + i), d = load4(down + i);
            store4(lo + i, min4(min4(u, h), d));
            store4(hi + i, max4(max4(u, h), d));
            store4(mid + i, max4(min4(u, h), min4(max4(u, h), d)));
        }
#endif
    median3x3_columns(up, here, down, i, n, lo, hi);
    median3x3_middles(up, here, down, i, n, mid);
    i = 3;  // every column sorted: the windows
#if defined(FIREFLY_DETAIL_LANES4)
    if constexpr (std::is_same_v<M, float>)
        for (; i + 7 <= n; i += 4) {  // the last lane's i + 3 inside
            const f4 l = max4(max4(load4(lo + i - 3), load4(lo + i)), load4(lo + i + 3));
            const f4 u = min4(min4(load4(hi + i - 3), load4(hi + i)), load4(hi + i + 3));
            const f4 m0 = load4(mid + i - 3), m1 = load4(mid + i), m2 = load4(mid + i + 3);
            const f4 m = max4(min4(m0, m1), min4(max4(m0, m1), m2));
            store4(o + i, max4(min4(l, m), min4(max4(l, m), u)));
        }
#endif
    median3x3_rows_of(lo, mid, hi, i, n, o);
}

// The 3x3 medians of a w x h image (3 interleaved channels) row by row, from input rows that
// `fill_row(y, out)` writes (3 w finite values) into `out` as they are needed: a ring of the
// last three input rows, made once each while rows are asked for in order (a row not in the
// ring is made again: ask in order). At the frame's edge the median of the pixels inside it,
// the mean of the middle two where they are even in number; inside it median3x3_interior.
// Inside the frame the values are first taken to T (held at T's largest): rounding is
// monotone, so the median of the rounded values is the rounded median, and a float profile is
// selected in float lanes (twice as many a register). A zero comes out +0 (-0 and a positive
// double below float's least denormal both round to a zero of T, and a selection among tied
// zeros could return either sign).
template <class T>
class median3x3_stream {
public:
    // Starts a pass over a w x h image: no row is held.
    void begin(int w, int h) {
        w_ = w, h_ = h, n_ = static_cast<std::size_t>(w) * 3;
        ring_.resize(3 * n_), ring_t_.resize(3 * n_), lo_.resize(n_), mid_.resize(n_), hi_.resize(n_);
        held_[0] = held_[1] = held_[2] = -1;
    }
    // Row y of the medians into o (3 w values).
    template <class FillRow>
    void row(int y, FillRow&& fill_row, T* o) {
        const int y0 = (std::max)(0, y - 1), y1 = (std::min)(h_ - 1, y + 1);
        for (int yy = y0; yy <= y1; ++yy) make(yy, fill_row);
        if (y == 0 || y == h_ - 1 || w_ < 3) {
            for (int x = 0; x < w_; ++x)
                for (int c = 0; c < 3; ++c) o[static_cast<std::size_t>(x) * 3 + static_cast<std::size_t>(c)] = put(edge(y, x, c));
            return;
        }
        median3x3_interior(line_t(y - 1), line_t(y), line_t(y + 1), n_, lo_.data(), mid_.data(), hi_.data(), o);
        for (int c = 0; c < 3; ++c) {
            o[c] = put(edge(y, 0, c));
            o[static_cast<std::size_t>(w_ - 1) * 3 + static_cast<std::size_t>(c)] = put(edge(y, w_ - 1, c));
        }
    }

private:
    // a median past the range of T (a float profile of a 2 FLT_MAX sum) is kept at its
    // largest; + 0 makes a zero +0
    static T put(double v) {
        return static_cast<T>(static_cast<T>((std::min)(v, static_cast<double>((std::numeric_limits<T>::max)()))) + T(0));
    }
    double* line(int yy) { return &ring_[static_cast<std::size_t>(yy % 3) * n_]; }
    T* line_t(int yy) { return &ring_t_[static_cast<std::size_t>(yy % 3) * n_]; }
    template <class FillRow>
    void make(int yy, FillRow& fill_row) {  // (a double image's T ring is a copy with zeros made +0)
        if (held_[yy % 3] == yy) return;
        double* r = line(yy);
        fill_row(yy, r);
        T* t = line_t(yy);
        for (std::size_t i = 0; i < n_; ++i) t[i] = put(r[i]);
        held_[yy % 3] = yy;
    }
    double edge(int y, int x, int c) {
        double t[9] = {};
        int k = 0;
        for (int yy = (std::max)(0, y - 1); yy <= (std::min)(h_ - 1, y + 1); ++yy)
            for (int xx = (std::max)(0, x - 1); xx <= (std::min)(w_ - 1, x + 1); ++xx)
                t[k++] = line(yy)[static_cast<std::size_t>(xx) * 3 + static_cast<std::size_t>(c)];
        std::nth_element(t, t + k / 2, t + k);
        double m = t[k / 2];
        if (k % 2 == 0) m = 0.5 * (m + *std::max_element(t, t + k / 2));  // mean of the middle two
        return m;
    }
    int w_ = 0, h_ = 0;
    std::size_t n_ = 0;
    int held_[3] = {-1, -1, -1};  // the input row each ring slot holds
    std::vector<double> ring_;    // as double (the edges) and as T (the interior)
    std::vector<T> ring_t_, lo_, mid_, hi_;
};

// Bands of rows as tasks: body(first, last) for each band of 16 rows. The callers take each
// band's rows in order through a median3x3_stream per thread (kept: a row's allocation freed
// and taken again costs page faults when the allocator returns it to the system), started at
// the band.
template <class Body>
inline void for_each_band_in_order(int h, const executor& exec, Body&& body) {
    constexpr int band = 16;
    exec.run(static_cast<std::size_t>((h + band - 1) / band), [&](std::size_t bi) {
        const int first = static_cast<int>(bi) * band;
        body(first, (std::min)(h, first + band));
    });
}

// 3x3 median of each of 3 interleaved channels of a w x h image whose rows `fill_row(y, out)`
// writes (3 w finite values) into `out` (median3x3_stream): no frame-sized copy of the input.
template <class T, class FillRow>
inline void median3x3_rows(FillRow&& fill_row, std::vector<T>& out, int w, int h, const executor& exec) {
    const std::size_t n = static_cast<std::size_t>(w) * 3;
    out.resize(n * static_cast<std::size_t>(h));
    for_each_band_in_order(h, exec, [&](int first, int last) {
        thread_local median3x3_stream<T> stream;
        stream.begin(w, h);
        for (int y = first; y < last; ++y) stream.row(y, fill_row, &out[static_cast<std::size_t>(y) * n]);
    });
}

// The 3x3 median of the 3x3 median, the same way: the first median's rows made as the second
// asks for them (a band's first and last row take two of its rows more), in T as a frame of
// the first median would hold them; nothing frame-sized but `out`.
template <class T, class FillRow>
inline void median3x3_twice_rows(FillRow&& fill_row, std::vector<T>& out, int w, int h, const executor& exec) {
    const std::size_t n = static_cast<std::size_t>(w) * 3;
    out.resize(n * static_cast<std::size_t>(h));
    for_each_band_in_order(h, exec, [&](int first, int last) {
        thread_local median3x3_stream<T> once, twice;
        thread_local std::vector<T> row_once;
        once.begin(w, h), twice.begin(w, h);
        row_once.resize(n);
        auto first_median = [&](int y, double* row) {
            once.row(y, fill_row, row_once.data());
            for (std::size_t i = 0; i < n; ++i) row[i] = static_cast<double>(row_once[i]);
        };
        for (int y = first; y < last; ++y) twice.row(y, first_median, &out[static_cast<std::size_t>(y) * n]);
    });
}

// The same over an image held whole (3 interleaved channels, w x h).
inline void median3x3(const std::vector<double>& in, std::vector<double>& out, int w, int h, const executor& exec) {
    const std::size_t n = static_cast<std::size_t>(w) * 3;
    median3x3_rows([&](int y, double* row) { std::copy_n(&in[static_cast<std::size_t>(y) * n], n, row); }, out, w, h,
                   exec);
}

// One pixel of removed excess: its column, and the M and V values of its record (e, 3
// channels, and |e|^2), in double.
struct excess_pixel {
    int x;
    double v[4];
};

// |e|^2 of one pixel's 3 channels, in double (written once: both orders square alike).
template <class E>
inline double squared(const E* e) noexcept {
    const double a = static_cast<double>(e[0]), b = static_cast<double>(e[1]), c = static_cast<double>(e[2]);
    return a * a + b * b + c * c;
}

// The record of column x holding excess e (3 channels).
template <class E>
inline excess_pixel excess_at(int x, const E* e) noexcept {
    return {x, {static_cast<double>(e[0]), static_cast<double>(e[1]), static_cast<double>(e[2]), squared(e)}};
}

// Where the removed excess is: the pixels where it is not 0, row after row (x ascending).
// Elsewhere the M and V sums get terms of +-0, and a sum begun at +0 stays +0 bit for bit
// under such terms (x + -0 = x; a sum reaches -0 only from -0 + -0): the sums run over these
// pixels alone, in the taps' order, with the same bits.
struct excess_map {
    std::vector<std::size_t> start;  // h + 1: row y's pixels are [start[y], start[y + 1])
    std::vector<excess_pixel> pixels;
    const excess_pixel* first(int y) const noexcept { return pixels.data() + start[static_cast<std::size_t>(y)]; }
    const excess_pixel* last(int y) const noexcept { return pixels.data() + start[static_cast<std::size_t>(y) + 1]; }
    std::size_t bytes() const noexcept {
        return start.capacity() * sizeof(std::size_t) + pixels.capacity() * sizeof(excess_pixel);
    }
};

}  // namespace detail

// Work arrays of the energy return, kept between frames. Frame-sized: the profile; the rest is
// per node, per row or per excess pixel.
struct energy_scratch {
    std::vector<float> profile;         // the shape's 3x3 median (two halves: taken twice), full
                                        // frame (float: half the memory; every sum is in double)
    std::vector<double> xy;             // the nodes' records, in sum_order_for's order (square
                                        // frames: x first, then the mean of both orders)
    std::vector<double> factor;         // the nodes: the return's share of the profile, 3
    detail::node_axis ax, ay;           // where the nodes are
    std::vector<std::uint32_t> order;   // return_energy_to_image: its list in pixel order
    std::vector<std::uint32_t> untaken; // ... and its pixels whose rebuild took nothing (ascending)
    std::vector<double> row_returned;   // each row's light added back (summed in row order)
    std::vector<double> cells, coarse;  // the coarse scale: cell sums, their Gaussian (empty: off)
    detail::cell_axis cx, cy;           // where the cells are
    double coarse_var_scale = 0;        // sum w_fine^2 / sum w_coarse^2 (per pixel weights)
    detail::excess_map where;           // the excess pixels
    std::size_t bytes() const noexcept {
        return profile.capacity() * sizeof(float) + where.bytes() +
               (xy.capacity() + factor.capacity() + cells.capacity() + coarse.capacity()) * sizeof(double) +
               row_returned.capacity() * sizeof(double) + (order.capacity() + untaken.capacity()) * sizeof(std::uint32_t);
    }
};

namespace detail {

// The excess_map of a frame's excess into m (its memory kept from frame to frame).
template <class E>
inline void map_excess(const std::vector<E>& excess, int w, int h, excess_map& m, const executor& exec) {
    m.start.assign(static_cast<std::size_t>(h) + 1, 0);
    const std::size_t n1 = static_cast<std::size_t>(w);
    auto counts = [&](std::size_t y, std::size_t x) {
        const E* e = &excess[(y * n1 + x) * 3];
        return (e[0] != E(0)) | (e[1] != E(0)) | (e[2] != E(0));
    };
    exec.run(static_cast<std::size_t>(h), [&](std::size_t y) {
        std::size_t k = 0;
        for (std::size_t x = 0; x < n1; ++x) k += counts(y, x) ? 1u : 0u;
        m.start[y + 1] = k;
    });
    for (std::size_t y = 0; y < static_cast<std::size_t>(h); ++y) m.start[y + 1] += m.start[y];
    m.pixels.resize(m.start.back());
    exec.run(static_cast<std::size_t>(h), [&](std::size_t y) {
        excess_pixel* o = m.pixels.data() + m.start[y];
        for (std::size_t x = 0; x < n1; ++x) {
            if (!counts(y, x)) continue;
            *o++ = excess_at(static_cast<int>(x), &excess[(y * n1 + x) * 3]);
        }
    });
}

// One row of the model's inputs as records (at out + x record): e (3 channels, from the
// excess_map: +0 where nothing was removed), the profile (3), |e|^2, 0; every value in double.
template <class P>
inline void input_records(const excess_map& where, const P* pr, int y, int w, double* out) noexcept {
    for (int x = 0; x < w; ++x) {
        const std::size_t q = static_cast<std::size_t>(x) * 3;
        double* o = out + static_cast<std::size_t>(x) * record;
        for (std::size_t c = 0; c < 3; ++c) {
            o[c] = 0.0;
            o[3 + c] = static_cast<double>(pr[q + c]);
        }
        o[6] = o[7] = 0.0;
    }
    for (const excess_pixel* e = where.first(y); e != where.last(y); ++e) {
        double* o = out + static_cast<std::size_t>(e->x) * record;
        for (std::size_t c = 0; c < 3; ++c) o[c] = e->v[c];
        o[6] = e->v[3];
    }
}

// One tap of record_sums into sum (K values), with the tap's weights wk. Opposite taps are
// added first (a + b): a mirrored line gives the mirrored result bit for bit.
template <int K>
inline void add_tap(double* sum, const double* wk, const double* a) noexcept {  // the centre
    for (int k = 0; k < K; ++k) sum[k] += wk[k] * a[k];
}
template <int K>
inline void add_tap(double* sum, const double* wk, const double* a, const double* b) noexcept {
    for (int k = 0; k < K; ++k) sum[k] += wk[k] * (a[k] + b[k]);
}
inline constexpr double zero_record[record] = {};  // the side of a tap outside the frame: x + 0

// The sums at node p2 along a line of n records of K values (record i at line + i stride): the
// separable Gaussian's taps, `weights` K per tap (a tap_weights' rec, profile or excess), each
// value taken in double.
template <int K>
inline void tap_sums(int p2, const tap_weights& tw, const double* weights, int n, const double* line,
                     std::size_t stride, double* out) noexcept {
    double sum[static_cast<std::size_t>(K)] = {};
    auto rec = [&](int i) { return line + static_cast<std::size_t>(i) * stride; };
    auto wk = [&](std::size_t d) { return weights + d * K; };
    const int r = static_cast<int>(tw.w.size()) - 1, shift = tw.half ? 1 : 0;
    const int lo = (p2 - shift) / 2, hi = (p2 + shift) / 2;  // tap 0's pixels (p2 - shift is even)
    if (lo - r >= 0 && hi + r < n) {  // every tap inside the line (most nodes): no tests
        const double *a = rec(lo), *b = rec(hi);
        std::size_t d = 0;
        if (!tw.half) add_tap<K>(sum, wk(0), a), d = 1;  // the centre: counted once
        for (; d < tw.w.size(); ++d) add_tap<K>(sum, wk(d), a - d * stride, b + d * stride);
    } else {
        for (std::size_t d = 0; d < tw.w.size(); ++d) {
            const tap_pair p = taps_at(p2, static_cast<int>(d), tw.half, n);
            if (p.lo < 0 && p.hi < 0) continue;  // a node outside the frame: no centre pixel
            if (d == 0 && !tw.half)
                add_tap<K>(sum, wk(d), rec(p.lo));
            else if (p.lo >= 0 && p.hi >= 0)
                add_tap<K>(sum, wk(d), rec(p.lo), rec(p.hi));
            else
                add_tap<K>(sum, wk(d), rec(p.lo >= 0 ? p.lo : p.hi), zero_record);
        }
    }
    std::copy_n(sum, K, out);
}

// The record at node p2 along a line of n whole records: M and L with the taps, V with the
// squared taps.
inline void record_sums(int p2, const tap_weights& tw, int n, const double* line, std::size_t stride,
                        double* out) noexcept {
    tap_sums<record>(p2, tw, tw.rec.data(), n, line, stride, out);
}

// M and V (4 values: excess_pixel::v) of record_sums at node p2 along a row, from the row's
// excess pixels [first, last) alone (excess_map): the taps nearest first, as record_sums adds
// them, a tap whose two pixels hold no excess skipped.
inline void excess_sums(int p2, const tap_weights& tw, const excess_pixel* first, const excess_pixel* last,
                        double* out) noexcept {
    double sum[4] = {};
    const int r = static_cast<int>(tw.w.size()) - 1, shift = tw.half ? 1 : 0;
    const int lo = (p2 - shift) / 2, hi = (p2 + shift) / 2;
    const excess_pixel* right = std::lower_bound(first, last, hi, [](const excess_pixel& e, int x) { return e.x < x; });
    const excess_pixel* left = right;  // the left side: left[-1], left[-2], ... (x <= lo)
    if (!tw.half && right != last && right->x == lo) add_tap<4>(sum, &tw.excess[0], right->v), ++right;
    for (;;) {
        const int dl = left != first && lo - left[-1].x <= r ? lo - left[-1].x : r + 1;
        const int dr = right != last && right->x - hi <= r ? right->x - hi : r + 1;
        const int d = (std::min)(dl, dr);
        if (d > r) break;
        const double* wk = &tw.excess[static_cast<std::size_t>(d) * 4];
        if (dl == dr)
            add_tap<4>(sum, wk, left[-1].v, right->v), --left, ++right;
        else if (dl < dr)
            add_tap<4>(sum, wk, left[-1].v, zero_record), --left;
        else
            add_tap<4>(sum, wk, right->v, zero_record), ++right;
    }
    std::copy_n(sum, 4, out);
}

// The L values (the profile, 3 channels) of pixels x0..x1 of one row into out + 3 x, in double.
template <class P>
inline void profile_line(const P* pr, int x0, int x1, double* out) noexcept {
    for (std::size_t q = static_cast<std::size_t>(x0) * 3; q < static_cast<std::size_t>(x1 + 1) * 3; ++q)
        out[q] = static_cast<double>(pr[q]);
}

// x first, a band of node columns at a time: every row's records at the band's columns (L from
// the row's stretch under the band, taken to double once for all of them; M and V from the
// row's excess pixels), then along y at the node rows. Nothing frame-sized.
template <class P>
inline void energy_x_then_y(const std::vector<P>& profile, const excess_map& where,
                            int w, int h, const node_axis& ax, const node_axis& ay, const tap_weights (&t)[2],
                            energy_scratch& s, const executor& exec) {
    const std::size_t nx = static_cast<std::size_t>(ax.count), hh = static_cast<std::size_t>(h);
    const int reach = static_cast<int>(t[0].w.size());  // pixels from a node to its last tap, at most
    constexpr std::size_t band = 64;  // node columns a task: a row's 6 sigma overlap shared by more
    s.xy.resize(static_cast<std::size_t>(ay.count) * nx * record);
    exec.run((nx + band - 1) / band, [&](std::size_t bi) {
        const std::size_t j0 = bi * band, j1 = (std::min)(nx, j0 + band);
        const int x0 = (std::max)(0, ax.pos2(static_cast<int>(j0)) / 2 - reach);
        const int x1 = (std::min)(w - 1, ax.pos2(static_cast<int>(j1 - 1)) / 2 + reach);
        thread_local std::vector<double> line, columns;  // per thread, kept (see median3x3_rows)
        line.resize(static_cast<std::size_t>(w) * 3);
        columns.resize((j1 - j0) * hh * record);
        for (std::size_t y = 0; y < hh; ++y) {
            profile_line(&profile[y * static_cast<std::size_t>(w) * 3], x0, x1, line.data());
            const excess_pixel *first = where.first(static_cast<int>(y)), *last = where.last(static_cast<int>(y));
            for (std::size_t j = j0; j < j1; ++j) {
                const int p2 = ax.pos2(static_cast<int>(j));
                const tap_weights& tw = t[(p2 & 1) != 0];
                double* o = &columns[((j - j0) * hh + y) * record];
                double mv[4];
                tap_sums<3>(p2, tw, tw.profile.data(), w, line.data(), 3, o + 3);
                excess_sums(p2, tw, first, last, mv);
                o[0] = mv[0], o[1] = mv[1], o[2] = mv[2], o[6] = mv[3], o[7] = 0.0;
            }
        }
        for (std::size_t j = j0; j < j1; ++j)
            for (int i = 0; i < ay.count; ++i) {
                const int q2 = ay.pos2(i);
                record_sums(q2, t[(q2 & 1) != 0], h, &columns[(j - j0) * hh * record], record,
                            &s.xy[(static_cast<std::size_t>(i) * nx + j) * record]);
            }
    });
}

// Values q0..q1 of one row of sums along y (dst) at a node's tap p, weighted wd, from the rows
// `row(y)` of a source, each value taken to double. Whole rows at a time: it vectorises.
template <class Row>
inline void add_rows(double* dst, std::size_t q0, std::size_t q1, Row&& row, double wd, const tap_pair& p,
                     bool centre) {
    const auto* a = p.lo >= 0 ? row(p.lo) : nullptr;
    const auto* b = p.hi >= 0 ? row(p.hi) : nullptr;
    if (centre)
        for (std::size_t q = q0; q < q1; ++q) dst[q] += wd * static_cast<double>(a[q]);
    else if (a && b)
        for (std::size_t q = q0; q < q1; ++q) dst[q] += wd * (static_cast<double>(a[q]) + static_cast<double>(b[q]));
    else
        for (std::size_t q = q0; q < q1; ++q) dst[q] += wd * (static_cast<double>((a ? a : b)[q]) + 0.0);
}

// Tap d of the sums along y into m (3 channels) and v (|e|^2) of every column, from the excess
// pixels of rows p.lo and p.hi alone (excess_map), merged by column: each column's sums take
// their terms in the taps' order (d ascending), as add_rows adds them, without the zeros.
inline void add_excess_rows(double* m, double* v, const tap_weights& tw, std::size_t d, const tap_pair& p,
                            bool centre, const excess_map& where) noexcept {
    const excess_pixel *a = nullptr, *a_end = nullptr, *b = nullptr, *b_end = nullptr;
    if (p.lo >= 0) a = where.first(p.lo), a_end = where.last(p.lo);
    if (p.hi >= 0 && !centre) b = where.first(p.hi), b_end = where.last(p.hi);
    const double* wk = &tw.excess[d * 4];
    auto put = [&](int x, const double* sum) {
        for (std::size_t c = 0; c < 3; ++c) m[static_cast<std::size_t>(x) * 3 + c] = sum[c];
        v[x] = sum[3];
    };
    while (a != a_end || b != b_end) {
        const int xa = a != a_end ? a->x : INT_MAX, xb = b != b_end ? b->x : INT_MAX;
        const int x = (std::min)(xa, xb);
        double sum[4] = {m[static_cast<std::size_t>(x) * 3], m[static_cast<std::size_t>(x) * 3 + 1],
                         m[static_cast<std::size_t>(x) * 3 + 2], v[x]};
        if (centre)
            add_tap<4>(sum, wk, (a++)->v);
        else if (xa == xb)
            add_tap<4>(sum, wk, (a++)->v, (b++)->v);
        else
            add_tap<4>(sum, wk, xa < xb ? (a++)->v : (b++)->v, zero_record);
        put(x, sum);
    }
}

// The sums along y at node row p2 (taps tw) for every column, as records in `line`: L from every
// tap's rows, M and V only from the pixels holding excess.
template <class P>
inline void y_sums(int p2, const tap_weights& tw, int w, int h, const std::vector<P>& profile,
                   const excess_map& where, std::vector<double>& line) {
    const std::size_t n3 = static_cast<std::size_t>(w) * 3, n1 = static_cast<std::size_t>(w);
    auto profile_row = [&](int y) { return &profile[static_cast<std::size_t>(y) * n3]; };
    thread_local std::vector<double> m, l, v;  // per thread, kept (see median3x3_rows)
    m.assign(n3, 0.0), l.assign(n3, 0.0), v.assign(n1, 0.0);
    for (std::size_t d = 0; d < tw.w.size(); ++d) {
        const tap_pair p = taps_at(p2, static_cast<int>(d), tw.half, h);
        if (p.lo < 0 && p.hi < 0) continue;
        const bool centre = d == 0 && !tw.half;
        add_rows(l.data(), 0, n3, profile_row, tw.w[d], p, centre);
        add_excess_rows(m.data(), v.data(), tw, d, p, centre, where);
    }
    line.resize(n1 * record);
    for (std::size_t x = 0; x < n1; ++x) {
        double* o = &line[x * record];
        for (std::size_t c = 0; c < 3; ++c) {
            o[c] = m[x * 3 + c];
            o[3 + c] = l[x * 3 + c];
        }
        o[6] = v[x];
        o[7] = 0.0;
    }
}

// y first, a node row at a time: the sums along y for every column, then along x at the node
// columns. With x first, the two orders a transposed frame swaps; average: the mean of both
// into s.xy (x first already there), else this order's alone.
template <class P>
inline void energy_y_then_x(const std::vector<P>& profile, const excess_map& where, int w, int h,
                            const node_axis& ax, const node_axis& ay, const tap_weights (&t)[2], energy_scratch& s,
                            bool average, const executor& exec) {
    const std::size_t nx = static_cast<std::size_t>(ax.count), ny = static_cast<std::size_t>(ay.count);
    s.xy.resize(ny * nx * record);
    exec.run(ny, [&](std::size_t i) {
        thread_local std::vector<double> line;  // per thread, kept (see median3x3_rows)
        const int p2 = ay.pos2(static_cast<int>(i));
        y_sums(p2, t[(p2 & 1) != 0], w, h, profile, where, line);
        for (std::size_t j = 0; j < nx; ++j) {
            const int q2 = ax.pos2(static_cast<int>(j));
            double yx[record];
            record_sums(q2, t[(q2 & 1) != 0], w, line.data(), record, yx);
            double* xy = &s.xy[(i * nx + j) * record];  // x first, from energy_x_then_y (average)
            for (int k = 0; k < record; ++k) xy[k] = average ? 0.5 * (xy[k] + yx[k]) : yx[k];
        }
    });
}

// ---- The coarse scale (see the top of this file) -----------------------------------------------

// Unit taps over 2 radius + 1 pixels: record_sums with them is a box sum (1 x v is v exactly).
inline tap_weights box_taps(int radius) {
    tap_weights t;
    t.w.assign(static_cast<std::size_t>(radius) + 1, 1.0);
    t.sq = t.w;
    set_record_weights(t);
    return t;
}

// Box sums of every cell: excess (3), profile (3), |e|^2, |e|^2 / |P|^2 (P the profile; 0 where
// it is 0), in the given order (both: their mean).
template <class P>
inline void cell_sums(const std::vector<P>& profile, const excess_map& where,
                      int w, int h, const cell_axis& cx, const cell_axis& cy, sum_order order, std::vector<double>& cells,
                      const executor& exec) {
    const std::size_t ncx = static_cast<std::size_t>(cx.count), hw = static_cast<std::size_t>(cx.width / 2);
    const std::size_t n = static_cast<std::size_t>(w) * record;  // a row of records
    cells.assign(static_cast<std::size_t>(cy.count) * ncx * record, 0.0);
    exec.run(static_cast<std::size_t>(cy.count), [&](std::size_t jy) {
        thread_local std::vector<double> px, rows, cols;
        const int c0 = cy.centre2(static_cast<int>(jy)) / 2, y0 = c0 - static_cast<int>(hw);
        const int wc = cy.width;
        px.resize(static_cast<std::size_t>(wc) * n);
        for (int r = 0; r < wc; ++r) {  // the band's pixels as records (0 outside the frame)
            const int y = y0 + r;
            if (y < 0 || y >= h) {
                std::fill_n(&px[static_cast<std::size_t>(r) * n], n, 0.0);
                continue;
            }
            const std::size_t at = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) * 3;
            double* line = &px[static_cast<std::size_t>(r) * n];
            input_records(where, &profile[at], y, w, line);
            for (std::size_t x = 0; x < static_cast<std::size_t>(w); ++x) {
                double* o = line + x * record;
                if (!(o[6] > 0)) continue;  // o[7] stays 0
                const double p2 = o[3] * o[3] + o[4] * o[4] + o[5] * o[5];  // relative: |e|^2 / |P|^2
                o[7] = p2 > 0 ? (std::min)(o[6] / p2, DBL_MAX) : 0.0;
            }
        }
        const tap_weights box = box_taps(static_cast<int>(hw));
        const bool x_first = order != sum_order::y_first, y_first = order != sum_order::x_first;
        if (x_first) {  // each row of the band summed over each cell, then the rows
            rows.assign(static_cast<std::size_t>(wc) * ncx * record, 0.0);
            for (int r = 0; r < wc; ++r)
                for (std::size_t j = 0; j < ncx; ++j)
                    record_sums(cx.centre2(static_cast<int>(j)), box, w, &px[static_cast<std::size_t>(r) * n], record,
                                &rows[(static_cast<std::size_t>(r) * ncx + j) * record]);
        }
        if (y_first) {  // each column summed over the band's rows (rows outside the frame are 0
                        // records here, so the band is summed whole: the same as skipping them),
                        // then the cells
            cols.assign(n, 0.0);
            for (std::size_t x = 0; x < static_cast<std::size_t>(w); ++x)
                record_sums(2 * static_cast<int>(hw), box, wc, &px[x * record], n, &cols[x * record]);
        }
        for (std::size_t j = 0; j < ncx; ++j) {
            double a[record] = {}, b[record] = {};
            if (x_first) record_sums(2 * static_cast<int>(hw), box, wc, &rows[j * record], ncx * record, a);
            if (y_first) record_sums(cx.centre2(static_cast<int>(j)), box, w, cols.data(), record, b);
            double* cell = &cells[(jy * ncx + j) * record];
            for (int k = 0; k < record; ++k) cell[k] = !y_first ? a[k] : !x_first ? b[k] : 0.5 * (a[k] + b[k]);
        }
    });
}

// One pass of the coarse Gaussian over a grid of cell records (nx x ny), along x or along y.
inline void cell_pass(const std::vector<double>& src, std::vector<double>& dst, std::size_t nx, std::size_t ny,
                      bool along_x, const tap_weights& tw, const executor& exec) {
    dst.resize(src.size());
    const std::size_t lines = along_x ? ny : nx, n = along_x ? nx : ny;
    const std::size_t stride = along_x ? record : nx * record;  // from one cell of a line to the next
    exec.run(lines, [&](std::size_t line) {
        const std::size_t first = along_x ? line * nx * record : line * record;
        for (std::size_t i = 0; i < n; ++i)
            record_sums(2 * static_cast<int>(i), tw, static_cast<int>(n), &src[first], stride,
                        &dst[first + i * stride]);
    });
}

// The coarse Gaussian (taps over cells) of the cell records in the given order (both: their
// mean): out holds M, L (the cells' weights) and V (their squares) per cell.
inline void coarse_blur(const std::vector<double>& cells, const cell_axis& cx, const cell_axis& cy, const tap_weights& tw,
                        sum_order order, std::vector<double>& out, const executor& exec) {
    const std::size_t nx = static_cast<std::size_t>(cx.count), ny = static_cast<std::size_t>(cy.count);
    std::vector<double> pass, yx;
    if (order != sum_order::y_first) {  // x first
        cell_pass(cells, pass, nx, ny, true, tw, exec);
        cell_pass(pass, out, nx, ny, false, tw, exec);
    }
    if (order == sum_order::x_first) return;
    cell_pass(cells, pass, nx, ny, false, tw, exec);  // y first
    cell_pass(pass, order == sum_order::both ? yx : out, nx, ny, true, tw, exec);
    if (order == sum_order::both)
        for (std::size_t i = 0; i < out.size(); ++i) out[i] = 0.5 * (out[i] + yx[i]);
}

// The cell interval of doubled pixel position p2 and its integer weight k on the upper cell,
// out of 2 width (positions past the outer centres take the outer cell).
struct cell_lerp {
    int j = 0, k = 0;
};
inline cell_lerp cell_lerp_at(const cell_axis& a, int p2) noexcept {
    if (a.count == 1) return {};
    const int span = 2 * a.width, off = p2 - a.centre2(0);
    if (off <= 0) return {0, 0};
    const int j = (std::min)(off / span, a.count - 2);
    return {j, (std::min)(p2 - a.centre2(j), span)};
}

// Bilinear interpolation of four values f00 (x0, y0), f01 (x1, y0), f10, f11 with weights ax,
// bx along x and ay, by along y, the mean of the two orders (x first, y first): flips and
// transposes (which swap the weights) give the same bits (weighted_pair: a fa + b fb, fused the
// same way for either order of the pair).
inline double weighted_bilinear(double f00, double f01, double f10, double f11, double ax, double bx, double ay,
                                double by) noexcept {
    const double xy = weighted_pair(ay, by, weighted_pair(ax, bx, f00, f01), weighted_pair(ax, bx, f10, f11));
    const double yx = weighted_pair(ax, bx, weighted_pair(ay, by, f00, f10), weighted_pair(ay, by, f01, f11));
    return 0.5 * (xy + yx);
}

// The coarse record at doubled pixel position (px2, py2): bilinear over the four cells, integer
// weights (out of 2 width along each axis): mirrored positions give the same bits.
inline void coarse_at(const std::vector<double>& coarse, const cell_axis& cx, const cell_axis& cy, int px2, int py2,
                      double* out) noexcept {
    const cell_lerp lx = cell_lerp_at(cx, px2), ly = cell_lerp_at(cy, py2);
    const std::size_t nx = static_cast<std::size_t>(cx.count);
    const std::size_t j0 = static_cast<std::size_t>(lx.j), j1 = cx.count > 1 ? j0 + 1 : j0;
    const std::size_t i0 = static_cast<std::size_t>(ly.j), i1 = cy.count > 1 ? i0 + 1 : i0;
    const double dx = 2.0 * cx.width, dy = 2.0 * cy.width;
    const double ax = dx - lx.k, bx = lx.k, ay = dy - ly.k, by = ly.k;
    for (int k = 0; k < record; ++k) {
        const double f00 = coarse[(i0 * nx + j0) * record + static_cast<std::size_t>(k)];
        const double f01 = coarse[(i0 * nx + j1) * record + static_cast<std::size_t>(k)];
        const double f10 = coarse[(i1 * nx + j0) * record + static_cast<std::size_t>(k)];
        const double f11 = coarse[(i1 * nx + j1) * record + static_cast<std::size_t>(k)];
        out[k] = weighted_bilinear(f00, f01, f10, f11, ax, bx, ay, by) / (dx * dy);
    }
}

// keep min(M / L, 1) per channel of a record (M, L, V), keep = 1 - V / |M|^2 (0 unless > 1e-9).
inline void shrunk_ratio(const double* r, double* f) noexcept {
    f[0] = f[1] = f[2] = 0.0;
    const double m2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    const double keep = m2 > 0 ? 1.0 - r[6] / m2 : 0.0;
    // a lone firefly gives keep = 0 up to rounding (1e-9: far above it, far below any second
    // firefly's share); nothing removed nearby gives m2 = 0
    if (!(keep > 1e-9) || !std::isfinite(m2)) return;
    // The ratio is capped at 1: the return never exceeds the shape's own level. Where the
    // removed light outweighs the rest the fireflies are no longer rare, the shape (a median of
    // few noisy values) is mostly their noise, and scaling it up multiplies that noise
    // (simulated dense fireflies at 4 samples a buffer: 2.4x the error of no return).
    for (int c = 0; c < 3; ++c) {
        const double l = r[3 + c];
        const double v = l > 0 ? keep * (std::min)(r[c] / l, 1.0) : 0.0;
        f[c] = std::isfinite(v) && v > 0 ? v : 0.0;
    }
}

// How far the coarse scale may be trusted at a node: the fine sums r against what the coarse
// ratio predicts for them (L_fine M_c / L_c), in units of the noise the fine M would have if the
// coarse window's fireflies were spread evenly in proportion to the image (the model's ratio:
// the relative excess |e| / |P| has the same distribution everywhere). With var_scale = sum
// w_f^2 / sum w_c^2, that noise is var_scale x (the coarse sum of w^2 |e|^2 / |P|^2) x |L_fine|^2:
// a bright cluster's large excess does not widen the tolerance in the dim pixels around it.
// 1 up to 2 noise deviations, 0 from 3.
inline double coarse_trust(const double* r, const double* c, double var_scale) noexcept {
    const double v0 = c[7] * var_scale * (r[3] * r[3] + r[4] * r[4] + r[5] * r[5]);
    if (!(v0 > 0) || !std::isfinite(v0)) return 0.0;
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
        const double predicted = c[3 + k] > 0 ? r[3 + k] * (c[k] / c[3 + k]) : 0.0;
        d2 += (r[k] - predicted) * (r[k] - predicted);
    }
    const double z = std::sqrt(d2 / v0);
    return std::isfinite(z) ? std::clamp(3.0 - z, 0.0, 1.0) : 0.0;
}

// The factor each node gives its channels, from the sums in sum_order_for's order (both
// orders' mean on a square frame): the fine
// scale's shrunk ratio, or the coarse scale's where the fine sums cannot tell them apart.
inline void energy_factors(energy_scratch& s) {
    const std::size_t nx = static_cast<std::size_t>(s.ax.count), ny = static_cast<std::size_t>(s.ay.count);
    s.factor.assign(nx * ny * 3, 0.0);
    for (std::size_t i = 0; i < ny; ++i)
        for (std::size_t j = 0; j < nx; ++j) {
            const std::size_t n = i * nx + j;
            double r[record], f[3];
            for (std::size_t k = 0; k < record; ++k) r[k] = s.xy[n * record + k];  // sum_order_for's sums
            shrunk_ratio(r, f);
            if (!s.coarse.empty()) {
                double c[record], fc[3];
                coarse_at(s.coarse, s.cx, s.cy, s.ax.pos2(static_cast<int>(j)), s.ay.pos2(static_cast<int>(i)), c);
                shrunk_ratio(c, fc);
                const double a = coarse_trust(r, c, s.coarse_var_scale);
                for (int k = 0; k < 3; ++k) f[k] = a * fc[k] + (1.0 - a) * f[k];
            }
            for (int k = 0; k < 3; ++k) s.factor[n * 3 + static_cast<std::size_t>(k)] = f[k];
        }
}

// The node interval of pixel x and its weight on the upper node (exact: step is a power of 2).
struct node_lerp {
    int j = 0;
    double t = 0.0;
};
inline node_lerp lerp_at(const node_axis& a, int x) noexcept {
    if (a.count == 1) return {};
    const int off = 2 * x - a.pos2(0);  // >= 0
    const int j = (std::min)(off / (2 * a.step), a.count - 2);
    return {j, static_cast<double>(2 * x - a.pos2(j)) / (2.0 * a.step)};
}

// add capped channel by channel at `limit` (a negative limit: 0), into out, which it returns.
inline const double* at_most(const double* add, const double* limit, double* out) noexcept {
    for (int c = 0; c < 3; ++c) out[c] = (std::min)(add[c], (std::max)(limit[c], 0.0));
    return out;
}

// At a pixel that already holds `held` of the rare light the return estimates, out of an
// expected share of `share` times its own return `add` (held_light): the rest, at most add,
// channel by channel.
inline const double* within_share(const double* add, const float* held, int share, double* out) noexcept {
    for (int c = 0; c < 3; ++c)
        out[c] = (std::min)(add[c], (std::max)(share * add[c] - static_cast<double>(held[c]), 0.0));
    return out;
}

// The light returned at a pixel of profile p where the interpolated factor is k (0 unless
// positive and finite).
inline double returned_light(double k, double p) noexcept {
    const double v = k > 0 ? k * p : 0.0;
    return std::isfinite(v) && v > 0 ? v : 0.0;
}

// Bilinear interpolation of the four nodes' values at fractions tx, ty (weighted_bilinear).
inline double bilinear(double f00, double f01, double f10, double f11, double tx, double ty) noexcept {
    return weighted_bilinear(f00, f01, f10, f11, 1.0 - tx, tx, 1.0 - ty, ty);
}

}  // namespace detail

// The Gaussians' widths in pixels: the fine scale, and the coarse one (0: none; else wider).
struct energy_scales {
    double fine = 8.0, coarse = 0.0;
    energy_scales(double f, double c = 0.0) : fine(f), coarse(c) {}  // NOLINT: a width alone is the fine one
};

// The coarse width an option may hold: 0 (none), or 2 to 256 pixels (a width not above the
// fine one turns the coarse scale off).
inline status check_energy_coarse(double coarse) noexcept {
    if (coarse == 0.0 || (coarse >= 2.0 && coarse <= 256.0)) return ok_status();
    return status{errc::invalid_argument, "energy_coarse_sigma must be 0 or lie in [2, 256]"};
}

namespace detail {
// The coarse scale's cells, sums and Gaussian (see cell_sums): cells of the odd width nearest
// a quarter of sigma (interpolating a Gaussian between points a quarter of its width apart
// errs by ~1/128 of its peak), the Gaussian over the cells sigma / width wide.
inline void coarse_model(const excess_map& where, int w, int h,
                         const energy_scales& sc, const tap_weights& fine, energy_scratch& s, const executor& exec) {
    if (!(sc.coarse > sc.fine)) {
        s.cells.clear(), s.coarse.clear();
        return;
    }
    const int width = (std::max)(1, static_cast<int>(sc.coarse / 4.0)) | 1;
    s.cx = make_cell_axis(w, width);
    s.cy = make_cell_axis(h, width);
    const double sigma = sc.coarse / width;
    const tap_weights tw = make_taps(sigma, (std::max)(1, static_cast<int>(std::ceil(3.0 * sigma))), false);
    const sum_order order = sum_order_for(w, h);
    cell_sums(s.profile, where, w, h, s.cx, s.cy, order, s.cells, exec);
    coarse_blur(s.cells, s.cx, s.cy, tw, order, s.coarse, exec);
    auto sum_sq = [](const tap_weights& t) {  // one axis, both sides
        double v = t.sq[0];
        for (std::size_t d = 1; d < t.sq.size(); ++d) v += 2.0 * t.sq[d];
        return v;
    };
    const double fine2 = sum_sq(fine), coarse2 = width * sum_sq(tw);  // a cell's weight is each pixel's
    s.coarse_var_scale = (fine2 * fine2) / (coarse2 * coarse2);
}

// The return's shape P: the 3x3 median of the caller's image, once or twice (twice: the
// half-buffer detector). One median drops a lone firefly, but where fireflies are dense a window
// holds 5 of 9 by chance (at 19% of pixels hit, 0.6% of windows; at 30% a half, 10%) and its
// median is a firefly's level, which the return then paints at ratio times that level. The
// second median drops such chance clusters (a few pixels, ragged) and keeps what the first kept
// over 3x3 (a streak two pixels wide or more, a spot's core). Measured, relMSE, once against
// twice, two halves (the simulator at 1024x540): dense30 0.0756 -> 0.0594, dense10 0.0235 ->
// 0.0203, production 0.00344 -> 0.00320, fine detail 0.00307 -> 0.00287, caustics 0.0314 ->
// 0.0309 (at 512x270, thinner streaks: 0.0554 -> 0.0573), the rest within 0.3%; 36 held-out
// frames (bench/research/held_out.cpp): 34 lower or equal, two caustics frames +0.2% at most.
// Its price is on small caustic spots: the Cycles caustics 0.02449 -> 0.02482 (a focus a few
// pixels wide loses its core to the second pass; after NL-means 0.0210 -> 0.0213), while the
// Cycles interior 0.1111 -> 0.1108 and the bokeh render at 8 samples a half 0.0289 -> 0.0287.
// Once for K buffers: there the second median took dense10 at 128 samples (512x270, 3 seeds)
// 0.0519 -> 0.0295 (K = 8) and 0.0878 -> 0.0626 (K = 4), but where light itself is sparse (K = 8
// at one sample a buffer, 5% of samples lit: 34% of pixels lit, the median a chance too) the
// shape falls to nothing, the return's cap (ratio <= 1) binds, and the frame kept 0.85 of its
// light against 0.93 (0.90 with the first median kept where the second is 0; 0.88 with the
// larger of the second and the cleaned mean's median, which also lost the production gain).
// Twice costs a second pass over the frame and no memory (median3x3_twice_rows: the first
// median's rows made as the second asks for them).
enum class shape_medians : unsigned char { once, twice };
template <class ShapeRows>
inline void shape_profile(ShapeRows&& shape_rows, shape_medians medians, int w, int h, energy_scratch& s,
                          const executor& exec) {
    if (medians == shape_medians::once) {
        median3x3_rows(shape_rows, s.profile, w, h, exec);
        return;
    }
    median3x3_twice_rows(shape_rows, s.profile, w, h, exec);
}

// The model of the energy return for one frame, from the removed excess already in s.where
// (see excess_map) and the image whose 3x3 median (shape_medians::twice: of its 3x3 median)
// shapes the return (3 channels, finite, >= 0; row y written by shape_rows(y, out)): the profile
// and the nodes' factors in `s`, read back per pixel by energy_at. sc: the Gaussians' widths in
// pixels.
template <class ShapeRows>
inline void energy_model_mapped(ShapeRows&& shape_rows, shape_medians medians, int w, int h, energy_scales sc,
                                energy_scratch& s, const executor& exec) {
    const double sigma = sc.fine;
    const int r = (std::max)(1, static_cast<int>(std::ceil(3.0 * sigma)));
    const tap_weights taps[2] = {make_taps(sigma, r, false), make_taps(sigma, r, true)};
    const int step = node_step(sigma);
    s.ax = make_node_axis(w, step);
    s.ay = make_node_axis(h, step);
    shape_profile(shape_rows, medians, w, h, s, exec);
    const sum_order order = sum_order_for(w, h);
    if (order != sum_order::y_first) energy_x_then_y(s.profile, s.where, w, h, s.ax, s.ay, taps, s, exec);
    if (order != sum_order::x_first)
        energy_y_then_x(s.profile, s.where, w, h, s.ax, s.ay, taps, s, order == sum_order::both, exec);
    coarse_model(s.where, w, h, sc, taps[0], s, exec);
    energy_factors(s);
}
}  // namespace detail

// The same from the excess as a frame (3 interleaved channels, w x h, 0 where nothing was
// removed; row y of the shape written by shape_rows, or held whole: energy_model).
template <class E, class ShapeRows>
inline void energy_model_rows(const std::vector<E>& excess, ShapeRows&& shape_rows, int w, int h, energy_scales sc,
                              energy_scratch& s, const executor& exec) {
    detail::map_excess(excess, w, h, s.where, exec);
    detail::energy_model_mapped(shape_rows, detail::shape_medians::once, w, h, sc, s, exec);
}

inline void energy_model(const std::vector<double>& excess, const std::vector<double>& shape, int w, int h,
                         energy_scales sigma, energy_scratch& s, const executor& exec) {
    const std::size_t n = static_cast<std::size_t>(w) * 3;
    energy_model_rows(excess, [&](int y, double* row) { std::copy_n(&shape[static_cast<std::size_t>(y) * n], n, row); },
                      w, h, sigma, s, exec);
}

// The energy to add back at pixel (x, y), channels 0..2 into add[0..2], after energy_model.
inline void energy_at(const energy_scratch& s, int x, int y, double* add) noexcept {
    const std::size_t nx = static_cast<std::size_t>(s.ax.count);
    const detail::node_lerp ly = detail::lerp_at(s.ay, y), lx = detail::lerp_at(s.ax, x);
    const std::size_t i0 = static_cast<std::size_t>(ly.j), i1 = s.ay.count > 1 ? i0 + 1 : i0;
    const std::size_t j0 = static_cast<std::size_t>(lx.j), j1 = s.ax.count > 1 ? j0 + 1 : j0;
    const std::size_t p = (static_cast<std::size_t>(y) * static_cast<std::size_t>(s.ax.pixels) + static_cast<std::size_t>(x)) * 3;
    for (std::size_t c = 0; c < 3; ++c) {
        const double* f = s.factor.data() + c;
        const double k = detail::bilinear(f[(i0 * nx + j0) * 3], f[(i0 * nx + j1) * 3], f[(i1 * nx + j0) * 3],
                                          f[(i1 * nx + j1) * 3], lx.t, ly.t);
        add[c] = detail::returned_light(k, static_cast<double>(s.profile[p + c]));
    }
}

namespace detail {
// energy_at over whole rows, its operations regrouped (the same bits): the factors interpolated
// along x on a node row once for all the rows it bounds, along y at the node columns once per
// row; each pixel takes the last step of both orders.
class energy_rows {
public:
    explicit energy_rows(const energy_scratch& s) : s_(s) {
        for (int x = 0; x < s.ax.pixels; ++x) lx_.push_back(lerp_at(s.ax, x));
        const std::size_t n = static_cast<std::size_t>(s.ax.pixels) * 3;
        upper_.resize(n), lower_.resize(n), along_y_.resize(static_cast<std::size_t>(s.ax.count) * 3);
    }

    // energy_at of every pixel of row y: add[3 x + c]
    void row(int y, double* add) {
        const node_lerp ly = lerp_at(s_.ay, y);
        const int i0 = ly.j, i1 = s_.ay.count > 1 ? i0 + 1 : i0;
        if (i0 != i0_) {
            if (i0 == i0_ + 1) std::swap(upper_, lower_), along_x(i1, lower_);
            else along_x(i0, upper_), along_x(i1, lower_);
            i0_ = i0;
        }
        const double ay = 1.0 - ly.t, by = ly.t;
        const double* f0 = &s_.factor[static_cast<std::size_t>(i0) * along_y_.size()];
        const double* f1 = &s_.factor[static_cast<std::size_t>(i1) * along_y_.size()];
        for (std::size_t q = 0; q < along_y_.size(); ++q) along_y_[q] = weighted_pair(ay, by, f0[q], f1[q]);
        const float* profile = &s_.profile[static_cast<std::size_t>(y) * upper_.size()];
        for (std::size_t x = 0; x < lx_.size(); ++x) {
            const std::size_t j0 = static_cast<std::size_t>(lx_[x].j), j1 = s_.ax.count > 1 ? j0 + 1 : j0;
            const double ax = 1.0 - lx_[x].t, bx = lx_[x].t;
            for (std::size_t c = 0; c < 3; ++c) {
                const double xy = weighted_pair(ay, by, upper_[x * 3 + c], lower_[x * 3 + c]);
                const double yx = weighted_pair(ax, bx, along_y_[j0 * 3 + c], along_y_[j1 * 3 + c]);
                add[x * 3 + c] = returned_light(0.5 * (xy + yx), static_cast<double>(profile[x * 3 + c]));
            }
        }
    }

private:
    void along_x(int i, std::vector<double>& out) const {  // node row i, interpolated at every pixel
        const double* f = &s_.factor[static_cast<std::size_t>(i) * along_y_.size()];
        for (std::size_t x = 0; x < lx_.size(); ++x) {
            const std::size_t j0 = static_cast<std::size_t>(lx_[x].j), j1 = s_.ax.count > 1 ? j0 + 1 : j0;
            const double ax = 1.0 - lx_[x].t, bx = lx_[x].t;
            for (std::size_t c = 0; c < 3; ++c) out[x * 3 + c] = weighted_pair(ax, bx, f[j0 * 3 + c], f[j1 * 3 + c]);
        }
    }

    const energy_scratch& s_;
    std::vector<node_lerp> lx_;          // each pixel's node interval along x
    std::vector<double> upper_, lower_;  // the factors along x on node rows i0_, i0_ + 1
    std::vector<double> along_y_;        // the factors along y at the node columns (this row)
    int i0_ = -2;                        // none yet
};

// energy_rows over bands of rows, a task a band: f(y, add) with row y's return, add[3 x + c].
template <class F>
inline void for_each_energy_row(const energy_scratch& s, int w, int h, const executor& exec, F&& f) {
    constexpr int band = 16;
    exec.run(static_cast<std::size_t>((h + band - 1) / band), [&](std::size_t bi) {
        energy_rows rows(s);
        std::vector<double> add(static_cast<std::size_t>(w) * 3);
        for (int y = static_cast<int>(bi) * band; y < (std::min)(h, static_cast<int>(bi + 1) * band); ++y) {
            rows.row(y, add.data());
            f(y, add.data());
        }
    });
}
}  // namespace detail

// The whole return as an image (3 interleaved channels, w x h) in `returned`.
inline void energy_return(const std::vector<double>& excess, const std::vector<double>& shape, int w, int h,
                          energy_scales sigma, std::vector<double>& returned, energy_scratch& s, const executor& exec) {
    energy_model(excess, shape, w, h, sigma, s, exec);
    const std::size_t row = static_cast<std::size_t>(w) * 3;
    returned.resize(row * static_cast<std::size_t>(h));
    detail::for_each_energy_row(s, w, h, exec, [&](int y, const double* add) {
        std::copy_n(add, row, &returned[static_cast<std::size_t>(y) * row]);
    });
}

// What one cleaned image gave and got back.
struct energy_totals {
    double removed = 0, returned = 0;  // sums over pixels of the mean colour channel
};

// Adds add[0..2] to the first three channels of pixel (x, y), keeping the old values in
// old[0..2]. False when a sum did not fit the image's own type (past FLT_MAX, or half's
// 65504): the caller restores the pixel (restore_light). A pixel with a non-finite channel
// to add to (one left as the input had it) is not written at all, and false: a float NaN
// loaded as a double and stored back is quieted, other bits than the input's.
template <class C>
bool add_light(const image_view<C>& color, int x, int y, const double* add, double* old) {
    for (int c = 0; c < 3; ++c) old[c] = color.load(x, y, c);
    for (int c = 0; c < 3; ++c)
        if (add[c] > 0 && !std::isfinite(old[c])) return false;
    bool finite = true;
    for (int c = 0; c < 3; ++c) {
        if (!(add[c] > 0)) continue;  // nothing to add: the bits stay as they are
        color.store(x, y, c, old[c] + add[c]);
        finite = finite && std::isfinite(color.load(x, y, c));
    }
    return finite;
}

// Undoes add_light: the channels it wrote (finite before, so the round trip is exact).
template <class C>
void restore_light(const image_view<C>& color, int x, int y, const double* old, const double* add) {
    for (int c = 0; c < 3; ++c)
        if (add[c] > 0 && std::isfinite(old[c])) color.store(x, y, c, old[c]);
}

namespace detail {
// What a rebuild took from pixel (x, y) of `color`, channel by channel: before[c] less the
// cleaned value, where that is finite and positive (else +0), as a float (at most FLT_MAX,
// never above the difference). False where every channel is 0.
template <class C>
inline bool rebuilt_excess(const image_view<C>& color, int x, int y, const float* before, float* f) {
    for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(before[c]) - color.load(x, y, c);
        f[c] = std::isfinite(d) && d > 0 ? static_cast<float>((std::min)(d, static_cast<double>(FLT_MAX))) : 0.0f;
        if (static_cast<double>(f[c]) > d)
            f[c] = std::nextafter(f[c], 0.0f);  // never above what was taken (return_energy_to_image)
    }
    return f[0] != 0.0f || f[1] != 0.0f || f[2] != 0.0f;
}

// The excess_map of what the rebuild took from `color`: at pixel rebuilt[e], before[3 e + c]
// less the cleaned value, where that is finite and positive (else +0), as a float (what a
// frame-sized float image of it would hold; at most FLT_MAX), straight from the list: nothing
// frame-sized. The list is taken in pixel order (sorted through `order` when it is not; of a
// pixel listed twice the last entry counts); entries outside the image are skipped. untaken:
// the pixels, ascending, whose rebuild took nothing from a finite input (it raised every
// channel): no excess to map, and nothing to give back to them.
template <class C>
inline void map_rebuilt_excess(const image_view<C>& color, const std::uint32_t* rebuilt, const float* before,
                               std::size_t n, excess_map& m, std::vector<std::uint32_t>& order,
                               std::vector<std::uint32_t>& untaken) {
    const int w = color.width(), h = color.height();
    const std::size_t np = color.pixel_count();
    const bool sorted = std::is_sorted(rebuilt, rebuilt + n);  // as the detector's lists are
    order.clear();
    if (!sorted) {
        order.resize(n);
        for (std::size_t e = 0; e < n; ++e) order[e] = static_cast<std::uint32_t>(e);
        std::stable_sort(order.begin(), order.end(), [&](std::uint32_t i, std::uint32_t j) { return rebuilt[i] < rebuilt[j]; });
    }
    auto entry = [&](std::size_t j) { return sorted ? j : static_cast<std::size_t>(order[j]); };
    m.start.assign(static_cast<std::size_t>(h) + 1, 0);
    m.pixels.clear();
    untaken.clear();
    for (std::size_t j = 0; j < n; ++j) {
        const std::size_t e = entry(j);
        const std::uint32_t p = rebuilt[e];
        if (p >= np || (j + 1 < n && rebuilt[entry(j + 1)] == p)) continue;
        const int x = detail::column_of(p, w), y = detail::row_of(p, w);
        float f[3];
        if (!rebuilt_excess(color, x, y, &before[e * 3], f)) {  // as map_excess: no record
            const float* b = &before[e * 3];
            if (std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2])) untaken.push_back(p);
            continue;
        }
        m.pixels.push_back(excess_at(x, f));
        ++m.start[static_cast<std::size_t>(y) + 1];
    }
    for (std::size_t y = 0; y < static_cast<std::size_t>(h); ++y) m.start[y + 1] += m.start[y];
}
}  // namespace detail

// Pixels that already hold some of the rare light the return estimates: at pixels[e]
// (strictly ascending), held[3 e .. 3 e + 2] >= 0 of it, channel by channel, out of an
// expected share of shares[e] times the pixel's own return (within_share, after a rebuilt
// pixel's cap). A list that is not strictly ascending, or whose arrays are missing, is not
// used (usable()). The two-half detector lists a pixel whose other half kept a rare sample
// above it (share 2: the pair's; held, that excess) and a half of a kept pair that stands
// above a smooth neighbourhood (share 1; held, its rise above that neighbourhood's level).
struct held_light {
    const std::uint32_t* pixels = nullptr;
    const float* held = nullptr;
    const std::uint8_t* shares = nullptr;
    std::size_t n = 0;
    bool usable() const noexcept {
        return n > 0 && pixels && held && shares &&
               std::adjacent_find(pixels, pixels + n, [](std::uint32_t a, std::uint32_t b) { return a >= b; }) == pixels + n;
    }
};

// The energy return on one cleaned image (the first three channels of `color`): pixel
// rebuilt[e] held before[3 e .. 3 e + 2] before it was rebuilt. The return is added wherever it
// is positive, never where keep[p] is false (black background, alpha 0): a change far below the
// pixel's noise still removes a bias that a denoiser, which averages the noise away, cannot.
// added (when not null, one per pixel): set to 1 where light was added, else left as it was.
// held: pixels that hold some of the rare light already get only the rest of their share.
// outside (when not null, one per pixel): pixels that are no part of the image (black
// background, alpha 0), whose colour, whatever it holds, the shape reads as 0.
template <class C>
energy_totals return_energy_to_image(const image_view<C>& color, const std::uint32_t* rebuilt, const float* before,
                                     std::size_t n, const std::uint8_t* keep, energy_scales sigma, energy_scratch& s,
                                     const executor& exec, std::uint8_t* added = nullptr, held_light held = {},
                                     const std::uint8_t* outside = nullptr) {
    energy_totals t;
    const int w = color.width(), h = color.height();
    if (color.channels() < 3) return t;
    detail::map_rebuilt_excess(color, rebuilt, before, n, s.where, s.order, s.untaken);
    // the shape: the image before the rebuild (the cleaned image plus what was removed), its
    // 3x3 median taken twice (shape_profile)
    auto shape_row = [&](int y, double* row) {
        auto put = [&](int x, int c, double v) {
            row[static_cast<std::size_t>(x) * 3 + static_cast<std::size_t>(c)] = std::isfinite(v) && v > 0 ? v : 0.0;
        };
        const std::size_t row0 = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c)
                put(x, c, outside && outside[row0 + static_cast<std::size_t>(x)] ? 0.0 : color.load(x, y, c));
        for (const detail::excess_pixel* e = s.where.first(y); e != s.where.last(y); ++e)
            for (int c = 0; c < 3; ++c) put(e->x, c, color.load(e->x, y, c) + e->v[c]);
    };
    detail::energy_model_mapped(shape_row, detail::shape_medians::twice, w, h, sigma, s, exec);
    // row-major, as over every pixel: the others' excess is +0 and adds nothing (excess_map)
    for (const detail::excess_pixel& e : s.where.pixels) t.removed += (e.v[0] + e.v[1] + e.v[2]) / 3.0;
    // bands of rows across the executor (distinct pixels); each row's total kept, summed in
    // row order after: the same bits for any executor
    s.row_returned.assign(static_cast<std::size_t>(h), 0.0);
    if (!held.usable()) held = {};
    const std::uint32_t* held_end = held.pixels + held.n;
    // A rebuilt pixel gets back at most what its rebuild took, channel by channel: the return
    // is the fireflies' light spread over their neighbourhood, and a firefly pixel lifted above
    // its own input would bring the firefly back brighter (a dense frame's shape, the 3x3 median
    // of the input, reads firefly levels where fireflies happen to crowd: at 30% of pixels hit
    // per half, 7% of the rebuilt pixels came out above their input). A pixel listed in `held`
    // then gets the rest of its share (within_share). At the cap a rebuilt pixel is its input
    // again (dense30: 847 of its 2,573 fireflies the recall misses). Tried: the return at a
    // rebuilt pixel scaled down to its rebuilt value where the profile is higher (a crowd of
    // fireflies sets the median): recall dense30 0.981 -> 0.987, the simulated caustics 0.905
    // -> 0.910, but relMSE 0.259 -> 0.272 and 0.0275 -> 0.0304: where fireflies crowd, they
    // are most of the pixel's light. A rebuilt pixel whose rebuild took nothing (s.untaken)
    // gets nothing: its cap is 0.
    detail::for_each_energy_row(s, w, h, exec, [&](int y, const double* row_add) {
        double sum = 0;
        const detail::excess_pixel* e = s.where.first(y);
        const std::size_t row0 = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        const std::uint32_t* q = std::lower_bound(held.pixels, held_end, row0);
        const std::uint32_t* u = std::lower_bound(s.untaken.data(), s.untaken.data() + s.untaken.size(), row0);
        const std::uint32_t* u_end = s.untaken.data() + s.untaken.size();
        double capped[3], rest[3];
        for (int x = 0; x < w; ++x) {
            const std::size_t p = row0 + static_cast<std::size_t>(x);
            const double* add = &row_add[static_cast<std::size_t>(x) * 3];
            while (e != s.where.last(y) && e->x < x) ++e;
            if (e != s.where.last(y) && e->x == x) add = detail::at_most(add, e->v, capped);
            while (u != u_end && *u < p) ++u;
            if (u != u_end && *u == p) continue;
            while (q != held_end && *q < p) ++q;
            if (q != held_end && *q == p) {
                const std::size_t k = static_cast<std::size_t>(q - held.pixels);
                add = detail::within_share(add, &held.held[k * 3], held.shares[k], rest);
            }
            if (!keep[p] || !(add[0] + add[1] + add[2] > 0)) continue;  // (each add is >= 0)
            const double mean_add = (add[0] + add[1] + add[2]) / 3.0;
            if (!(mean_add > 0)) continue;
            double old[3];
            if (!add_light(color, x, y, add, old)) {
                restore_light(color, x, y, old, add);
                continue;
            }
            sum += mean_add;
            if (added) added[p] = 1;
        }
        s.row_returned[static_cast<std::size_t>(y)] = sum;
    });
    for (const double r : s.row_returned) t.returned += r;
    return t;
}

}  // namespace firefly

#ifdef FIREFLY_DETAIL_CLANG_FP_PRAGMAS
#pragma float_control(pop)
#endif
