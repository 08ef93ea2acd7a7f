// firefly/sim: where each effect is in the frame, and what one pixel looks like before noise.
//
// A pixel's model (radiance, noise, firefly rates, coverage) is computed from the effects
// whose footprint holds the pixel and nothing else; spots and regions are placed by streams of
// their own effect. Turning an effect on or off therefore changes the model of its footprint
// only, and `touched` records that footprint.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <vector>

#include "../image_view.hpp"
#include "random.hpp"
#include "types.hpp"

namespace firefly::sim::detail {

struct capsule {  // the points within r of the segment (x0, y0)-(x1, y1), in pixels
    double x0, y0, x1, y1, r;
    double distance(double x, double y) const noexcept {
        const double dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
        const double t = len2 > 0 ? std::clamp(((x - x0) * dx + (y - y0) * dy) / len2, 0.0, 1.0) : 0.0;
        return std::hypot(x - (x0 + t * dx), y - (y0 + t * dy));
    }
    bool in_box(double x, double y) const noexcept {  // within the bounding box
        return x >= (std::min)(x0, x1) - r && x <= (std::max)(x0, x1) + r && y >= (std::min)(y0, y1) - r &&
               y <= (std::max)(y0, y1) + r;
    }
};

struct pixel_model {
    double cov = 1.0;                // geometry coverage (alpha)
    double mu[3] = {0, 0, 0};        // radiance of the ordinary samples
    double sign = 1.0;               // -0.2 where the samples go negative
    double s = 0.0;                  // per-sample relative sd
    double p_ff = 0.0, p_caustic = 0.0;  // firefly probability per sample
    double energy_scale = 0.0;       // firefly sample value = energy_scale x ratio
    bool highlight = false;
    bool bucket = false;   // failed_bucket: NaN in buffer 0
    bool dropped = false;  // dropped_bucket: black in buffer 0
    bool garbage = false;  // garbage_bucket: 1e30 colour in buffer 0
    std::uint32_t touched = 0;
};

// A pixel coordinate or length from a double option: clamped to [lo, hi] first (NaN: lo), so
// that no option value casts out of int's range.
inline int clamped_int(double v, int lo, int hi) noexcept {
    if (!(v >= lo)) return lo;
    return v <= hi ? static_cast<int>(v) : hi;
}

// Mean of the firefly ratio: U[0.5, 1.5) x E, or log-uniform on [E, E_max).
// An energy that is not a finite positive number (NaN, infinite, 0 or below) draws no firefly
// light: a ratio of 0, in the draws and in the expectation alike. One past 1e150 is held there,
// as the spreads are (its square, in the variance, was inf and the variance NaN).
inline bool usable_energy(double e) noexcept { return e > 0 && e <= DBL_MAX; }
inline double held_energy(double e) noexcept { return usable_energy(e) ? (std::min)(e, 1e150) : 0.0; }
inline double mean_ratio(const scene& sc) noexcept {
    const double lo = held_energy(sc.firefly_energy), hi = held_energy(sc.firefly_energy_max);
    if (lo == 0) return 0.0;
    return hi > lo ? (hi - lo) / std::log(hi / lo) : lo;
}
inline double draw_ratio(const scene& sc, counter_rng& r) noexcept {
    const double lo = held_energy(sc.firefly_energy), hi = held_energy(sc.firefly_energy_max);
    if (lo == 0) return 0.0;
    return hi > lo ? lo * std::exp(r.uniform() * std::log(hi / lo)) : lo * (0.5 + r.uniform());
}
// Per-sample probability from a share of pixels hit among n samples: 1 - (1 - p)^n = rate,
// exactly (the Poisson form -log(1 - rate) / n overshot it, 0.325 of pixels hit for 0.30 at
// 2 samples, and passed 1 at high rates).
inline double rate_to_probability(double rate, double n) noexcept {
    if (!(rate > 0)) return 0.0;  // NaN too: the sampling takes it as 0, so must the expectation
    return -std::expm1(std::log1p(-std::clamp(rate, 0.0, 0.99)) / n);
}

class layout {
    // The effects that share the failed bucket's square.
    static constexpr std::uint32_t buckets = failed_bucket | dropped_bucket | garbage_bucket;

public:
    explicit layout(const scene& sc) : sc_(sc), w_((std::max)(sc.width, 0)), h_((std::max)(sc.height, 0)), fx_(sc.effects) {
        const double n = (std::max)(sc.spp, 2);
        if (fx_ & fireflies)
            p_ff_ = sc.firefly_probability > 0 ? (std::min)(sc.firefly_probability, 1.0)
                                               : rate_to_probability(sc.firefly_pixel_rate, n);
        if (fx_ & (highlights | wide_highlight)) place_spots();
        if (fx_ & caustics) place_caustics();
        if ((fx_ & log_gradient) && h_ > 0)  // (a frame of no pixel reads no ramp)
            for (int x = 0; x < w_; ++x)
                log_ramp_.push_back(0.02 * std::pow(1000.0, w_ > 1 ? static_cast<double>(x) / (w_ - 1) : 0.5));
        const double m = (std::min)(w_, h_);
        region_ = {sc.region_x0 * w_, sc.region_y0 * h_, sc.region_x1 * w_, sc.region_y1 * h_, sc.region_radius * m};
        // (a bucket is at most the frame's size and starts within a frame's size of it)
        const int side = clamped_int(std::round(sc.bucket_size * w_), 0, (std::max)(w_, h_));
        bx_ = clamped_int(sc.bucket_x * w_, -w_, w_);
        by_ = clamped_int(sc.bucket_y * h_, -h_, h_);
        bx1_ = static_cast<int>((std::min<std::int64_t>)(std::int64_t{bx_} + side, w_));  // (in int64: INT_MAX + side)
        by1_ = static_cast<int>((std::min<std::int64_t>)(std::int64_t{by_} + side, h_));
    }

    double firefly_probability() const noexcept { return p_ff_; }  // per sample, on the geometry

    double coverage(int x, int y) const noexcept {
        if (!(fx_ & (black_background | alpha_coverage))) return 1.0;
        const double cx = 0.5 * w_, cy = 0.5 * h_, rx = 0.46 * w_, ry = 0.46 * h_;
        const double u = (x + 0.5 - cx) / rx, v = (y + 0.5 - cy) / ry;
        const double d = (std::sqrt(u * u + v * v) - 1.0) * (std::min)(rx, ry);  // ~signed distance
        return std::clamp(0.5 - d, 0.0, 1.0);  // one-pixel soft rim
    }

    pixel_model model(int x, int y) const noexcept {
        pixel_model p;
        const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x);
        p.cov = coverage(x, y);
        if (p.cov < 1.0) p.touched |= fx_ & (black_background | alpha_coverage);
        double b = sc_.base, s = sc_.noise;
        const double tx = w_ > 1 ? static_cast<double>(x) / (w_ - 1) : 0.5;
        if (fx_ & gradient) scale(p, gradient, b, 0.25 + 1.5 * tx);
        if (fx_ & log_gradient) scale(p, log_gradient, b, log_ramp_[static_cast<std::size_t>(x)]);
        if (fx_ & fine_detail) {
            if (x % 16 == 5 || y % 24 == 7) scale(p, fine_detail, b, 6.0);  // thin lines
            if (x >= w_ / 2 && x < w_ / 2 + 32 && y >= h_ / 4 && y < h_ / 4 + 32 && ((x + y) & 1))
                scale(p, fine_detail, b, 8.0);  // checker
        }
        if (fx_ & varying_noise)
            scale(p, varying_noise, s, 0.25 + 1.75 * (h_ > 1 ? static_cast<double>(y) / (h_ - 1) : 0.5));
        if (fx_ & caustics) caustic(p, x, y, b);
        if ((fx_ & bright_region) && region_.in_box(x + 0.5, y + 0.5) && region_.distance(x + 0.5, y + 0.5) <= region_.r) {
            p.touched |= bright_region;
            const double lit = sc_.region_radiance * sc_.base;
            // as the spots: off the geometry it is background, and a highlight only above
            // what it covers
            p.highlight = p.cov >= 1.0 && lit > b;
            b = lit;
            s = sc_.region_noise;
        }
        if (!spots_.empty() && spots_[i]) {
            p.touched |= spots_[i];
            // A spot's light is its own (a lamp's reflection), whatever lies under it; where a
            // ramp or a line is brighter still (calibration scenes: a line of 29 under a spot
            // of 12.5) it is no highlight, just a pixel of another level.
            const double lit = sc_.highlight_radiance * sc_.base;
            p.highlight = lit > b;
            b = lit;
            s = sc_.highlight_noise;
        }
        // (not on a highlight: a highlight of negative light is none)
        if ((fx_ & negative) && !p.highlight && mix64(sc_.seed ^ (i * golden + negative_pixels)) % 50 == 0) {
            p.sign = -0.2;  // the same pixels in every buffer
            p.touched |= negative;
        }
        if ((fx_ & buckets) && x >= bx_ && x < bx1_ && y >= by_ && y < by1_) {
            p.bucket = (fx_ & failed_bucket) != 0;
            p.dropped = (fx_ & dropped_bucket) != 0;
            p.garbage = (fx_ & garbage_bucket) != 0;
            p.touched |= fx_ & buckets;
        }
        static constexpr double tint[3] = {1.0, 0.85, 0.7};
        for (int c = 0; c < 3; ++c) p.mu[c] = b * tint[c];
        p.s = s;
        p.p_ff = p.cov > 0 ? p_ff_ : 0.0;
        if (p.cov <= 0) p.p_caustic = 0.0;
        p.energy_scale = sc_.firefly_relative ? (p.mu[0] + p.mu[1] + p.mu[2]) / 3.0 * (std::max)(sc_.spp, 2) : sc_.base;
        return p;
    }

    // The radiance the estimator converges to, per channel.
    // Returns the part that fireflies contribute (the same in every channel).
    // A firefly sample takes the place of an ordinary one (scene.hpp, simulate_pixel): each
    // position is a firefly with probability p_ff and a caustic's with p_caustic (at most 1:
    // p >= 1 hits every position), and the ordinary samples keep the rest of the positions.
    // Exact unless the two kinds of hits together can outnumber a pixel's samples (both effects
    // on, few samples, high rates): there the ordinary share is a little above 1 - hit.
    double expected(const pixel_model& p, float out[3]) const noexcept {
        const double hit = (std::min)(p.p_ff, 1.0) + (std::min)(p.p_caustic, 1.0);
        const double ff = hit * p.energy_scale * mean_ratio_;
        const double ordinary = 1.0 - (std::min)(hit, 1.0);
        for (int c = 0; c < 3; ++c) out[c] = channel_traits<float>::store(p.cov * (p.sign * p.mu[c] * ordinary + ff));
        return p.cov * ff;
    }

private:
    void scale(pixel_model& p, effect e, double& v, double factor) const noexcept {
        if (!(fx_ & e)) return;
        v *= factor;
        if (factor != 1.0) p.touched |= e;
    }

    void caustic(pixel_model& p, int x, int y, double& b) const noexcept {
        double c = 0;  // 1 in a caustic's core, falling to 0 at its rim
        for (const capsule& k : caustics_)
            if (k.in_box(x + 0.5, y + 0.5))
                c = (std::max)(c, std::clamp((1.0 - k.distance(x + 0.5, y + 0.5) / k.r) / 0.4, 0.0, 1.0));
        if (c <= 0) return;
        p.touched |= caustics;
        b *= 1.0 + (sc_.caustic_radiance - 1.0) * c;
        p.p_caustic = rate_to_probability(sc_.caustic_pixel_rate * c, (std::max)(sc_.spp, 2));
    }

    void place_spots() {
        spots_.assign(static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_), 0);
        std::int64_t unmarked = 0;  // pixels a spot could still mark (on the geometry)
        for (int y = 0; y < h_; ++y)
            for (int x = 0; x < w_; ++x) unmarked += coverage(x, y) >= 1.0;
        auto mark = [&](int x, int y, effect e) {
            if (x < 0 || y < 0 || x >= w_ || y >= h_ || coverage(x, y) < 1.0) return;
            std::uint8_t& s = spots_[static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x)];
            if (e == highlights && !(s & highlights)) --unmarked;
            s |= static_cast<std::uint8_t>(e);
        };
        if (fx_ & highlights) {
            counter_rng r(sc_.seed, stream_of(highlights), 0, 0);
            // Once every pixel is marked the rest of the spots change nothing: stop there (INT_MAX
            // spots took a minute on a 1x1 frame).
            for (int k = 0; k < sc_.highlight_count && unmarked > 0; ++k) {
                const int x0 = static_cast<int>(r.uniform() * w_), y0 = static_cast<int>(r.uniform() * h_);
                const int rad = r.uniform() < 0.5 ? 0 : 1;
                for (int y = y0 - rad; y <= y0 + rad; ++y)
                    for (int x = x0 - rad; x <= x0 + rad; ++x) mark(x, y, highlights);
            }
        }
        if (fx_ & wide_highlight) {
            const double wr = sc_.wide_radius * (std::min)(w_, h_), wx = 0.3 * w_, wy = 0.35 * h_;
            for (int y = clamped_int(wy - wr - 1, 0, h_); y < clamped_int(wy + wr + 2, 0, h_); ++y)
                for (int x = clamped_int(wx - wr - 1, 0, w_); x < clamped_int(wx + wr + 2, 0, w_); ++x)
                    if (std::hypot(x + 0.5 - wx, y + 0.5 - wy) <= wr) mark(x, y, wide_highlight);
        }
    }

    // Caustics: blobs (60%) and thin streaks, away from the frame's edge.
    void place_caustics() {
        counter_rng r(sc_.seed, stream_of(caustics), 0, 0);
        const double m = (std::min)(w_, h_);
        const int count = std::clamp(sc_.caustic_count, 0, max_caustics);  // each costs a pass over the frame
        const std::int64_t blobs = (std::int64_t{count} * 3 + 4) / 5;
        for (int k = 0; k < count; ++k) {
            const double x0 = (0.15 + 0.7 * r.uniform()) * w_, y0 = (0.15 + 0.7 * r.uniform()) * h_;
            if (k < blobs) {
                caustics_.push_back({x0, y0, x0, y0, (0.03 + 0.04 * r.uniform()) * m});
            } else {
                const double a = 6.283185307179586 * r.uniform(), len = (0.08 + 0.15 * r.uniform()) * m;
                caustics_.push_back({x0, y0, x0 + len * std::cos(a), y0 + len * std::sin(a), 1.5 + r.uniform()});
            }
        }
    }

    static std::uint64_t stream_of(effect e) noexcept {
        return std::uint64_t{detail::layout_stream} + static_cast<std::uint64_t>(e);
    }

    const scene& sc_;
    int w_, h_;
    std::uint32_t fx_;
    double p_ff_ = 0.0;
    double mean_ratio_ = mean_ratio(sc_);
    std::vector<std::uint8_t> spots_;  // highlights | wide_highlight bits (both fit a byte)
    std::vector<capsule> caustics_;
    std::vector<double> log_ramp_;  // log_gradient factor per column
    capsule region_{};
    int bx_ = 0, by_ = 0, bx1_ = 0, by1_ = 0;
};

}  // namespace firefly::sim::detail
