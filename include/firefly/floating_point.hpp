// firefly: what the library needs from the compiler's floating point.
//
// IEEE semantics: NaN and Inf are what the library finds and repairs in renderer output, its
// statistics reach tails of 1e-300 and sum with compensation, and its results must not depend
// on scan order. -ffast-math (GCC, Clang), -ffinite-math-only and MSVC's /fp:fast let the
// compiler drop the NaN and Inf tests and reorder sums: built so, the tests found a Student-t
// point of infinity at q = 1e-250 and a crash on a NaN degree of freedom. So a translation
// unit built so is refused here, with the way out in the message. Defining
// FIREFLY_ALLOW_FAST_MATH builds it anyway, without those guarantees.
//
// And C++17, said plainly (every header but parallel.hpp and version.hpp includes this one):
// before it the first error was an unrelated one deep in a header. MSVC reports its standard
// in _MSVC_LANG (__cplusplus stays 199711L without /Zc:__cplusplus).
#pragma once

#if defined(_MSVC_LANG)
#if _MSVC_LANG < 201703L
#error "firefly needs C++17 or later: compile with /std:c++17"
#endif
#elif __cplusplus < 201703L
#error "firefly needs C++17 or later: compile with -std=c++17 (CMake: the firefly::firefly target asks for it)"
#endif

#if !defined(FIREFLY_ALLOW_FAST_MATH) && \
    (defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__) || defined(_M_FP_FAST))
#error "firefly needs IEEE floating point, which -ffast-math, -ffinite-math-only and /fp:fast turn off: compile the files that include firefly without them (GCC, Clang: -fno-fast-math on those files), or define FIREFLY_ALLOW_FAST_MATH to build them anyway, without firefly's NaN repair and exactness guarantees."
#endif
