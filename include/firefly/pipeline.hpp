// firefly: the whole pipeline over the two half buffers of a frame, and the detector object a
// renderer's denoise stage keeps from frame to frame (it owns the lambda cache and the
// scratch memory, so the second half buffer and every later frame reuse both).
//
//   per half      variance -> standard deviation; modified Z-score bound; one-sided
//                 generalized ESD on the standard deviations (top values from the pixels
//                 above the bound's cutoff, statistics built from the bottom up)
//   across halves the highlight check: an outlier in both halves may be kept (highlight_rule)
//   per half      two-phase reconstruction of fireflies and non-finite pixels, in place
//
// Halves run as two tasks on the executor; they write disjoint memory, and the lambda
// cache is filled between the two parallel stages, so every executor gives the same bytes.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "bound.hpp"
#include "esd.hpp"
#include "highlight.hpp"
#include "image_view.hpp"
#include "parallel.hpp"
#include "reconstruct.hpp"
#include "statistics.hpp"
#include "status.hpp"
#include "stddev.hpp"

namespace firefly {

// One half buffer: colour (1 to 4 channels; the first three are colour, all are
// reconstructed), its variance (1 channel, or one per colour channel) and optional alpha.
template <class T>
struct half_buffer {
    image_view<T> color;
    image_view<T> variance;
    image_view<const T> alpha;  // empty: no alpha
};

struct detector_options {
    double alpha = 0.05;                // significance of the generalized ESD test
    double bound_threshold = 3.5;       // modified Z-score cut for the upper bound
    variance_reduction reduction = variance_reduction::mean;
    lambda_method lambdas = lambda_method::exact;
    highlight_options highlight{};
    reconstruct_options reconstruction{};
    bool reconstruct = true;            // false: detect and report only, change nothing
};

inline status check_options(const detector_options& o) noexcept {
    if (!(o.alpha > 0.0 && o.alpha < 1.0))
        return status{errc::invalid_argument, "alpha must lie in (0, 1)"};
    if (!(o.bound_threshold >= 0.0) || !std::isfinite(o.bound_threshold))
        return status{errc::invalid_argument, "bound threshold must be finite and >= 0"};
    if (!(o.highlight.max_ratio >= 1.0) || !(o.highlight.max_relative_error >= 0.0) ||
        !(o.highlight.min_excess_z >= 0.0) || !(o.highlight.cluster_relative_error >= 0.0))
        return status{errc::invalid_argument,
                      "highlight: max_ratio >= 1, max_relative_error >= 0, min_excess_z >= 0"};
    return check_reconstruct_options(o.reconstruction);
}

// Bits of the optional per-pixel masks.
namespace mask_bits {
inline constexpr std::uint8_t firefly = 1;    // outlier reconstructed
inline constexpr std::uint8_t highlight = 2;  // outlier in both halves, kept
inline constexpr std::uint8_t nonfinite = 4;  // NaN/Inf repaired
inline constexpr std::uint8_t consistent = 8; // outlier in one half, but within the noise of
                                              // the other half: kept (min_excess_z)
}  // namespace mask_bits

struct half_report {
    std::size_t pixels = 0;
    std::size_t valid = 0;              // pixels in the statistics
    std::size_t ignored = 0;            // black or alpha <= 0
    std::size_t nonfinite = 0;          // NaN/Inf in colour, variance or alpha
    std::size_t negative_variance = 0;  // pixels with a negative variance (taken as 0)
    double median = 0.0;                // of the standard deviations
    double mad = 0.0;
    std::size_t bound = 0;              // modified Z-score upper bound
    std::size_t outliers = 0;           // generalized ESD outliers
    std::size_t highlights = 0;         // outliers kept (outlier in both halves)
    std::size_t consistent = 0;         // outliers kept (within the other half's noise)
    std::size_t fireflies = 0;          // outliers reconstructed
    std::size_t repaired = 0;           // non-finite pixels reconstructed
    int phase1_rounds = 0;
    int phase2_iterations = 0;
    double final_change = 0.0;
    status reconstruction{};            // no_valid_pixels when nothing could be read
};

struct [[nodiscard]] frame_report {
    // True when the frame was checked and every pixel that needed it was rebuilt.
    bool ok() const noexcept { return error.ok(); }
    status error{};                     // why not ok(): inputs or options refused, or pixels
                                        // left without a usable source
    half_report half[2];
    std::size_t both_outliers = 0;      // pixels that are outliers in both halves
    double variance_calibration = 1.0;  // variance -> variance of the mean (highlight rule)
    std::size_t lambdas_computed = 0;   // lambda cache misses in this frame
    std::size_t scratch_bytes = 0;      // detector memory after this frame
};

class detector {
public:
    explicit detector(detector_options options = {}, executor exec = {})
        : options_(options), exec_(std::move(exec)) {}

    const detector_options& options() const noexcept { return options_; }
    void set_options(const detector_options& o) { options_ = o; }
    void set_executor(executor e) { exec_ = std::move(e); }
    lambda_cache& lambdas() noexcept { return cache_; }

    std::size_t scratch_bytes() const noexcept {
        std::size_t n = cache_.bytes();
        for (const auto& h : halves_)
            n += h.sd.capacity() * sizeof(float) + h.label.capacity() +
                 h.hist.bytes() + h.select_f.capacity() * sizeof(float) +
                 h.select.capacity() * sizeof(double) + h.order.capacity() * sizeof(std::uint32_t) +
                 h.removed.capacity() * sizeof(double) + h.keys.capacity() * sizeof(std::uint64_t) +
                 h.recon.bytes();
        return n;
    }

    // Cleans both halves in place and reports. mask_a / mask_b (optional, 1 channel, the
    // frame's size) receive mask_bits per pixel.
    template <class T>
    frame_report process(const half_buffer<T>& a, const half_buffer<T>& b,
                         const image_view<std::uint8_t>& mask_a = {},
                         const image_view<std::uint8_t>& mask_b = {}) {
        static_assert(!std::is_const_v<T>, "process() cleans the half buffers in place");
        frame_report rep;
        const half_buffer<T>* hb[2] = {&a, &b};
        const image_view<std::uint8_t>* masks[2] = {&mask_a, &mask_b};
        if (status st = check_options(options_); !st.ok()) return fail(rep, st);
        for (int h = 0; h < 2; ++h) {
            if (status st = check_half_views(hb[h]->color, hb[h]->variance, hb[h]->alpha); !st.ok())
                return fail(rep, st);
            if (hb[h]->color.channels() > 4)
                return fail(rep, status{errc::channel_mismatch, "colour needs 1 to 4 channels"});
            if (!masks[h]->empty() && (!same_size(*masks[h], a.color) || masks[h]->channels() != 1))
                return fail(rep, status{errc::size_mismatch, "a mask must be 1 channel, frame-sized"});
        }
        if (!same_size(a.color, b.color))
            return fail(rep, status{errc::size_mismatch, "the two halves differ in size"});
        if (a.color.channels() != b.color.channels() || a.variance.channels() != b.variance.channels())
            return fail(rep, status{errc::channel_mismatch, "the two halves differ in channels"});
        if (a.color.pixel_count() >= (std::size_t{1} << 32))
            return fail(rep, status{errc::size_overflow, "more than 2^32 pixels"});
        if (status st = check_no_aliasing(a, b, mask_a, mask_b); !st.ok()) return fail(rep, st);

        const std::size_t lambdas_before = cache_.computed();

        // Stage 1 (parallel): standard deviations, bound, ESD candidates, per half.
        exec_.run(2, [&](std::size_t h) { detect_candidates(*hb[h], halves_[h], rep.half[h]); });
        // Stage 2 (serial): the ESD decision, reading and filling the shared lambda cache.
        for (int h = 0; h < 2; ++h) decide(halves_[h], rep.half[h]);
        // Stage 3: the highlight check across halves.
        check_highlights(a, b, rep);
        // Stage 4 (parallel): reconstruction, masks.
        exec_.run(2, [&](std::size_t h) { finish(*hb[h], halves_[h], *masks[h], rep.half[h]); });

        rep.lambdas_computed = cache_.computed() - lambdas_before;
        rep.scratch_bytes = scratch_bytes();
        return rep;
    }

private:
    // Label byte: pixel_class in the low two bits, then these flags.
    static constexpr std::uint8_t outlier_bit = 8;
    static constexpr std::uint8_t highlight_bit = 16;
    static constexpr std::uint8_t fix_bit = 32;
    static constexpr std::uint8_t consistent_bit = 64;

    struct half_state {
        std::vector<float> sd;
        std::vector<std::uint8_t> label;
        sd_histogram hist;                   // of the valid standard deviations
        std::vector<float> select_f;         // median selection scratch
        std::vector<double> select;          // MAD selection scratch
        std::vector<std::uint32_t> order;    // ESD candidates, removal order
        std::vector<std::uint64_t> keys;     // sort keys for that order
        std::vector<double> removed;         // their standard deviations
        summary rest;                        // summary of the valid pixels never removed
        std::size_t valid = 0;
        reconstruct_scratch recon;
    };

    // Every view process() writes must be apart from every other view it reads or writes:
    // the halves run on two threads, and a pixel read after it was rebuilt would change results.
    template <class T>
    static status check_no_aliasing(const half_buffer<T>& a, const half_buffer<T>& b,
                                    const image_view<std::uint8_t>& ma, const image_view<std::uint8_t>& mb) {
        const image_view<const T> written[4] = {a.color, a.variance, b.color, b.variance};
        const image_view<const std::uint8_t> masks[2] = {ma, mb};
        for (int i = 0; i < 4; ++i) {
            for (int j = i + 1; j < 4; ++j)
                if (views_may_overlap(written[i], written[j]))
                    return status{errc::aliased_views, "colour and variance views of the two halves must not share memory"};
            if (views_may_overlap(written[i], a.alpha) || views_may_overlap(written[i], b.alpha))
                return status{errc::aliased_views, "an alpha view shares memory with a colour or variance view"};
            for (const auto& m : masks)
                if (views_may_overlap(written[i], m))
                    return status{errc::aliased_views, "a mask shares memory with a colour or variance view"};
        }
        if (views_may_overlap(masks[0], masks[1]) || views_may_overlap(masks[0], a.alpha) ||
            views_may_overlap(masks[0], b.alpha) || views_may_overlap(masks[1], a.alpha) ||
            views_may_overlap(masks[1], b.alpha))
            return status{errc::aliased_views, "the masks must not share memory with each other or with alpha"};
        return ok_status();
    }

    static frame_report& fail(frame_report& r, status st) {
        r.error = st;
        return r;
    }

    static std::uint8_t cls(std::uint8_t label) noexcept { return label & pixel_class_bits; }
    static constexpr std::uint8_t valid_class = static_cast<std::uint8_t>(pixel_class::valid);
    static constexpr std::uint8_t nonfinite_class = static_cast<std::uint8_t>(pixel_class::nonfinite);

    template <class T>
    void detect_candidates(const half_buffer<T>& hb, half_state& s, half_report& r) {
        const std::size_t n = hb.color.pixel_count();
        s.sd.resize(n);
        s.label.resize(n);
        const stddev_counts c =
            detail::stddev_pass(hb.color, hb.variance, hb.alpha, options_.reduction, s.sd.data(), s.label.data());
        s.hist.build(s.sd.data(), n);
        r.pixels = n;
        r.valid = c.valid;
        r.ignored = c.ignored;
        r.nonfinite = c.nonfinite;
        r.negative_variance = c.negative_variance;
        s.valid = c.valid;
        const float* sd = s.sd.data();  // valid: >= 0; ignored: -1; non-finite: NaN
        // Modified Z-score bound (exact median and MAD; see bound.hpp for the definition).
        bound_result b;
        b.threshold = options_.bound_threshold;
        b.n = c.valid;
        if (c.valid > 0) {
            b.median = s.hist.median(sd, n, s.select_f);
            b.mad = s.hist.mad(sd, n, b.median, s.select);
            set_bound_scale(b, [&] {
                return detail::blocked_sum(n, [&](std::size_t i) {
                           return sd[i] >= 0 ? std::fabs(static_cast<double>(sd[i]) - b.median) : 0.0;
                       }) / static_cast<double>(c.valid);
            });
        }
        r.median = b.median;
        r.mad = b.mad;
        // The bound's test as one float comparison: cut is the smallest float x with
        // b.above(x), found exactly (above() is monotone in x).
        float cut = HUGE_VALF;
        if (b.scale > 0) {
            const double guess = b.median + b.threshold * b.scale;
            cut = guess <= static_cast<double>(FLT_MAX) ? static_cast<float>(guess) : HUGE_VALF;
            while (cut > 0 && b.above(std::nextafter(cut, 0.0f))) cut = std::nextafter(cut, 0.0f);
            while (std::isfinite(cut) && !b.above(cut)) cut = std::nextafter(cut, HUGE_VALF);
        }
        const double med = b.median;
        // One pass: the candidates (>= cut: exactly the values the bound counts, the top
        // values) and the shifted sums of every other valid value, in fixed blocks.
        double s1 = 0, s2 = 0;
        std::size_t rest_n = 0;
        detail::shifted_sums_below(sd, n, cut, med, s1, s2, rest_n, s.order);
        r.bound = s.order.size();
        // Removal order: largest first, lower index first among equals. Sorting packed keys
        // (the bits of a float >= 0 order like the float) avoids the indirection.
        s.keys.resize(s.order.size());
        for (std::size_t j = 0; j < s.order.size(); ++j) {
            std::uint32_t bits;
            std::memcpy(&bits, &sd[s.order[j]], 4);
            s.keys[j] = (static_cast<std::uint64_t>(~bits) << 32) | s.order[j];
        }
        std::sort(s.keys.begin(), s.keys.end());
        for (std::size_t j = 0; j < s.order.size(); ++j) s.order[j] = static_cast<std::uint32_t>(s.keys[j]);
        // At most n - 2 steps: candidates beyond that rejoin the rest.
        const std::size_t m = std::min(s.order.size(), s.valid >= 2 ? s.valid - 2 : 0);
        for (std::size_t j = m; j < s.order.size(); ++j) {
            const double d = static_cast<double>(sd[s.order[j]]) - med;
            s1 += d;
            s2 += d * d;
            ++rest_n;
        }
        s.order.resize(m);
        s.removed.resize(m);
        for (std::size_t j = 0; j < m; ++j) s.removed[j] = sd[s.order[j]];
        s.rest = summary{};
        if (rest_n > 0) {
            s.rest.count = rest_n;
            s.rest.mean = med + s1 / static_cast<double>(rest_n);
            s.rest.m2 = std::max(0.0, s2 - s1 * s1 / static_cast<double>(rest_n));
        }
    }

    void decide(half_state& s, half_report& r) {
        esd_options o;
        o.alpha = options_.alpha;
        o.max_outliers = s.order.size();
        o.method = options_.lambdas;
        esd_result res;
        if (!s.order.empty())
            detail::esd_from_removals(s.removed.data(), s.order.size(), s.rest, s.valid, o, cache_, res);
        r.outliers = res.outliers;
        for (std::size_t j = 0; j < res.outliers; ++j) s.label[s.order[j]] |= outlier_bit;
    }

    template <class T>
    void check_highlights(const half_buffer<T>& a, const half_buffer<T>& b, frame_report& rep) {
        std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        // Outliers come from the two lists, not from a pass over the frame.
        std::vector<std::uint32_t>& pairs = pairs_;
        pairs.clear();
        bool single = false;
        for (std::size_t j = 0; j < rep.half[0].outliers; ++j) {
            const std::uint32_t i = halves_[0].order[j];
            if (lab[1][i] & outlier_bit) pairs.push_back(i);
            else single = true;
        }
        single |= rep.half[1].outliers > pairs.size();
        rep.both_outliers = pairs.size();
        const highlight_options& ho = options_.highlight;
        const bool check_single = single && ho.min_excess_z > 0;
        if (pairs.empty() && !check_single) return;
        const int w = a.color.width();
        const int nc = colour_channels(a.color.channels());
        const int nv = a.variance.channels();
        const bool need_cal = check_single || ho.rule == highlight_rule::confident ||
                              ho.rule == highlight_rule::confident_and_agree;
        double calibration = 1.0;
        if (need_cal) {
            // (A - B)^2 / (vA + vB) over ordinary pixels on a lattice of about 16k pixels,
            // whatever the resolution: a median of that many ratios is good to ~1%.
            calibration_.clear();
            const int hgt = a.color.height();
            const double cells = static_cast<double>(w) * static_cast<double>(hgt) / 16384.0;
            const int step = std::max(1, static_cast<int>(std::sqrt(cells)));
            for (int y = step / 2; y < hgt; y += step)
                for (int x = step / 2; x < w; x += step) {
                    const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
                    if (lab[0][i] != valid_class || lab[1][i] != valid_class) continue;
                    for (int c = 0; c < nc; ++c)
                        calibration_.add(a.color.load(x, y, c), b.color.load(x, y, c),
                                         a.variance.load(x, y, nv == 1 ? 0 : c), b.variance.load(x, y, nv == 1 ? 0 : c));
                }
            calibration = calibration_.factor();
        }
        rep.variance_calibration = calibration;
        const half_buffer<T>* hb[2] = {&a, &b};
        auto mean_colour = [nc](const image_view<T>& v, int x, int y) {
            double s = 0;
            for (int c = 0; c < nc; ++c) s += v.load(x, y, c);
            return s / nc;
        };
        auto reduced_variance = [this](const image_view<T>& v, int x, int y) {
            bool nonfinite = false, negative = false;
            return detail::reduce_variance(&v(x, y, 0), v.channel_stride(), v.channels(), options_.reduction,
                                           nonfinite, negative);
        };
        const int hgt = a.color.height();
        auto both = [&](int x, int y) {
            const std::size_t j = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
            return (lab[0][j] & outlier_bit) && (lab[1][j] & outlier_bit);
        };
        for (const std::uint32_t i : pairs) {
            const int x = static_cast<int>(i % static_cast<std::uint32_t>(w));
            const int y = static_cast<int>(i / static_cast<std::uint32_t>(w));
            bool cluster = false;
            for (int dy = -1; dy <= 1 && !cluster; ++dy)
                for (int dx = -1; dx <= 1 && !cluster; ++dx)
                    if ((dx || dy) && x + dx >= 0 && y + dy >= 0 && x + dx < w && y + dy < hgt)
                        cluster = both(x + dx, y + dy);
            const double la = mean_colour(a.color, x, y), lb = mean_colour(b.color, x, y);
            const double va = reduced_variance(a.variance, x, y), vb = reduced_variance(b.variance, x, y);
            if (!is_highlight(ho, la, lb, va, vb, calibration, cluster)) continue;  // both rebuilt
            // A highlight. A firefly may still sit on top of it in one half: that half then
            // exceeds the other by far more than the noise, and only it is rebuilt.
            const bool a_over = ho.min_excess_z > 0 && exceeds_other_half(ho, la, lb, vb, calibration);
            const bool b_over = ho.min_excess_z > 0 && exceeds_other_half(ho, lb, la, va, calibration);
            if (!a_over) lab[0][i] |= highlight_bit;
            if (!b_over) lab[1][i] |= highlight_bit;
        }
        if (!check_single) return;
        for (int h = 0; h < 2; ++h)
            for (std::size_t j = 0; j < rep.half[h].outliers; ++j) {
            const std::uint32_t i = halves_[h].order[j];
            if (lab[1 - h][i] & outlier_bit) continue;  // a pair, decided above
            if (cls(lab[1 - h][i]) == nonfinite_class) continue;  // nothing to compare with
            const int x = static_cast<int>(i % static_cast<std::uint32_t>(w));
            const int y = static_cast<int>(i / static_cast<std::uint32_t>(w));
            if (!exceeds_other_half(ho, mean_colour(hb[h]->color, x, y), mean_colour(hb[1 - h]->color, x, y),
                                    reduced_variance(hb[1 - h]->variance, x, y), calibration))
                lab[h][i] |= consistent_bit;
            }
    }

    template <class T>
    void finish(const half_buffer<T>& hb, half_state& s, const image_view<std::uint8_t>& mask,
                half_report& r) {
        const std::size_t n = s.label.size();
        std::uint8_t* label = s.label.data();
        // Outliers: walk their list, not the frame.
        std::size_t highlights = 0, consistent = 0, fireflies = 0;
        for (std::size_t j = 0; j < r.outliers; ++j) {
            const std::uint32_t i = s.order[j];
            const std::uint8_t l = label[i];
            if (l & highlight_bit) {
                ++highlights;
            } else if (l & consistent_bit) {
                ++consistent;
            } else {
                ++fireflies;
                label[i] = static_cast<std::uint8_t>(l | fix_bit);
            }
        }
        r.highlights = highlights;
        r.consistent = consistent;
        r.fireflies = fireflies;
        r.repaired = r.nonfinite;
        if (r.nonfinite > 0)  // a byte-wise loop that vectorizes
            for (std::size_t i = 0; i < n; ++i)
                label[i] = static_cast<std::uint8_t>(label[i] | (((label[i] & pixel_class_bits) == nonfinite_class) ? fix_bit : 0));
        if (options_.reconstruct) {
            const reconstruct_report rr =
                reconstruct(hb.color, hb.variance, label, options_.reconstruction, s.recon, fix_bit);
            r.phase1_rounds = rr.phase1_rounds;
            r.phase2_iterations = rr.phase2_iterations;
            r.final_change = rr.final_change;
            r.reconstruction = rr.error;
        }
        if (!mask.empty()) {
            const int w = mask.width();
            for (int y = 0; y < mask.height(); ++y)
                for (int x = 0; x < w; ++x) {
                    const std::uint8_t l = label[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)];
                    std::uint8_t m = 0;
                    if ((l & outlier_bit) && !(l & (highlight_bit | consistent_bit))) m |= mask_bits::firefly;
                    if (l & highlight_bit) m |= mask_bits::highlight;
                    if (l & consistent_bit) m |= mask_bits::consistent;
                    if (cls(l) == nonfinite_class) m |= mask_bits::nonfinite;
                    mask(x, y) = m;
                }
        }
    }

    detector_options options_;
    executor exec_;
    lambda_cache cache_;
    half_state halves_[2];
    variance_calibration calibration_;
    std::vector<std::uint32_t> pairs_;
};

// The final image of a frame, (A + B) / 2, and the variance of that mean, (vA + vB) / 4.
// out_variance may be empty. Views must share size and channel counts.
template <class T, class U>
status combine_halves(const image_view<T>& a, const image_view<T>& b, const image_view<U>& out,
                      const image_view<T>& var_a = {}, const image_view<T>& var_b = {},
                      const image_view<U>& out_variance = {}) {
    if (!same_size(a, b) || !same_size(a, out)) return status{errc::size_mismatch, "combine: sizes differ"};
    if (a.channels() != b.channels() || out.channels() != a.channels())
        return status{errc::channel_mismatch, "combine: channel counts differ"};
    const bool var = !out_variance.empty();
    if (var && (!same_size(var_a, out_variance) || !same_size(var_b, out_variance) ||
                var_a.channels() != out_variance.channels() || var_b.channels() != out_variance.channels()))
        return status{errc::size_mismatch, "combine: variance views do not match"};
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            for (int c = 0; c < a.channels(); ++c) out.store(x, y, c, 0.5 * a.load(x, y, c) + 0.5 * b.load(x, y, c));
            if (var)
                for (int c = 0; c < out_variance.channels(); ++c)
                    out_variance.store(x, y, c, 0.25 * (var_a.load(x, y, c) + var_b.load(x, y, c)));
        }
    return ok_status();
}

}  // namespace firefly
