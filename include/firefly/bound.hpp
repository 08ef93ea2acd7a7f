// firefly: the upper bound on the number of outliers, from the modified Z-score
// (Iglewicz and Hoaglin 1993):  M_i = 0.6745 (x_i - median) / MAD,  bound = #{ M_i > threshold }.
// One-sided: only values above the median count (fireflies are bright).
//
// MAD = 0 happens when more than half of the values are equal (flat areas rendered with
// few samples). Then the scale falls back to 1.253314 x the mean absolute deviation about
// the median (M_i = (x_i - median) / (1.253314 MeanAD), the usual fallback), and when that is
// 0 as well every value equals the median and the bound is 0.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

#include "statistics.hpp"

namespace firefly {

struct bound_result {
    std::size_t count = 0;     // values with M > threshold: the bound
    std::size_t n = 0;         // values that took part (finite ones)
    double median = 0.0;
    double mad = 0.0;          // median absolute deviation about the median (unscaled)
    double scale = 0.0;        // what divides (x - median): MAD / 0.6745, or the fallback
    double cutoff = 0.0;       // values strictly above this are counted (+inf when none can be)
    double threshold = 3.5;
    bool mad_fallback = false; // MAD was 0 and the mean absolute deviation was used

    // M(x) > threshold, decided by the ratio itself (no rounded cutoff can disagree with it).
    bool above(double x) const noexcept {
        return scale > 0 && (x - median) / scale > threshold;
    }
};

inline constexpr double modified_zscore_constant = 0.6745;
inline constexpr double mean_ad_constant = 1.253314;

// Sets r.scale from r.mad, or from the mean absolute deviation about the median when the MAD
// is 0 (mean_ad() computes it only then). A scale of 0 means every value is the median.
template <class MeanAbsDev>
void set_bound_scale(bound_result& r, MeanAbsDev&& mean_ad) {
    if (r.mad > 0) {
        r.scale = r.mad / modified_zscore_constant;
    } else {
        r.mad_fallback = true;
        r.scale = mean_ad_constant * mean_ad();
    }
}

// Generic form: the kept value(i), i in [0, n). Non-finite values never take part.
template <class Value, class Keep>
bound_result modified_zscore_bound_if(std::size_t n, Value&& value, Keep&& keep, double threshold,
                                      std::vector<double>& scratch) {
    bound_result r;
    r.cutoff = HUGE_VAL;
    auto kept = [&](std::size_t i) {
        return keep(i) && std::isfinite(static_cast<double>(value(i)));
    };
    std::size_t count = 0;
    for (std::size_t i = 0; i < n; ++i) count += kept(i) ? 1u : 0u;
    r.n = count;
    if (count == 0 || !(threshold >= 0)) return r;
    r.threshold = threshold;
    (void)median_of(
        n, [&](std::size_t i) { return static_cast<double>(value(i)); }, kept, count, r.median,
        scratch);
    const double med = r.median;
    auto dev = [&](std::size_t i) { return std::fabs(static_cast<double>(value(i)) - med); };
    (void)median_of(n, dev, kept, count, r.mad, scratch);
    set_bound_scale(r, [&] {
        return detail::blocked_sum(n, [&](std::size_t i) { return kept(i) ? dev(i) : 0.0; }) /
               static_cast<double>(count);
    });
    if (!(r.scale > 0)) return r;  // every value equals the median: nothing stands out
    r.cutoff = med + threshold * r.scale;
    for (std::size_t i = 0; i < n; ++i)
        if (kept(i) && r.above(static_cast<double>(value(i)))) ++r.count;
    return r;
}

// The bound over n values (float or double). threshold defaults to Iglewicz-Hoaglin's 3.5.
template <class T>
bound_result modified_zscore_bound(const T* values, std::size_t n, double threshold = 3.5) {
    std::vector<double> scratch;
    return modified_zscore_bound_if(
        n, [&](std::size_t i) { return values[i]; }, [](std::size_t) { return true; }, threshold,
        scratch);
}

}  // namespace firefly
