// firefly: the statistics the detector rests on, written so they stay exact when a few
// values dwarf the rest (a 1e30 firefly among pixels of 1e-3):
//
//   summary_of        count, mean and M2 = sum (x - mean)^2 by two passes over fixed-size
//                     blocks (error ~ (block + n/block) eps instead of n eps; the block
//                     partition never depends on threads, so results are bit-reproducible)
//   running_summary   Welford updates. add() is stable for any value; the detector only ever
//                     ADDS values back (the largest last): removing a dominant value from
//                     running sums cancels catastrophically, so there is no remove().
//   select_pair       exact k-th and (k+1)-th smallest of n keys by a 4096-bucket histogram
//                     on the float bits, then nth_element inside one bucket: two light
//                     passes instead of a full nth_element over a copy.
//   sd_histogram      the detector's fast path over an array of standard deviations (valid
//                     values >= 0; others negative or NaN): a 65536-bucket histogram built
//                     while the values are written, then the exact median in one more pass
//                     and the exact MAD in one more (bracketed from the same histogram).
//   sort_by_high_word 64-bit keys ordered by their high 32 bits, stably (an LSD radix sort of
//                     11 bits a pass, as many passes as the largest key needs): the detector's
//                     lists of pixels put in row order, with the entry's index below.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#endif

#include "floating_point.hpp"
#include "scratch.hpp"

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
    const summary& get() const noexcept { return s_; }

private:
    summary s_{};
};

namespace detail {

inline constexpr std::size_t block_size = 1024;

// Over the v[i] in [0, cut): count, sum of (v - shift) and of (v - shift)^2, in double, in
// fixed blocks (so the result never depends on threads). SSE2 keeps four independent sums
// per block; the scalar fallback two.
// The indices i with v[i] >= cut (a few percent at most) are appended to `above` in the
// same pass, in increasing order.
inline void shifted_sums_below(const float* v, std::size_t n, float cut, double shift, double& s1, double& s2,
                               std::size_t& count, std::vector<std::uint32_t>& above) {
    s1 = s2 = 0.0;
    count = 0;
    above.clear();
    for (std::size_t blk = 0; blk < n; blk += block_size) {
        const std::size_t e = (std::min)(n, blk + block_size);
        std::size_t i = blk;
        double b1 = 0, b2 = 0;
#if defined(__SSE2__) || defined(_M_X64)
        __m128d a1 = _mm_setzero_pd(), a2 = _mm_setzero_pd(), c1 = _mm_setzero_pd(), c2 = _mm_setzero_pd();
        const __m128 zero = _mm_setzero_ps(), vc = _mm_set1_ps(cut);
        const __m128d sh = _mm_set1_pd(shift);
        for (; i + 4 <= e; i += 4) {
            const __m128 x = _mm_loadu_ps(v + i);
            const __m128 in = _mm_and_ps(_mm_cmpge_ps(x, zero), _mm_cmplt_ps(x, vc));
            int hi_mask = _mm_movemask_ps(_mm_cmpge_ps(x, vc));
            while (hi_mask) {
                const int k = hi_mask & -hi_mask;
                above.push_back(static_cast<std::uint32_t>(i + (k == 1 ? 0u : k == 2 ? 1u : k == 4 ? 2u : 3u)));
                hi_mask ^= k;
            }
            const int m = _mm_movemask_ps(in);
            count += static_cast<std::size_t>((m & 1) + ((m >> 1) & 1) + ((m >> 2) & 1) + ((m >> 3) & 1));
            const __m128i mi = _mm_castps_si128(in);
            const __m128d mlo = _mm_castsi128_pd(_mm_unpacklo_epi32(mi, mi));
            const __m128d mhi = _mm_castsi128_pd(_mm_unpackhi_epi32(mi, mi));
            const __m128d dlo = _mm_and_pd(_mm_sub_pd(_mm_cvtps_pd(x), sh), mlo);
            const __m128d dhi = _mm_and_pd(_mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(x, x)), sh), mhi);
            a1 = _mm_add_pd(a1, dlo);
            c1 = _mm_add_pd(c1, dhi);
            a2 = _mm_add_pd(a2, _mm_mul_pd(dlo, dlo));
            c2 = _mm_add_pd(c2, _mm_mul_pd(dhi, dhi));
        }
        double t[2];
        _mm_storeu_pd(t, _mm_add_pd(a1, c1));
        b1 = t[0] + t[1];
        _mm_storeu_pd(t, _mm_add_pd(a2, c2));
        b2 = t[0] + t[1];
#endif
        for (; i < e; ++i) {
            const float x = v[i];
            if (x >= cut) {
                above.push_back(static_cast<std::uint32_t>(i));
            } else if (x >= 0.0f) {
                const double d = static_cast<double>(x) - shift;
                b1 += d;
                b2 += d * d;
                ++count;
            }
        }
        s1 += b1;
        s2 += b2;
    }
}

// Counts the v[i] in [in_lo, in_hi] and appends to out the v[i] in [lo, hi] outside it
// (NaN and negatives never match when lo >= 0). Returns how many were appended; out needs room
// for all of them. The matches are a few percent of the values: SSE2 tests four at a time and
// branches only when one of them matches.
inline std::size_t count_and_collect(const float* v, std::size_t n, float in_lo, float in_hi, float lo, float hi,
                                     float* out, std::size_t& inner) noexcept {
    std::size_t i = 0, j = 0, below = 0;
#if defined(__SSE2__) || defined(_M_X64)
    const __m128 vil = _mm_set1_ps(in_lo), vih = _mm_set1_ps(in_hi), vl = _mm_set1_ps(lo), vh = _mm_set1_ps(hi);
    for (; i + 4 <= n; i += 4) {
        const __m128 x = _mm_loadu_ps(v + i);
        const __m128 in = _mm_and_ps(_mm_cmpge_ps(x, vil), _mm_cmple_ps(x, vih));
        const __m128 band = _mm_andnot_ps(in, _mm_and_ps(_mm_cmpge_ps(x, vl), _mm_cmple_ps(x, vh)));
        const int im = _mm_movemask_ps(in);
        below += static_cast<std::size_t>((im & 1) + ((im >> 1) & 1) + ((im >> 2) & 1) + ((im >> 3) & 1));
        int bm = _mm_movemask_ps(band);
        while (bm) {
            const int k = bm & -bm;
            const int lane = k == 1 ? 0 : k == 2 ? 1 : k == 4 ? 2 : 3;
            out[j++] = v[i + static_cast<std::size_t>(lane)];
            bm ^= k;
        }
    }
#endif
    for (; i < n; ++i) {
        const float x = v[i];
        const bool in = (x >= in_lo) & (x <= in_hi);
        below += in;
        if (!in && x >= lo && x <= hi) out[j++] = x;
    }
    inner = below;
    return j;
}

// w (p + q) for w a power of two below 1: one rounding where the sum is finite, so two halves
// of the least denormal average to it (w p + w q rounded each product to 0); w p + w q where
// the sum overflows, so DBL_MAX halves stay finite.
inline double scaled_sum(double p, double q, double w) noexcept {
    const double s = p + q;
    return std::isfinite(s) || !std::isfinite(p) || !std::isfinite(q) ? w * s : w * p + w * q;
}

// Sum of f(i) for i in [0, n) in fixed blocks, in a Sum (double, or a few sums together).
template <class Sum = double, class F>
Sum blocked_sum(std::size_t n, F&& f) {
    Sum total{};
    for (std::size_t b = 0; b < n; b += block_size) {
        const std::size_t e = (std::min)(n, b + block_size);
        Sum s{};
        for (std::size_t i = b; i < e; ++i) s += f(i);
        total += s;
    }
    return total;
}

// The second pass of summary_of: squared deviations and their plain sum, summed together.
struct deviation_sums {
    double squares = 0.0, plain = 0.0;
    deviation_sums& operator+=(const deviation_sums& o) noexcept {
        squares += o.squares;
        plain += o.plain;
        return *this;
    }
};

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
    // Squared deviations and their plain sum c, which corrects the mean's rounding (the
    // "corrected two-pass"), both in blocks: c summed in one run drifted with the order of the
    // values (R_i of the ESD off by 7e-12 over a million values in heap order).
    const detail::deviation_sums dev = detail::blocked_sum<detail::deviation_sums>(n, [&](std::size_t i) {
        if (!keep(i)) return detail::deviation_sums{};
        const double d = static_cast<double>(value(i)) - mean0;
        return detail::deviation_sums{d * d, d};
    });
    const double m2 = dev.squares, c = dev.plain;
    s.mean = mean0 + c / static_cast<double>(count);
    s.m2 = (std::max)(0.0, m2 - c * c / static_cast<double>(count));
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

// keys ordered by their high 32 bits, keeping the order of equal ones (tmp: scratch). With
// distinct high words, as the detector's pixel lists have, this is std::sort's order.
inline void sort_by_high_word(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& tmp) {
    constexpr int bits = 11;
    constexpr std::size_t buckets = std::size_t{1} << bits;
    std::uint64_t top = 0;
    for (const std::uint64_t k : keys) top = (std::max)(top, k >> 32);
    tmp.resize(keys.size());
    std::array<std::size_t, buckets> start;
    for (int shift = 32; shift < 64 && (shift == 32 || (top >> (shift - 32)) != 0); shift += bits) {
        start.fill(0);
        for (const std::uint64_t k : keys) ++start[(k >> shift) & (buckets - 1)];
        std::size_t at = 0;
        for (std::size_t& b : start) at += std::exchange(b, at);
        for (const std::uint64_t k : keys) tmp[start[(k >> shift) & (buckets - 1)]++] = k;
        keys.swap(tmp);
    }
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
    const std::size_t k2 = (std::min)(k + 1, total - 1);
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
    median = (count % 2 == 1) ? a : detail::scaled_sum(a, b, 0.5);
    return true;
}

// ---------------------------------------------------------------------------------------
// Exact median and MAD of the non-negative entries of a float array, with a histogram of
// the upper 16 bits of each value (1/128 of an octave per bucket) built by the caller.
class sd_histogram {
public:
    static constexpr std::size_t buckets = 1u << 16;

    // Histogram of the values >= 0 in v[0, n). Two interleaved tables, so runs of equal
    // buckets (neighbouring pixels) do not serialise on one counter.
    void build(const float* v, std::size_t n) {
        hist_.assign(buckets, 0);  // assign keeps the capacity: no new pages after the first frame
        spare_.assign(buckets, 0);
        std::uint32_t* h0 = hist_.data();
        std::uint32_t* h1 = spare_.data();
        std::size_t i = 0, total = 0;
        for (; i + 1 < n; i += 2) {
            const float a = v[i], b = v[i + 1];
            if (a >= 0) { ++h0[bucket(a)]; ++total; }
            if (b >= 0) { ++h1[bucket(b)]; ++total; }
        }
        if (i < n && v[i] >= 0) { ++h0[bucket(v[i])]; ++total; }
        for (std::size_t b = 0; b < buckets; ++b) h0[b] += h1[b];
        total_ = total;
    }
    std::size_t total() const noexcept { return total_; }

    static std::uint32_t bucket(float v) noexcept {
        std::uint32_t bits;
        std::memcpy(&bits, &v, sizeof bits);
        return (bits & 0x7fffffffu) >> 16;  // -0 is 0: only zero can carry a sign here
    }
    static float lower_edge(std::uint32_t b) noexcept {
        const std::uint32_t bits = b << 16;
        float f;
        std::memcpy(&f, &bits, sizeof f);
        return f;
    }

    // Exact median of the values >= 0 in v[0, n): one pass collecting the middle bucket(s).
    double median(const float* v, std::size_t n, std::vector<float>& scratch) const {
        if (total_ == 0) return 0.0;
        const std::size_t k = (total_ - 1) / 2, k2 = total_ / 2;
        std::size_t below = 0, b1 = 0;
        while (below + hist_[b1] <= k) below += hist_[b1++];
        std::size_t b2 = b1, upto = below + hist_[b1];
        while (upto <= k2) upto += hist_[++b2];
        // Buckets b1..b2 hold exactly the floats in [lower_edge(b1), lower_edge(b2 + 1)).
        const float lo = lower_edge(static_cast<std::uint32_t>(b1));
        const float hi = b2 + 1 < buckets ? lower_edge(static_cast<std::uint32_t>(b2 + 1)) : HUGE_VALF;
        std::size_t count = 0;
        for (std::size_t b = b1; b <= b2; ++b) count += hist_[b];
        scratch.resize(count + 1);
        std::size_t none = 0;  // [1, 0] is an empty inner interval
        // [lo, hi) as a closed interval; +Inf's bucket (0x7f80, counted: it is >= 0) is the
        // last, whose next edge is a NaN's bits
        const float hi_incl = b2 >= 0x7f80 ? HUGE_VALF : std::nextafter(hi, -HUGE_VALF);
        scratch.resize(detail::count_and_collect(v, n, 1.0f, 0.0f, lo, hi_incl, scratch.data(), none));
        auto first = scratch.begin() + static_cast<std::ptrdiff_t>(k - below);
        std::nth_element(scratch.begin(), first, scratch.end());
        const double a = static_cast<double>(*first);
        const double b = (k2 == k) ? a : static_cast<double>(*std::min_element(first + 1, scratch.end()));
        return 0.5 * a + 0.5 * b;
    }

    // Exact MAD (median of |x - med|) of the values >= 0. The histogram brackets the answer
    // in (d_lo, d_hi]; one pass counts the deviations <= d_lo and collects those inside.
    double mad(const float* v, std::size_t n, double med, std::vector<double>& scratch) const {
        if (total_ == 0) return 0.0;
        const std::size_t k = (total_ - 1) / 2, k2 = total_ / 2;
        std::vector<std::uint64_t>& prefix = prefix_;  // reused: a fresh 512 KiB block would fault in
        prefix.resize(buckets + 1);
        prefix[0] = 0;
        for (std::size_t b = 0; b < buckets; ++b) prefix[b + 1] = prefix[b] + hist_[b];
        double d_lo = -1.0, d_hi = HUGE_VAL;
        deviation_bracket(med, k, k2, d_lo, d_hi);
        return mad_in_bracket(v, n, med, d_lo, d_hi, k, k2, scratch);
    }

    std::size_t bytes() const noexcept {
        return (hist_.capacity() + spare_.capacity()) * sizeof(std::uint32_t) + band_.capacity() * sizeof(float) +
               prefix_.capacity() * sizeof(std::uint64_t);
    }

private:
    // The deviations' bracket from the histogram (prefix_ built): d_lo the largest d with at
    // most k values possibly within med +- d (-1: none), d_hi the smallest with at least k2 + 1
    // surely within (HUGE_VAL: none), each by bisection on bucket counts.
    void deviation_bracket(double med, std::size_t k, std::size_t k2, double& d_lo, double& d_hi) const {
        const std::vector<std::uint64_t>& prefix = prefix_;
        std::size_t top = buckets;
        while (top > 0 && hist_[top - 1] == 0) --top;
        const double hi = top < buckets ? static_cast<double>(lower_edge(static_cast<std::uint32_t>(top))) : HUGE_VAL;
        // Counts of values surely inside / possibly inside [med - d, med + d].
        auto range = [&](double d, bool outer) -> std::uint64_t {
            const double lo_v = (std::max)(med - d, 0.0), hi_v = med + d;
            long bl = static_cast<long>(bucket(static_cast<float>(lo_v)));
            long br = hi_v >= 3.0e38 ? static_cast<long>(buckets) - 1 : static_cast<long>(bucket(static_cast<float>(hi_v)));
            if (outer) {
                bl = (std::max)(bl - 1, 0L);
                br = (std::min)(br + 1, static_cast<long>(buckets) - 1);
                if (med - d <= 0) bl = 0;
            } else {
                bl = (med - d <= 0) ? 0 : bl + 1;
                br = br - 1;
            }
            return br < bl ? 0 : prefix[static_cast<std::size_t>(br) + 1] - prefix[static_cast<std::size_t>(bl)];
        };
        const double dmax = std::isfinite(hi) ? (std::max)(med, hi - med) * 2.0 + 1.0 : HUGE_VAL;
        if (range(0.0, true) <= k && std::isfinite(dmax)) {
            double a = 0.0, b = dmax;
            for (int it = 0; it < 80; ++it) {
                const double m = 0.5 * (a + b);
                if (range(m, true) <= k) a = m; else b = m;
            }
            d_lo = a;
        }
        if (std::isfinite(dmax) && range(dmax, false) >= k2 + 1) {
            double a = (std::max)(d_lo, 0.0), b = dmax;
            for (int it = 0; it < 80; ++it) {
                const double m = 0.5 * (a + b);
                if (range(m, false) >= k2 + 1) b = m; else a = m;
            }
            d_hi = b;
        }
    }

    static float float_at_or_above(double x) noexcept {  // the smallest float >= x
        if (!(x > -3.4e38)) return -HUGE_VALF;
        if (!(x < 3.4e38)) return HUGE_VALF;
        const float f = static_cast<float>(x);
        return static_cast<double>(f) < x ? std::nextafter(f, HUGE_VALF) : f;
    }
    static float float_at_or_below(double x) noexcept {  // the largest float <= x
        if (!(x > -3.4e38)) return -HUGE_VALF;
        if (!(x < 3.4e38)) return HUGE_VALF;
        const float f = static_cast<float>(x);
        return static_cast<double>(f) > x ? std::nextafter(f, -HUGE_VALF) : f;
    }

    // The MAD from its bracket: in float terms |x - med| <= d_lo when x lies in [in_lo, in_hi]
    // (the bounds rounded inwards, then checked in the deviation's own rounding), and every
    // deviation in (d_lo, d_hi] has its x in [out_lo, out_hi] (rounded outwards). One pass counts the first and collects the
    // second; values collected beyond d_hi rank above the answer and do no harm.
    double mad_in_bracket(const float* v, std::size_t n, double med, double d_lo, double d_hi, std::size_t k,
                          std::size_t k2, std::vector<double>& scratch) const {
        const std::vector<std::uint64_t>& prefix = prefix_;
        const bool has_inner = d_lo >= 0;
        float in_lo = has_inner ? float_at_or_above(med - d_lo) : 1.0f;
        float in_hi = has_inner ? float_at_or_below(med + d_lo) : 0.0f;
        // med +- d_lo is rounded to double before it is rounded to a float: a bound can land one
        // float outside, whose deviation (as computed below) exceeds d_lo. Step it inwards.
        while (has_inner && in_lo <= in_hi && !(std::fabs(static_cast<double>(in_lo) - med) <= d_lo))
            in_lo = std::nextafter(in_lo, HUGE_VALF);
        while (has_inner && in_lo <= in_hi && !(std::fabs(static_cast<double>(in_hi) - med) <= d_lo))
            in_hi = std::nextafter(in_hi, -HUGE_VALF);
        const float out_lo = (std::max)(float_at_or_below(med - d_hi), 0.0f), out_hi = float_at_or_above(med + d_hi);
        // The band holds at most the values of the buckets its two intervals touch.
        auto count_buckets = [&](float a, float b) -> std::size_t {
            if (!(a <= b)) return 0;
            const std::size_t ba = bucket((std::max)(a, 0.0f)), bb = (std::min<std::size_t>)(bucket(b), buckets - 1);
            return bb < ba ? 0 : static_cast<std::size_t>(prefix[bb + 1] - prefix[ba]);
        };
        const std::size_t cap = has_inner ? count_buckets(out_lo, in_lo) + count_buckets(in_hi, out_hi)
                                          : count_buckets(out_lo, out_hi);
        band_.resize(cap + 1);
        float* out = band_.data();
        std::size_t below = 0;
        const std::size_t j = detail::count_and_collect(v, n, in_lo, in_hi, out_lo, out_hi, out, below);
        scratch.resize(j);
        for (std::size_t t = 0; t < j; ++t) scratch[t] = std::fabs(static_cast<double>(out[t]) - med);
        if (below > k || below + scratch.size() < k2 + 1) {  // cannot happen; stay exact anyway
            below = 0;
            scratch.clear();
            for (std::size_t i = 0; i < n; ++i)
                if (v[i] >= 0) scratch.push_back(std::fabs(static_cast<double>(v[i]) - med));
        }
        auto first = scratch.begin() + static_cast<std::ptrdiff_t>(k - below);
        std::nth_element(scratch.begin(), first, scratch.end());
        const double a = *first;
        const double b = (k2 == k) ? a : *std::min_element(first + 1, scratch.end());
        return 0.5 * a + 0.5 * b;
    }

    std::vector<std::uint32_t> hist_, spare_;
    mutable std::vector<float> band_;
    mutable std::vector<std::uint64_t> prefix_;
    detail::reset_on_move<std::size_t> total_;  // (scratch.hpp: a moved-from histogram is empty)
};

}  // namespace firefly
