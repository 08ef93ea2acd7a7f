// firefly: the statistics the detector rests on, written so they stay exact when a few
// values dwarf the rest (a 1e30 firefly among pixels of 1e-3):
//
//   summary_of        count, mean and M2 = sum (x - mean)^2 by two passes over fixed-size
//                     blocks (error ~ (block + n/block) eps instead of n eps; the block
//                     partition never depends on threads, so results are bit-reproducible)
//   running_summary   Welford updates. add() is stable for any value; the detector only ever
//                     ADDS values back (the largest last) and never subtracts one out.
//   select_pair       exact k-th and (k+1)-th smallest of n non-negative keys by a 4096-bucket
//                     histogram on the float bits, then nth_element inside one bucket:
//                     two light passes instead of a full nth_element over a copy.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace firefly {

// Count, mean and sum of squared deviations of a set of values.
struct summary {
    std::size_t count = 0;
    double mean = 0.0;
    double m2 = 0.0;  // sum (x - mean)^2

    // Sample variance (n - 1 denominator); 0 for fewer than two values.
    double variance() const noexcept { return count > 1 ? m2 / static_cast<double>(count - 1) : 0.0; }
    double stddev() const noexcept { return std::sqrt(variance()); }
};

// Welford's running mean and M2. add() is exact to rounding for any order of magnitude.
class running_summary {
public:
    running_summary() = default;
    explicit running_summary(const summary& s) noexcept : s_(s) {}

    void add(double x) noexcept {
        ++s_.count;
        const double delta = x - s_.mean;
        s_.mean += delta / static_cast<double>(s_.count);
        s_.m2 += delta * (x - s_.mean);
    }
    // Removing a value cancels catastrophically when it dominates the set; prefer building
    // the small set first and adding the large values back. Kept for completeness.
    void remove(double x) noexcept {
        if (s_.count <= 1) {
            s_ = summary{};
            return;
        }
        const double delta = x - s_.mean;
        --s_.count;
        s_.mean -= delta / static_cast<double>(s_.count);
        s_.m2 -= delta * (x - s_.mean);
        if (s_.m2 < 0) s_.m2 = 0;
    }
    const summary& get() const noexcept { return s_; }

private:
    summary s_{};
};

namespace detail {

inline constexpr std::size_t block_size = 1024;

// Sum of f(i) for i in [0, n) in fixed blocks.
template <class F>
double blocked_sum(std::size_t n, F&& f) {
    double total = 0.0;
    for (std::size_t b = 0; b < n; b += block_size) {
        const std::size_t e = std::min(n, b + block_size);
        double s = 0.0;
        for (std::size_t i = b; i < e; ++i) s += f(i);
        total += s;
    }
    return total;
}

}  // namespace detail

// Summary of value(i) over the i in [0, n) with keep(i) true, by two blocked passes.
template <class Value, class Keep>
summary summary_of(std::size_t n, Value&& value, Keep&& keep) {
    summary s;
    std::size_t count = 0;
    const double sum = detail::blocked_sum(n, [&](std::size_t i) {
        if (!keep(i)) return 0.0;
        ++count;
        return static_cast<double>(value(i));
    });
    if (count == 0) return s;
    s.count = count;
    const double mean0 = sum / static_cast<double>(count);
    double c = 0.0;  // sum of deviations: corrects the mean's rounding (the "corrected two-pass")
    const double m2 = detail::blocked_sum(n, [&](std::size_t i) {
        if (!keep(i)) return 0.0;
        const double d = static_cast<double>(value(i)) - mean0;
        c += d;
        return d * d;
    });
    s.mean = mean0 + c / static_cast<double>(count);
    s.m2 = std::max(0.0, m2 - c * c / static_cast<double>(count));
    return s;
}

template <class T>
summary summary_of(const T* values, std::size_t n) {
    return summary_of(
        n, [&](std::size_t i) { return values[i]; }, [](std::size_t) { return true; });
}

// ---------------------------------------------------------------------------------------
namespace detail {

// Monotone 12-bit bucket of a finite key: the float's sign, exponent and 3 mantissa bits,
// mapped so that unsigned order is numeric order.
inline std::uint32_t key_bucket(double key) noexcept {
    const float f = static_cast<float>(key);  // rounding to float is monotone
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    bits = (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
    return bits >> 20;
}

}  // namespace detail

// The k-th and (k+1)-th smallest (0-based; the second equals the first when k + 1 == n)
// among the finite key(i) for the i in [0, n) with keep(i). `scratch` is reused between calls.
// Returns false when fewer than k + 1 values are kept.
template <class Key, class Keep>
bool select_pair(std::size_t n, Key&& key, Keep&& keep, std::size_t k, double& kth,
                 double& next, std::vector<double>& scratch) {
    constexpr std::size_t buckets = 4096;
    std::vector<std::uint32_t> hist(buckets, 0);
    std::size_t total = 0;
    for (std::size_t i = 0; i < n; ++i)
        if (keep(i)) {
            ++hist[detail::key_bucket(key(i))];
            ++total;
        }
    if (k >= total) return false;
    const std::size_t k2 = std::min(k + 1, total - 1);
    // Buckets holding ranks k and k2, and how many values lie below the first.
    std::size_t below = 0, b1 = 0;
    while (below + hist[b1] <= k) below += hist[b1++];
    std::size_t b2 = b1, upto = below + hist[b1];
    while (upto <= k2) upto += hist[++b2];
    scratch.clear();
    for (std::size_t i = 0; i < n; ++i)
        if (keep(i)) {
            const double v = key(i);
            const std::uint32_t b = detail::key_bucket(v);
            if (b >= b1 && b <= b2) scratch.push_back(v);
        }
    auto first = scratch.begin() + static_cast<std::ptrdiff_t>(k - below);
    std::nth_element(scratch.begin(), first, scratch.end());
    kth = *first;
    next = (k2 == k) ? kth : *std::min_element(first + 1, scratch.end());
    return true;
}

// Exact median of the kept key(i) (mean of the two middle values for an even count).
template <class Key, class Keep>
bool median_of(std::size_t n, Key&& key, Keep&& keep, std::size_t count, double& median,
               std::vector<double>& scratch) {
    if (count == 0) return false;
    double a, b;
    if (!select_pair(n, key, keep, (count - 1) / 2, a, b, scratch)) return false;
    median = (count % 2 == 1) ? a : 0.5 * a + 0.5 * b;
    return true;
}

}  // namespace firefly
