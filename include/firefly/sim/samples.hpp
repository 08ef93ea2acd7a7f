// firefly/sim: the ordinary (non-firefly) samples of a pixel, reduced to what a renderer keeps.
//
// Samples are X = mu (1 + s g) for `normal`, and X = mu R for `gamma` and `lognormal`, where R
// has mean 1 and relative standard deviation s (gamma: shape 1/s^2; lognormal: sigma^2 =
// log(1 + s^2)). What is drawn is the sample mean of m samples and their sum of squared
// deviations, relative to mu:
//   normal     the mean is normal (exact), the sum of squares chi-square, independent of it
//              (exact below 30 degrees of freedom, above by the Wilson-Hilferty cube, whose
//              quantiles are within 1e-3 of the spread there);
//   gamma,     m <= 64, or whenever the approximation below would be poor: every sample is
//   lognormal  drawn (exact);
//              m > 64: the mean from its own law (gamma: Wilson-Hilferty cube of Gamma(m/s^2);
//              lognormal: Fenton-Wilkinson, a lognormal with the sum's mean and variance), the
//              sample variance from a gamma law with its exact mean and variance (which need
//              the fourth moment), the two tied by a Gaussian copula with their exact asymptotic
//              correlation mu3 / sqrt(sigma^2 (mu4 - sigma^4 (m-3)/(m-1))). Used only when the
//              sample variance's coefficient of variation is below 1/8, where its law is close
//              to a gamma's (quantiles from 1% to 99% within 3% of drawing every sample, tested);
//              heavier tails loop over the samples.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "random.hpp"

namespace firefly::sim {

// Per-sample distribution of the ordinary samples.
enum class distribution : std::uint8_t { normal, gamma, lognormal };

namespace detail {

struct sample_moments {
    double mean = 1.0;  // sample mean / mu
    double m2 = 0.0;    // sum of squared deviations / mu^2
};

inline constexpr std::uint64_t exact_sample_limit = 64;

// Draws R (mean 1, relative sd s) of one law, with the per-law constants computed once.
class relative_sampler {
public:
    relative_sampler(distribution d, double s) noexcept : d_(d) {
        if (d == distribution::gamma) {
            a_ = 1.0 / (s * s);
            const double shape = a_ < 1.0 ? a_ + 1.0 : a_;  // below 1: boosted, U^(1/a)
            md_ = shape - 1.0 / 3.0;
            mc_ = 1.0 / std::sqrt(9.0 * md_);
        } else {
            sl2_ = std::log1p(s * s);
            sl_ = std::sqrt(sl2_);
        }
    }
    double operator()(counter_rng& r) const noexcept {
        if (d_ != distribution::gamma) return std::exp(sl_ * r.normal() - 0.5 * sl2_);
        double g = r.marsaglia_tsang(md_, mc_);
        if (a_ < 1.0) g *= std::pow(r.open_uniform(), 1.0 / a_);
        return g / a_;
    }

private:
    distribution d_;
    double a_ = 1, md_ = 1, mc_ = 1, sl2_ = 0, sl_ = 0;
};

inline sample_moments loop_samples(counter_rng& r, distribution d, double s, std::uint64_t m) noexcept {
    const relative_sampler draw(d, s);
    // Sums about the known mean 1 (no cancellation to speak of, and no division per sample).
    double s1 = 0, s2 = 0;
    for (std::uint64_t j = 0; j < m; ++j) {
        const double d1 = draw(r) - 1.0;
        s1 += d1;
        s2 += d1 * d1;
    }
    const double dm = static_cast<double>(m);
    return {1.0 + s1 / dm, (std::max)(s2 - s1 * s1 / dm, 0.0)};
}

// Central moments of R (mean 1, variance s^2): third, and excess kurtosis.
inline void shape_moments(distribution d, double s, double& mu3, double& kurt) noexcept {
    const double v = s * s;
    if (d == distribution::gamma) {
        mu3 = 2.0 * v * v;  // skewness 2 s
        kurt = 6.0 * v;
        return;
    }
    const double w = 1.0 + v;  // exp(sigma^2)
    mu3 = (w + 2.0) * std::sqrt(v) * v * std::sqrt(v);
    kurt = w * w * w * w + 2.0 * w * w * w + 3.0 * w * w - 6.0;
}

inline sample_moments approx_samples(counter_rng& r, distribution d, double s, std::uint64_t m_count) noexcept {
    const double m = static_cast<double>(m_count), v = s * s;
    double mu3 = 0, kurt = 0;
    shape_moments(d, s, mu3, kurt);
    const double var_s2 = v * v * (kurt / m + 2.0 / (m - 1.0));  // variance of the sample variance
    const double cv2 = var_s2 / (v * v);
    if (!(cv2 <= 1.0 / 64.0)) return loop_samples(r, d, s, m_count);
    double rho = (mu3 / m) / std::sqrt(v / m * var_s2);
    rho = std::fmin(std::fmax(rho, -0.995), 0.995);
    const double z1 = r.normal(), z2 = rho * z1 + std::sqrt(1.0 - rho * rho) * r.normal();
    sample_moments out;
    if (d == distribution::gamma) {
        const double shape = m / v;
        out.mean = counter_rng::wilson_hilferty(shape, z1) / shape;
    } else {
        const double sf2 = std::log1p(v / m);
        out.mean = std::exp(std::sqrt(sf2) * z1 - 0.5 * sf2);
    }
    const double s2 = v * counter_rng::wilson_hilferty(1.0 / cv2, z2) * cv2;
    out.m2 = s2 * (m - 1.0);
    return out;
}

// Constants of the normal law's draw for one sample count (most pixels of a buffer share it).
struct normal_constants {
    std::uint64_t m = 0;
    double inv_sqrt_m = 0, wh_c = 0, wh_sqrt_c = 0;
    explicit normal_constants(std::uint64_t count = 0) noexcept : m(count) {
        if (m == 0) return;
        inv_sqrt_m = 1.0 / std::sqrt(static_cast<double>(m));
        const double half_k = 0.5 * (static_cast<double>(m) - 1.0);  // chi-square(m - 1) = 2 Gamma((m-1)/2)
        wh_c = half_k > 0 ? 1.0 / (9.0 * half_k) : 0.0;
        wh_sqrt_c = std::sqrt(wh_c);
    }
};

// The mean and sum of squared deviations of m ordinary samples, relative to mu. `nc` are the
// normal law's constants when computed for this m (else computed here).
inline sample_moments draw_samples(counter_rng& r, distribution d, double s, std::uint64_t m,
                                   const normal_constants* nc = nullptr) noexcept {
    if (m == 0) return {0.0, 0.0};
    // A spread whose square is not a normal double (below 1e-150, NaN too) is none at float
    // precision; one past 1e150 is held there (the gamma law's shape 1 / s^2 was inf or 0,
    // and every pixel NaN).
    if (!(s >= 1e-150)) s = 0;
    else if (!(s <= 1e150)) s = 1e150;
    if (d == distribution::normal || !(s > 0)) {
        const normal_constants local = nc && nc->m == m ? normal_constants() : normal_constants(m);
        const normal_constants& k = nc && nc->m == m ? *nc : local;
        const double dm = static_cast<double>(m);
        const double gbar = r.normal() * k.inv_sqrt_m;
        double s2 = 0.0;  // chi-square(m - 1) / (m - 1): exact below 30 degrees of freedom, else
        if (m > 1 && m - 1 < 30) {  // the Wilson-Hilferty cube
            s2 = r.chi2_over_k(dm - 1.0);
        } else if (m > 1) {
            const double t = 1.0 - k.wh_c + r.normal() * k.wh_sqrt_c;
            s2 = t > 0 ? t * t * t : 0.0;
        }
        return {1.0 + s * gbar, s * s * s2 * (dm - 1.0)};
    }
    if (m <= exact_sample_limit) return loop_samples(r, d, s, m);
    return approx_samples(r, d, s, m);
}

}  // namespace detail
}  // namespace firefly::sim
