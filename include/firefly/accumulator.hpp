// firefly: K per-pixel buffers a renderer feeds sample by sample or pass by pass, read out as
// the views cross_buffer_detector (buffers.hpp) takes.
//
// Sample i of a pixel goes to buffer i mod K, i the renderer's own sample index (never the
// order in which threads arrive), so the same render gives the same buffers on any number
// of threads. Per pixel, buffer and channel the accumulator keeps Welford's running mean and
// sum of squared deviations in double: M2 only ever adds delta * (x - mean), two factors of
// one sign, so it never goes negative, and a 1e30 sample next to 1e-3 samples loses nothing
// to cancellation (no sum of squares is subtracted). A NaN or Inf sample makes that pixel's
// buffer non-finite; the detector rebuilds it from the other buffers. So does a buffer pixel
// that got no sample (fewer than K samples: adaptive sampling), which reads NaN, not black.
//
// Threads: add() and add_tile() may run concurrently without locks as long as no two calls
// at the same time touch the same pixel (disjoint tiles, rows or pixels per thread; the
// buffer a sample goes to does not matter). finish() must happen after every add (join the
// threads, or any other synchronisation) and before the views are read.
//
// Memory: K x pixels x (1 count + 2 doubles per channel), plus the float views from finish().
#pragma once

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "buffers.hpp"
#include "image_view.hpp"
#include "scratch.hpp"
#include "status.hpp"

namespace firefly {

class sample_accumulator {
public:
    sample_accumulator() = default;

    // k >= 2 buffers of width x height pixels of `channels` (1 to 4) channels. Views taken
    // before (color(), variance(), views()) point into storage a reset frees: take them again.
    status reset(int width, int height, int k, int channels = 3) {
        if (width <= 0 || height <= 0) return status{errc::empty_image, "accumulator: empty image"};
        if (k < 2 || k > 64) return status{errc::invalid_argument, "accumulator: 2 to 64 buffers"};
        if (channels < 1 || channels > 4) return status{errc::channel_mismatch, "accumulator: 1 to 4 channels"};
        const std::size_t px = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
        if (px >= (std::size_t{1} << 32)) return status{errc::size_overflow, "accumulator: more than 2^32 pixels"};
        w_ = width;
        h_ = height;
        k_ = k;
        nc_ = channels;
        const std::size_t cells = px * static_cast<std::size_t>(k);
        count_.assign(cells, 0);
        mean_.assign(cells * static_cast<std::size_t>(channels), 0.0);
        m2_.assign(cells * static_cast<std::size_t>(channels), 0.0);
        color_.assign(static_cast<std::size_t>(k), std::vector<float>(px * static_cast<std::size_t>(channels)));
        variance_.assign(static_cast<std::size_t>(k), std::vector<float>(px * static_cast<std::size_t>(channels)));
        return ok_status();
    }

    int width() const noexcept { return w_; }
    int height() const noexcept { return h_; }
    int buffers() const noexcept { return k_; }
    int channels() const noexcept { return nc_; }
    std::size_t bytes() const noexcept {
        return count_.capacity() * sizeof(std::uint32_t) + (mean_.capacity() + m2_.capacity()) * sizeof(double) +
               2 * static_cast<std::size_t>(k_) * (color_.empty() ? 0 : color_[0].capacity()) * sizeof(float);
    }

    // One sample (channels() values) of pixel (x, y), the pixel's sample_index-th. A buffer
    // pixel holds at most 2^32 - 1 samples (its count is 32-bit): one more is refused
    // (size_overflow), where the count once wrapped to 0 and the mean turned NaN.
    status add(int x, int y, std::uint64_t sample_index, const float* value) noexcept {
        if (value == nullptr) return status{errc::null_data, "accumulator: no sample values"};
        if (x < 0 || y < 0 || x >= w_ || y >= h_)
            return status{errc::invalid_argument, "accumulator: sample outside the image"};
        if (count_[cell_of(x, y, sample_index)] == UINT32_MAX) return full();
        double v[4];
        for (int c = 0; c < nc_; ++c) v[c] = static_cast<double>(value[c]);
        add_unchecked(x, y, sample_index, v);
        return ok_status();
    }

    // One pass over a tile: pixel (i, j) of `tile` is sample sample_index of pixel
    // (x0 + i, y0 + j). The tile's channels must match.
    template <class T>
    status add_tile(int x0, int y0, std::uint64_t sample_index, const image_view<T>& tile) noexcept {
        if (tile.empty()) return ok_status();
        if (tile.channels() != nc_) return status{errc::channel_mismatch, "accumulator: tile channels differ"};
        if (x0 < 0 || y0 < 0 || x0 > w_ - tile.width() || y0 > h_ - tile.height())
            return status{errc::invalid_argument, "accumulator: tile outside the image"};
        for (int j = 0; j < tile.height(); ++j)  // all of the tile or nothing
            for (int i = 0; i < tile.width(); ++i)
                if (count_[cell_of(x0 + i, y0 + j, sample_index)] == UINT32_MAX) return full();
        double v[4];  // (a double tile's samples as they are: no narrowing before the sums)
        for (int j = 0; j < tile.height(); ++j)
            for (int i = 0; i < tile.width(); ++i) {
                for (int c = 0; c < nc_; ++c) v[c] = tile.load(i, j, c);
                add_unchecked(x0 + i, y0 + j, sample_index, v);
            }
        return ok_status();
    }

    // Mean colour and variance of the mean, per buffer, as float. A buffer pixel with no
    // sample is NaN, colour and variance: no value, which the detector rebuilds from the
    // buffers that have one (0 read as black: at 3 samples for 8 buffers a pixel kept 0.38 of
    // its light); with one sample its variance is unknown and is set to the sample's square
    // (relative standard error 1: the least it can claim). Finite values beyond FLT_MAX (a
    // 1e30 sample's variance, a lone 1e200 sample's square) are stored as FLT_MAX. A NaN or
    // Inf sample makes its buffer pixel NaN, and so do finite ones whose sums pass double's
    // range (1e308 and -1e308: the difference overflowed, and came out as a mean of -Inf with
    // variance 0). Views read 0 before the first finish().
    void finish() {
        const std::size_t px = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
        for (int b = 0; b < k_; ++b)
            for (std::size_t p = 0; p < px; ++p) {
                const std::size_t cell = p * static_cast<std::size_t>(k_) + static_cast<std::size_t>(b);
                const double n = count_[cell];
                for (int c = 0; c < nc_; ++c) {
                    const std::size_t e = cell * static_cast<std::size_t>(nc_) + static_cast<std::size_t>(c);
                    const bool value = n > 0 && std::isfinite(mean_[e]) && std::isfinite(m2_[e]);
                    const double m = value ? mean_[e] : std::numeric_limits<double>::quiet_NaN();
                    double var = value && n >= 2 ? m2_[e] / (n - 1) / n : m * m;  // (NaN without value)
                    if (!(var >= 0) && var == var) var = 0;  // never negative (NaN stays NaN)
                    if (value && var > DBL_MAX) var = DBL_MAX;  // one sample past 1.3e154 squared to Inf
                    using ct = channel_traits<float>;         // float saturates, never turns Inf
                    color_[static_cast<std::size_t>(b)][p * static_cast<std::size_t>(nc_) + static_cast<std::size_t>(c)] = ct::store(m);
                    variance_[static_cast<std::size_t>(b)][p * static_cast<std::size_t>(nc_) + static_cast<std::size_t>(c)] = ct::store(var);
                }
            }
    }

    // Samples in buffer b at (x, y); 0 outside the buffers or the image.
    std::uint32_t samples(int b, int x, int y) const noexcept {
        if (b < 0 || b >= k_ || x < 0 || y < 0 || x >= w_ || y >= h_) return 0;
        return count_[pixel(x, y) * static_cast<std::size_t>(k_) + static_cast<std::size_t>(b)];
    }
    // Buffer b's mean colour and variance of the mean (after finish()), packed interleaved;
    // empty for b outside [0, buffers()).
    image_view<float> color(int b) noexcept { return b >= 0 && b < k_ ? view(color_[static_cast<std::size_t>(b)]) : image_view<float>{}; }
    image_view<float> variance(int b) noexcept {
        return b >= 0 && b < k_ ? view(variance_[static_cast<std::size_t>(b)]) : image_view<float>{};
    }
    // All K buffers for cross_buffer_detector::process().
    std::vector<buffer_view<float>> views() {
        std::vector<buffer_view<float>> v;
        for (int b = 0; b < k_; ++b) v.push_back({color(b), variance(b)});
        return v;
    }

private:
    std::size_t pixel(int x, int y) const noexcept {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
    }
    image_view<float> view(std::vector<float>& v) noexcept {
        return image_view<float>::unchecked(v.data(), w_, h_, nc_, static_cast<std::ptrdiff_t>(sizeof(float)) * nc_,
                                            static_cast<std::ptrdiff_t>(sizeof(float)) * nc_ * w_,
                                            static_cast<std::ptrdiff_t>(sizeof(float)));
    }
    std::size_t cell_of(int x, int y, std::uint64_t sample_index) const noexcept {
        return pixel(x, y) * static_cast<std::size_t>(k_) + static_cast<std::size_t>(sample_index % static_cast<std::uint64_t>(k_));
    }
    static status full() noexcept {
        return status{errc::size_overflow, "accumulator: 2^32 - 1 samples in one pixel of one buffer"};
    }
    void add_unchecked(int x, int y, std::uint64_t sample_index, const double* value) noexcept {
        const std::size_t cell = cell_of(x, y, sample_index);
        const double n = ++count_[cell];
        double* mean = &mean_[cell * static_cast<std::size_t>(nc_)];
        double* m2 = &m2_[cell * static_cast<std::size_t>(nc_)];
        for (int c = 0; c < nc_; ++c) {
            const double v = value[c];
            const double delta = v - mean[c];
            mean[c] += delta / n;
            m2[c] += delta * (v - mean[c]);
        }
    }

    // (scratch.hpp: a moved-from accumulator is empty, 0 x 0, as a new one; reset() to use it)
    detail::reset_on_move<int> w_, h_, k_, nc_;
    std::vector<std::uint32_t> count_;   // pixel-major: K cells per pixel
    std::vector<double> mean_, m2_;      // cell-major: channels per cell
    std::vector<std::vector<float>> color_, variance_;
};

}  // namespace firefly
