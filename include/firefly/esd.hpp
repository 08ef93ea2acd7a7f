// firefly: Rosner's (1983) generalized ESD test for up to m outliers, one-sided (upper tail,
// the default: fireflies are bright) or two-sided, with cached critical values.
//
// Step i (i = 1..m) removes the most extreme value of what is left and computes
//   R_i      = (x_i - mean_i) / sd_i           (two-sided: |x_i - mean_i| / sd_i)
//   lambda_i = (k - 1) t / sqrt((k - 2 + t^2) k),   k = n - i + 1 values still in the data,
//              t = Student-t upper point at q = alpha / k (two-sided alpha / 2k), df = k - 2.
// The number of outliers is the LARGEST i with R_i > lambda_i (not the first failure).
//
// Exactness: removing a 1e30 value from running sums leaves noise, so the statistics are
// built the other way round: the summary of the n - m values that are never removed first
// (two blocked passes, no large value among them), then the removed values are ADDED back
// from the last removed (smallest) to the first (largest), giving R_m ... R_1 in O(1) each.
//
// lambda depends only on k and alpha, so the cache is keyed by (k, alpha, sidedness, method):
// both half buffers and later frames with other valid-pixel counts share it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <numeric>
#include <unordered_map>
#include <vector>

#include "statistics.hpp"
#include "status.hpp"
#include "student_t.hpp"

namespace firefly {

// How lambda's Student-t point is computed: what accuracy costs in time.
enum class lambda_method : std::uint8_t {
    exact,   // student_t_upper_quantile: ~1e-15 relative
    hill,    // Hill (1970) approximation alone, no refinement
    normal,  // the normal quantile (the df -> infinity limit)
};

struct esd_options {
    std::size_t max_outliers = 10;
    double alpha = 0.05;
    bool two_sided = false;
    lambda_method method = lambda_method::exact;
};

// The least alpha the tests take: alpha / k (and alpha / 2k) stays a normal double for any k
// below 2^64, where the Student-t point keeps its digits (at alpha = 5e-324, alpha / k was 0,
// every lambda NaN and the test found nothing without saying why).
inline constexpr double min_alpha = 1e-280;

inline status check_alpha(double alpha) noexcept {
    if (!(alpha >= min_alpha && alpha < 1.0)) return status{errc::invalid_argument, "alpha must lie in [1e-280, 1)"};
    return {};
}

// The critical value lambda for k values still in the data (k >= 3). NaN for k < 3 or alpha
// outside (0, 1).
inline double esd_lambda(std::size_t k, double alpha, bool two_sided = false,
                         lambda_method method = lambda_method::exact) noexcept {
    if (k < 3 || !(alpha > 0.0 && alpha < 1.0)) return std::numeric_limits<double>::quiet_NaN();
    const double kd = static_cast<double>(k);
    const double q = two_sided ? alpha / (2.0 * kd) : alpha / kd;
    const double df = kd - 2.0;
    double t;
    switch (method) {
        case lambda_method::hill:
            t = df == 1.0 || df == 2.0 ? student_t_upper_quantile(q, df)
                                       : detail::hill_start(q, df, normal_upper_quantile(q));
            break;
        case lambda_method::normal: t = normal_upper_quantile(q); break;
        default: t = student_t_upper_quantile(q, df); break;
    }
    // (k-1) t / sqrt((k-2+t^2) k) without forming t^2 (t reaches 1e299 at df 1, q 1e-300)
    return (kd - 1.0) / std::sqrt(kd) * (t / std::hypot(std::sqrt(df), t));
}

// Lambdas computed once and reused, in chunks of 64 consecutive k per (alpha, sidedness,
// method). Values are stored unrounded: neighbouring k differ in the 9th digit at n = 1e8.
// Shared by several detectors through std::shared_ptr; see mutex().
class lambda_cache {
public:
    double get(std::size_t k, double alpha, bool two_sided = false,
               lambda_method method = lambda_method::exact) {
        table& t = table_for(alpha, two_sided, method);
        const std::uint64_t c = k >> 6;
        chunk* ch;
        if (t.last && t.last_index == c) {
            ch = t.last;
        } else {
            auto it = t.chunks.find(c);
            if (it == t.chunks.end()) it = t.chunks.emplace(c, std::make_unique<chunk>()).first;
            ch = it->second.get();
            t.last = ch;
            t.last_index = c;
        }
        const unsigned bit = static_cast<unsigned>(k & 63u);
        if (!(ch->valid >> bit & 1u)) {
            ch->value[bit] = esd_lambda(k, alpha, two_sided, method);
            ch->valid |= std::uint64_t{1} << bit;
            ++computed_;
        } else {
            ++hits_;
        }
        return ch->value[bit];
    }

    std::size_t computed() const noexcept { return computed_; }  // misses so far
    std::size_t hits() const noexcept { return hits_; }
    // Under the cache's own lock: a detector asks at the end of each frame (scratch_bytes)
    // while another detector sharing the cache may be filling it (a data race before).
    std::size_t bytes() const noexcept {
        const std::lock_guard<std::mutex> lock(mutex_);
        std::size_t n = 0;
        for (const auto& t : tables_) n += t.chunks.size() * sizeof(chunk);
        return n;
    }
    void clear() noexcept {
        tables_.clear();
        computed_ = hits_ = 0;
    }
    // get() is not thread-safe by itself: detectors that share one cache (one per thread in a
    // farm process) hold this lock while they read and fill it.
    std::mutex& mutex() const noexcept { return mutex_; }

private:
    struct chunk {
        std::uint64_t valid = 0;
        double value[64];
    };
    struct table {
        double alpha;
        bool two_sided;
        lambda_method method;
        std::unordered_map<std::uint64_t, std::unique_ptr<chunk>> chunks;
        chunk* last = nullptr;
        std::uint64_t last_index = 0;
    };
    table& table_for(double alpha, bool two_sided, lambda_method method) {
        for (auto& t : tables_)
            if (std::memcmp(&t.alpha, &alpha, sizeof alpha) == 0 && t.two_sided == two_sided &&
                t.method == method)
                return t;
        tables_.push_back(table{alpha, two_sided, method, {}, nullptr, 0});
        return tables_.back();
    }
    std::vector<table> tables_;  // few: one per (alpha, sidedness, method) in use
    std::size_t computed_ = 0;
    std::size_t hits_ = 0;
    mutable std::mutex mutex_;
};

struct [[nodiscard]] esd_result {
    status error{};                       // invalid_argument for a bad alpha
    std::size_t n = 0;                    // finite values tested
    std::size_t outliers = 0;             // largest i with R_i > lambda_i
    std::vector<std::size_t> indices;     // input indices in removal order (steps tested)
    std::vector<double> r;                // R_1 .. R_steps
    std::vector<double> lambda;           // lambda_1 .. lambda_steps
    std::vector<std::size_t> nonfinite;   // NaN / Inf inputs: outliers outright, never tested
};

namespace detail {

// Binary exponent shift that brings the largest magnitude near 1 when squares would
// overflow or underflow a double (0 otherwise). Scaling by a power of two is exact, even
// from denormals (ldexp per value: 2^1074 itself is not a double), and leaves R_i unchanged.
inline int esd_shift(double max_abs) noexcept {
    if (!(max_abs > 0) || !std::isfinite(max_abs)) return 0;
    const int e = std::ilogb(max_abs);
    return (e > 400 || e < -400) ? -e : 0;
}

// The core: `removed` holds the values in removal order (already scaled), `rest` the summary
// of the values never removed. Fills r, lambda and the outlier count.
inline void esd_from_removals(const double* removed, std::size_t m, summary rest, std::size_t n,
                              const esd_options& o, lambda_cache& cache, esd_result& out) {
    out.r.assign(m, 0.0);
    out.lambda.assign(m, 0.0);
    running_summary s(rest);
    for (std::size_t j = m; j-- > 0;) {  // step i = j + 1, from the last removed to the first
        const double x = removed[j];
        s.add(x);
        const summary& cur = s.get();
        const double sd = cur.stddev();
        const double dev = o.two_sided ? std::fabs(x - cur.mean) : x - cur.mean;
        out.r[j] = sd > 0 ? dev / sd : 0.0;
        out.lambda[j] = cache.get(n - j, o.alpha, o.two_sided, o.method);  // k = n - i + 1
    }
    out.outliers = 0;
    for (std::size_t j = m; j-- > 0;)
        if (out.r[j] > out.lambda[j]) {
            out.outliers = j + 1;
            break;
        }
}

// Neumaier-compensated sum, for the few removed values of the two-sided decision pass.
struct compensated {
    double sum = 0.0, c = 0.0;
    void add(double x) noexcept {
        const double t = sum + x;
        c += std::fabs(sum) >= std::fabs(x) ? (sum - t) + x : (x - t) + sum;
        sum = t;
    }
    double value() const noexcept { return sum + c; }
};

// The m removals of the one-sided test, in order (indices and values), and the summary of
// the values never removed. idx: the finite values' indices (reordered).
template <class Val>
summary one_sided_removals(std::vector<std::size_t>& idx, std::size_t m, Val&& val, std::vector<std::size_t>& indices,
                           double* removed) {
    // Max-heap by (value, lower index first): the top m pop out in removal order.
    auto less = [&](std::size_t a, std::size_t b) {
        const double va = val(a), vb = val(b);
        return va < vb || (va == vb && a > b);
    };
    std::make_heap(idx.begin(), idx.end(), less);
    auto end = idx.end();
    for (std::size_t j = 0; j < m; ++j, --end) {
        std::pop_heap(idx.begin(), end, less);
        indices.push_back(*(end - 1));
        removed[j] = val(*(end - 1));
    }
    const std::size_t keep = idx.size() - m;  // idx[0, keep) are never removed
    return summary_of(keep, [&](std::size_t j) { return val(idx[j]); }, [](std::size_t) { return true; });
}

// The same for the two-sided test: each step removes the value furthest from the mean of
// those left.
template <class Val>
summary two_sided_removals(std::vector<std::size_t>& idx, std::size_t m, Val&& val, std::vector<std::size_t>& indices,
                           double* removed) {
    const std::size_t nf = idx.size();
    std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) {
        const double va = val(a), vb = val(b);
        return va < vb || (va == vb && a < b);
    });
    // Decision pass: the mean of sorted[lo..hi] = core + low part + high part, the parts
    // summed from the inside out so a removed extreme never cancels against the rest.
    const std::size_t core_lo = m, core_hi = nf - m;  // core = [m, nf - m)
    const double core = blocked_sum(core_hi - core_lo, [&](std::size_t j) { return val(idx[core_lo + j]); });
    std::vector<double> low(m + 1, 0.0), high(m + 1, 0.0);  // low[j]: sum idx[j..m)
    compensated acc;
    for (std::size_t j = m; j-- > 0;) {
        acc.add(val(idx[j]));
        low[j] = acc.value();
    }
    acc = {};
    for (std::size_t j = 0; j < m; ++j) {  // high[j + 1]: sum idx[core_hi .. core_hi + j]
        acc.add(val(idx[core_hi + j]));
        high[j + 1] = acc.value();
    }
    std::size_t lo = 0, hi = nf - 1;
    for (std::size_t j = 0; j < m; ++j) {
        const double count = static_cast<double>(hi - lo + 1);
        const double mean = (core + low[lo] + high[hi + 1 - core_hi]) / count;
        const double dlo = mean - val(idx[lo]), dhi = val(idx[hi]) - mean;
        const std::size_t pick = dhi >= dlo ? hi-- : lo++;
        indices.push_back(idx[pick]);
        removed[j] = val(idx[pick]);
    }
    return summary_of(hi - lo + 1, [&](std::size_t j) { return val(idx[lo + j]); }, [](std::size_t) { return true; });
}
}  // namespace detail

// Generalized ESD over values[0..n) (float or double). Non-finite values are listed in
// result.nonfinite and left out. At most min(max_outliers, n - 2) steps are tested (lambda
// needs df = k - 2 >= 1); two-sided at most n / 2. One-sided takes the top values from a
// max-heap: O(n + m log n).
template <class T>
esd_result generalized_esd(const T* values, std::size_t n, const esd_options& o,
                           lambda_cache& cache) {
    esd_result out;
    if (const status e = check_alpha(o.alpha); !e.ok()) {
        out.error = e;
        return out;
    }
    std::vector<std::size_t> idx;
    idx.reserve(n);
    double max_abs = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double v = static_cast<double>(values[i]);
        if (std::isfinite(v)) {
            idx.push_back(i);
            max_abs = (std::max)(max_abs, std::fabs(v));
        } else {
            out.nonfinite.push_back(i);
        }
    }
    const std::size_t nf = idx.size();
    out.n = nf;
    std::size_t m = (std::min)(o.max_outliers, nf >= 2 ? nf - 2 : 0);
    if (o.two_sided) m = (std::min)(m, nf / 2);
    if (m == 0) return out;
    const int shift = detail::esd_shift(max_abs);
    auto val = [&](std::size_t i) {
        const double v = static_cast<double>(values[i]);
        return shift ? std::ldexp(v, shift) : v;
    };
    std::vector<double> removed(m);
    const summary rest = o.two_sided ? detail::two_sided_removals(idx, m, val, out.indices, removed.data())
                                     : detail::one_sided_removals(idx, m, val, out.indices, removed.data());
    detail::esd_from_removals(removed.data(), m, rest, nf, o, cache, out);
    return out;
}

template <class T>
esd_result generalized_esd(const T* values, std::size_t n, const esd_options& o) {
    lambda_cache cache;
    return generalized_esd(values, n, o, cache);
}

}  // namespace firefly
