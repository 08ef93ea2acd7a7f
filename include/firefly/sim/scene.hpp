// firefly/sim: a Monte Carlo half-buffer simulator for tests, benchmarks and demos. Opt-in;
// not part of the core umbrella header.
//
// A scene is a size, samples per pixel per half, a seed and a set of effects; only the
// effects listed are simulated (and cost time). Each half holds what a renderer keeps: the
// per-pixel mean of its samples and the variance of that mean, per channel. Nothing loops
// over samples: the ordinary samples' mean and sample variance are drawn from their exact
// distributions (normal, and chi-square by the Wilson-Hilferty transform), the rare events
// by a geometric skip over the whole sample stream (an exact Bernoulli process), and the two
// are merged with the parallel-variance formula.
//
// Ground truth comes with every frame: the expected radiance per pixel (including the
// expected firefly energy), the firefly energy each half received, and the highlights.
// Random numbers are the simulator's own (splitmix64 + xoshiro256**, Box-Muller), so a seed
// gives the same frame with every compiler and standard library.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace firefly::sim {

enum effect : std::uint32_t {
    gradient = 1u << 0,          // base radiance ramps across the frame (else flat)
    fine_detail = 1u << 1,       // one-pixel lines and a checker patch of high contrast
    varying_noise = 1u << 2,     // per-sample noise varies 8x over the frame
    fireflies = 1u << 3,         // rare samples of very high value
    highlights = 1u << 4,        // small bright spots of high variance in both halves
    wide_highlight = 1u << 5,    // a disk in which every pixel is a highlight
    black_background = 1u << 6,  // no geometry outside a large disk: colour and variance 0
    alpha_coverage = 1u << 7,    // alpha: 1 on the geometry, 0 outside, fractional on the rim
    nonfinite = 1u << 8,         // a few NaN / Inf samples
    negative = 1u << 9,          // some negative samples, and variances of -0 round-off
};

struct scene {
    std::string name = "custom";
    int width = 256;
    int height = 256;
    int spp = 64;                        // samples per pixel per half
    std::uint64_t seed = 1;
    std::uint32_t effects = 0;
    double base = 0.5;                   // base radiance
    double noise = 0.6;                  // per-sample relative standard deviation
    double firefly_pixel_rate = 0.005;   // expected share of pixels hit, per half ...
    double firefly_probability = 0.0;    // ... or, when > 0, the probability of each sample
    double firefly_energy = 400.0;       // firefly sample value, x base (x U[0.5, 1.5))
    int highlight_count = 60;            // small highlight spots
    double highlight_radiance = 25.0;    // x base
    double highlight_noise = 2.5;        // per-sample relative sd inside a highlight
    double wide_radius = 0.08;           // wide highlight radius, share of min(width, height)
    double nonfinite_pixel_rate = 2e-4;
};

struct frame {
    int width = 0, height = 0;
    // Interleaved RGB float per half: colour (mean of samples), variance of that mean.
    std::vector<float> color[2], variance[2];
    std::vector<float> alpha;            // 1 channel; empty unless alpha_coverage
    std::vector<float> expected;         // RGB: the radiance the estimator converges to
    std::vector<float> firefly_energy[2];// per pixel: mean-colour energy fireflies added to the
                                         // half's pixel mean (0: no firefly sample)
    std::vector<std::uint8_t> highlight; // 1: highlight pixel (small spot or wide disk)
    std::vector<std::uint8_t> nonfinite[2];
    std::size_t pixels() const noexcept { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
};

namespace detail {

struct rng {
    std::uint64_t s[4];
    explicit rng(std::uint64_t seed) {
        for (auto& v : s) {  // splitmix64
            seed += 0x9E3779B97F4A7C15ull;
            std::uint64_t z = seed;
            z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
            z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
            v = z ^ (z >> 31);
        }
    }
    static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
    std::uint64_t next() {  // xoshiro256**
        const std::uint64_t r = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = rotl(s[3], 45);
        return r;
    }
    double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
    double normal() {
        if (has_spare) {
            has_spare = false;
            return spare;
        }
        double u = uniform(), v = uniform();
        if (u < 1e-300) u = 1e-300;
        const double r = std::sqrt(-2.0 * std::log(u)), a = 6.283185307179586 * v;
        spare = r * std::sin(a);
        has_spare = true;
        return r * std::cos(a);
    }
    // Chi-square with k degrees of freedom, divided by k (Wilson-Hilferty).
    double chi2_over_k(double k) {
        const double c = 2.0 / (9.0 * k);
        const double t = 1.0 - c + normal() * std::sqrt(c);
        return t > 0 ? t * t * t : 0.0;
    }
    // Number of failures before the next success of a Bernoulli(p) process.
    std::uint64_t geometric(double p) {
        if (p >= 1.0) return 0;
        if (p <= 0.0) return std::numeric_limits<std::uint64_t>::max();
        const double u = 1.0 - uniform();  // (0, 1]
        const double g = std::floor(std::log(u) / std::log1p(-p));
        return g >= 1.8e19 ? std::numeric_limits<std::uint64_t>::max() : static_cast<std::uint64_t>(g);
    }
    bool has_spare = false;
    double spare = 0.0;
};

}  // namespace detail

// Simulates both halves of one frame.
inline frame simulate(const scene& sc) {
    frame f;
    f.width = std::max(sc.width, 0);
    f.height = std::max(sc.height, 0);
    const std::size_t np = f.pixels();
    const int w = f.width, h = f.height;
    const double n = std::max(sc.spp, 2);
    const std::uint32_t fx = sc.effects;
    detail::rng layout(sc.seed ^ 0x5eedull);

    // Geometry coverage (black background / alpha): an ellipse filling most of the frame.
    const double cx = 0.5 * w, cy = 0.5 * h, rx = 0.46 * w, ry = 0.46 * h;
    auto coverage = [&](int x, int y) {
        if (!(fx & (black_background | alpha_coverage))) return 1.0;
        const double u = (x + 0.5 - cx) / rx, v = (y + 0.5 - cy) / ry;
        const double d = (std::sqrt(u * u + v * v) - 1.0) * std::min(rx, ry);  // ~signed distance
        return std::clamp(0.5 - d, 0.0, 1.0);  // one-pixel soft rim
    };
    // Highlights: small spots, and the wide disk.
    f.highlight.assign(np, 0);
    if (fx & highlights) {
        for (int k = 0; k < sc.highlight_count; ++k) {
            const int x0 = static_cast<int>(layout.uniform() * w), y0 = static_cast<int>(layout.uniform() * h);
            const int r = layout.uniform() < 0.5 ? 0 : 1;
            for (int y = y0 - r; y <= y0 + r; ++y)
                for (int x = x0 - r; x <= x0 + r; ++x)
                    if (x >= 0 && y >= 0 && x < w && y < h && coverage(x, y) >= 1.0)
                        f.highlight[static_cast<std::size_t>(y) * w + x] = 1;
        }
    }
    if (fx & wide_highlight) {
        const double wr = sc.wide_radius * std::min(w, h);
        const double wx = 0.3 * w, wy = 0.35 * h;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x)
                if (std::hypot(x + 0.5 - wx, y + 0.5 - wy) <= wr && coverage(x, y) >= 1.0)
                    f.highlight[static_cast<std::size_t>(y) * w + x] = 1;
    }

    // Expected radiance, per-sample noise and tint per pixel.
    f.expected.assign(np * 3, 0.0f);
    std::vector<float> sigma(np, 0.0f);  // per-sample relative sd
    const double tint[3] = {1.0, 0.85, 0.7};
    const double ff_mean_energy = sc.firefly_energy * sc.base;  // E[U[0.5,1.5)] = 1
    // Per-sample probability: given, or from the share of pixels hit (a Poisson rate:
    // n p = -log(1 - rate), so that 1 - exp(-n p) = rate).
    const double p_sample = !(fx & fireflies)            ? 0.0
                            : sc.firefly_probability > 0 ? std::min(sc.firefly_probability, 1.0)
                                                         : -std::log1p(-std::min(sc.firefly_pixel_rate, 0.5)) / n;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * w + x;
            double b = sc.base;
            if (fx & gradient) b *= 0.25 + 1.5 * (w > 1 ? static_cast<double>(x) / (w - 1) : 0.5);
            if (fx & fine_detail) {
                if (x % 16 == 5 || y % 24 == 7) b *= 6.0;                               // thin lines
                if (x >= w / 2 && x < w / 2 + 32 && y >= h / 4 && y < h / 4 + 32 && ((x + y) & 1))
                    b *= 8.0;                                                            // checker
            }
            double s = sc.noise;
            if (fx & varying_noise) s *= 0.25 + 1.75 * (h > 1 ? static_cast<double>(y) / (h - 1) : 0.5);
            if (f.highlight[i]) {
                b = sc.highlight_radiance * sc.base;
                s = sc.highlight_noise;
            }
            const double cov = coverage(x, y);
            for (int c = 0; c < 3; ++c)
                f.expected[i * 3 + c] = static_cast<float>(cov * (b * tint[c] + p_sample * ff_mean_energy));
            sigma[i] = static_cast<float>(s);
        }

    if (fx & alpha_coverage) {
        f.alpha.resize(np);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) f.alpha[static_cast<std::size_t>(y) * w + x] = static_cast<float>(coverage(x, y));
    }

    for (int half = 0; half < 2; ++half) {
        detail::rng r(sc.seed * 0x9E3779B97F4A7C15ull + 17 + static_cast<std::uint64_t>(half));
        f.color[half].assign(np * 3, 0.0f);
        f.variance[half].assign(np * 3, 0.0f);
        f.firefly_energy[half].assign(np, 0.0f);
        f.nonfinite[half].assign(np, 0);
        // Firefly samples: positions in the stream of np * n samples (exact Bernoulli process).
        std::vector<std::uint32_t> ff_count(np, 0);
        std::vector<double> ff_sum(np, 0.0), ff_sq(np, 0.0);
        if (p_sample > 0) {
            const std::uint64_t total = static_cast<std::uint64_t>(np) * static_cast<std::uint64_t>(n);
            std::uint64_t pos = r.geometric(p_sample);
            while (pos < total) {
                const std::size_t i = static_cast<std::size_t>(pos / static_cast<std::uint64_t>(n));
                const double e = ff_mean_energy * (0.5 + r.uniform());
                if (coverage(static_cast<int>(i % w), static_cast<int>(i / w)) > 0) {
                    ++ff_count[i];
                    ff_sum[i] += e;
                    ff_sq[i] += e * e;
                }
                const std::uint64_t gap = r.geometric(p_sample);
                if (gap >= total) break;
                pos += 1 + gap;
            }
        }
        for (std::size_t i = 0; i < np; ++i) {
            const int x = static_cast<int>(i % w), y = static_cast<int>(i / w);
            const double cov = coverage(x, y);
            if (cov <= 0) continue;  // background: colour and variance exactly 0
            const std::uint32_t k = ff_count[i];
            const double m = n - k;  // ordinary samples
            // Ordinary samples: value_c = mu_c (1 + s g), one g shared by the channels.
            const double s = sigma[i];
            const double gbar = m > 0 ? r.normal() * std::sqrt(1.0 / m) : 0.0;
            const double s2 = m > 1 ? r.chi2_over_k(m - 1) : 0.0;  // sample var of g / 1
            double nb = 1.0;  // a pixel whose samples go negative (the same pixels in both halves)
            if ((fx & negative) && ((i * 0x9E3779B97F4A7C15ull + sc.seed) >> 40) % 50 == 0) nb = -0.2;
            for (int c = 0; c < 3; ++c) {
                const double mu = f.expected[i * 3 + c] / std::max(cov, 1e-12) - p_sample * ff_mean_energy;
                const double mean0 = mu * (1.0 + s * gbar) * nb;
                const double m2_0 = (mu * s * nb) * (mu * s * nb) * s2 * std::max(m - 1, 0.0);
                // Merge with the k firefly samples (each channel gets the firefly's energy).
                double mean = mean0, m2 = m2_0, cnt = m;
                if (k > 0) {
                    const double fm = ff_sum[i] / k, fm2 = std::max(ff_sq[i] - k * fm * fm, 0.0);
                    const double tot = cnt + k, d = fm - mean;
                    mean = mean + d * k / tot;
                    m2 = m2 + fm2 + d * d * cnt * k / tot;
                    cnt = tot;
                }
                const double var_mean = m2 / (cnt - 1) / cnt;
                f.color[half][i * 3 + c] = static_cast<float>(cov * mean);
                f.variance[half][i * 3 + c] = static_cast<float>(cov * cov * var_mean);
            }
            if (k > 0) f.firefly_energy[half][i] = static_cast<float>(cov * ff_sum[i] / n);
            if ((fx & negative) && r.uniform() < 0.01) f.variance[half][i * 3 + 1] = -1e-7f;
            if ((fx & nonfinite) && r.uniform() < sc.nonfinite_pixel_rate) {
                const float bad = r.uniform() < 0.5 ? std::numeric_limits<float>::quiet_NaN()
                                                    : std::numeric_limits<float>::infinity();
                f.color[half][i * 3 + static_cast<int>(r.uniform() * 3)] = bad;
                f.variance[half][i * 3] = bad;
                f.nonfinite[half][i] = 1;
            }
        }
    }
    return f;
}

// ---------------------------------------------------------------------------------------
// Named scenes. Each turns on only the effects it is about.
inline scene named_scene(const std::string& name, int width = 256, int height = 256, std::uint64_t seed = 1) {
    scene s;
    s.name = name;
    s.width = width;
    s.height = height;
    s.seed = seed;
    if (name == "sparse_fireflies") {
        s.effects = gradient | fireflies;
        s.firefly_pixel_rate = 0.002;
    } else if (name == "dense_fireflies") {
        s.effects = gradient | varying_noise | fireflies;
        s.firefly_pixel_rate = 0.02;
    } else if (name == "highlights") {
        s.effects = gradient | highlights | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "wide_highlight") {
        s.effects = wide_highlight | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "fine_detail") {
        s.effects = fine_detail | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "black_alpha") {
        s.effects = black_background | alpha_coverage | gradient | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "nonfinite") {
        s.effects = gradient | nonfinite | negative | fireflies;
        s.firefly_pixel_rate = 0.003;
    } else if (name == "production") {
        s.effects = gradient | fine_detail | varying_noise | fireflies | highlights | wide_highlight |
                    black_background | alpha_coverage | nonfinite | negative;
        s.firefly_pixel_rate = 0.006;
    } else {
        s.name = "flat";
        s.effects = 0;
    }
    return s;
}

inline const std::vector<std::string>& scene_names() {
    static const std::vector<std::string> names = {"sparse_fireflies", "dense_fireflies", "highlights",
                                                   "wide_highlight",   "fine_detail",     "black_alpha",
                                                   "nonfinite",        "production"};
    return names;
}

}  // namespace firefly::sim
