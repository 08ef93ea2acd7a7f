// firefly: sums of products whose bits do not depend on how the compiler fuses multiply and add.
//
// Where the target has a fused multiply-add (-mfma, -march=native on x86-64, aarch64), a
// compiler may contract a x + b y into fma(a, x, b y) or fma(b, y, a x), rounding one product
// less, and may choose differently in two loops that compute the same value (a row pass and a
// column pass, a vector loop and its scalar tail). Results that must not depend on scan order,
// flips or pixel layout take such sums from here: on those targets the fusing is written out
// (std::fma), which leaves the compiler nothing to contract; elsewhere nothing can be
// contracted and the plain expression is exact to its own rounding.
#pragma once

#include <cmath>

#include "floating_point.hpp"

// GCC says the target fuses with __FP_FAST_FMA; Clang does not define it (and contracts within
// an expression by default), so the target's own macros are read too.
#if defined(__FP_FAST_FMA) || defined(__FMA__) || defined(__ARM_FEATURE_FMA) || defined(__aarch64__) || \
    (defined(_MSC_VER) && defined(__AVX2__))
#define FIREFLY_DETAIL_TARGET_FMA 1
#endif

// Clang's pragmas for the floating-point state of a region (float_control push and pop, fp
// contract): LLVM 11 and later, Apple's Clang 13 and later.
#if defined(__clang__) && ((defined(__apple_build_version__) && __clang_major__ >= 13) || \
                           (!defined(__apple_build_version__) && __clang_major__ >= 11))
#define FIREFLY_DETAIL_CLANG_FP_PRAGMAS 1
#endif

namespace firefly::detail {

// a fa + b fb, the same bits with the pairs swapped (a flip swaps them): both fusings taken
// and averaged where the target fuses.
template <class R>
inline R weighted_pair(R a, R b, R fa, R fb) noexcept {
#ifdef FIREFLY_DETAIL_TARGET_FMA
    return R(0.5) * (std::fma(a, fa, b * fb) + std::fma(b, fb, a * fa));
#else
    return a * fa + b * fb;
#endif
}

// Rec. 709 luminance weights of r, g, b, summed in that order, fused the one way.
template <class R>
inline R luminance(R r, R g, R b) noexcept {
#ifdef FIREFLY_DETAIL_TARGET_FMA
    return std::fma(R(0.0722), b, std::fma(R(0.7152), g, R(0.2126) * r));
#else
    return R(0.2126) * r + R(0.7152) * g + R(0.0722) * b;
#endif
}

}  // namespace firefly::detail
