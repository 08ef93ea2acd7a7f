// The fuzz targets' shared pieces: how a target fails, how it compares values, and the values
// it feeds the detectors.
#pragma once

#include <fuzzer/FuzzedDataProvider.h>

#include <cfloat>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>

namespace fuzz_values {

// Reports what failed and aborts: libFuzzer keeps the input as a reproducer.
[[noreturn]] inline void fail(const char* target, const char* what) {
    std::fprintf(stderr, "%s: %s\n", target, what);
    std::abort();
}

// Whether a and b hold the same bytes (NaN payloads and the sign of 0 included).
template <class T>
bool same_bits(const T& a, const T& b) {
    return std::memcmp(&a, &b, sizeof(T)) == 0;
}

// A value: mostly plausible radiance (so that fireflies occur), sometimes a special value or
// raw bits.
template <class T>
T value(FuzzedDataProvider& p, bool variance) {
    const int kind = p.ConsumeIntegralInRange<int>(0, 15);
    if (kind < 10) {
        const double v = p.ConsumeIntegralInRange<int>(0, 1000) / 100.0;
        return static_cast<T>(kind == 9 ? v * 1000 : variance ? v * v * 0.01 : v);
    }
    if (kind == 10) {
        static const T special[] = {std::numeric_limits<T>::quiet_NaN(), std::numeric_limits<T>::infinity(),
                                    -std::numeric_limits<T>::infinity(), T(-0.0), std::numeric_limits<T>::denorm_min(),
                                    std::numeric_limits<T>::max(), -std::numeric_limits<T>::max(), T(FLT_MAX),
                                    T(0), std::numeric_limits<T>::min(), T(-1)};
        return special[p.ConsumeIntegralInRange<std::size_t>(0, sizeof special / sizeof special[0] - 1)];
    }
    if (sizeof(T) == 4 || kind == 11) {
        const std::uint32_t bits = p.ConsumeIntegral<std::uint32_t>();
        float f;
        std::memcpy(&f, &bits, 4);
        return static_cast<T>(f);
    }
    const std::uint64_t bits = p.ConsumeIntegral<std::uint64_t>();
    T d;
    std::memcpy(&d, &bits, sizeof d);
    return d;
}

// One input: run(p, float{}) or run(p, double{}), as its first bit says.
template <class Run>
int float_or_double(const std::uint8_t* data, std::size_t size, Run&& run) {
    FuzzedDataProvider p(data, size);
    if (p.ConsumeBool()) run(p, float{});
    else run(p, double{});
    return 0;
}

}  // namespace fuzz_values
