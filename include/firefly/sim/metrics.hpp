// firefly/sim: accuracy of a cleaned frame against the simulator's ground truth. Works for
// any method (firefly or a peer): "changed" is read off the pixels themselves.
//
//   recall             visible firefly hits changed / visible firefly hits, per half. Visible:
//                      the firefly energy adds more than 10x the pixel's expected value.
//   precision          changed pixels that got a firefly or a non-finite sample / changed
//   false_positive     changed pixels with no firefly and not a highlight / all such pixels
//   highlight_kept     highlight pixels unchanged in both halves / highlight pixels
//   relmse             mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01) for the
//                      combined image (A + B) / 2 against the expected radiance
#pragma once

#include <cmath>
#include <cstddef>
#include <cstring>
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
};

// Relative MSE of an interleaved RGB image against a reference (non-finite pixels count
// as an error of 1e6).
inline double relmse(const float* img, const float* ref, std::size_t pixels) {
    double s = 0;
    for (std::size_t i = 0; i < pixels * 3; ++i) {
        const double d = static_cast<double>(img[i]) - ref[i];
        const double e = d * d / (static_cast<double>(ref[i]) * ref[i] + 0.01);
        s += std::isfinite(e) ? e : 1e6;
    }
    return pixels ? s / static_cast<double>(pixels * 3) : 0.0;
}

// `original` is the simulated frame, `cleaned_color[h]` the cleaned RGB colour of half h.
inline accuracy evaluate(const frame& original, const std::vector<float>* const cleaned_color[2]) {
    accuracy a;
    const std::size_t np = original.pixels();
    std::size_t vis_hit = 0, changed_true = 0, clean_px = 0, clean_changed = 0, hl = 0, hl_kept = 0;
    std::vector<float> combined(np * 3);
    for (std::size_t i = 0; i < np; ++i) {
        bool changed[2];
        for (int h = 0; h < 2; ++h)
            changed[h] = std::memcmp(&original.color[h][i * 3], &(*cleaned_color[h])[i * 3], 12) != 0;
        const double expected = (original.expected[i * 3] + original.expected[i * 3 + 1] + original.expected[i * 3 + 2]) / 3.0;
        for (int h = 0; h < 2; ++h) {
            const bool hit = original.firefly_energy[h][i] > 0 || original.nonfinite[h][i];
            if (original.firefly_energy[h][i] > 10.0 * expected) {
                ++a.visible;
                vis_hit += changed[h] ? 1 : 0;
            }
            if (changed[h]) {
                ++a.changed;
                changed_true += hit ? 1 : 0;
            }
            if (!hit && !original.highlight[i]) {
                ++clean_px;
                clean_changed += changed[h] ? 1 : 0;
            }
        }
        if (original.highlight[i]) {
            ++hl;
            hl_kept += (!changed[0] && !changed[1]) ? 1 : 0;
        }
        for (int c = 0; c < 3; ++c)
            combined[i * 3 + c] = 0.5f * (*cleaned_color[0])[i * 3 + c] + 0.5f * (*cleaned_color[1])[i * 3 + c];
    }
    a.recall = a.visible ? static_cast<double>(vis_hit) / static_cast<double>(a.visible) : 1.0;
    a.precision = a.changed ? static_cast<double>(changed_true) / static_cast<double>(a.changed) : 1.0;
    a.false_positive = clean_px ? static_cast<double>(clean_changed) / static_cast<double>(clean_px) : 0.0;
    a.highlight_kept = hl ? static_cast<double>(hl_kept) / static_cast<double>(hl) : 1.0;
    a.relmse = relmse(combined.data(), original.expected.data(), np);
    return a;
}

}  // namespace firefly::sim
