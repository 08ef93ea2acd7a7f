// A renderer's own channel type through firefly::channel_traits: a minimal IEEE binary16
// (standing in for Imath::half and the like). load/store are what every view needs; the
// optional to_float(in, out, n) converts a run of values at once and puts the type on the
// packed fast paths (the standard-deviation pass, the local test's levels). Loads read a
// table of all 65,536 values, as Imath's half does: a lookup instead of the bit surgery.
#pragma once

#include <firefly/image_view.hpp>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

namespace firefly_examples {

struct half16 {
    std::uint16_t bits = 0;
};

// float -> half as Imath::half converts: round to nearest even, half's subnormals below
// 2^-14, overflow to infinity, and a NaN stays a NaN (sign and the top of its payload kept).
inline half16 to_half(float f) {
    std::uint32_t x;
    std::memcpy(&x, &f, 4);
    const std::uint32_t sign = (x >> 16) & 0x8000u, a = x & 0x7fffffffu;
    auto bits = [&](std::uint32_t h) { return half16{static_cast<std::uint16_t>(sign | h)}; };
    if (a >= 0x7f800000u) {  // Inf, NaN: a NaN whose payload lies below half's bits keeps one
        const std::uint32_t m = (a & 0x7fffffu) >> 13;
        return bits(0x7c00u | m | (a != 0x7f800000u && m == 0 ? 1u : 0u));
    }
    if (a >= 0x477ff000u) return bits(0x7c00u);  // 65520 and above round past 65504
    if (a >= 0x38800000u) {                       // a normal half: rebias, round 13 bits to even
        const std::uint32_t r = a - 0x38000000u;
        return bits((r + 0xfffu + ((r >> 13) & 1u)) >> 13);
    }
    if (a <= 0x33000000u) return bits(0);  // up to 2^-25, half the smallest subnormal: to even, 0
    // a subnormal half: the significand in units of 2^-24, rounded to even (it may round up
    // to the smallest normal, whose bits follow the largest subnormal's)
    const int shift = 126 - static_cast<int>(a >> 23);  // 14 .. 24
    const std::uint32_t s = 0x800000u | (a & 0x7fffffu), tie = 1u << (shift - 1);
    const std::uint32_t h = s >> shift, rest = s & ((tie << 1) - 1u);
    return bits(h + (rest > tie || (rest == tie && (h & 1u)) ? 1u : 0u));
}

inline float to_float(half16 v) {
    const std::uint32_t sign = static_cast<std::uint32_t>(v.bits & 0x8000u) << 16;
    const int e = (v.bits >> 10) & 0x1f;
    const std::uint32_t m = v.bits & 0x3ffu;
    std::uint32_t x;
    if (e == 0) {
        const float f = std::ldexp(static_cast<float>(m), -24);
        std::memcpy(&x, &f, 4);
        x |= sign;
    } else if (e == 31) {
        x = sign | 0x7f800000u | (m << 13);
    } else {
        x = sign | (static_cast<std::uint32_t>(e - 15 + 127) << 23) | (m << 13);
    }
    float f;
    std::memcpy(&f, &x, 4);
    return f;
}

// Every half's float, built once (to_float above; thread-safe static initialisation).
inline const float* half16_table() {
    static const std::vector<float> table = [] {
        std::vector<float> t(65536);
        for (std::uint32_t b = 0; b < 65536; ++b) t[b] = to_float(half16{static_cast<std::uint16_t>(b)});
        return t;
    }();
    return table.data();
}

inline std::atomic<std::size_t> half16_rows_converted{0};  // how often the bulk hook ran (tests read it;
                                                           // rows convert on any thread)

}  // namespace firefly_examples

template <>
struct firefly::channel_traits<firefly_examples::half16> {
    static constexpr bool is_specialized = true;
    static double load(firefly_examples::half16 v) noexcept {
        return static_cast<double>(firefly_examples::half16_table()[v.bits]);
    }
    static firefly_examples::half16 store(double v) noexcept {
        return firefly_examples::to_half(static_cast<float>(v));
    }
    static void to_float(const firefly_examples::half16* in, float* out, std::size_t n) noexcept {
        ++firefly_examples::half16_rows_converted;
        const float* table = firefly_examples::half16_table();
        for (std::size_t i = 0; i < n; ++i) out[i] = table[in[i].bits];
    }
};
