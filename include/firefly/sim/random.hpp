// firefly/sim: counter-based random numbers for the simulator.
//
// Every draw is a hash of (seed, stream, pixel, buffer, draw index): a stream is keyed by what
// it is for, so an effect that is switched on or off draws from its own stream and never moves
// another effect's numbers. No state is shared between pixels, so the order in which pixels
// are visited (or how many threads visit them) cannot change a value. The hash is the
// splitmix64 finaliser, the same bits on every compiler and standard library.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "../floating_point.hpp"

namespace firefly::sim::detail {

inline constexpr std::uint64_t golden = 0x9E3779B97F4A7C15ull;

inline std::uint64_t mix64(std::uint64_t z) noexcept {  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

// Stream ids beyond the effect bits (which are ids themselves).
enum stream_id : std::uint64_t {
    base_noise = 0,              // the ordinary samples of a pixel
    negative_variance_stream = 1ull << 40,
    negative_pixels = 2ull << 40,
    layout_stream = 3ull << 40,  // where spots and regions are (per effect, pixel 0)
};

class counter_rng {
public:
    counter_rng(std::uint64_t seed, std::uint64_t stream, std::uint64_t pixel, std::uint64_t buffer) noexcept
        : key_(mix64(mix64(mix64(seed + golden) ^ (stream + 0x632BE59BD9B4E019ull)) ^ (pixel * golden + buffer))) {}

    std::uint64_t next() noexcept { return mix64(key_ + (++count_) * golden); }
    double uniform() noexcept { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
    double open_uniform() noexcept { return (static_cast<double>(next() >> 11) + 0.5) * 0x1.0p-53; }  // (0, 1)
    // Standard normal, exact: the ziggurat (Marsaglia and Tsang 2000; 256 layers, Doornik's
    // layout), one draw for ~99% of numbers; the tail beyond 3.65 by Marsaglia's method.
    double normal() noexcept {
        const ziggurat& z = ziggurat::get();
        for (;;) {
            const std::uint64_t bits = next();
            const unsigned i = static_cast<unsigned>(bits & 0xff);
            const double u = static_cast<double>(bits >> 12) * 0x1.0p-51 - 1.0;  // [-1, 1)
            const double x = u * z.x[i];
            if (std::fabs(x) < z.x[i + 1]) return x;
            if (i == 0) return tail(u < 0);
            if (z.f[i + 1] + (z.f[i] - z.f[i + 1]) * uniform() < std::exp(-0.5 * x * x)) return x;
        }
    }
    // Gamma(shape, 1), exact: Marsaglia and Tsang (2000); shape < 1 by the U^(1/shape) boost.
    double gamma(double shape) noexcept {
        if (!(shape > 0)) return 0.0;
        if (shape < 1.0) return gamma(shape + 1.0) * std::pow(open_uniform(), 1.0 / shape);
        const double d = shape - 1.0 / 3.0;
        return marsaglia_tsang(d, 1.0 / std::sqrt(9.0 * d));
    }
    // Marsaglia-Tsang's loop for shape >= 1, with d = shape - 1/3 and c = 1 / sqrt(9 d).
    double marsaglia_tsang(double d, double c) noexcept {
        for (;;) {
            double x, v;
            do {
                x = normal();
                v = 1.0 + c * x;
            } while (v <= 0.0);
            v = v * v * v;
            const double u = open_uniform(), x2 = x * x;
            if (u < 1.0 - 0.0331 * x2 * x2) return d * v;
            if (std::log(u) < 0.5 * x2 + d * (1.0 - v + std::log(v))) return d * v;
        }
    }
    // Chi-square with k degrees of freedom, divided by k: exact below k = 30, above by the
    // Wilson-Hilferty cube (quantile error < 1e-3 of the spread there).
    double chi2_over_k(double k) noexcept {
        if (k < 30.0) return 2.0 * gamma(0.5 * k) / k;
        return wilson_hilferty(0.5 * k, normal()) / (0.5 * k);
    }
    // Failures before the next success of a Bernoulli(p) process.
    std::uint64_t geometric(double p) noexcept {
        if (p >= 1.0) return 0;
        if (p <= 0.0) return (std::numeric_limits<std::uint64_t>::max)();
        const double g = std::floor(std::log(open_uniform()) / std::log1p(-p));
        return g >= 1.8e19 ? (std::numeric_limits<std::uint64_t>::max)() : static_cast<std::uint64_t>(g);
    }
    // Gamma(shape, 1) quantile at normal score z, Wilson-Hilferty (accurate for shape >= ~10).
    static double wilson_hilferty(double shape, double z) noexcept {
        const double c = 1.0 / (9.0 * shape);
        const double t = 1.0 - c + z * std::sqrt(c);
        return t > 0 ? shape * t * t * t : 0.0;
    }

private:
    struct ziggurat {
        static constexpr double r = 3.6541528853610088;  // start of the tail
        double x[257], f[257];                          // layer edges and exp(-x^2 / 2) there
        ziggurat() noexcept {
            const double v = 0.00492867323399;  // area of each layer
            x[0] = v / std::exp(-0.5 * r * r);
            x[1] = r;
            for (int i = 2; i < 256; ++i)
                x[i] = std::sqrt(-2.0 * std::log(std::fmin(v / x[i - 1] + std::exp(-0.5 * x[i - 1] * x[i - 1]), 1.0)));
            x[256] = 0.0;
            for (int i = 0; i < 257; ++i) f[i] = std::exp(-0.5 * x[i] * x[i]);
        }
        static const ziggurat& get() noexcept {
            static const ziggurat z;
            return z;
        }
    };
    double tail(bool negative_side) noexcept {
        for (;;) {
            const double x = std::log(open_uniform()) / ziggurat::r, y = std::log(open_uniform());
            if (-2.0 * y >= x * x) return negative_side ? x - ziggurat::r : ziggurat::r - x;
        }
    }

    std::uint64_t key_;
    std::uint64_t count_ = 0;
};

}  // namespace firefly::sim::detail
