// Peer firefly filters, re-implemented from their published descriptions, to measure
// firefly against. Each cleans one half buffer (RGB colour, RGB variance) in place.
//
//   median3x3        Mara et al. 2017: every pixel becomes the per-channel 3x3 median.
//   cycles_prefilter Blender Cycles' former denoiser prefilter: the pixel's mean colour L
//                    against ref = 2 x the 75th percentile of the 5x5 window's L. Above it,
//                    it is an outlier when its variance is > 9x the window's largest, or
//                    when L - 3 sd < ref; outliers are scaled down to ref.
//   bcd_spikes       BCD spike removal (SpikeRemovalFilter; appleseed, LuxCore): per channel,
//                    the 3x3 window's mean and sample sd (n - 1), the window moved inward at
//                    the borders so it always holds 9 pixels; a channel beyond mean +- k sd
//                    replaces the pixel by the window's L1 medoid.
//   nrd_clamp        NRD RELAX anti-firefly: the centre's luminance clamped to the min..max
//                    of its eight neighbours' luminance.
//   fixed_clamp      every channel clamped at a fixed value (a renderer's sample clamp).
//
// Also here: repair_nonfinite, the non-finite repair every peer gets first (so comparisons
// measure firefly handling), and the per-pixel estimators over K buffers (mean, median of
// means, G-MoN).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
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
            const float ref = 2.0f * vals[static_cast<int>(static_cast<float>(n) * 0.75f)] - 1e-5f;
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

// BCD's 3x3 window along one axis: its first index, moved inward at the borders so that a
// border pixel's window holds 3 pixels too (fewer only when the image is narrower).
inline int bcd_window_start(int x, int size) { return std::max(0, std::min(x - 1, size - 3)); }

// BCD's spike test at (x, y): a channel farther than k sample standard deviations (n - 1)
// from the mean of its window (nx x ny pixels from x0, y0; 3 x 3 but in a tiny image).
inline bool bcd_is_spike(const view& color, int x, int y, float k) {
    const int x0 = bcd_window_start(x, color.width()), y0 = bcd_window_start(y, color.height());
    const int nx = std::min(3, color.width()), ny = std::min(3, color.height()), n = nx * ny;
    if (n < 2) return false;
    for (int c = 0; c < 3; ++c) {
        double sum = 0, sq = 0;
        for (int yy = y0; yy < y0 + ny; ++yy)
            for (int xx = x0; xx < x0 + nx; ++xx) sum += color(xx, yy, c);
        const double m = sum / n;
        for (int yy = y0; yy < y0 + ny; ++yy)
            for (int xx = x0; xx < x0 + nx; ++xx) sq += (color(xx, yy, c) - m) * (color(xx, yy, c) - m);
        const double sd = std::sqrt(sq / (n - 1));
        if (std::fabs(color(x, y, c) - m) > k * sd) return true;
    }
    return false;
}

// The pixel of (x, y)'s window whose colour has the least L1 distance to all the others (the
// first one on a tie, in row order).
inline void bcd_medoid(const view& color, int x, int y, int& pick_x, int& pick_y) {
    const int x0 = bcd_window_start(x, color.width()), y0 = bcd_window_start(y, color.height());
    const int x1 = x0 + std::min(3, color.width()), y1 = y0 + std::min(3, color.height());
    double best = HUGE_VAL;
    for (int ya = y0; ya < y1; ++ya)
        for (int xa = x0; xa < x1; ++xa) {
            double d = 0;
            for (int yb = y0; yb < y1; ++yb)
                for (int xb = x0; xb < x1; ++xb)
                    for (int c = 0; c < 3; ++c) d += std::fabs(color(xa, ya, c) - color(xb, yb, c));
            if (d < best) {
                best = d;
                pick_x = xa;
                pick_y = ya;
            }
        }
}

inline void bcd_spikes(const view& color, const view& /*variance*/, float k = 2.0f) {
    const int w = color.width(), h = color.height();
    std::vector<float> out(static_cast<std::size_t>(w) * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            int pick_x = x, pick_y = y;
            if (bcd_is_spike(color, x, y, k)) bcd_medoid(color, x, y, pick_x, pick_y);
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

// ---------------------------------------------------------------------------------------
// The shared non-finite repair every peer gets before it runs, so the tables measure firefly
// handling rather than NaN handling. A pixel of one half whose colour or variance holds a
// NaN/Inf takes the other half's colour and variance when those are finite (an unbiased
// estimate of the same pixel), else the mean of the finite 3x3 neighbours in its own half,
// else 0. Only pixels that were finite on entry serve as sources, so the order of the two
// halves does not matter.
inline bool finite_pixel(const view& c, const view& v, int x, int y) {
    for (int k = 0; k < 3; ++k)
        if (!std::isfinite(c(x, y, k)) || !std::isfinite(v(x, y, k))) return false;
    return true;
}

inline void repair_half(const view& col, const view& var, const view& other_col, const view& other_var,
                        const std::vector<unsigned char>& good, const std::vector<unsigned char>& other_good) {
    const int w = col.width(), h = col.height();
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * w + x;
            if (good[i]) continue;
            if (other_good[i]) {
                for (int k = 0; k < 3; ++k) {
                    col(x, y, k) = other_col(x, y, k);
                    var(x, y, k) = other_var(x, y, k);
                }
                continue;
            }
            double sc[3] = {0, 0, 0}, sv[3] = {0, 0, 0};
            int m = 0;
            for (int yy = std::max(y - 1, 0); yy <= std::min(y + 1, h - 1); ++yy)
                for (int xx = std::max(x - 1, 0); xx <= std::min(x + 1, w - 1); ++xx) {
                    if (!good[static_cast<std::size_t>(yy) * w + xx]) continue;
                    ++m;
                    for (int k = 0; k < 3; ++k) {
                        sc[k] += col(xx, yy, k);
                        sv[k] += var(xx, yy, k);
                    }
                }
            for (int k = 0; k < 3; ++k) {
                col(x, y, k) = m ? static_cast<float>(sc[k] / m) : 0.0f;
                var(x, y, k) = m ? static_cast<float>(sv[k] / m) : 0.0f;
            }
        }
}

// Repairs both halves in place; returns the number of pixel x half repaired.
inline std::size_t repair_nonfinite(const view& a_col, const view& a_var, const view& b_col, const view& b_var) {
    const int w = a_col.width(), h = a_col.height();
    std::vector<unsigned char> good_a(static_cast<std::size_t>(w) * h), good_b(good_a.size());
    std::size_t bad = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * w + x;
            good_a[i] = finite_pixel(a_col, a_var, x, y);
            good_b[i] = finite_pixel(b_col, b_var, x, y);
            bad += !good_a[i] + !good_b[i];
        }
    if (bad == 0) return 0;
    // B first: it reads A's pixels only where A was good, which A's repair never changes.
    repair_half(b_col, b_var, a_col, a_var, good_b, good_a);
    repair_half(a_col, a_var, b_col, b_var, good_a, good_b);
    return bad;
}

// ---------------------------------------------------------------------------------------
// Per-pixel robust estimators over K buffers of the same pixel (K renders with different
// seeds, or K sub-buffers; K = 2 gives the halves, where all three reduce to the mean).
//
//   mean_of_buffers   the mean of the K buffers: what a renderer outputs.
//   median_of_means   the K buffers grouped into M consecutive groups of K/M, each group
//                     averaged, the per-channel median of the M group means (the mean of
//                     the two middle ones for even M).
//   gmon              G-MoN's binary variant (Buisine, Delepoulle and Renaud, "Firefly
//                     removal in Monte Carlo rendering with adaptive Median of meaNs", EGSR
//                     2021): per pixel, the Gini coefficient G of the M means, averaged over
//                     the channels (values shifted to be non-negative, plus a tiny epsilon);
//                     below the threshold (the paper's 0.25) the mean of the means, else
//                     their median.
//   agmon             the paper's adaptive G-MoN (Section 4.3, Eq. 6), no threshold: the
//                     sorted means with c = floor(G M / 2) dropped at each end, averaged;
//                     the mean where the means agree, nearer their median as G grows.
// Each writes interleaved RGB. Non-finite buffer values are left out of the pixel's values
// (the same repair as above, generalised: the other buffers hold unbiased estimates).
using buffer_list = std::vector<const float*>;

inline void group_means(const buffer_list& buf, std::size_t i, int groups, float* out /* groups */) {
    const int K = static_cast<int>(buf.size()), per = K / groups;
    for (int g = 0; g < groups; ++g) {
        double s = 0;
        int n = 0;
        for (int j = g * per; j < (g + 1) * per; ++j)
            if (std::isfinite(buf[j][i])) {
                s += buf[j][i];
                ++n;
            }
        out[g] = n ? static_cast<float>(s / n) : std::numeric_limits<float>::quiet_NaN();
    }
}

// Median of the finite values among v[0..n); 0 when none is.
inline float finite_median(float* v, int n) {
    int m = 0;
    for (int i = 0; i < n; ++i)
        if (std::isfinite(v[i])) v[m++] = v[i];
    if (m == 0) return 0.0f;
    std::sort(v, v + m);
    return m % 2 ? v[m / 2] : 0.5f * (v[m / 2 - 1] + v[m / 2]);
}

inline float finite_mean(const float* v, int n) {
    double s = 0;
    int m = 0;
    for (int i = 0; i < n; ++i)
        if (std::isfinite(v[i])) {
            s += v[i];
            ++m;
        }
    return m ? static_cast<float>(s / m) : 0.0f;
}

// Gini coefficient of n values: sum (2i - n - 1) x_(i) / (n sum x), over sorted x shifted to
// be non-negative.
inline double gini(float* v, int n) {
    int m = 0;
    for (int i = 0; i < n; ++i)
        if (std::isfinite(v[i])) v[m++] = v[i];
    if (m < 2) return 0.0;
    std::sort(v, v + m);
    const double shift = v[0] < 0 ? -static_cast<double>(v[0]) : 0.0;
    double sum = 0, weighted = 0;
    for (int i = 0; i < m; ++i) {
        const double x = v[i] + shift + 1e-11;
        sum += x;
        weighted += (2.0 * (i + 1) - m - 1) * x;
    }
    return weighted / (m * sum);
}

inline void mean_of_buffers(const buffer_list& buf, std::size_t pixels, float* out) {
    std::vector<float> v(buf.size());
    for (std::size_t i = 0; i < pixels * 3; ++i) {
        for (std::size_t j = 0; j < buf.size(); ++j) v[j] = buf[j][i];
        out[i] = finite_mean(v.data(), static_cast<int>(v.size()));
    }
}

inline void median_of_means(const buffer_list& buf, std::size_t pixels, int groups, float* out) {
    std::vector<float> v(static_cast<std::size_t>(groups));
    for (std::size_t i = 0; i < pixels * 3; ++i) {
        group_means(buf, i, groups, v.data());
        out[i] = finite_median(v.data(), groups);
    }
}

// Pixel p's M means per channel (into means, channel after channel) and their Gini
// coefficient averaged over the channels; scratch holds M values.
inline double pixel_means_gini(const buffer_list& buf, std::size_t p, int groups, float* means, float* scratch) {
    double g = 0;
    for (int c = 0; c < 3; ++c) {
        float* m = means + static_cast<std::size_t>(c) * groups;
        group_means(buf, p * 3 + c, groups, m);
        std::copy_n(m, groups, scratch);
        g += gini(scratch, groups) / 3.0;
    }
    return g;
}

inline void gmon(const buffer_list& buf, std::size_t pixels, int groups, double threshold, float* out) {
    std::vector<float> means(static_cast<std::size_t>(groups) * 3), scratch(static_cast<std::size_t>(groups));
    for (std::size_t p = 0; p < pixels; ++p) {
        const double g = pixel_means_gini(buf, p, groups, means.data(), scratch.data());
        for (int c = 0; c < 3; ++c) {
            float* m = &means[static_cast<std::size_t>(c) * groups];
            out[p * 3 + c] = g < threshold ? finite_mean(m, groups) : finite_median(m, groups);
        }
    }
}

// The mean of the finite values among v[0..n) once sorted, c = floor(g m / 2) of the m dropped
// at each end (none for g <= 0, at least one kept); 0 when none is finite. (Equal means give a
// Gini a rounding below 0, -2.6e-17 for eight at 2.15: floor made that c = -1, read before v.)
inline float gini_trimmed_mean(float* v, int n, double g) {
    int m = 0;
    for (int i = 0; i < n; ++i)
        if (std::isfinite(v[i])) v[m++] = v[i];
    if (m == 0) return 0.0f;
    std::sort(v, v + m);
    const int c = g > 0 ? std::min(static_cast<int>(std::floor(std::min(g, 1.0) * m / 2.0)), (m - 1) / 2) : 0;
    double s = 0;
    for (int i = c; i < m - c; ++i) s += v[i];
    return static_cast<float>(s / (m - 2 * c));
}

inline void agmon(const buffer_list& buf, std::size_t pixels, int groups, float* out) {
    std::vector<float> means(static_cast<std::size_t>(groups) * 3), scratch(static_cast<std::size_t>(groups));
    for (std::size_t p = 0; p < pixels; ++p) {
        const double g = pixel_means_gini(buf, p, groups, means.data(), scratch.data());
        for (int c = 0; c < 3; ++c)
            out[p * 3 + c] = gini_trimmed_mean(&means[static_cast<std::size_t>(c) * groups], groups, g);
    }
}

}  // namespace firefly_peers
