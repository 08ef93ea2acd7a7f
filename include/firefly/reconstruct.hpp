// firefly: two-phase Gaussian reconstruction of the pixels a mask marks (paper, section 4).
//
// Each marked pixel becomes the Gaussian-weighted mean of its neighbours in a square kernel
// (5 pixels wide by default), colour and variance alike; the kernel is renormalised over
// the neighbours that may be read, so borders and corners need no special case. Pixels a
// role marks `excluded` (outliers that are kept, like highlights) are not read, nor are those
// it marks `outside` (no geometry).
//
//   phase 1  gives every marked pixel a first value, in rounds. A round reads only pixels
//            known when it began (sources, and marked ones set by earlier rounds), so a
//            cluster wider than the kernel fills from its rim inwards, the same from every
//            side: no scan order, no directional bias (the paper's "2 2 x x 8 8"). Round
//            r + 1 looks only at the marked pixels next to those set in round r (a frontier),
//            so a cluster costs time in proportion to its area, not its area times width.
//   phase 2  Jacobi iterations, now reading every neighbour, over an active set: at first
//            the marked pixels with marked neighbours, then only those next to a pixel that
//            changed by more than the tolerance (relative) in the last iteration. Converged
//            regions stop costing time while a large cluster's interior still settles;
//            each iteration reads only values of the one before, so the result depends on
//            neither scan order nor thread count. Capped at max_iterations.
//
// A marked pixel that no source can reach (its whole neighbourhood, transitively, is marked
// or excluded: a firefly inside a kept highlight region) reads the excluded pixels after
// all (never the outside ones), in two more phases run once every other pixel is settled:
// what it reads changes no pixel elsewhere. One that nothing can reach keeps its values and
// is reported (unreachable, no_valid_pixels).
//
// Exact symmetry: the weighted sums are kernel.hpp's flip-exact trees, so a flipped or
// transposed input gives a bit-identical (flipped) output.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "image_view.hpp"
#include "kernel.hpp"
#include "status.hpp"

namespace firefly {

struct reconstruct_options {
    int kernel_width = 5;       // odd, >= 3
    double sigma = 1.0;         // Gaussian sigma in pixels
    double tolerance = 1e-3;    // phase 2 stops when max |change| / |value| falls below this
                                // (0: at max_iterations alone)
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
    // Below 0.1 a neighbour's weight exp(-1 / (2 sigma^2)) and its square (the variance's
    // weight) underflow: at 0.02 every weight is 0 and a pixel with eight valid neighbours
    // "has no source"; a kernel that narrow is its nearest ring alone (kernel_width 3).
    if (!(o.sigma >= 0.1) || !std::isfinite(o.sigma))
        return status{errc::invalid_argument, "kernel sigma must be finite and at least 0.1"};
    if (!(o.tolerance >= 0) || o.max_iterations < 0)
        return status{errc::invalid_argument, "tolerance and iteration cap must be >= 0"};
    return ok_status();
}

// What reconstruction does with a pixel.
enum class pixel_role : std::uint8_t {
    source = 0,    // read by its neighbours, never changed
    rebuild = 1,   // marked: gets the weighted mean of its readable neighbours
    excluded = 3,  // neither read nor changed, but read when nothing else reaches a pixel
    outside = 4,   // no part of the image (alpha 0): never read, never changed
};

// Memory reused across calls (and frames).
class reconstruct_scratch {
public:
    std::size_t bytes() const noexcept {
        return state_.capacity() + (list_.capacity() + next_.capacity()) * sizeof(std::uint32_t) +
               staged_.capacity() * sizeof(double);
    }

    // Internal state of reconstruct(); public only so the function template can reach it.
    detail::gaussian_kernel kernel_;
    // Per pixel: 0 source, 1 marked, 2 marked and known, 3 excluded, 4 outside; | queued when listed
    // for the next round or iteration.
    std::vector<std::uint8_t> state_;
    std::vector<std::uint32_t> list_;   // marked pixels of this round / iteration
    std::vector<std::uint32_t> next_;   // those of the next one
    std::vector<double> staged_;        // new values, list entry x channel
    static constexpr std::uint8_t queued = 0x80;
};

namespace detail {

// The marked pixels of a role map: scans `interesting` bytes of mask eight at a time
// (marked pixels are rare) and asks role() only about those.
template <class Role>
void mark_roles(const std::uint8_t* mask, std::size_t npix, std::uint8_t interesting, Role&& role,
                reconstruct_scratch& s) {
    s.state_.assign(npix, 0);
    s.list_.clear();
    auto visit = [&](std::size_t k) {
        const pixel_role r = role(mask[k]);
        s.state_[k] = static_cast<std::uint8_t>(r);
        if (r == pixel_role::rebuild) s.list_.push_back(static_cast<std::uint32_t>(k));
    };
    const std::uint64_t wide = 0x0101010101010101ull * interesting;
    std::size_t i = 0;
    for (; i + 8 <= npix; i += 8) {
        std::uint64_t word;
        std::memcpy(&word, mask + i, 8);
        if (!(word & wide)) continue;
        for (std::size_t k = i; k < i + 8; ++k)
            if (mask[k] & interesting) visit(k);
    }
    for (; i < npix; ++i)
        if (mask[i] & interesting) visit(i);
}

// Adds to s.next_ the marked pixels (state `want`) within the kernel of pixel p, once each.
inline void queue_neighbours(std::size_t p, int w, int h, int r, std::uint8_t want, reconstruct_scratch& s) {
    const int x = detail::column_of(p, w), y = detail::row_of(p, w);
    for (int yy = (std::max)(0, y - r); yy <= (std::min)(h - 1, y + r); ++yy)
        for (int xx = (std::max)(0, x - r); xx <= (std::min)(w - 1, x + r); ++xx) {
            if (xx == x && yy == y) continue;  // a value depends on its neighbours only
            const std::size_t q = static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) + static_cast<std::size_t>(xx);
            if (s.state_[q] != want) continue;
            s.state_[q] = static_cast<std::uint8_t>(want | reconstruct_scratch::queued);
            s.next_.push_back(static_cast<std::uint32_t>(q));
        }
}

// Moves next_ into list_ (sorted: memory order) and clears the queued flags.
inline void advance(reconstruct_scratch& s) {
    std::sort(s.next_.begin(), s.next_.end());
    s.list_.swap(s.next_);
    s.next_.clear();
    for (const std::uint32_t q : s.list_) s.state_[q] &= static_cast<std::uint8_t>(~reconstruct_scratch::queued);
}

// After both phases left pixels pending: excluded and rebuilt pixels become sources (state
// 0; the rebuilt ones are final), and list_ gets the pending pixels that now have one within
// the kernel. False when there are none.
inline bool fallback_to_excluded(reconstruct_scratch& s, int w, int h, int r) {
    s.next_.clear();
    for (std::size_t p = 0; p < s.state_.size(); ++p) {
        if (s.state_[p] == 2) s.state_[p] = 0;
        if (s.state_[p] != 3) continue;
        s.state_[p] = 0;
        queue_neighbours(p, w, h, r, 1, s);
    }
    advance(s);
    return !s.list_.empty();
}

}  // namespace detail

namespace detail {

// The two phases over one image pair; state, lists and staged values live in the scratch.
template <class C, class V>
class rebuilder {
    using ct = channel_traits<std::remove_cv_t<C>>;
    using vt = channel_traits<std::remove_cv_t<V>>;

public:
    rebuilder(const image_view<C>& color, const image_view<V>& variance, reconstruct_scratch& s, int radius)
        : color_(color), variance_(variance), s_(s), w_(color.width()), h_(color.height()),
          ncol_(color.channels()), nch_(color.channels() + (variance.empty() ? 0 : variance.channels())), r_(radius) {}

    // Phase 1: rounds over the listed pixels (the first round all marked ones, then the
    // frontier of the last). Returns how many pixels it set.
    std::size_t fill(reconstruct_report& rep) {
        std::size_t set = 0;
        while (!s_.list_.empty()) {
            s_.staged_.resize(s_.list_.size() * stride());
            std::size_t kept = 0;  // entries that found a neighbour move to the front
            for (std::size_t e = 0; e < s_.list_.size(); ++e)
                if (filter_any(e)) {
                    if (kept != e) {
                        std::memmove(&s_.staged_[kept * stride()], &s_.staged_[e * stride()], sizeof(double) * stride());
                        s_.list_[kept] = s_.list_[e];
                    }
                    ++kept;
                }
            if (kept == 0) break;
            s_.list_.resize(kept);
            ++rep.phase1_rounds;
            for (std::size_t e = 0; e < kept; ++e) {
                (void)commit(e);
                s_.state_[s_.list_[e]] = 2;
            }
            set += kept;
            for (const std::uint32_t p : s_.list_) queue_neighbours(p, w_, h_, r_, 1, s_);
            advance(s_);
        }
        return set;
    }

    // Phase 2: Jacobi iterations over the known marked pixels with known marked neighbours,
    // then over those next to a pixel that changed by more than the tolerance.
    void settle(reconstruct_report& rep, const reconstruct_options& o) {
        s_.next_.clear();
        for (std::size_t p = 0; p < s_.state_.size(); ++p)  // state 2 pixels only: a byte scan
            if (s_.state_[p] == 2 && has_known_neighbour(p)) s_.next_.push_back(static_cast<std::uint32_t>(p));
        s_.list_.swap(s_.next_);
        s_.next_.clear();
        for (int it = 0; it < o.max_iterations && !s_.list_.empty(); ++it) {
            s_.staged_.resize(s_.list_.size() * stride());
            for (std::size_t e = 0; e < s_.list_.size(); ++e) (void)filter_any(e);
            double change = 0.0;
            for (std::size_t e = 0; e < s_.list_.size(); ++e) {
                const double c = commit(e);
                change = (std::max)(change, c);
                if (c > o.tolerance) queue_neighbours(s_.list_[e], w_, h_, r_, 2, s_);
            }
            ++rep.phase2_iterations;
            rep.final_change = change;
            advance(s_);
        }
        for (const std::uint32_t q : s_.list_) s_.state_[q] &= static_cast<std::uint8_t>(~reconstruct_scratch::queued);
    }

private:
    std::size_t stride() const noexcept { return static_cast<std::size_t>(nch_); }
    double load(int x, int y, int c) const {
        return c < ncol_ ? ct::load(color_(x, y, c)) : vt::load(variance_(x, y, c - ncol_));
    }
    void store(int x, int y, int c, double v) const {
        if (c < ncol_) color_(x, y, c) = ct::store(v);
        else variance_(x, y, c - ncol_) = vt::store(v);
    }
    std::size_t at(int x, int y) const noexcept {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
    }
    // Sources and known marked pixels are read; queued flags do not change that.
    bool readable(int x, int y) const {
        const std::uint8_t st = s_.state_[at(x, y)] & static_cast<std::uint8_t>(~reconstruct_scratch::queued);
        return st == 0 || st == 2;
    }
    bool has_known_neighbour(std::size_t p) const {
        const int x = static_cast<int>(p % static_cast<std::size_t>(w_)), y = static_cast<int>(p / static_cast<std::size_t>(w_));
        for (int yy = (std::max)(0, y - r_); yy <= (std::min)(h_ - 1, y + r_); ++yy)
            for (int xx = (std::max)(0, x - r_); xx <= (std::min)(w_ - 1, x + r_); ++xx)
                if ((xx != x || yy != y) && (s_.state_[at(xx, yy)] & 0x7f) == 2) return true;
        return false;
    }
    // Weighted mean of list entry e's readable neighbours into staged; false when none. Where
    // the plain sums overflow (double sources near DBL_MAX) they are taken again at
    // overflow_scale (kernel.hpp); no rebuild leaves an infinite source.
    template <int NC>
    bool filter(std::size_t e) {
        const std::size_t p = s_.list_[e];
        const int x = static_cast<int>(p % static_cast<std::size_t>(w_)), y = static_cast<int>(p / static_cast<std::size_t>(w_));
        double acc[16] = {};
        const double wsum = source_sums<NC>(x, y, unscaled{}, acc);
        if (!(wsum > 0)) return false;
        double* out = &s_.staged_[e * stride()];
        if (all_finite(acc, nch_)) {
            for (int c = 0; c < nch_; ++c) out[c] = acc[c] / wsum;
            return true;
        }
        std::fill(acc, acc + 16, 0.0);
        (void)source_sums<NC>(x, y, overflow_scale, acc);
        for (int c = 0; c < nch_; ++c) out[c] = from_overflow_scale(acc[c] / wsum);
        return true;
    }
    // The kernel's weighted sums of the readable sources around (x, y), each value times
    // `scale` (unscaled, or overflow_scale), into acc; returns the sum of the weights.
    template <int NC, class Scale>
    double source_sums(int x, int y, Scale scale, double* acc) {
        return kernel_sum<NC>(
            s_.kernel_, x, y, w_, h_, nch_, [this](int xx, int yy) { return readable(xx, yy); },
            [this, scale](int xx, int yy, double* v) {
                for (int c = 0; c < (NC > 0 ? NC : nch_); ++c) v[c] = load(xx, yy, c) * scale;
            },
            acc);
    }
    bool filter_any(std::size_t e) {
        switch (nch_) {  // common channel counts at compile time
            case 3: return filter<3>(e);
            case 4: return filter<4>(e);
            case 6: return filter<6>(e);
            case 7: return filter<7>(e);
            case 8: return filter<8>(e);
            default: return filter<0>(e);
        }
    }
    // Writes entry e's staged values; returns the largest relative change.
    double commit(std::size_t e) {
        const std::size_t p = s_.list_[e];
        const int x = static_cast<int>(p % static_cast<std::size_t>(w_)), y = static_cast<int>(p / static_cast<std::size_t>(w_));
        double change = 0.0;
        for (int c = 0; c < nch_; ++c) {
            const double before = load(x, y, c);
            store(x, y, c, s_.staged_[e * stride() + static_cast<std::size_t>(c)]);
            const double after = load(x, y, c);
            const double scale = (std::max)(std::fabs(before), std::fabs(after));
            if (scale > 0 && std::isfinite(before)) change = (std::max)(change, std::fabs(after - before) / scale);
        }
        return change;
    }

    image_view<C> color_;
    image_view<V> variance_;
    reconstruct_scratch& s_;
    int w_, h_, ncol_, nch_, r_;
};

}  // namespace detail

// Reconstructs the pixels whose role is `rebuild`, in colour and, when not empty, variance.
// role(mask[i]) is asked only for pixels with (mask[i] & interesting) != 0; the others are
// sources. Every pixel not rebuilt is left bit-identical.
template <class C, class V, class Role>
reconstruct_report reconstruct(const image_view<C>& color, const image_view<V>& variance,
                               const std::uint8_t* mask, const reconstruct_options& o,
                               reconstruct_scratch& s, std::uint8_t interesting, Role&& role) {
    static_assert(!std::is_const_v<C> && !std::is_const_v<V>, "reconstruct writes its images");
    reconstruct_report rep;
    if (status st = check_reconstruct_options(o); !st.ok()) {
        rep.error = st;
        return rep;
    }
    if (color.empty()) return rep;
    const bool has_var = !variance.empty();
    if (has_var && !same_size(color, variance)) {
        rep.error = status{errc::size_mismatch, "variance and colour differ in size"};
        return rep;
    }
    if (color.channels() + (has_var ? variance.channels() : 0) > 16) {
        rep.error = status{errc::channel_mismatch, "reconstruct handles at most 16 channels in all"};
        return rep;
    }
    const std::size_t npix = color.pixel_count();
    if (npix >= (std::size_t{1} << 32)) {
        rep.error = status{errc::size_overflow, "reconstruct handles fewer than 2^32 pixels"};
        return rep;
    }
    s.kernel_.set(o.kernel_width, o.sigma);
    detail::mark_roles(mask, npix, interesting, role, s);
    rep.pixels = s.list_.size();
    if (s.list_.empty()) return rep;
    const int r = o.kernel_width / 2;
    detail::rebuilder<C, V> rb(color, variance, s, r);
    std::size_t pending = rep.pixels - rb.fill(rep);
    rb.settle(rep, o);
    // Pixels no source can reach (a firefly inside a kept highlight region, say) may read
    // the excluded pixels after all, rather than stay as they are; the others are settled
    // already, and read none of it (before, one such pixel anywhere let every rebuilt cluster
    // beside a kept highlight read it).
    if (pending > 0 && detail::fallback_to_excluded(s, color.width(), color.height(), r)) {
        pending -= rb.fill(rep);
        rb.settle(rep, o);
    }
    if (pending > 0) {
        rep.unreachable = pending;
        rep.error = status{errc::no_valid_pixels, "pixels with no usable source anywhere were left as they were"};
    }
    return rep;
}

// Reconstructs the pixels i (row-major, i = y * width + x) with (mask[i] & bits) != 0; every
// other pixel is a source.
template <class C, class V>
reconstruct_report reconstruct(const image_view<C>& color, const image_view<V>& variance,
                               const std::uint8_t* mask, const reconstruct_options& o,
                               reconstruct_scratch& s, std::uint8_t bits = 0xFF) {
    return reconstruct(color, variance, mask, o, s, bits,
                       [](std::uint8_t) { return pixel_role::rebuild; });
}

}  // namespace firefly
