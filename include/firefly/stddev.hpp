// firefly: per-pixel variance -> one standard deviation per pixel, and which pixels count.
//
// Step 1 of the detector. The channel variances of a pixel reduce to one number (mean of the
// channels by default; Rec. 709 luminance weights or the max as options), and its square
// root is the statistic tested: the bound is much tighter on standard deviations than on
// variances (paper, section 3.2).
//
//   valid      counts in every statistic
//   ignored    black colour (every colour channel exactly 0) or alpha <= 0: left out of the
//              statistics and never an outlier (the image may not be a final beauty pass)
//   nonfinite  NaN or Inf in colour, variance or alpha: an outlier outright, repaired by the
//              reconstruction, and kept out of every statistic
// Negative variance (a renderer's round-off) counts as 0.
//
// Speed: this pass reads every input byte, so it is written to vectorize. Packed float images
// take a loop with compile-time channel counts and no branches; square roots are taken
// afterwards four at a time (std::sqrt's errno path keeps compilers from vectorizing it).
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#endif

#include "fused.hpp"
#include "image_view.hpp"
#include "parallel.hpp"
#include "status.hpp"

namespace firefly {

enum class variance_reduction : std::uint8_t { mean, luminance, max };

// Written into the low bits of a per-pixel label byte.
enum class pixel_class : std::uint8_t { valid = 0, ignored = 1, nonfinite = 2 };
inline constexpr std::uint8_t pixel_class_bits = 3;

struct stddev_counts {
    std::size_t valid = 0;
    std::size_t ignored = 0;
    std::size_t nonfinite = 0;
    std::size_t negative_variance = 0;  // pixels with a channel variance < 0 (clamped to 0)
    stddev_counts& operator+=(const stddev_counts& o) noexcept {  // (the counts of two bands)
        valid += o.valid;
        ignored += o.ignored;
        nonfinite += o.nonfinite;
        negative_variance += o.negative_variance;
        return *this;
    }
};

// Which colour channels count: the first three (a fourth is alpha or padding).
inline int colour_channels(int channels) noexcept { return channels < 3 ? channels : 3; }

// Check the views that describe one half buffer. alpha may be empty.
template <class C, class V, class A>
status check_half_views(const image_view<C>& color, const image_view<V>& variance,
                        const image_view<A>& alpha) noexcept {
    if (color.empty()) return status{errc::empty_image, "colour image is empty"};
    if (!same_size(color, variance))
        return status{errc::size_mismatch, "variance and colour differ in size"};
    if (variance.channels() != 1 && variance.channels() != color.channels())
        return status{errc::channel_mismatch,
                      "variance needs 1 channel or as many channels as colour"};
    if (!alpha.empty()) {
        if (!same_size(color, alpha)) return status{errc::size_mismatch, "alpha and colour differ in size"};
        if (alpha.channels() != 1) return status{errc::channel_mismatch, "alpha needs 1 channel"};
    }
    return ok_status();
}

namespace detail {

// Channel variances of one pixel reduced to one number, in double (for the few per-pixel
// decisions of the half-buffer checks). Non-finite sets `nonfinite`; negative counts as 0.
template <class V>
inline double reduce_variance(const V* px, std::ptrdiff_t cstride, int channels,
                              variance_reduction how, bool& nonfinite, bool& negative) noexcept {
    using traits = channel_traits<std::remove_cv_t<V>>;
    const int n = colour_channels(channels);
    double v[3] = {0, 0, 0};
    for (int c = 0; c < n; ++c) {
        v[c] = traits::load(*reinterpret_cast<const V*>(reinterpret_cast<const unsigned char*>(px) + c * cstride));
        if (!std::isfinite(v[c])) nonfinite = true;
        if (v[c] < 0) {
            negative = true;
            v[c] = 0;
        }
    }
    if (n == 1) return v[0];
    if (how == variance_reduction::max) return (std::max)(v[0], (std::max)(v[1], v[2]));
    if (how == variance_reduction::luminance && n == 3) return luminance(v[0], v[1], v[2]);
    return (v[0] + v[1] + v[2]) / n;
}

// Element (not byte) strides: every stride of a checked view is a multiple of its element
// size, so the per-pixel loop indexes plain pointers.
template <class T>
struct strided {
    T* p;
    std::ptrdiff_t c, x, y;
    explicit strided(const image_view<T>& v) noexcept
        : p(v.data()),
          c(v.channel_stride() / static_cast<std::ptrdiff_t>(sizeof(T))),
          x(v.pixel_stride() / static_cast<std::ptrdiff_t>(sizeof(T))),
          y(v.row_stride() / static_cast<std::ptrdiff_t>(sizeof(T))) {}
};

// Whether channel_traits<T> converts runs of values to float in bulk:
//   static void to_float(const T* in, float* out, std::size_t n) noexcept;
// (the documented hook for a renderer's half type: the stddev pass then converts each row
// and runs the packed float kernel, instead of loading value by value).
template <class T, class = void>
struct has_row_conversion : std::false_type {};
template <class T>
struct has_row_conversion<T, std::void_t<decltype(channel_traits<T>::to_float(
                                 std::declval<const T*>(), std::declval<float*>(), std::size_t{}))>>
    : std::true_type {};

// Arithmetic of the standard deviation: float for float images and for types that convert to
// float in bulk (vectorizes, and float precision is what the images carry), double otherwise.
// Every layout uses the same formula in the same order, so an RGB view and an RGBA view of
// the same pixels, or a packed and a padded view of half values, give the same bits.
template <class T>
using sd_arith = std::conditional_t<std::is_same_v<std::remove_cv_t<T>, float> || has_row_conversion<std::remove_cv_t<T>>::value,
                                    float, double>;

// One pixel, branch-free: its class, and its reduced variance (-1 ignored, NaN non-finite).
// c, v: the first three colour / variance channels (unused ones 0); NC colour channels, NV
// variance channels used (1 or NC); How: the reduction.
template <variance_reduction How, int NC, int NV, bool HasAlpha, class R>
inline R classify_pixel(const R (&c)[3], const R (&v)[3], R a, std::uint8_t& label, bool& negative) noexcept {
    R fin = (c[0] - c[0]) + (c[1] - c[1]) + (c[2] - c[2]) + (v[0] - v[0]) + (v[1] - v[1]) + (v[2] - v[2]);
    if (HasAlpha) fin += a - a;  // NaN for any NaN or Inf
    const bool finite = fin == R(0);
    bool black = c[0] == R(0);
    if (NC > 1) black &= c[1] == R(0);
    if (NC > 2) black &= c[2] == R(0);
    const bool covered = !HasAlpha || a > R(0);
    negative = (v[0] < R(0)) | (v[1] < R(0)) | (v[2] < R(0));
    // negative and -0 -> +0 (std::max(-0.0, 0.0) is -0.0, whose sign would reach the
    // histogram); non-finite pixels are discarded anyway
    const R v0 = v[0] > R(0) ? v[0] : R(0), v1 = v[1] > R(0) ? v[1] : R(0), v2 = v[2] > R(0) ? v[2] : R(0);
    R var;
    if (NV == 1) var = v0;
    else if (How == variance_reduction::max) var = (std::max)(v0, (std::max)(v1, v2));
    else if (How == variance_reduction::luminance && NV == 3) var = luminance(v0, v1, v2);
    else var = (v0 + v1 + v2) / R(NV);
    const bool ignored = black | !covered;
    label = static_cast<std::uint8_t>(finite ? (ignored ? 1 : 0) : 2);
    return finite ? (ignored ? R(-1) : var) : std::numeric_limits<R>::quiet_NaN();
}

// The float version, on bit patterns: integer compares and selects, which compilers turn
// into vector code under default floating-point flags (float compare-selects they do not).
// Same results as the generic version for every float input.
inline std::uint32_t float_bits(float f) noexcept {
    std::uint32_t b;
    std::memcpy(&b, &f, sizeof b);
    return b;
}
inline float bits_float(std::uint32_t b) noexcept {
    float f;
    std::memcpy(&f, &b, sizeof f);
    return f;
}

// The class of a pixel from what the pass stored: NaN non-finite, -1 ignored, else valid.
inline std::uint8_t label_of(float stored) noexcept {
    const std::uint32_t b = float_bits(stored);
    return static_cast<std::uint8_t>(((b == 0x7fc00000u) << 1) | (b == 0xbf800000u));
}

template <variance_reduction How, int NC, int NV, bool HasAlpha>
inline float classify_bits(float cf0, float cf1, float cf2, float vf0, float vf1, float vf2, float a,
                           std::uint32_t& negative) noexcept {
    constexpr std::uint32_t exp = 0x7f800000u, mag = 0x7fffffffu, sign = 0x80000000u;
    const std::uint32_t c0 = float_bits(cf0), c1 = float_bits(cf1), c2 = float_bits(cf2);
    const std::uint32_t v0b = float_bits(vf0), v1b = float_bits(vf1), v2b = float_bits(vf2);
    const std::uint32_t ab = float_bits(a);
    std::uint32_t nonfinite = ((c0 & exp) == exp) | ((c1 & exp) == exp) | ((c2 & exp) == exp) |
                              ((v0b & exp) == exp) | ((v1b & exp) == exp) | ((v2b & exp) == exp);
    if (HasAlpha) nonfinite |= (ab & exp) == exp;
    std::uint32_t any_colour = c0 & mag;
    if (NC > 1) any_colour |= c1 & mag;
    if (NC > 2) any_colour |= c2 & mag;
    const std::uint32_t black = any_colour == 0;
    const std::uint32_t covered = HasAlpha ? ((ab & sign) == 0) & ((ab & mag) != 0) : 1u;
    // negative: sign set and not zero; such channels count as 0. Masks, not selects.
    auto neg = [](std::uint32_t b) -> std::uint32_t { return (b >> 31) & static_cast<std::uint32_t>((b & 0x7fffffffu) != 0); };
    const std::uint32_t n0 = neg(v0b), n1 = neg(v1b), n2 = neg(v2b);
    negative = n0 | n1 | n2;
    const float v0 = bits_float(v0b & mag & (n0 - 1u));  // n = 1 -> mask 0 -> +0
    const float v1 = bits_float(v1b & mag & (n1 - 1u));
    const float v2 = bits_float(v2b & mag & (n2 - 1u));
    float var;
    if (NV == 1) var = v0;
    else if (How == variance_reduction::max) var = (std::max)(v0, (std::max)(v1, v2));
    else if (How == variance_reduction::luminance && NV == 3) var = luminance(v0, v1, v2);
    else var = v0 / float(NV) + v1 / float(NV) + v2 / float(NV);  // no overflow at FLT_MAX
    const std::uint32_t ignored = black | (covered ^ 1u);
    const std::uint32_t nf_mask = 0u - nonfinite, ig_mask = 0u - ignored;
    const std::uint32_t out = (nf_mask & 0x7fc00000u) |                       // NaN
                              (~nf_mask & ((ig_mask & 0xbf800000u) |           // -1
                                           (~ig_mask & float_bits(var))));     // variance
    return bits_float(out);
}

template <variance_reduction How, int NC, int NV, bool HasAlpha>
inline float classify_pixel(const float (&c)[3], const float (&v)[3], float a, std::uint8_t& label,
                            bool& negative) noexcept {
    std::uint32_t neg = 0;
    const float r = classify_bits<How, NC, NV, HasAlpha>(c[0], c[1], c[2], v[0], v[1], v[2], a, neg);
    negative = neg != 0;
    label = label_of(r);
    return r;
}

template <int NC, int NV, bool HasAlpha, class R>
inline R classify_pixel(variance_reduction how, const R (&c)[3], const R (&v)[3], R a, std::uint8_t& label,
                        bool& negative) noexcept {
    switch (how) {
        case variance_reduction::max:
            return classify_pixel<variance_reduction::max, NC, NV, HasAlpha>(c, v, a, label, negative);
        case variance_reduction::luminance:
            return classify_pixel<variance_reduction::luminance, NC, NV, HasAlpha>(c, v, a, label, negative);
        default: return classify_pixel<variance_reduction::mean, NC, NV, HasAlpha>(c, v, a, label, negative);
    }
}

// What the pass stores for one pixel: with float arithmetic the variance (square roots come
// afterwards, four at a time); with double the standard deviation, clamped to FLT_MAX.
template <class R>
inline float store_value(R value) noexcept {
    if constexpr (std::is_same_v<R, float>) {
        return value;
    } else {
        if (!(value >= 0)) return static_cast<float>(value);
        const double s = std::sqrt(value);
        return s < static_cast<double>(FLT_MAX) ? static_cast<float>(s) : FLT_MAX;
    }
}

// sd[i] = sqrt(sd[i]) for the entries >= 0; -1 and NaN stay. IEEE square roots are correctly
// rounded, so the SIMD lanes equal std::sqrt bit for bit.
inline void sqrt_nonnegative(float* sd, std::size_t n) noexcept {
    std::size_t i = 0;
#if defined(__SSE2__) || defined(_M_X64)
    const __m128 zero = _mm_setzero_ps();
    for (; i + 4 <= n; i += 4) {
        const __m128 x = _mm_loadu_ps(sd + i);
        const __m128 keep = _mm_cmpge_ps(x, zero);  // false for -1 and NaN
        const __m128 r = _mm_sqrt_ps(_mm_and_ps(x, keep));
        _mm_storeu_ps(sd + i, _mm_or_ps(_mm_and_ps(keep, r), _mm_andnot_ps(keep, x)));
    }
#elif defined(__ARM_NEON) && defined(__aarch64__)
    for (; i + 4 <= n; i += 4) {
        const float32x4_t x = vld1q_f32(sd + i);
        const uint32x4_t keep = vcgeq_f32(x, vdupq_n_f32(0.0f));
        vst1q_f32(sd + i, vbslq_f32(keep, vsqrtq_f32(vmaxq_f32(x, vdupq_n_f32(0.0f))), x));
    }
#endif
    for (; i < n; ++i)
        if (sd[i] >= 0) sd[i] = std::sqrt(sd[i]);
}

#if defined(__SSE2__) || defined(_M_X64)
// The common case by hand: packed RGB float colour and variance, the mean reduction, four
// pixels at a time, finishing the pass (square root, label) in the same loop. The same
// operations as classify_bits in the same order, so the same bits. Returns the pixels done
// (a multiple of 4; the caller finishes the rest) and counts negative-variance pixels.
template <bool HasAlpha>
std::size_t stddev_rgb_mean_sse2(const float* col, const float* var, const float* alpha, std::size_t n, float* sd,
                                 std::uint8_t* label, std::size_t& negative_n, std::size_t& nonfinite_n,
                                 std::size_t& ignored_n) noexcept {
    const __m128i exp = _mm_set1_epi32(0x7f800000), mag = _mm_set1_epi32(0x7fffffff);
    const __m128i zero_i = _mm_setzero_si128();
    const __m128 three = _mm_set1_ps(3.0f), minus_one = _mm_set1_ps(-1.0f);
    const __m128 qnan = _mm_castsi128_ps(_mm_set1_epi32(0x7fc00000));
    // De-interleave 4 RGB pixels: A = r0 g0 b0 r1, B = g1 b1 r2 g2, C = b2 r3 g3 b3.
    auto split = [](const float* p, __m128& r, __m128& g, __m128& b) {
        const __m128 A = _mm_loadu_ps(p), B = _mm_loadu_ps(p + 4), C = _mm_loadu_ps(p + 8);
        r = _mm_shuffle_ps(A, _mm_shuffle_ps(B, C, _MM_SHUFFLE(1, 1, 2, 2)), _MM_SHUFFLE(2, 0, 3, 0));
        g = _mm_shuffle_ps(_mm_shuffle_ps(A, B, _MM_SHUFFLE(0, 0, 1, 1)), _mm_shuffle_ps(B, C, _MM_SHUFFLE(2, 2, 3, 3)),
                           _MM_SHUFFLE(2, 0, 2, 0));
        b = _mm_shuffle_ps(_mm_shuffle_ps(A, B, _MM_SHUFFLE(1, 1, 2, 2)), _mm_shuffle_ps(C, C, _MM_SHUFFLE(3, 3, 0, 0)),
                           _MM_SHUFFLE(2, 0, 2, 0));
    };
    auto is_exp = [&](__m128 x) { return _mm_cmpeq_epi32(_mm_and_si128(_mm_castps_si128(x), exp), exp); };
    std::size_t i = 0, neg = 0, nf_count = 0, ig_count = 0;
    auto bits4 = [](int m) { return static_cast<std::size_t>((m & 1) + ((m >> 1) & 1) + ((m >> 2) & 1) + ((m >> 3) & 1)); };
    for (; i + 4 <= n; i += 4) {
        __m128 c0, c1, c2, v0, v1, v2;
        split(col + 3 * i, c0, c1, c2);
        split(var + 3 * i, v0, v1, v2);
        __m128i nonfinite = _mm_or_si128(_mm_or_si128(is_exp(c0), is_exp(c1)), _mm_or_si128(is_exp(c2), is_exp(v0)));
        nonfinite = _mm_or_si128(nonfinite, _mm_or_si128(is_exp(v1), is_exp(v2)));
        __m128i covered = _mm_set1_epi32(-1);
        if (HasAlpha) {
            const __m128 a = _mm_loadu_ps(alpha + i);
            nonfinite = _mm_or_si128(nonfinite, is_exp(a));
            const __m128i ab = _mm_castps_si128(a);
            // sign clear and not zero: as an int32, > 0
            covered = _mm_cmpgt_epi32(ab, zero_i);
        }
        const __m128i any = _mm_and_si128(
            _mm_or_si128(_mm_or_si128(_mm_castps_si128(c0), _mm_castps_si128(c1)), _mm_castps_si128(c2)), mag);
        const __m128i black = _mm_cmpeq_epi32(any, zero_i);
        // negative: sign set and not zero (as an int32: < 0 and not the bit pattern of -0)
        auto negative = [&](__m128 x) {
            const __m128i b = _mm_castps_si128(x);
            return _mm_andnot_si128(_mm_cmpeq_epi32(_mm_and_si128(b, mag), zero_i), _mm_cmplt_epi32(b, zero_i));
        };
        const __m128i n0 = negative(v0), n1 = negative(v1), n2 = negative(v2);
        const int nm = _mm_movemask_ps(_mm_castsi128_ps(_mm_or_si128(_mm_or_si128(n0, n1), n2)));
        neg += bits4(nm);
        auto clamp = [&](__m128 x, __m128i nx) {
            return _mm_castsi128_ps(_mm_andnot_si128(nx, _mm_and_si128(_mm_castps_si128(x), mag)));
        };
        const __m128 vm = _mm_add_ps(_mm_add_ps(_mm_div_ps(clamp(v0, n0), three), _mm_div_ps(clamp(v1, n1), three)),
                                     _mm_div_ps(clamp(v2, n2), three));
        const __m128i ignored = _mm_or_si128(black, _mm_xor_si128(covered, _mm_set1_epi32(-1)));
        const __m128 ig = _mm_castsi128_ps(ignored), nf = _mm_castsi128_ps(nonfinite);
        const __m128 root = _mm_sqrt_ps(vm);
        __m128 out = _mm_or_ps(_mm_and_ps(ig, minus_one), _mm_andnot_ps(ig, root));
        out = _mm_or_ps(_mm_and_ps(nf, qnan), _mm_andnot_ps(nf, out));
        _mm_storeu_ps(sd + i, out);
        // label: 2 non-finite, else 1 ignored, else 0
        const __m128i lab = _mm_or_si128(_mm_and_si128(nonfinite, _mm_set1_epi32(2)),
                                         _mm_andnot_si128(nonfinite, _mm_and_si128(ignored, _mm_set1_epi32(1))));
        const __m128i bytes = _mm_packus_epi16(_mm_packs_epi32(lab, zero_i), zero_i);
        const int word = _mm_cvtsi128_si32(bytes);
        std::memcpy(label + i, &word, 4);
        const int nfm = _mm_movemask_ps(nf);
        nf_count += bits4(nfm);
        ig_count += bits4(_mm_movemask_ps(ig) & ~nfm);
    }
    negative_n += neg;
    nonfinite_n += nf_count;
    ignored_n += ig_count;
    return i;
}
#endif

// Packed float images: plain arrays, channel counts known at compile time.
template <variance_reduction How, int CS, int VS, bool HasAlpha>
std::size_t stddev_packed(const float* col, const float* var, const float* alpha, std::size_t n, float* sd) noexcept {
    constexpr int nc = CS < 3 ? CS : 3;
    constexpr int nv = VS == 1 ? 1 : nc;
    std::uint32_t negative_n = 0;  // per-pixel 0/1 summed: fits unless n >= 2^32 (refused upstream)
    for (std::size_t i = 0; i < n; ++i) {
        const float* cp = col + i * CS;
        const float* vp = var + i * VS;
        const float c1 = nc > 1 ? cp[1] : 0.0f, c2 = nc > 2 ? cp[2] : 0.0f;
        const float v1 = nv > 1 ? vp[1] : 0.0f, v2 = nv > 2 ? vp[2] : 0.0f;
        // A 4th channel is no colour, but NaN or Inf in it makes the pixel non-finite:
        // x - x is 0 for finite x and NaN otherwise, and folds into channel 0 at no cost.
        const float c0 = CS > 3 ? cp[0] + (cp[3] - cp[3]) : cp[0];
        const float v0 = VS > 3 ? vp[0] + (vp[3] - vp[3]) : vp[0];
        std::uint32_t negative;
        sd[i] = classify_bits<How, nc, nv, HasAlpha>(c0, c1, c2, v0, v1, v2, HasAlpha ? alpha[i] : 1.0f, negative);
        negative_n += negative;
    }
    return negative_n;
}

template <int CS, int VS>
std::size_t stddev_packed(const float* col, const float* var, const float* alpha, std::size_t n,
                          variance_reduction how, float* sd) noexcept {
    using vr = variance_reduction;
    if (alpha) {
        return how == vr::max         ? stddev_packed<vr::max, CS, VS, true>(col, var, alpha, n, sd)
               : how == vr::luminance ? stddev_packed<vr::luminance, CS, VS, true>(col, var, alpha, n, sd)
                                      : stddev_packed<vr::mean, CS, VS, true>(col, var, alpha, n, sd);
    }
    return how == vr::max         ? stddev_packed<vr::max, CS, VS, false>(col, var, alpha, n, sd)
           : how == vr::luminance ? stddev_packed<vr::luminance, CS, VS, false>(col, var, alpha, n, sd)
                                  : stddev_packed<vr::mean, CS, VS, false>(col, var, alpha, n, sd);
}


// Row y of a packed view as floats: the view's own memory for float, else converted into
// scratch through the traits' bulk hook.
template <class T>
const float* float_row(const image_view<T>& v, int y, std::vector<float>& scratch) {
    const std::size_t n = static_cast<std::size_t>(v.width()) * static_cast<std::size_t>(v.channels());
    const T* p = v.data() + static_cast<std::size_t>(y) * n;
    if constexpr (std::is_same_v<std::remove_cv_t<T>, float>) {
        (void)scratch;
        return p;
    } else {
        scratch.resize(n);
        channel_traits<std::remove_cv_t<T>>::to_float(p, scratch.data(), n);
        return scratch.data();
    }
}

// Whether T's packed rows read as floats: float itself, or a type with the bulk hook.
template <class T>
inline constexpr bool float_rows_v = std::is_same_v<std::remove_cv_t<T>, float> || has_row_conversion<std::remove_cv_t<T>>::value;

// Packed colour and variance of which at least one converts: row by row through float rows.
template <class C, class V>
std::size_t stddev_converted_rows(const image_view<C>& color, const image_view<V>& variance,
                                  const float* alpha, variance_reduction how, float* sd) {
    const int w = color.width(), cc = color.channels(), vc = variance.channels();
    std::vector<float> crow_scratch, vrow_scratch;
    std::size_t negative_n = 0;
    for (int y = 0; y < color.height(); ++y) {
        const std::size_t first = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        const float* col = float_row(color, y, crow_scratch);
        const float* var = float_row(variance, y, vrow_scratch);
        const float* ap = alpha ? alpha + first : nullptr;
        float* out = sd + first;
        const std::size_t n = static_cast<std::size_t>(w);
        if (cc == 3) negative_n += vc == 1 ? stddev_packed<3, 1>(col, var, ap, n, how, out)
                                           : stddev_packed<3, 3>(col, var, ap, n, how, out);
        else negative_n += vc == 1 ? stddev_packed<4, 1>(col, var, ap, n, how, out)
                                   : stddev_packed<4, 4>(col, var, ap, n, how, out);
    }
    return negative_n;
}

// Packed float views: the row kernels (by hand with SSE2 for RGB colour and variance reduced
// by their mean). False, and nothing written, for other layouts.
template <class C, class V, class A>
bool stddev_packed_float(const image_view<C>& color, const image_view<V>& variance, const image_view<A>& alpha,
                         variance_reduction how, float* sd, std::uint8_t* label, stddev_counts& t,
                         std::size_t& finished) noexcept {
    if constexpr (std::is_same_v<std::remove_cv_t<C>, float> && std::is_same_v<std::remove_cv_t<V>, float> &&
                  std::is_same_v<std::remove_cv_t<A>, float>) {
        const bool has_alpha = !alpha.empty();
        if (!(color.is_packed() && variance.is_packed() && (!has_alpha || alpha.is_packed()))) return false;
        const float* ap = has_alpha ? alpha.data() : nullptr;
        const int cc = color.channels(), vc = variance.channels();
        const std::size_t n = color.pixel_count();
#if defined(__SSE2__) || defined(_M_X64)
        if (cc == 3 && vc == 3 && how == variance_reduction::mean) {
            // The first `finished` pixels by hand, roots and labels included; the tail by
            // the generic kernel and the common finish (finish_stddev).
            finished = ap ? stddev_rgb_mean_sse2<true>(color.data(), variance.data(), ap, n, sd, label,
                                                       t.negative_variance, t.nonfinite, t.ignored)
                          : stddev_rgb_mean_sse2<false>(color.data(), variance.data(), ap, n, sd, label,
                                                        t.negative_variance, t.nonfinite, t.ignored);
            t.negative_variance += stddev_packed<3, 3>(color.data() + 3 * finished, variance.data() + 3 * finished,
                                                       ap ? ap + finished : nullptr, n - finished, how, sd + finished);
            return true;
        }
#endif
        if (cc == 3 && vc == 3) t.negative_variance = stddev_packed<3, 3>(color.data(), variance.data(), ap, n, how, sd);
        else if (cc == 3 && vc == 1) t.negative_variance = stddev_packed<3, 1>(color.data(), variance.data(), ap, n, how, sd);
        else if (cc == 4 && vc == 4) t.negative_variance = stddev_packed<4, 4>(color.data(), variance.data(), ap, n, how, sd);
        else if (cc == 4 && vc == 1) t.negative_variance = stddev_packed<4, 1>(color.data(), variance.data(), ap, n, how, sd);
        else return false;
        return true;
    } else {
        (void)color, (void)variance, (void)alpha, (void)how, (void)sd, (void)label, (void)t, (void)finished;
        return false;
    }
}

// Colour or variance of a type that converts whole rows to float (a renderer's half), packed:
// each row is converted into a scratch row and the packed float kernel runs on it. Alpha:
// packed float, or none. False, and nothing written, for other layouts.
template <class C, class V, class A>
bool stddev_float_rows(const image_view<C>& color, const image_view<V>& variance, const image_view<A>& alpha,
                       variance_reduction how, float* sd, stddev_counts& t) {
    if constexpr (float_rows_v<C> && float_rows_v<V> &&
                  !(std::is_same_v<std::remove_cv_t<C>, float> && std::is_same_v<std::remove_cv_t<V>, float>)) {
        constexpr bool float_alpha = std::is_same_v<std::remove_cv_t<A>, float>;
        const int cc = color.channels(), vc = variance.channels();
        const bool has_alpha = !alpha.empty();
        if (!(color.is_packed() && variance.is_packed() && (!has_alpha || (float_alpha && alpha.is_packed())) &&
              (cc == 3 || cc == 4) && (vc == 1 || vc == cc)))
            return false;
        const float* ap = nullptr;
        if constexpr (float_alpha) ap = has_alpha ? alpha.data() : nullptr;
        t.negative_variance = stddev_converted_rows(color, variance, ap, how, sd);
        return true;
    } else {
        (void)color, (void)variance, (void)alpha, (void)how, (void)sd, (void)t;
        return false;
    }
}

// Any layout and channel type, one pixel at a time: the values (as float for float arithmetic,
// labels then follow from them in finish_stddev) and, written here, the labels.
template <class C, class V, class A>
void stddev_strided(const image_view<C>& color, const image_view<V>& variance, const image_view<A>& alpha,
                    variance_reduction how, float* sd, std::uint8_t* label, stddev_counts& t) noexcept {
    using R = sd_arith<C>;
    using ct = channel_traits<std::remove_cv_t<C>>;
    using vt = channel_traits<std::remove_cv_t<V>>;
    using at = channel_traits<std::remove_cv_t<A>>;
    using I1 = std::integral_constant<int, 1>;
    using I2 = std::integral_constant<int, 2>;
    using I3 = std::integral_constant<int, 3>;
    const int w = color.width(), h = color.height();
    const int nc = colour_channels(color.channels());
    const int nv = variance.channels() == 1 ? 1 : nc;
    const int cc = color.channels(), vc = variance.channels();
    const bool has_alpha = !alpha.empty();
    const strided<C> cs(color);
    const strided<V> vs(variance);
    const strided<A> as(alpha);
    for (int y = 0; y < h; ++y) {
        const C* crow = cs.p + y * cs.y;
        const V* vrow = vs.p + y * vs.y;
        const A* arow = has_alpha ? as.p + y * as.y : nullptr;
        const std::size_t base = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        for (int x = 0; x < w; ++x) {
            const C* cp = crow + x * cs.x;
            const V* vp = vrow + x * vs.x;
            R c[3] = {0, 0, 0}, v[3] = {0, 0, 0};
            for (int k = 0; k < nc; ++k) c[k] = static_cast<R>(ct::load(cp[k * cs.c]));
            for (int k = 0; k < nv; ++k) v[k] = static_cast<R>(vt::load(vp[k * vs.c]));
            for (int k = 3; k < cc; ++k) {  // beyond colour: only finiteness counts (as packed)
                const R e = static_cast<R>(ct::load(cp[k * cs.c]));
                c[0] += e - e;
            }
            for (int k = 3; k < vc; ++k) {
                const R e = static_cast<R>(vt::load(vp[k * vs.c]));
                v[0] += e - e;
            }
            const R a = has_alpha ? static_cast<R>(at::load(arow[x * as.x])) : R(1);
            bool negative = false;
            std::uint8_t& l = label[base + static_cast<std::size_t>(x)];
            // The channel counts become template arguments: the same formula as packed.
            auto run = [&](auto nc_c, auto nv_c) {
                constexpr int NC = decltype(nc_c)::value, NV = decltype(nv_c)::value;
                return has_alpha ? classify_pixel<NC, NV, true>(how, c, v, a, l, negative)
                                 : classify_pixel<NC, NV, false>(how, c, v, a, l, negative);
            };
            R value;
            if (nc == 3) value = nv == 1 ? run(I3{}, I1{}) : run(I3{}, I3{});
            else if (nc == 2) value = nv == 1 ? run(I2{}, I1{}) : run(I2{}, I2{});
            else value = run(I1{}, I1{});
            sd[base + static_cast<std::size_t>(x)] = store_value(value);
            t.negative_variance += negative;
        }
    }
}

// After any layout's values: in float arithmetic the labels follow from the stored values
// (past the `finished` pixels a kernel completed, roots and labels), then the square roots;
// otherwise the labels are written, and counted here. Then the valid count.
template <class R>
void finish_stddev(std::size_t n, float* sd, std::uint8_t* label, std::size_t finished, stddev_counts& t) noexcept {
    if constexpr (std::is_same_v<R, float>) {
        for (std::size_t i = finished; i < n; ++i) {
            const std::uint8_t l = label_of(sd[i]);
            label[i] = l;
            t.nonfinite += l >> 1;
            t.ignored += l & 1u;
        }
        sqrt_nonnegative(sd + finished, n - finished);
    } else {
        for (std::size_t i = 0; i < n; ++i) {
            t.nonfinite += (label[i] & 3) == 2;
            t.ignored += (label[i] & 3) == 1;
        }
    }
    t.valid = n - t.nonfinite - t.ignored;
}

// The pass over any layout: a packed kernel where one fits, else one pixel at a time.
template <class C, class V, class A>
stddev_counts stddev_pass(const image_view<C>& color, const image_view<V>& variance, const image_view<A>& alpha,
                          variance_reduction how, float* sd, std::uint8_t* label) noexcept {
    stddev_counts counts;
    std::size_t finished = 0;  // pixels whose roots and labels a kernel already wrote
    if (!stddev_packed_float(color, variance, alpha, how, sd, label, counts, finished) &&
        !stddev_float_rows(color, variance, alpha, how, sd, counts))
        stddev_strided(color, variance, alpha, how, sd, label, counts);
    finish_stddev<sd_arith<C>>(color.pixel_count(), sd, label, finished, counts);
    return counts;
}

}  // namespace detail

// Writes sd[y * width + x] and label[y * width + x] = pixel_class for every pixel. sd is -1
// for ignored pixels and NaN for non-finite ones. sd is stored as float (4 bytes a pixel),
// clamped to FLT_MAX for double inputs whose variance exceeds 3e76. The views are not checked
// here: pass ones check_half_views accepts, and sd and label of width x height.
template <class C, class V, class A>
stddev_counts compute_stddev(const image_view<C>& color, const image_view<V>& variance,
                             const image_view<A>& alpha, variance_reduction how, float* sd,
                             std::uint8_t* label) noexcept {
    return detail::stddev_pass(color, variance, alpha, how, sd, label);
}

// Rows per task of the banded pass: a 2K half gives 17 tasks, work for any pool.
inline constexpr int stddev_band_rows = 64;

namespace detail {
// Band `band` (rows band * stddev_band_rows onwards) of the pass, into the same places of sd
// and label as the whole pass writes. Every pixel's value depends on that pixel alone, so
// the bands give the whole pass's bits.
template <class C, class V, class A>
stddev_counts stddev_band(const image_view<C>& color, const image_view<V>& variance, const image_view<A>& alpha,
                          variance_reduction how, float* sd, std::uint8_t* label, std::size_t band) noexcept {
    const int w = color.width();
    const int y0 = static_cast<int>(band) * stddev_band_rows;
    const int rows = (std::min)(stddev_band_rows, color.height() - y0);
    const std::size_t at = static_cast<std::size_t>(y0) * static_cast<std::size_t>(w);
    return stddev_pass(*color.subview(0, y0, w, rows), *variance.subview(0, y0, w, rows),
                       alpha.empty() ? alpha : *alpha.subview(0, y0, w, rows), how, sd + at, label + at);
}

inline std::size_t stddev_bands(int height) noexcept {  // (in size_t: no int overflow near INT_MAX)
    const std::size_t rows = static_cast<std::size_t>((std::max)(height, 0)), band = stddev_band_rows;
    return (rows + band - 1) / band;
}
}  // namespace detail

// The same pass with its rows in bands across exec (one half on a renderer's pool): the same
// bits and counts as compute_stddev above, for any executor, and the same precondition.
template <class C, class V, class A>
stddev_counts compute_stddev(const image_view<C>& color, const image_view<V>& variance,
                             const image_view<A>& alpha, variance_reduction how, float* sd,
                             std::uint8_t* label, const executor& exec) {
    std::vector<stddev_counts> bands(detail::stddev_bands(color.height()));
    exec.run(bands.size(), [&](std::size_t band) {
        bands[band] = detail::stddev_band(color, variance, alpha, how, sd, label, band);
    });
    stddev_counts all;
    for (const stddev_counts& b : bands) all += b;
    return all;
}

}  // namespace firefly
