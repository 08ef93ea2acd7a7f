// firefly: two-phase Gaussian reconstruction of the pixels a mask marks (paper, section 4).
//
// Each marked pixel becomes the Gaussian-weighted mean of its neighbours in a square kernel
// (5 pixels wide by default), colour and variance alike; the kernel is renormalised over
// the neighbours that may be read, so borders and corners need no special case.
//
//   phase 1  gives every marked pixel a first value, in rounds. A round reads only pixels
//            known when it began (unmarked ones, and marked ones set by earlier rounds), so
//            a cluster wider than the kernel fills from its rim inwards, the same from every
//            side: no scan order, no directional bias (the paper's "2 2 x x 8 8").
//   phase 2  Jacobi iterations over the marked pixels that have marked neighbours, now
//            reading every neighbour, until the largest relative change is below a
//            tolerance or an iteration cap is reached.
//
// Exact symmetry: the kernel's offsets fall into classes that the 8 flips/transposes of the
// square permute among themselves with equal weights. Each class is listed as opposite pairs
// (m, -m) and summed as the tree ((P1 + P2) + (P3 + P4)) of pair sums P = v(m) + v(-m): every
// flip or transpose only swaps operands of some + in that tree (the 180-degree turn fixes
// each pair; the rest of the group permutes the pairs as the Klein four-group, which keeps
// the pairing {P1, P2}, {P3, P4}), and + is commutative, so a flipped or transposed input
// gives a bit-identical (flipped) output with no sorting.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "image_view.hpp"
#include "status.hpp"

namespace firefly {

struct reconstruct_options {
    int kernel_width = 5;       // odd, >= 3
    double sigma = 1.0;         // Gaussian sigma in pixels
    double tolerance = 1e-3;    // phase 2 stops when max |change| / |value| falls below this
    int max_iterations = 20;    // phase 2 iteration cap (0: phase 1 only)
};

struct [[nodiscard]] reconstruct_report {
    status error{};               // no_valid_pixels when nothing could be read at all
    std::size_t pixels = 0;       // marked pixels
    std::size_t unreachable = 0;  // marked pixels left without a value (no valid pixel at all)
    int phase1_rounds = 0;
    int phase2_iterations = 0;
    double final_change = 0.0;    // largest relative change of the last phase 2 iteration
};

inline status check_reconstruct_options(const reconstruct_options& o) noexcept {
    if (o.kernel_width < 3 || o.kernel_width % 2 == 0 || o.kernel_width > 63)
        return status{errc::invalid_argument, "kernel width must be odd and in [3, 63]"};
    if (!(o.sigma > 0) || !std::isfinite(o.sigma))
        return status{errc::invalid_argument, "kernel sigma must be positive"};
    if (!(o.tolerance >= 0) || o.max_iterations < 0)
        return status{errc::invalid_argument, "tolerance and iteration cap must be >= 0"};
    return ok_status();
}

// Memory reused across calls (and frames).
class reconstruct_scratch {
public:
    std::size_t bytes() const noexcept {
        return state_.capacity() + list_.capacity() * sizeof(std::uint32_t) +
               staged_.capacity() * sizeof(double) + ready_.capacity();
    }

    // Internal state of reconstruct(); public only so the function template can reach it.
    struct kernel_class {
        double weight;
        int count;
        int dx[8], dy[8];
    };
    std::vector<kernel_class> classes_;
    int classes_width_ = 0;
    double classes_sigma_ = 0;
    std::vector<std::uint8_t> state_;   // per pixel: 0 source, 1 marked, 2 marked + known
    std::vector<std::uint32_t> list_;   // marked pixels, row-major order
    std::vector<double> staged_;        // new values, list entry x channel
    std::vector<std::uint8_t> ready_;   // staged this round
};

// Reconstructs the pixels i (row-major, i = y * width + x) with (mask[i] & bits) != 0 in
// colour and, when not empty, variance. Every other pixel is left bit-identical.
template <class C, class V>
reconstruct_report reconstruct(const image_view<C>& color, const image_view<V>& variance,
                               const std::uint8_t* mask, const reconstruct_options& o,
                               reconstruct_scratch& s, std::uint8_t bits = 0xFF) {
    static_assert(!std::is_const_v<C> && !std::is_const_v<V>, "reconstruct writes its images");
    using ct = channel_traits<std::remove_cv_t<C>>;
    using vt = channel_traits<std::remove_cv_t<V>>;
    reconstruct_report rep;
    if (status st = check_reconstruct_options(o); !st.ok()) {
        rep.error = st;
        return rep;
    }
    const int w = color.width(), h = color.height();
    if (color.empty()) return rep;
    const bool has_var = !variance.empty();
    if (has_var && !same_size(color, variance)) {
        rep.error = status{errc::size_mismatch, "variance and colour differ in size"};
        return rep;
    }
    const int ncol = color.channels(), nvar = has_var ? variance.channels() : 0;
    const int nch = ncol + nvar;
    if (nch > 16) {
        rep.error = status{errc::channel_mismatch, "reconstruct handles at most 16 channels in all"};
        return rep;
    }

    // Kernel symmetry classes (rebuilt only when the options change).
    if (s.classes_width_ != o.kernel_width || s.classes_sigma_ != o.sigma) {
        s.classes_.clear();
        const int r = o.kernel_width / 2;
        for (int a = 0; a <= r; ++a)
            for (int b = a; b <= r; ++b) {
                if (a == 0 && b == 0) continue;
                reconstruct_scratch::kernel_class k{};
                k.weight = std::exp(-(a * a + b * b) / (2.0 * o.sigma * o.sigma));
                // Opposite pairs, in the order the summation tree expects.
                auto add = [&k](int dx, int dy) {
                    k.dx[k.count] = dx;
                    k.dy[k.count] = dy;
                    ++k.count;
                };
                if (a == 0) {  // the axis class (0, b)
                    add(0, b), add(0, -b), add(b, 0), add(-b, 0);
                } else if (a == b) {  // the diagonal class
                    add(a, a), add(-a, -a), add(-a, a), add(a, -a);
                } else {
                    add(a, b), add(-a, -b), add(-a, b), add(a, -b);
                    add(b, a), add(-b, -a), add(-b, a), add(b, -a);
                }
                s.classes_.push_back(k);
            }
        s.classes_width_ = o.kernel_width;
        s.classes_sigma_ = o.sigma;
    }

    const std::size_t npix = color.pixel_count();
    if (npix >= (std::size_t{1} << 32)) {
        rep.error = status{errc::size_overflow, "reconstruct handles fewer than 2^32 pixels"};
        return rep;
    }
    s.state_.assign(npix, 0);
    s.list_.clear();
    {  // marked pixels are rare: test eight mask bytes at a time
        const std::uint64_t wide = 0x0101010101010101ull * bits;
        std::size_t i = 0;
        for (; i + 8 <= npix; i += 8) {
            std::uint64_t word;
            std::memcpy(&word, mask + i, 8);
            if (!(word & wide)) continue;
            for (std::size_t k = i; k < i + 8; ++k)
                if (mask[k] & bits) {
                    s.state_[k] = 1;
                    s.list_.push_back(static_cast<std::uint32_t>(k));
                }
        }
        for (; i < npix; ++i)
            if (mask[i] & bits) {
                s.state_[i] = 1;
                s.list_.push_back(static_cast<std::uint32_t>(i));
            }
    }
    rep.pixels = s.list_.size();
    if (s.list_.empty()) return rep;
    s.staged_.assign(s.list_.size() * static_cast<std::size_t>(nch), 0.0);
    s.ready_.assign(s.list_.size(), 0);

    auto load = [&](int x, int y, int c) -> double {
        return c < ncol ? ct::load(color(x, y, c)) : vt::load(variance(x, y, c - ncol));
    };
    auto store = [&](int x, int y, int c, double v) {
        if (c < ncol) color(x, y, c) = ct::store(v);
        else variance(x, y, c - ncol) = vt::store(v);
    };

    // Weighted mean of the readable neighbours of list entry e into staged; false when none.
    // readable(state) says which neighbour states may be read; an unreadable or outside
    // neighbour contributes 0 to its place in the summation tree (and nothing to the weight).
    constexpr int max_ch = 16;
    // NC: the channel count when known at compile time (common counts), else 0 (runtime).
    auto filter_n = [&](std::size_t e, auto readable, auto nc_const) -> bool {
        constexpr int NC = decltype(nc_const)::value;
        const int nchan = NC > 0 ? NC : nch;
        const std::size_t p = s.list_[e];
        const int x = static_cast<int>(p % static_cast<std::size_t>(w));
        const int y = static_cast<int>(p / static_cast<std::size_t>(w));
        double wsum = 0.0;
        double acc[max_ch] = {};
        double v[8][max_ch];
        for (const auto& k : s.classes_) {
            int used = 0;
            for (int j = 0; j < k.count; ++j) {
                const int xx = x + k.dx[j], yy = y + k.dy[j];
                const bool ok = xx >= 0 && yy >= 0 && xx < w && yy < h &&
                                readable(s.state_[static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) +
                                                  static_cast<std::size_t>(xx)]);
                used += ok;
                for (int c = 0; c < nchan; ++c) v[j][c] = ok ? load(xx, yy, c) : 0.0;
            }
            if (used == 0) continue;
            wsum += k.weight * used;
            if (k.count == 8) {
                for (int c = 0; c < nchan; ++c)
                    acc[c] += k.weight * (((v[0][c] + v[1][c]) + (v[2][c] + v[3][c])) +
                                          ((v[4][c] + v[5][c]) + (v[6][c] + v[7][c])));
            } else {
                for (int c = 0; c < nchan; ++c) acc[c] += k.weight * ((v[0][c] + v[1][c]) + (v[2][c] + v[3][c]));
            }
        }
        if (!(wsum > 0)) return false;
        double* out = &s.staged_[e * static_cast<std::size_t>(nch)];
        for (int c = 0; c < nchan; ++c) out[c] = acc[c] / wsum;
        return true;
    };
    auto filter = [&](std::size_t e, auto readable) -> bool {
        switch (nch) {
            case 3: return filter_n(e, readable, std::integral_constant<int, 3>{});
            case 4: return filter_n(e, readable, std::integral_constant<int, 4>{});
            case 6: return filter_n(e, readable, std::integral_constant<int, 6>{});
            case 7: return filter_n(e, readable, std::integral_constant<int, 7>{});
            case 8: return filter_n(e, readable, std::integral_constant<int, 8>{});
            default: return filter_n(e, readable, std::integral_constant<int, 0>{});
        }
    };
    auto commit = [&](std::size_t e) -> double {  // write staged values, return rel. change
        const std::size_t p = s.list_[e];
        const int x = static_cast<int>(p % static_cast<std::size_t>(w));
        const int y = static_cast<int>(p / static_cast<std::size_t>(w));
        double change = 0.0;
        for (int c = 0; c < nch; ++c) {
            const double before = load(x, y, c);
            store(x, y, c, s.staged_[e * static_cast<std::size_t>(nch) + static_cast<std::size_t>(c)]);
            const double after = load(x, y, c);
            const double scale = std::max(std::fabs(before), std::fabs(after));
            if (scale > 0 && std::isfinite(before)) change = std::max(change, std::fabs(after - before) / scale);
        }
        return change;
    };

    // Phase 1: rounds that read only what was known when the round began.
    std::size_t pending = s.list_.size();
    while (pending > 0) {
        std::size_t done = 0;
        for (std::size_t e = 0; e < s.list_.size(); ++e) {
            if (s.state_[s.list_[e]] != 1) continue;
            s.ready_[e] = filter(e, [](std::uint8_t st) { return st == 0 || st == 2; }) ? 1 : 0;
            done += s.ready_[e];
        }
        if (done == 0) break;  // nothing readable anywhere: no valid pixel at all
        ++rep.phase1_rounds;
        for (std::size_t e = 0; e < s.list_.size(); ++e)
            if (s.ready_[e]) {
                (void)commit(e);
                s.state_[s.list_[e]] = 2;
                s.ready_[e] = 0;
            }
        pending -= done;
    }
    if (pending > 0) {
        rep.unreachable = pending;
        rep.error = status{errc::no_valid_pixels, "no valid pixel to reconstruct from"};
        // Nothing may become or stay NaN: non-finite values of unreachable pixels become 0.
        for (std::size_t e = 0; e < s.list_.size(); ++e) {
            const std::size_t p = s.list_[e];
            if (s.state_[p] != 1) continue;
            const int x = static_cast<int>(p % static_cast<std::size_t>(w));
            const int y = static_cast<int>(p / static_cast<std::size_t>(w));
            for (int c = 0; c < nch; ++c)
                if (!std::isfinite(load(x, y, c))) store(x, y, c, 0.0);
        }
        return rep;
    }

    // Phase 2: only entries with a marked neighbour can still change.
    std::vector<std::uint32_t>& active = s.list_;  // reorder in place: active entries first
    std::size_t nactive = 0;
    {
        // Staged values need no reordering: they are recomputed before every commit.
        const int r = o.kernel_width / 2;
        for (std::size_t e = 0; e < active.size(); ++e) {
            const std::size_t p = active[e];
            const int x = static_cast<int>(p % static_cast<std::size_t>(w));
            const int y = static_cast<int>(p / static_cast<std::size_t>(w));
            bool has = false;
            for (int dy = -r; dy <= r && !has; ++dy)
                for (int dx = -r; dx <= r && !has; ++dx) {
                    const int xx = x + dx, yy = y + dy;
                    if ((dx || dy) && xx >= 0 && yy >= 0 && xx < w && yy < h &&
                        s.state_[static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) +
                                 static_cast<std::size_t>(xx)] != 0)
                        has = true;
                }
            if (has) std::swap(active[nactive++], active[e]);
        }
        std::sort(active.begin(), active.begin() + static_cast<std::ptrdiff_t>(nactive));
    }
    for (int it = 0; it < o.max_iterations && nactive > 0; ++it) {
        for (std::size_t e = 0; e < nactive; ++e) (void)filter(e, [](std::uint8_t) { return true; });
        double change = 0.0;
        for (std::size_t e = 0; e < nactive; ++e) change = std::max(change, commit(e));
        rep.phase2_iterations = it + 1;
        rep.final_change = change;
        if (change <= o.tolerance) break;
    }
    return rep;
}

}  // namespace firefly
