// firefly: upper-tail quantiles of the normal and Student-t distributions.
//
// Both take the SMALL upper-tail probability q = P(X > x) itself and never form 1 - q:
// the generalized ESD test asks for q = alpha / n, which is 1e-8 at film resolution and
// far smaller in tests, and 1 - q would round those away.
//
//   normal_upper_quantile(q)        Wichura's AS241 (relative error ~1e-16), q down to 1e-308.
//   student_t_upper_quantile(q, df) df real >= 1 (up to 1e10 and beyond):
//       df == 1, df == 2       closed forms;
//       max(z^2, 1)/df < 1e-3  Cornish-Fisher expansion about the normal quantile z to 1/df^4
//                              (the next term is below 1e-17 relative there);
//       otherwise              Hill (1970) start, then Newton steps on log P(T > t) (tail)
//                              or on 1/2 - P(T > t) (centre), with P from a continued
//                              fraction of the regularized incomplete beta, evaluated on
//                              whichever side is small.
// Out of domain (q not in (0, 1), NaN, df < 1 or NaN): NaN. q in (1/2, 1) gives -t(1 - q).
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

#include "floating_point.hpp"

namespace firefly {

namespace detail {

inline constexpr double pi = 3.14159265358979323846;

template <std::size_t N>
constexpr double horner(const double (&c)[N], double x) noexcept {
    double r = c[N - 1];
    for (int i = static_cast<int>(N) - 2; i >= 0; --i) r = r * x + c[i];
    return r;
}

// log B(a, 1/2) accurate in the ABSOLUTE sense for a up to 1e10 and beyond: lgamma(a) -
// lgamma(a + 1/2) cancels catastrophically for large a, so that difference comes from
// Stirling's series written for the difference itself.
template <class Real>
Real log_beta_half(Real a) noexcept {
    const Real rpi = static_cast<Real>(3.141592653589793238462643383279502884L);
    if (a < 30) return std::log(std::tgamma(a) * std::sqrt(rpi) / std::tgamma(a + Real(0.5)));
    // ln G(a+1/2) - ln G(a) = [a log1p(h) - 1/2] + 1/2 ln a + delta(a+1/2) - delta(a), h = 1/(2a)
    const Real h = Real(0.5) / a;
    // a log1p(h) - 1/2 = sum_{k>=2} (-1)^(k+1) h^(k-1) / (2k)
    Real s = 0, hp = h, sign = -1;
    for (int k = 2; k <= 14; ++k) {
        s += sign * hp / Real(2 * k);
        hp *= h;
        sign = -sign;
    }
    auto delta = [](Real x) {  // Stirling remainder of ln Gamma(x), x >= 30
        const Real r = 1 / x, r2 = r * r;
        return r * (Real(1) / 12 -
                    r2 * (Real(1) / 360 -
                          r2 * (Real(1) / 1260 -
                                r2 * (Real(1) / 1680 - r2 * (Real(1) / 1188 - r2 * Real(691) / 360360)))));
    };
    const Real diff = s + Real(0.5) * std::log(a) + (delta(a + Real(0.5)) - delta(a));
    return Real(0.5) * std::log(rpi) - diff;
}

// Continued fraction of I_x(a, b) (modified Lentz). I_x(a,b) = front * cf / a with
// front = x^a (1-x)^b / B(a,b). Converges fast for x < (a+1)/(a+b+2).
template <class Real>
Real incbeta_cf(Real a, Real b, Real x) noexcept {
    const Real tiny = Real(1e-300);
    const Real eps = std::numeric_limits<Real>::epsilon();
    const Real qab = a + b, qap = a + 1, qam = a - 1;
    Real c = 1;
    Real d = 1 - qab * x / qap;
    if (std::fabs(d) < tiny) d = tiny;
    d = Real(1.0) / d;
    Real h = d;
    for (int m = 1; m <= 200000; ++m) {
        const Real m2 = Real(2 * m);
        Real aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = Real(1.0) + aa * d;
        if (std::fabs(d) < tiny) d = tiny;
        c = Real(1.0) + aa / c;
        if (std::fabs(c) < tiny) c = tiny;
        d = Real(1.0) / d;
        h *= d * c;
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = Real(1.0) + aa * d;
        if (std::fabs(d) < tiny) d = tiny;
        c = Real(1.0) + aa / c;
        if (std::fabs(c) < tiny) c = tiny;
        d = Real(1.0) / d;
        const Real del = d * c;
        h *= del;
        if (std::fabs(del - Real(1.0)) <= eps) break;
    }
    return h;
}

// Student-t upper tail at t >= 0 in the two forms Newton needs.
template <class Real>
struct t_tail {
    Real log_p;    // log P(T > t)
    Real centre;   // 1/2 - P(T > t)  (accurate when small)
    Real log_pdf;  // log density at t
};

template <class Real>
t_tail<Real> student_t_tail(Real t, Real df) noexcept {
    const Real a = df / 2;
    const Real r = t / std::sqrt(df);
    // L1 = log(1 + r^2), log x = -L1, log y = log(r^2 / (1 + r^2)); no overflow for huge r.
    Real L1, log_y, x, y;
    if (r > Real(1e150)) {
        L1 = Real(2.0) * std::log(r);
        log_y = Real(0.0);
        x = Real(0.0);
        y = Real(1.0);
    } else {
        const Real r2 = r * r;
        L1 = std::log1p(r2);
        x = Real(1.0) / (Real(1.0) + r2);
        if (r >= Real(1.0)) {
            y = Real(1.0) / (Real(1.0) + Real(1.0) / r2);
            log_y = -std::log1p(Real(1.0) / r2);
        } else {
            y = r2 / (Real(1.0) + r2);
            log_y = r2 > 0 ? std::log(r2) - L1 : -std::numeric_limits<Real>::infinity();
        }
    }
    const Real lb = log_beta_half(a);
    const Real one_half = Real(0.5);
    t_tail<Real> out;
    out.log_pdf = -(a + one_half) * L1 - one_half * std::log(df) - lb;
    const Real log_front = -a * L1 + one_half * log_y - lb;  // log(x^a y^(1/2) / B)
    if (x < (a + 1) / (a + Real(2.5))) {
        // P = 1/2 I_x(a, 1/2): the small side when t is large.
        const Real h = incbeta_cf(a, one_half, x);
        out.log_p = log_front + std::log(h / a) - std::log(Real(2));
        out.centre = one_half - std::exp(out.log_p);
    } else {
        // 1/2 - P = 1/2 I_y(1/2, a): the small side when t is near 0.
        const Real j = y > 0 ? std::exp(log_front) * incbeta_cf(one_half, a, y) / one_half : Real(0);
        out.centre = one_half * j;
        out.log_p = std::log(one_half) + std::log1p(-j);
    }
    return out;
}

// Hill (1970), ACM Algorithm 396, as a starting value: relative error ~1e-6..1e-3.
inline double hill_start(double q, double df, double z) noexcept {
    const double a = 1.0 / (df - 0.5);
    const double b = 48.0 / (a * a);
    double c = ((20700.0 * a / b - 98.0) * a - 16.0) * a + 96.36;
    const double d = ((94.5 / (b + c) - 3.0) / b + 1.0) * std::sqrt(a * pi / 2.0) * df;
    const double log_p2 = std::log(2.0 * q);
    const double xl = (std::log(d) + log_p2) / df;  // log of (d P)^(1/df)
    double y = std::exp(2.0 * xl);
    if ((df < 2.1 && q > 0.25) || y > 0.05 + a) {
        const double x = -z;  // Hill's x is the lower-tail normal quantile
        double yy = x * x;
        if (df < 5) c += 0.3 * (df - 4.5) * (x + 0.6);
        c = (((0.05 * d * x - 5.0) * x - 7.0) * x - 2.0) * x + b + c;
        yy = (((((0.4 * yy + 6.3) * yy + 36.0) * yy + 94.5) / c - yy - 3.0) / b + 1.0) * x;
        yy = std::expm1(a * yy * yy);
        return std::sqrt(df * yy);
    }
    if (y < std::numeric_limits<double>::epsilon()) return std::sqrt(df) * std::exp(-xl);
    y = ((1.0 / (((df + 6.0) / (df * y) - 0.089 * d - 0.822) * (df + 2.0) * 3.0) + 0.5 / (df + 4.0)) *
             y - 1.0) * (df + 1.0) / (df + 2.0) + 1.0 / y;
    return std::sqrt(df * y);
}

// Cornish-Fisher: t = z + g1/df + g2/df^2 + g3/df^3 + g4/df^4 (Abramowitz-Stegun 26.7.5).
inline double cornish_fisher_t(double z, double df) noexcept {
    const double z2 = z * z;
    const double g1 = (z2 + 1.0) * z / 4.0;
    const double g2 = ((5.0 * z2 + 16.0) * z2 + 3.0) * z / 96.0;
    const double g3 = (((3.0 * z2 + 19.0) * z2 + 17.0) * z2 - 15.0) * z / 384.0;
    const double g4 = ((((79.0 * z2 + 776.0) * z2 + 1482.0) * z2 - 1920.0) * z2 - 945.0) * z / 92160.0;
    const double v = 1.0 / df;
    return z + v * (g1 + v * (g2 + v * (g3 + v * g4)));
}

// The general method (Hill start + Newton on the incomplete beta), any df >= 1, q in (0, 1/2).
// Real = long double gives the tests an independent, more precise oracle.
template <class Real>
Real student_t_upper_quantile_refined(Real q, Real df, double z) noexcept;

}  // namespace detail

// x with P(Z > x) = q for a standard normal Z. Wichura (1988), AS241 PPND16.
inline double normal_upper_quantile(double q) noexcept {
    if (!(q > 0.0 && q < 1.0)) return std::numeric_limits<double>::quiet_NaN();
    static constexpr double a[8] = {3.3871328727963666080e0, 1.3314166789178437745e+2,
                                    1.9715909503065514427e+3, 1.3731693765509461125e+4,
                                    4.5921953931549871457e+4, 6.7265770927008700853e+4,
                                    3.3430575583588128105e+4, 2.5090809287301226727e+3};
    static constexpr double b[8] = {1.0, 4.2313330701600911252e+1, 6.8718700749205790830e+2,
                                    5.3941960214247511077e+3, 2.1213794301586595867e+4,
                                    3.9307895800092710610e+4, 2.8729085735721942674e+4,
                                    5.2264952788528545610e+3};
    static constexpr double c[8] = {1.42343711074968357734e0, 4.63033784615654529590e0,
                                    5.76949722146069140550e0, 3.64784832476320460504e0,
                                    1.27045825245236838258e0, 2.41780725177450611770e-1,
                                    2.27238449892691845833e-2, 7.74545014278341407640e-4};
    static constexpr double d[8] = {1.0, 2.05319162663775882187e0, 1.67638483018380384940e0,
                                    6.89767334985100004550e-1, 1.48103976427480074590e-1,
                                    1.51986665636164571966e-2, 5.47593808499534494600e-4,
                                    1.05075007164441684324e-9};
    static constexpr double e[8] = {6.65790464350110377720e0, 5.46378491116411436990e0,
                                    1.78482653991729133580e0, 2.96560571828504891230e-1,
                                    2.65321895265761230930e-2, 1.24266094738807843860e-3,
                                    2.71155556874348757815e-5, 2.01033439929228813265e-7};
    static constexpr double f[8] = {1.0, 5.99832206555887937690e-1, 1.36929880922735805310e-1,
                                    1.48753612908506148525e-2, 7.86869131145613259100e-4,
                                    1.84631831751005468180e-5, 1.42151175831644588870e-7,
                                    2.04426310338993978564e-15};
    using detail::horner;
    // Work with the lower-tail p = 1 - q only through u = q - 1/2 (exact near the centre).
    const double u = 0.5 - q;  // = p - 1/2
    if (std::fabs(u) <= 0.425) {
        const double r = 0.180625 - u * u;
        return u * horner(a, r) / horner(b, r);
    }
    const double tail = u > 0 ? q : 1.0 - q;  // the small one; 1 - q exact for q > 1/2
    double r = std::sqrt(-std::log(tail));
    double x;
    if (r <= 5.0) {
        r -= 1.6;
        x = horner(c, r) / horner(d, r);
    } else {
        r -= 5.0;
        x = horner(e, r) / horner(f, r);
    }
    return u > 0 ? x : -x;
}

// t with P(T > t) = q for Student's t with df degrees of freedom (df real, >= 1).
inline double student_t_upper_quantile(double q, double df) noexcept {
    if (!(q > 0.0 && q < 1.0) || !(df >= 1.0)) return std::numeric_limits<double>::quiet_NaN();
    if (q > 0.5) return -student_t_upper_quantile(1.0 - q, df);  // 1 - q exact here
    if (q == 0.5) return 0.0;
    if (df == 1.0) {  // Cauchy: t = cot(pi q)
        if (q < 1e-150) return (1.0 / detail::pi) / q;
        return q <= 0.25 ? 1.0 / std::tan(detail::pi * q) : std::tan(detail::pi * (0.5 - q));
    }
    if (df == 2.0) return (1.0 - 2.0 * q) / std::sqrt(2.0 * q * (1.0 - q));
    const double z = normal_upper_quantile(q);
    if (std::isinf(df)) return z;
    const double z2 = z * z;
    if ((z2 > 1.0 ? z2 : 1.0) < 1e-3 * df) return detail::cornish_fisher_t(z, df);
    return detail::student_t_upper_quantile_refined<double>(q, df, z);
}

template <class Real>
Real detail::student_t_upper_quantile_refined(Real q, Real df, double z) noexcept {
    Real t = static_cast<Real>(hill_start(static_cast<double>(q), static_cast<double>(df), z));
    if (!(t > 0) || std::isinf(t)) t = z > 0 ? Real(z) : Real(1);
    const bool tail_mode = q < Real(0.25);
    const Real log_q = std::log(q);
    const Real g = Real(0.5) - q;  // exact (Sterbenz) for q >= 1/4
    const Real eps = std::numeric_limits<Real>::epsilon();
    Real lo = 0, hi = std::numeric_limits<Real>::infinity();
    for (int it = 0; it < 200; ++it) {
        const t_tail<Real> s = student_t_tail(t, df);
        Real step;
        if (tail_mode) {
            const Real f = s.log_p - log_q;  // decreasing in t
            if (f > 0) lo = t; else hi = t;
            step = f * std::exp(s.log_p - s.log_pdf);
        } else {
            const Real f = s.centre - g;  // increasing in t
            if (f < 0) lo = t; else hi = t;
            step = -f * std::exp(-s.log_pdf);
        }
        Real next = t + step;
        if (!(next > lo && next < hi)) {  // Newton left the bracket: bisect (geometrically when wide)
            next = std::isinf(hi) ? 2 * t + 1
                   : (lo > 0 && hi > 4 * lo) ? std::sqrt(lo * hi) : (lo + hi) / 2;
        }
        const Real change = std::fabs(next - t);
        t = next;
        if (change <= 2 * eps * t) break;
        if (hi - lo <= 2 * eps * t) break;
    }
    return t;
}

}  // namespace firefly
