// firefly/sim: what a simulated scene is made of, and what the simulator hands back.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "samples.hpp"

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
    negative = 1u << 9,          // some negative pixels, and variances of round-off below 0 (-1e-7)
    log_gradient = 1u << 10,     // base radiance spans three decades across the frame (x0.02 .. x20)
    caustics = 1u << 11,         // a few bright caustic blobs and streaks with a firefly rate of their own
    failed_bucket = 1u << 12,    // a square block of NaN colour and variance in buffer 0 only
    bright_region = 1u << 13,    // a bright, noisy, legitimate region (a lit ceiling, a light beam)
    dropped_bucket = 1u << 14,   // the failed bucket's square written black (colour and variance
                                 // 0) in buffer 0 only, as a renderer that never wrote it
    garbage_bucket = 1u << 15,   // the failed bucket's square holding 1e30 in every colour channel
                                 // of buffer 0 only, its variance as rendered (finite garbage)
};

// Most caustics a scene draws: each costs a pass over the frame.
inline constexpr int max_caustics = 4096;

struct scene {
    std::string name = "custom";
    int width = 256;
    int height = 256;
    int spp = 64;                        // samples per pixel per half
    std::uint64_t seed = 1;
    std::uint32_t effects = 0;
    double base = 0.5;                   // base radiance
    double noise = 0.6;                  // per-sample relative standard deviation
    distribution samples = distribution::normal;  // law of the ordinary samples (samples.hpp)
    double firefly_pixel_rate = 0.005;   // expected share of pixels hit, per half ...
    double firefly_probability = 0.0;    // ... or, when > 0, the probability of each sample
    double firefly_energy = 400.0;       // firefly sample value, x base (x U[0.5, 1.5)) ...
    double firefly_energy_max = 0.0;     // ... or, when > firefly_energy, log-uniform between the two
    bool firefly_relative = false;       // energies are multiples of the pixel's own radiance, as
                                         // added to the mean of `spp` samples (a firefly of 5
                                         // takes one sample's place: a pixel of 1 reads 6 - 1/spp)
    int highlight_count = 60;            // small highlight spots
    double highlight_radiance = 25.0;    // x base
    double highlight_noise = 2.5;        // per-sample relative sd inside a highlight
    double wide_radius = 0.08;           // wide highlight radius, share of min(width, height)
    double nonfinite_pixel_rate = 2e-4;
    int caustic_count = 5;               // caustic blobs and streaks (at most max_caustics)
    double caustic_radiance = 3.0;       // brightness inside a caustic, x the pixel's radiance
    double caustic_pixel_rate = 0.5;     // share of a caustic's core pixels hit, per half
    double bucket_size = 0.125;          // failed (or dropped) bucket side, share of the width
    double bucket_x = 0.55, bucket_y = 0.3;  // its top-left corner, share of width and height
    // Bright region: a capsule around the segment (x0, y0)-(x1, y1) (shares of width, height).
    double region_x0 = 0.15, region_y0 = 0.1, region_x1 = 0.85, region_y1 = 0.1;
    double region_radius = 0.08;         // share of min(width, height)
    double region_radiance = 20.0;       // x base
    double region_noise = 1.2;           // per-sample relative sd inside the region
};

struct frame {
    int width = 0, height = 0;
    // Interleaved RGB float per half: colour (mean of samples), variance of that mean.
    std::vector<float> color[2], variance[2];
    std::vector<float> alpha;            // 1 channel; empty unless alpha_coverage
    std::vector<float> expected;         // RGB: the radiance the estimator converges to
    std::vector<float> firefly_expected; // per pixel: the part of `expected` (every channel)
                                         // that fireflies bring; empty as firefly_energy
    std::vector<float> firefly_energy[2];// per pixel: mean-colour energy fireflies added to the
                                         // half's pixel mean (0: no firefly sample); empty when
                                         // the scene has no fireflies or caustics
    std::vector<std::uint8_t> highlight; // 1: highlight pixel (spot, wide disk, bright region)
    std::vector<std::uint8_t> nonfinite[2];  // bad values (NaN/Inf, a failed or garbage bucket);
                                             // empty unless nonfinite, failed_ or garbage_bucket
    std::vector<std::uint32_t> touched;  // per pixel: the effects that changed it (its footprint
                                         // bits); empty when the scene has no effect
    std::uint32_t effects = 0;
    std::size_t pixels() const noexcept { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
    // Ground truth that reads 0 where an array was not allocated.
    float firefly(int which, std::size_t i) const noexcept {
        return firefly_energy[which].empty() ? 0.0f : firefly_energy[which][i];
    }
    bool bad(int which, std::size_t i) const noexcept { return !nonfinite[which].empty() && nonfinite[which][i]; }
    // Mean expected radiance over the channels without the fireflies' share.
    double expected_without_fireflies(std::size_t i) const noexcept {
        const double e =
            static_cast<double>(expected[i * 3] + expected[i * 3 + 1] + expected[i * 3 + 2]) / 3.0;
        return firefly_expected.empty() ? e : e - static_cast<double>(firefly_expected[i]);
    }
};

// K >= 2 independent buffers of one frame (simulate_buffers). The scene's 2 x spp samples are
// split evenly (the first 2 spp mod K buffers get one more); K = 2 are the two halves,
// bit-identical to simulate(). Ground truth as in `frame`, per buffer where it differs.
struct buffers {
    int width = 0, height = 0;
    std::vector<int> spp;                       // samples in each buffer
    std::vector<std::vector<float>> color, variance;  // per buffer, interleaved RGB
    std::vector<std::vector<float>> firefly_energy;   // per buffer; empty as in frame
    std::vector<std::vector<std::uint8_t>> nonfinite; // per buffer; empty as in frame
    std::vector<float> alpha, expected;
    std::vector<float> firefly_expected;
    std::vector<std::uint8_t> highlight;
    std::vector<std::uint32_t> touched;
    std::uint32_t effects = 0;
    int count() const noexcept { return static_cast<int>(color.size()); }
    std::size_t pixels() const noexcept { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
    float firefly(int b, std::size_t i) const noexcept {
        const std::vector<float>& e = firefly_energy[static_cast<std::size_t>(b)];
        return e.empty() ? 0.0f : e[i];
    }
    bool bad(int b, std::size_t i) const noexcept {
        const std::vector<std::uint8_t>& v = nonfinite[static_cast<std::size_t>(b)];
        return !v.empty() && v[i];
    }
    double expected_without_fireflies(std::size_t i) const noexcept {
        const double e =
            static_cast<double>(expected[i * 3] + expected[i * 3 + 1] + expected[i * 3 + 2]) / 3.0;
        return firefly_expected.empty() ? e : e - static_cast<double>(firefly_expected[i]);
    }
};

}  // namespace firefly::sim
