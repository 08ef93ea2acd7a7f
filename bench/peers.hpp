// Peer firefly filters, re-implemented from their published descriptions, to measure
// firefly against. Each cleans one half buffer (RGB colour, RGB variance) in place.
//
//   median3x3        Mara et al. 2017: every pixel becomes the per-channel 3x3 median.
//   cycles_prefilter Blender Cycles' former denoiser prefilter: the pixel's mean colour L
//                    against ref = 2 x the 75th percentile of the 5x5 window's L. Above it,
//                    it is an outlier when its variance is > 9x the window's largest, or
//                    when L - 3 sd < ref; outliers are scaled down to ref.
//   bcd_spikes       BCD spike removal (appleseed, LuxCore): 3x3 mean and sd per channel;
//                    a channel beyond mean +- k sd replaces the pixel by the window's L1 medoid.
//   nrd_clamp        NRD RELAX anti-firefly: the centre's luminance clamped to the min..max
//                    of its eight neighbours' luminance.
//   fixed_clamp      every channel clamped at a fixed value (a renderer's sample clamp).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include <firefly/image_view.hpp>

namespace firefly_peers {

using view = firefly::image_view<float>;

inline float mean3(const view& v, int x, int y) {
    return (std::max(v(x, y, 0), 0.0f) + std::max(v(x, y, 1), 0.0f) + std::max(v(x, y, 2), 0.0f)) / 3.0f;
}
inline float luma(const view& v, int x, int y) {
    return 0.2126f * v(x, y, 0) + 0.7152f * v(x, y, 1) + 0.0722f * v(x, y, 2);
}

inline void median3x3(const view& color, const view& /*variance*/) {
    const int w = color.width(), h = color.height();
    std::vector<float> out(static_cast<std::size_t>(w) * h * 3);
    float vals[9];
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                int n = 0;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int xx = x + dx, yy = y + dy;
                        if (xx >= 0 && yy >= 0 && xx < w && yy < h) vals[n++] = color(xx, yy, c);
                    }
                std::nth_element(vals, vals + n / 2, vals + n);
                out[(static_cast<std::size_t>(y) * w + x) * 3 + c] = vals[n / 2];
            }
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) color(x, y, c) = out[(static_cast<std::size_t>(y) * w + x) * 3 + c];
}

inline void cycles_prefilter(const view& color, const view& variance) {
    const int w = color.width(), h = color.height();
    std::vector<float> out_c(static_cast<std::size_t>(w) * h * 3), out_v(out_c.size());
    float vals[25];
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            int n = 0;
            float max_var = 0.0f, pixel_var = 0.0f;
            for (int yy = std::max(y - 2, 0); yy <= std::min(y + 2, h - 1); ++yy)
                for (int xx = std::max(x - 2, 0); xx <= std::min(x + 2, w - 1); ++xx) {
                    vals[n++] = mean3(color, xx, yy);
                    const float v0 = variance(xx, yy, 0), v1 = variance(xx, yy, 1), v2 = variance(xx, yy, 2);
                    const float var = (v0 + v1 + v2) / 3.0f;
                    if (xx == x && yy == y) pixel_var = (v0 < 0 || v1 < 0 || v2 < 0) ? -1.0f : var;
                    else max_var = std::max(max_var, var);
                }
            std::sort(vals, vals + n);
            max_var += 1e-4f + 1e-5f;
            const float ref = 2.0f * vals[static_cast<int>(n * 0.75f)] - 1e-5f;
            const float L = mean3(color, x, y);
            float fac = 1.0f, var_fac = 1.0f;
            bool set_var = false;
            if (L > ref) {
                if (pixel_var < 0 || pixel_var > 9.0f * max_var) {
                    fac = ref / L;
                    set_var = true;
                } else if (L - 3.0f * std::sqrt(pixel_var) < ref) {
                    fac = ref / L;
                    var_fac = fac * fac;
                }
            }
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = (static_cast<std::size_t>(y) * w + x) * 3 + c;
                out_c[i] = fac == 1.0f ? color(x, y, c) : std::max(color(x, y, c), 0.0f) * fac;
                out_v[i] = set_var ? max_var : (var_fac == 1.0f ? variance(x, y, c) : variance(x, y, c) * var_fac);
            }
        }
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = (static_cast<std::size_t>(y) * w + x) * 3 + c;
                color(x, y, c) = out_c[i];
                variance(x, y, c) = out_v[i];
            }
}

inline void bcd_spikes(const view& color, const view& /*variance*/, float k = 2.0f) {
    const int w = color.width(), h = color.height();
    std::vector<float> out(static_cast<std::size_t>(w) * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            int px[9], py[9], n = 0;
            double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0};
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int xx = x + dx, yy = y + dy;
                    if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                    px[n] = xx;
                    py[n] = yy;
                    ++n;
                    for (int c = 0; c < 3; ++c) {
                        sum[c] += color(xx, yy, c);
                        sum2[c] += static_cast<double>(color(xx, yy, c)) * color(xx, yy, c);
                    }
                }
            bool spike = false;
            for (int c = 0; c < 3; ++c) {
                const double m = sum[c] / n, sd = std::sqrt(std::max(sum2[c] / n - m * m, 0.0));
                spike |= std::fabs(color(x, y, c) - m) > k * sd && sd > 0;
            }
            int pick_x = x, pick_y = y;
            if (spike) {  // the window's L1 medoid
                double best = HUGE_VAL;
                for (int i = 0; i < n; ++i) {
                    double d = 0;
                    for (int j = 0; j < n; ++j)
                        for (int c = 0; c < 3; ++c) d += std::fabs(color(px[i], py[i], c) - color(px[j], py[j], c));
                    if (d < best) {
                        best = d;
                        pick_x = px[i];
                        pick_y = py[i];
                    }
                }
            }
            for (int c = 0; c < 3; ++c) out[(static_cast<std::size_t>(y) * w + x) * 3 + c] = color(pick_x, pick_y, c);
        }
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) color(x, y, c) = out[(static_cast<std::size_t>(y) * w + x) * 3 + c];
}

inline void nrd_clamp(const view& color, const view& /*variance*/) {
    const int w = color.width(), h = color.height();
    std::vector<float> scale(static_cast<std::size_t>(w) * h, 1.0f);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float lo = HUGE_VALF, hi = -HUGE_VALF;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int xx = x + dx, yy = y + dy;
                    if ((dx == 0 && dy == 0) || xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                    const float l = luma(color, xx, yy);
                    lo = std::min(lo, l);
                    hi = std::max(hi, l);
                }
            const float L = luma(color, x, y);
            if (L > 0 && hi >= lo && (L > hi || L < lo)) scale[static_cast<std::size_t>(y) * w + x] = std::clamp(L, lo, hi) / L;
        }
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const float s = scale[static_cast<std::size_t>(y) * w + x];
            if (s != 1.0f)
                for (int c = 0; c < 3; ++c) color(x, y, c) *= s;
        }
}

inline void fixed_clamp(const view& color, const view& /*variance*/, float level) {
    for (int y = 0; y < color.height(); ++y)
        for (int x = 0; x < color.width(); ++x)
            for (int c = 0; c < 3; ++c) color(x, y, c) = std::min(color(x, y, c), level);
}

}  // namespace firefly_peers
