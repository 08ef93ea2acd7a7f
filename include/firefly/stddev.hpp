// firefly: per-pixel variance -> one standard deviation per pixel, and which pixels count.
//
// Step 1 of the detector. The channel variances of a pixel reduce to one number (mean of the
// channels by default; Rec. 709 luminance weights or the max as options), and its square
// root is the statistic tested: the bound is much tighter on standard deviations than on
// variances (paper, section 3.2).
//
//   valid      counts in every statistic
//   ignored    black colour (every colour channel exactly 0) or alpha <= 0: left out of the
//              statistics and never an outlier (the image may not be a final beauty pass)
//   nonfinite  NaN or Inf in colour, variance or alpha: an outlier outright, repaired by the
//              reconstruction, and kept out of every statistic
// Negative variance (a renderer's round-off) counts as 0.
#pragma once

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "image_view.hpp"
#include "status.hpp"

namespace firefly {

enum class variance_reduction : std::uint8_t { mean, luminance, max };

// Written into the low bits of a per-pixel label byte.
enum class pixel_class : std::uint8_t { valid = 0, ignored = 1, nonfinite = 2 };
inline constexpr std::uint8_t pixel_class_bits = 3;

struct stddev_counts {
    std::size_t valid = 0;
    std::size_t ignored = 0;
    std::size_t nonfinite = 0;
    std::size_t negative_variance = 0;  // pixels with a channel variance < 0 (clamped to 0)
};

// Which colour channels count: the first three (a fourth is alpha or padding).
inline int colour_channels(int channels) noexcept { return channels < 3 ? channels : 3; }

// Check the views that describe one half buffer. alpha may be empty.
template <class C, class V, class A>
status check_half_views(const image_view<C>& color, const image_view<V>& variance,
                        const image_view<A>& alpha) noexcept {
    if (color.empty()) return status{errc::empty_image, "colour image is empty"};
    if (!same_size(color, variance))
        return status{errc::size_mismatch, "variance and colour differ in size"};
    if (variance.channels() != 1 && variance.channels() != color.channels())
        return status{errc::channel_mismatch,
                      "variance needs 1 channel or as many channels as colour"};
    if (!alpha.empty()) {
        if (!same_size(color, alpha)) return status{errc::size_mismatch, "alpha and colour differ in size"};
        if (alpha.channels() != 1) return status{errc::channel_mismatch, "alpha needs 1 channel"};
    }
    return ok_status();
}

namespace detail {

template <class V>
inline double reduce_variance(const V* px, std::ptrdiff_t cstride, int channels,
                              variance_reduction how, bool& nonfinite, bool& negative) noexcept {
    using traits = channel_traits<std::remove_cv_t<V>>;
    auto at = [&](int c) {
        return traits::load(*reinterpret_cast<const V*>(reinterpret_cast<const unsigned char*>(px) +
                                                        c * cstride));
    };
    const int n = colour_channels(channels);
    double v[3] = {0, 0, 0};
    for (int c = 0; c < n; ++c) {
        v[c] = at(c);
        if (!std::isfinite(v[c])) nonfinite = true;
        if (v[c] < 0) {
            negative = true;
            v[c] = 0;
        }
    }
    if (n == 1) return v[0];
    switch (how) {
        case variance_reduction::max: {
            double m = n > 0 ? v[0] : 0.0;
            for (int c = 1; c < n; ++c) m = v[c] > m ? v[c] : m;
            return m;
        }
        case variance_reduction::luminance:
            if (n == 3) return 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
            [[fallthrough]];
        default: {
            double s = 0;
            for (int c = 0; c < n; ++c) s += v[c];
            return s / n;
        }
    }
}

}  // namespace detail

// Writes sd[y * width + x] and label[y * width + x] = pixel_class for every pixel. sd is -1
// for ignored pixels and NaN for non-finite ones. sd is stored as float (4 bytes a pixel),
// clamped to FLT_MAX for double inputs whose variance exceeds 3e76.
template <class C, class V, class A>
stddev_counts compute_stddev(const image_view<C>& color, const image_view<V>& variance,
                             const image_view<A>& alpha, variance_reduction how, float* sd,
                             std::uint8_t* label) noexcept {
    using ct = channel_traits<std::remove_cv_t<C>>;
    using at = channel_traits<std::remove_cv_t<A>>;
    stddev_counts counts;
    const int w = color.width(), h = color.height();
    const int nc = colour_channels(color.channels());
    const bool has_alpha = !alpha.empty();
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                  static_cast<std::size_t>(x);
            bool nonfinite = false, negative = false, black = true;
            for (int c = 0; c < nc; ++c) {
                const double v = ct::load(color(x, y, c));
                if (!std::isfinite(v)) nonfinite = true;
                if (v != 0) black = false;
            }
            const double var = detail::reduce_variance(&variance(x, y, 0), variance.channel_stride(),
                                                       variance.channels(), how, nonfinite, negative);
            bool covered = true;
            if (has_alpha) {
                const double a = at::load(alpha(x, y, 0));
                if (!std::isfinite(a)) nonfinite = true;
                covered = a > 0;
            }
            counts.negative_variance += negative ? 1 : 0;
            if (nonfinite) {
                label[i] = static_cast<std::uint8_t>(pixel_class::nonfinite);
                sd[i] = std::numeric_limits<float>::quiet_NaN();
                ++counts.nonfinite;
            } else if (black || !covered) {
                label[i] = static_cast<std::uint8_t>(pixel_class::ignored);
                sd[i] = -1.0f;
                ++counts.ignored;
            } else {
                label[i] = static_cast<std::uint8_t>(pixel_class::valid);
                const double s = std::sqrt(var);
                sd[i] = s < static_cast<double>(FLT_MAX) ? static_cast<float>(s) : FLT_MAX;
                ++counts.valid;
            }
        }
    }
    return counts;
}

}  // namespace firefly
