// firefly/sim: accuracy of a cleaned frame against the simulator's ground truth. Works for
// any method (firefly or a peer): what a method did is read off the pixels themselves.
//
// A pixel (in one half) is "changed" when any bit of its colour changed, and "lowered" when it
// changed and some channel is now below the input (or the input was not finite; a finite input
// made non-finite is not lowered, so NaN output earns no detection). The detection
// counts are of lowered pixels: removing a firefly lowers its pixel, while giving removed
// energy back (energy.hpp) only adds light, which is a change of the estimate and not a
// detection; what it does to the image is in relmse, made_worse and energy.
//
//   recall             visible firefly hits lowered / visible firefly hits, per half. Visible:
//                      the firefly energy adds more than 10x the pixel's expected value without
//                      fireflies (with them, no firefly could be visible on a dense frame, where
//                      fireflies bring most of the expected energy).
//   precision          lowered pixels that got a firefly or a non-finite sample / lowered
//   false_positive     lowered pixels with no firefly and not a highlight / all such pixels
//   highlight_kept     highlight pixels lowered in no half without a firefly or a non-finite
//                      sample there / highlight pixels (a firefly on a highlight is the
//                      method's to remove: its half may change)
//   relmse             mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01) for the
//                      combined image (A + B) / 2 against the expected radiance
//   changed            changed pixels (pixel x half)
//   made_worse         changed pixels (pixel x half) whose error against the expected radiance
//                      grew: the relMSE term summed over the channels (a non-finite input
//                      counts as an infinite error)
//   energy             mean brightness of the combined image / the expected image's, over all
//                      pixels, highlight pixels, and non-highlight pixels (1: no energy lost)
//
// With nothing to count a ratio reads its best value: recall, precision and highlight_kept 1
// and false_positive 0 with no visible firefly, lowered pixel, highlight or clean pixel, relmse
// 0 over no pixel, energy 1 where the expected image is black (and the highlight and rest
// energies 1 when the highlight mask does not fit the image). relmse charges a non-finite value
// 1e6 and a finite one its own error, however large.
//
// For K buffers (simulate_buffers): evaluate_buffers, the same counts over buffers, relmse and
// energy on the combined image (the spp-weighted mean of the cleaned buffers); and
// evaluate_combined for a method that outputs one image (median of means and the like).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "scene.hpp"

namespace firefly::sim {

struct accuracy {
    double recall = 1.0;
    double precision = 1.0;
    double false_positive = 0.0;
    double highlight_kept = 1.0;
    double relmse = 0.0;
    std::size_t visible = 0;   // visible firefly hits (pixel x half)
    std::size_t changed = 0;   // changed pixels (pixel x half)
    std::size_t lowered = 0;   // of those, lowered in some channel (or non-finite before)
    std::size_t made_worse = 0;  // changed pixels (pixel x half) now further from the expected
    double energy = 1.0;            // combined mean / expected mean
    double energy_highlight = 1.0;  // the same over highlight pixels
    double energy_rest = 1.0;       // the same over the other pixels
};

// One combined image against the ground truth.
struct combined_accuracy {
    double relmse = 0.0;
    double energy = 1.0, energy_highlight = 1.0, energy_rest = 1.0;
};

// Relative MSE of an interleaved RGB image against a reference (non-finite pixels count
// as an error of 1e6).
inline double relmse(const float* img, const float* ref, std::size_t pixels) {
    double s = 0;
    for (std::size_t i = 0; i < pixels * 3; ++i) {
        const double d = static_cast<double>(img[i]) - static_cast<double>(ref[i]);
        const double e = d * d / (static_cast<double>(ref[i]) * static_cast<double>(ref[i]) + 0.01);
        s += std::isfinite(e) ? e : 1e6;
    }
    return pixels ? s / static_cast<double>(pixels * 3) : 0.0;
}

// Mean brightness of `img` over the pixels where mask[i] == want (all pixels when mask is
// null), divided by the reference's over the same pixels; pixels non-finite in either are
// skipped. 1 when the reference's mean is 0.
inline double energy_ratio(const float* img, const float* ref, std::size_t pixels,
                           const std::uint8_t* mask = nullptr, std::uint8_t want = 1) {
    double si = 0, sr = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        if (mask && mask[i] != want) continue;
        for (std::size_t c = 0; c < 3; ++c) {
            const double a = static_cast<double>(img[i * 3 + c]), r = static_cast<double>(ref[i * 3 + c]);
            if (!std::isfinite(a) || !std::isfinite(r)) continue;
            si += a;
            sr += r;
        }
    }
    return sr != 0 ? si / sr : 1.0;
}

// Error of one RGB pixel against the reference: the relMSE term summed over the channels
// (infinite when non-finite), as docs/accuracy.md defines "made worse".
inline double pixel_error(const float* px, const float* ref) {
    double e = 0;
    for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(px[c]) - static_cast<double>(ref[c]);
        e += d * d / (static_cast<double>(ref[c]) * static_cast<double>(ref[c]) + 0.01);
    }
    return std::isfinite(e) ? e : std::numeric_limits<double>::infinity();
}

// Pixels that `after` changed from `before` and that are now further from `ref`.
inline std::size_t made_worse(const float* before, const float* after, const float* ref, std::size_t pixels) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < pixels; ++i)
        if (std::memcmp(before + i * 3, after + i * 3, 12) != 0 && pixel_error(after + i * 3, ref + i * 3) > pixel_error(before + i * 3, ref + i * 3))
            ++n;
    return n;
}

// relMSE and energy of one combined image against the expected radiance.
inline combined_accuracy evaluate_combined(const float* combined, const std::vector<float>& expected,
                                           const std::vector<std::uint8_t>& highlight) {
    combined_accuracy a;
    const std::size_t np = expected.size() / 3;
    a.relmse = relmse(combined, expected.data(), np);
    a.energy = energy_ratio(combined, expected.data(), np);
    if (highlight.size() == np) {
        a.energy_highlight = energy_ratio(combined, expected.data(), np, highlight.data(), 1);
        a.energy_rest = energy_ratio(combined, expected.data(), np, highlight.data(), 0);
    }
    return a;
}

namespace detail {
// The counts of `evaluate` over any number of buffers; `orig(b)` / `clean(b)` give buffer b.
// Some channel of the output c below the input o, or an input that was not finite.
inline bool lowered_from(const float* o, const float* c) noexcept {
    bool below = false, bad_input = false;
    for (int k = 0; k < 3; ++k) {
        below = below || c[k] < o[k];
        bad_input = bad_input || !std::isfinite(o[k]);
    }
    return below || bad_input;
}

template <class Truth, class Orig, class Clean>
accuracy evaluate_counts(const Truth& t, int k, Orig orig, Clean clean) {
    accuracy a;
    const std::size_t np = t.pixels();
    std::size_t vis_hit = 0, lowered_true = 0, clean_px = 0, clean_lowered = 0, hl = 0, hl_kept = 0;
    for (std::size_t i = 0; i < np; ++i) {
        const float* ex = &t.expected[i * 3];
        const double expected = t.expected_without_fireflies(i);
        const bool is_hl = !t.highlight.empty() && t.highlight[i];
        bool clean_lowered_here = false;  // a half without a firefly or NaN here lowered
        for (int b = 0; b < k; ++b) {
            const float* o = &(*orig(b))[i * 3];
            const float* c = &(*clean(b))[i * 3];
            const bool changed = std::memcmp(o, c, 12) != 0;
            const bool lowered = changed && lowered_from(o, c);
            const bool hit = t.firefly(b, i) > 0 || t.bad(b, i);
            clean_lowered_here = clean_lowered_here || (lowered && !hit);
            if (t.firefly(b, i) > 0 && static_cast<double>(t.firefly(b, i)) > 10.0 * std::fabs(expected)) {
                ++a.visible;
                vis_hit += lowered ? 1 : 0;
            }
            if (changed) {
                ++a.changed;
                a.made_worse += pixel_error(c, ex) > pixel_error(o, ex) ? 1u : 0u;
            }
            if (lowered) {
                ++a.lowered;
                lowered_true += hit ? 1 : 0;
            }
            if (!hit && !is_hl) {
                ++clean_px;
                clean_lowered += lowered ? 1 : 0;
            }
        }
        if (is_hl) {
            ++hl;
            hl_kept += clean_lowered_here ? 0 : 1;
        }
    }
    a.recall = a.visible ? static_cast<double>(vis_hit) / static_cast<double>(a.visible) : 1.0;
    a.precision = a.lowered ? static_cast<double>(lowered_true) / static_cast<double>(a.lowered) : 1.0;
    a.false_positive = clean_px ? static_cast<double>(clean_lowered) / static_cast<double>(clean_px) : 0.0;
    a.highlight_kept = hl ? static_cast<double>(hl_kept) / static_cast<double>(hl) : 1.0;
    return a;
}

// Whether every cleaned image holds the frame's RGB pixels (the metrics read them whole), and
// there is one per buffer.
inline bool cleaned_fit(std::size_t pixels, const std::vector<float>* const* cleaned, std::size_t n, std::size_t k) {
    if (n != k) return false;
    for (std::size_t b = 0; b < n; ++b)
        if (!cleaned[b] || cleaned[b]->size() != pixels * 3) return false;
    return true;
}
// Whether the ground truth the metrics read fits the frame's size: colour and expected RGB,
// highlight, firefly and non-finite records per pixel or empty, for each of its k buffers (a
// half moved out of a frame, a hand-made one, were read past their end).
template <class V>
bool empty_or(const V& v, std::size_t n) {
    return v.empty() || v.size() == n;
}
template <class Truth>
bool truth_fits(const Truth& f, std::size_t k) {
    const std::size_t np = f.pixels();
    if (f.width <= 0 || f.height <= 0 || f.expected.size() != np * 3) return false;
    if (!empty_or(f.highlight, np) || !empty_or(f.firefly_expected, np)) return false;
    for (std::size_t b = 0; b < k; ++b)
        if (f.color[b].size() != np * 3 || !empty_or(f.firefly_energy[b], np) || !empty_or(f.nonfinite[b], np))
            return false;
    return true;
}
inline bool truth_fits(const frame& f) { return truth_fits(f, 2); }
inline bool truth_fits(const buffers& f) {
    const std::size_t k = f.color.size();
    return k > 0 && f.firefly_energy.size() == k && f.nonfinite.size() == k && truth_fits(f, k);
}

// The frame's ground truth and K cleaned buffers, each the frame's size.
inline bool cleaned_fit(const buffers& original, const std::vector<std::vector<float>>& cleaned) {
    if (!truth_fits(original)) return false;
    std::vector<const std::vector<float>*> p;
    for (const auto& c : cleaned) p.push_back(&c);
    return cleaned_fit(original.pixels(), p.data(), p.size(), static_cast<std::size_t>(original.count()));
}

// Metrics of a call whose cleaned images do not fit: every one NaN (never a read past them).
inline accuracy unfit() {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    accuracy a;
    a.recall = a.precision = a.false_positive = a.highlight_kept = a.relmse = nan;
    a.energy = a.energy_highlight = a.energy_rest = nan;
    return a;
}

inline void set_combined(accuracy& a, const combined_accuracy& c) {
    a.relmse = c.relmse;
    a.energy = c.energy;
    a.energy_highlight = c.energy_highlight;
    a.energy_rest = c.energy_rest;
}
}  // namespace detail

// `original` is the simulated frame, `cleaned_color[h]` the cleaned RGB colour of half h (the
// frame's size, as the frame's own arrays; else every metric is NaN).
inline accuracy evaluate(const frame& original, const std::vector<float>* const cleaned_color[2]) {
    if (!cleaned_color || !detail::truth_fits(original) || !detail::cleaned_fit(original.pixels(), cleaned_color, 2, 2))
        return detail::unfit();
    accuracy a = detail::evaluate_counts(
        original, 2, [&](int b) { return &original.color[b]; }, [&](int b) { return cleaned_color[b]; });
    const std::size_t np = original.pixels();
    std::vector<float> combined(np * 3);
    for (std::size_t i = 0; i < np * 3; ++i)
        combined[i] = 0.5f * (*cleaned_color[0])[i] + 0.5f * (*cleaned_color[1])[i];
    detail::set_combined(a, evaluate_combined(combined.data(), original.expected, original.highlight));
    return a;
}

// The combined image of K buffers: their mean weighted by samples (the estimate of all samples);
// NaN unless `color` holds every buffer at the frame's size.
inline std::vector<float> combine(const buffers& original, const std::vector<std::vector<float>>& color) {
    if (!detail::cleaned_fit(original, color))
        return std::vector<float>(original.pixels() * 3, std::numeric_limits<float>::quiet_NaN());
    std::vector<float> out(original.pixels() * 3, 0.0f);
    double total = 0;
    for (int s : original.spp) total += s;
    for (std::size_t b = 0; b < color.size() && b < original.spp.size(); ++b) {
        const float wgt = static_cast<float>(original.spp[b] / total);
        for (std::size_t i = 0; i < out.size(); ++i) out[i] += wgt * color[b][i];
    }
    return out;
}

// K buffers: `cleaned[b]` is buffer b's cleaned RGB colour (as many as original.count(), each
// the frame's size; else every metric is NaN).
inline accuracy evaluate_buffers(const buffers& original, const std::vector<std::vector<float>>& cleaned) {
    if (!detail::cleaned_fit(original, cleaned)) return detail::unfit();
    const int k = original.count();
    accuracy a = detail::evaluate_counts(
        original, k, [&](int b) { return &original.color[static_cast<std::size_t>(b)]; },
        [&](int b) { return &cleaned[static_cast<std::size_t>(b)]; });
    const std::vector<float> combined = combine(original, cleaned);
    detail::set_combined(a, evaluate_combined(combined.data(), original.expected, original.highlight));
    return a;
}

}  // namespace firefly::sim
