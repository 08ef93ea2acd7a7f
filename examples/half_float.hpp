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

inline half16 to_half(float f) {  // round to nearest even; tiny values flush to zero
    std::uint32_t x;
    std::memcpy(&x, &f, 4);
    const std::uint32_t sign = (x >> 16) & 0x8000u;
    const int e = static_cast<int>((x >> 23) & 0xff) - 127 + 15;
    std::uint32_t m = x & 0x7fffffu;
    if (e <= 0) return {static_cast<std::uint16_t>(sign)};
    if (e >= 31) return {static_cast<std::uint16_t>(sign | 0x7c00u)};
    std::uint32_t h = sign | (static_cast<std::uint32_t>(e) << 10) | (m >> 13);
    const std::uint32_t rest = m & 0x1fffu;
    if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) ++h;
    return {static_cast<std::uint16_t>(h)};
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
    static double load(firefly_examples::half16 v) noexcept { return firefly_examples::half16_table()[v.bits]; }
    static firefly_examples::half16 store(double v) noexcept {
        return firefly_examples::to_half(static_cast<float>(v));
    }
    static void to_float(const firefly_examples::half16* in, float* out, std::size_t n) noexcept {
        ++firefly_examples::half16_rows_converted;
        const float* table = firefly_examples::half16_table();
        for (std::size_t i = 0; i < n; ++i) out[i] = table[in[i].bits];
    }
};
