// firefly: the Gaussian reconstruction kernel and its flip-exact weighted sums.
//
// The kernel's offsets fall into classes that the 8 flips/transposes of the square permute
// among themselves with equal weights. Each class is listed as opposite pairs (m, -m) and
// summed as the tree ((P1 + P2) + (P3 + P4)) of pair sums P = v(m) + v(-m): every flip or
// transpose only swaps operands of some + in that tree (the 180-degree turn fixes each pair;
// the rest of the group permutes the pairs as the Klein four-group, which keeps the pairing
// {P1, P2}, {P3, P4}), and + is commutative, so a flipped or transposed input gives a
// bit-identical (flipped) output with no sorting.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <vector>

#include "floating_point.hpp"
#include "scratch.hpp"

namespace firefly::detail {

// Sums of double values near DBL_MAX overflow (inf, or inf - inf = NaN) where the mean they
// make is finite. Such sums are taken again over the values times overflow_scale (a power of
// two: exact for all but values far below any that overflow) and the mean scaled back with
// from_overflow_scale, held within the finite range. Float data never needs it.
inline constexpr double overflow_scale = 0x1p-128;
struct unscaled {  // the plain sums' scale: no multiply in their loops
    friend constexpr double operator*(double v, unscaled) noexcept { return v; }
};
inline bool all_finite(const double* v, int n) noexcept {
    for (int i = 0; i < n; ++i)
        if (!std::isfinite(v[i])) return false;
    return true;
}
inline double from_overflow_scale(double scaled_mean) noexcept {
    const double m = std::ldexp(scaled_mean, 128);
    return m == m ? std::clamp(m, -DBL_MAX, DBL_MAX) : 0.0;  // NaN only from an infinite value
}

struct kernel_class {
    double weight;
    int count;  // 4 or 8 offsets
    int dx[8], dy[8];
};

// The classes of a width x width Gaussian kernel (width odd), centre excluded.
class gaussian_kernel {
public:
    // Rebuilds the classes only when width or sigma change.
    void set(int width, double sigma) {
        if (width == width_ && sigma == sigma_) return;
        classes_.clear();
        const int r = width / 2;
        for (int a = 0; a <= r; ++a)
            for (int b = a; b <= r; ++b) {
                if (a == 0 && b == 0) continue;
                kernel_class k{};
                k.weight = std::exp(-(a * a + b * b) / (2.0 * sigma * sigma));
                auto add = [&k](int dx, int dy) {  // opposite pairs, in the tree's order
                    k.dx[k.count] = dx;
                    k.dy[k.count] = dy;
                    ++k.count;
                };
                if (a == 0) {
                    add(0, b), add(0, -b), add(b, 0), add(-b, 0);
                } else if (a == b) {
                    add(a, a), add(-a, -a), add(-a, a), add(a, -a);
                } else {
                    add(a, b), add(-a, -b), add(-a, b), add(a, -b);
                    add(b, a), add(-b, -a), add(-b, a), add(b, -a);
                }
                classes_.push_back(k);
            }
        width_ = width;
        sigma_ = sigma;
    }
    const std::vector<kernel_class>& classes() const noexcept { return classes_; }
    int radius() const noexcept { return width_ / 2; }

private:
    std::vector<kernel_class> classes_;
    reset_on_move<int> width_;  // (scratch.hpp: a moved-from kernel builds again)
    reset_on_move<double> sigma_;
};

// acc[c] += wk * (the class's tree of pair sums of v[j][c]) for c < n: one class's share.
template <std::size_t Cap>
inline void add_class(const kernel_class& k, double wk, const double (&v)[8][Cap], int n, double* acc) {
    if (k.count == 8) {
        for (int c = 0; c < n; ++c)
            acc[c] += wk * (((v[0][c] + v[1][c]) + (v[2][c] + v[3][c])) + ((v[4][c] + v[5][c]) + (v[6][c] + v[7][c])));
    } else {
        for (int c = 0; c < n; ++c) acc[c] += wk * ((v[0][c] + v[1][c]) + (v[2][c] + v[3][c]));
    }
}

// Weighted sums over the neighbours of (x, y) in a w x h image that `readable(xx, yy)`
// accepts, two at once (readable asked once a neighbour): acc_a[c] += weight * a(c) for c < NA
// channels and acc_b[c] += weight^2 * b(c) for c < NB, where load_a(xx, yy, v) fills v[0..NA)
// (NA, NB = 0: na, nb at run time). Returns the sum of the weights of the neighbours read (0:
// none, and neither acc touched). Unreadable and outside neighbours contribute 0 to their
// place in the tree, so the sums are flip-exact.
template <int NA, int NB, class Readable, class LoadA, class LoadB>
double kernel_sum_1_2(const gaussian_kernel& kernel, int x, int y, int w, int h, int na, int nb, Readable&& readable,
                      LoadA&& load_a, LoadB&& load_b, double* acc_a, double* acc_b) {
    constexpr std::size_t cap_a = NA > 0 ? NA : 32, cap_b = NB > 0 ? NB : 32;
    const int n_a = NA > 0 ? NA : na, n_b = NB > 0 ? NB : nb;
    double wsum = 0.0;
    double va[8][cap_a], vb[8][cap_b];
    for (const kernel_class& k : kernel.classes()) {
        int used = 0;
        for (int j = 0; j < k.count; ++j) {
            const int xx = x + k.dx[j], yy = y + k.dy[j];
            const bool ok = xx >= 0 && yy >= 0 && xx < w && yy < h && readable(xx, yy);
            used += ok;
            if (ok) {
                load_a(xx, yy, va[j]);
                load_b(xx, yy, vb[j]);
            } else {
                for (int c = 0; c < n_a; ++c) va[j][c] = 0.0;
                for (int c = 0; c < n_b; ++c) vb[j][c] = 0.0;
            }
        }
        if (used == 0) continue;
        wsum += k.weight * used;
        add_class(k, k.weight, va, n_a, acc_a);
        add_class(k, k.weight * k.weight, vb, n_b, acc_b);
    }
    return wsum;
}

// kernel_sum_1_2's first sum alone.
template <int NC, class Readable, class Load>
double kernel_sum(const gaussian_kernel& kernel, int x, int y, int w, int h, int nchan, Readable&& readable,
                  Load&& load, double* acc) {
    return kernel_sum_1_2<NC, 0>(kernel, x, y, w, h, nchan, 0, readable, load, [](int, int, double*) {}, acc, nullptr);
}

}  // namespace firefly::detail
