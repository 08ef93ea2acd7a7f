// firefly/sim: a Monte Carlo half-buffer simulator for tests, benchmarks and demos. Opt-in;
// not part of the core umbrella header.
//
// A scene is a size, samples per pixel per half, a seed and a set of effects; only the
// effects listed are simulated, cost time and allocate ground-truth arrays. Each half (or each
// of K buffers, simulate_buffers) holds what a renderer keeps: the per-pixel mean of its
// samples and the variance of that mean, per channel. The ordinary samples are drawn as their
// mean and sum of squares (samples.hpp); firefly samples are an exact Bernoulli process over a
// pixel's samples (a geometric skip from the first hit), merged with the parallel-variance
// formula.
//
// Independence: every random number comes from a counter-based stream keyed by (seed, effect,
// pixel, buffer) (random.hpp), and a pixel's model depends only on the effects whose footprint
// holds it (layout.hpp). Turning an effect on or off therefore leaves every pixel outside its
// footprint bit-identical in colour, variance, alpha and expected radiance, in every buffer,
// with one exception: `fireflies` adds its expected energy to the expected radiance of every
// pixel it may reach (it is part of what the estimator converges to), so `expected` changes on
// all the geometry while colour and variance change only where a firefly landed (caustics keep
// theirs inside their own footprint). `frame::touched` gives each pixel's footprint bits. Nothing depends on visiting order; results are the same on every
// compiler and standard library.
//
// Ground truth comes with every frame: the expected radiance per pixel (including the
// expected firefly energy), the firefly energy each half received, the highlights, the
// non-finite pixels.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "../image_view.hpp"
#include "layout.hpp"
#include "random.hpp"
#include "samples.hpp"
#include "scenes.hpp"
#include "types.hpp"

namespace firefly::sim {

namespace detail {

struct hits {
    std::uint64_t count = 0;
    double sum = 0.0, sq = 0.0;  // of the firefly sample values
};

// Successes of `trials` Bernoulli(p) trials, by geometric skips: cost in successes, not trials.
template <class F>
void bernoulli_trials(counter_rng& r, double p, std::uint64_t trials, F&& on_success) {
    if (!(p > 0)) return;
    for (std::uint64_t pos = r.geometric(p); pos < trials;) {
        on_success(pos);
        const std::uint64_t gap = r.geometric(p);
        if (gap >= trials - pos - 1) break;
        pos += 1 + gap;
    }
}

// Firefly samples among a pixel's n with probability p each (q0 = (1 - p)^n, the chance of
// none): the first hit's position from its law truncated to n, then geometric gaps. One draw
// when there is no hit. For per-pixel rates (caustics).
inline void pixel_hits(hits& h, counter_rng& r, double p, std::uint64_t n, const scene& sc, double energy_scale) noexcept {
    const double q0 = std::exp(static_cast<double>(n) * std::log1p(-(std::min)(p, 1.0)));
    const double u = r.uniform();
    if (u < q0) return;
    const double v = (u - q0) / (1.0 - q0);  // uniform, given at least one hit
    double first = p >= 1.0 ? 0.0 : std::ceil(std::log1p(-v * (1.0 - q0)) / std::log1p(-p)) - 1.0;
    first = std::clamp(first, 0.0, static_cast<double>(n - 1));
    for (std::uint64_t pos = static_cast<std::uint64_t>(first); pos < n;) {
        const double e = energy_scale * draw_ratio(sc, r);
        ++h.count;
        h.sum += e;
        h.sq += e * e;
        const std::uint64_t gap = r.geometric(p);
        if (gap >= n - pos - 1) break;
        pos += 1 + gap;
    }
}

// The rare events of one row of one buffer, drawn by geometric skips along the row (one
// stream per effect, row and buffer), so that their cost follows the events, not the pixels.
struct row_events {
    struct firefly_hit {
        int x;
        hits ratio;  // firefly ratios; a sample's value is the pixel's energy_scale x ratio
    };
    struct bad_value {
        int x, channel;
        bool nan;
    };
    std::vector<firefly_hit> ff;
    std::vector<int> negative_variance;
    std::vector<bad_value> nonfinite;
    std::size_t next_ff = 0, next_neg = 0, next_bad = 0;

    void draw(const scene& sc, double p_ff, int y, std::size_t b, int w, std::uint64_t n) {
        ff.clear();
        negative_variance.clear();
        nonfinite.clear();
        next_ff = next_neg = next_bad = 0;
        const std::uint64_t row = static_cast<std::uint64_t>(y), buf = static_cast<std::uint64_t>(b);
        const std::uint64_t uw = static_cast<std::uint64_t>(w);
        if (p_ff > 0) {
            counter_rng r(sc.seed, fireflies, row, buf);
            bernoulli_trials(r, p_ff, uw * n, [&](std::uint64_t pos) {
                const int x = static_cast<int>(pos / n);
                if (ff.empty() || ff.back().x != x) ff.push_back({x, {}});
                const double e = draw_ratio(sc, r);
                ++ff.back().ratio.count;
                ff.back().ratio.sum += e;
                ff.back().ratio.sq += e * e;
            });
        }
        if (sc.effects & sim::negative) {
            counter_rng r(sc.seed, negative_variance_stream, row, buf);
            bernoulli_trials(r, 0.01, uw, [&](std::uint64_t x) { negative_variance.push_back(static_cast<int>(x)); });
        }
        if (sc.effects & sim::nonfinite) {
            counter_rng r(sc.seed, sim::nonfinite, row, buf);
            bernoulli_trials(r, sc.nonfinite_pixel_rate, uw, [&](std::uint64_t x) {
                const bool is_nan = r.uniform() < 0.5;
                nonfinite.push_back({static_cast<int>(x), static_cast<int>(r.uniform() * 3), is_nan});
            });
        }
    }
    template <class T>
    static const T* at(const std::vector<T>& v, std::size_t& next, int x) {
        while (next < v.size() && key(v[next]) < x) ++next;
        return next < v.size() && key(v[next]) == x ? &v[next] : nullptr;
    }
    static int key(const firefly_hit& h) { return h.x; }
    static int key(const bad_value& h) { return h.x; }
    static int key(int x) { return x; }
};

// One pixel of one buffer: colour and variance of the mean, and the firefly energy added.
// Returns `fireflies` when the fireflies effect hit the pixel.
inline std::uint32_t simulate_pixel(const scene& sc, const pixel_model& p, std::size_t i,
                                    std::size_t b, std::uint64_t n, const hits* ff_ratio,
                                    const normal_constants& nc, buffers& out) {
    hits h;
    std::uint32_t touched = 0;
    if (ff_ratio) {
        h.count = ff_ratio->count;
        h.sum = p.energy_scale * ff_ratio->sum;
        h.sq = p.energy_scale * p.energy_scale * ff_ratio->sq;
        touched = fireflies;
    }
    if (p.p_caustic > 0) {
        counter_rng r(sc.seed, caustics, i, static_cast<std::uint64_t>(b));
        pixel_hits(h, r, p.p_caustic, n, sc, p.energy_scale);
    }
    const std::uint64_t k = (std::min)(h.count, n), m = n - k;
    counter_rng base(sc.seed, base_noise, i, static_cast<std::uint64_t>(b));
    const sample_moments o = draw_samples(base, sc.samples, p.s, m, &nc);
    const double dm = static_cast<double>(m), dk = static_cast<double>(k), dn = static_cast<double>(n);
    const double to_var_mean = p.cov * p.cov / ((dn - 1) * dn);  // m2 -> variance of the mean
    for (std::size_t c = 0; c < 3; ++c) {
        const double mu = p.mu[c] * p.sign;
        double mean = mu * o.mean, m2 = mu * mu * o.m2;
        if (k > 0) {  // merge with the k firefly samples (each channel gets the firefly's energy)
            const double fm = h.sum / dk, fm2 = (std::max)(h.sq - dk * fm * fm, 0.0);
            const double d = fm - mean;
            mean += d * dk / dn;
            m2 += fm2 + d * d * dm * dk / dn;
        }
        // (held at FLT_MAX past it, as the library stores: the plain cast is undefined there)
        out.color[b][i * 3 + c] = channel_traits<float>::store(p.cov * mean);
        out.variance[b][i * 3 + c] = channel_traits<float>::store(m2 * to_var_mean);
    }
    if (k > 0) out.firefly_energy[b][i] = channel_traits<float>::store(p.cov * h.sum / dn);
    return touched;
}

// Negative variances, NaN/Inf samples and the failed or dropped bucket, after the pixel is drawn.
inline std::uint32_t damage_pixel(const pixel_model& p, int x, std::size_t i, std::size_t b,
                                  row_events& ev, buffers& out) {
    std::uint32_t touched = 0;
    const bool covered = p.cov > 0;
    // A renderer's E[x^2] - E[x]^2 rounds below 0 where the spread is below float precision:
    // an ordinary pixel's green variance written -1e-7, never a highlight's or a firefly's
    // (whose variance is nowhere near round-off, and whose truth must stay what it says).
    const bool hit = !out.firefly_energy[b].empty() && out.firefly_energy[b][i] != 0;
    if (row_events::at(ev.negative_variance, ev.next_neg, x) && covered && !p.highlight && !hit) {
        out.variance[b][i * 3 + 1] = -1e-7f;
        touched |= negative;
    }
    if (const row_events::bad_value* v = row_events::at(ev.nonfinite, ev.next_bad, x); v && covered) {
        const float bad = v->nan ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
        out.color[b][i * 3 + static_cast<std::size_t>(v->channel)] = bad;
        out.variance[b][i * 3] = bad;
        out.nonfinite[b][i] = 1;
        touched |= nonfinite;
    }
    if (p.bucket && b == 0) {
        const float nan = std::numeric_limits<float>::quiet_NaN();
        for (std::size_t c = 0; c < 3; ++c) out.color[b][i * 3 + c] = out.variance[b][i * 3 + c] = nan;
        out.nonfinite[b][i] = 1;
    } else if (p.dropped && b == 0) {
        for (std::size_t c = 0; c < 3; ++c) out.color[b][i * 3 + c] = out.variance[b][i * 3 + c] = 0.0f;
        if (!out.firefly_energy[b].empty()) out.firefly_energy[b][i] = 0.0f;  // no sample was kept
        if (!out.nonfinite[b].empty()) out.nonfinite[b][i] = 0;                // nor a bad one
    } else if (p.garbage && b == 0) {
        for (std::size_t c = 0; c < 3; ++c) out.color[b][i * 3 + c] = 1e30f;
        out.nonfinite[b][i] = 1;
    }
    return touched;
}

inline void allocate(const scene& sc, int k, buffers& f) {
    const std::size_t np = f.pixels();
    const std::uint32_t fx = sc.effects;
    const std::int64_t total = 2 * std::int64_t{(std::max)(sc.spp, 2)};  // (no overflow at INT_MAX)
    for (int b = 0; b < k; ++b) f.spp.push_back(static_cast<int>((std::max<std::int64_t>)(total / k + (b < total % k ? 1 : 0), 2)));
    f.color.assign(static_cast<std::size_t>(k), std::vector<float>(np * 3, 0.0f));
    f.variance = f.color;
    f.firefly_energy.assign(static_cast<std::size_t>(k), std::vector<float>());
    f.nonfinite.assign(static_cast<std::size_t>(k), std::vector<std::uint8_t>());
    for (std::size_t b = 0; b < static_cast<std::size_t>(k); ++b) {
        if (fx & (fireflies | caustics)) f.firefly_energy[b].assign(np, 0.0f);
    if (fx & (fireflies | caustics)) f.firefly_expected.assign(np, 0.0f);
        if (fx & (nonfinite | failed_bucket | garbage_bucket)) f.nonfinite[b].assign(np, 0);
    }
    f.expected.assign(np * 3, 0.0f);
    f.highlight.assign(np, 0);
    if (fx) f.touched.assign(np, 0);
    if (fx & alpha_coverage) f.alpha.assign(np, 0.0f);
}

}  // namespace detail

// Simulates k >= 2 independent buffers of one frame (k below 2 counts as 2; every buffer gets
// at least 2 samples). k = 2 gives the halves of simulate(), bit for bit.
inline buffers simulate_buffers(const scene& sc, int k) {
    k = (std::max)(k, 2);
    buffers f;
    f.width = (std::max)(sc.width, 0);
    f.height = (std::max)(sc.height, 0);
    f.effects = sc.effects;
    detail::allocate(sc, k, f);
    const detail::layout lay(sc);
    const std::size_t nb = static_cast<std::size_t>(k);  // (k >= 2)
    std::vector<detail::row_events> ev(nb);
    std::vector<detail::normal_constants> nc;
    for (int s : f.spp) nc.emplace_back(static_cast<std::uint64_t>(s));
    for (int y = 0; y < f.height; ++y) {
        for (std::size_t b = 0; b < nb; ++b)
            ev[b].draw(sc, lay.firefly_probability(), y, b, f.width, static_cast<std::uint64_t>(f.spp[b]));
        for (int x = 0; x < f.width; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(f.width) + static_cast<std::size_t>(x);
            const detail::pixel_model p = lay.model(x, y);
            const double ff_expected = lay.expected(p, &f.expected[i * 3]);
            if (!f.firefly_expected.empty()) f.firefly_expected[i] = channel_traits<float>::store(ff_expected);
            f.highlight[i] = p.highlight ? 1 : 0;
            if (!f.alpha.empty()) f.alpha[i] = static_cast<float>(p.cov);
            std::uint32_t touched = p.touched;
            for (std::size_t b = 0; b < nb; ++b) {
                const auto* hit = detail::row_events::at(ev[b].ff, ev[b].next_ff, x);
                if (p.cov > 0)
                    touched |= detail::simulate_pixel(sc, p, i, b, static_cast<std::uint64_t>(f.spp[b]),
                                                      hit ? &hit->ratio : nullptr, nc[b], f);
                touched |= detail::damage_pixel(p, x, i, b, ev[b], f);
            }
            if (!f.touched.empty()) f.touched[i] = touched;
        }
    }
    return f;
}

// Simulates both halves of one frame.
inline frame simulate(const scene& sc) {
    buffers b = simulate_buffers(sc, 2);
    frame f;
    f.width = b.width;
    f.height = b.height;
    f.effects = b.effects;
    for (std::size_t h = 0; h < 2; ++h) {
        f.color[h] = std::move(b.color[h]);
        f.variance[h] = std::move(b.variance[h]);
        f.firefly_energy[h] = std::move(b.firefly_energy[h]);
        f.nonfinite[h] = std::move(b.nonfinite[h]);
    }
    f.alpha = std::move(b.alpha);
    f.expected = std::move(b.expected);
    f.firefly_expected = std::move(b.firefly_expected);
    f.highlight = std::move(b.highlight);
    f.touched = std::move(b.touched);
    return f;
}

}  // namespace firefly::sim
