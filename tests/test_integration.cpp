// The integration a renderer writes: views over its own buffers (planar, RGBA, strided tiles,
// mixed channel types), its own thread pool through executor, the report, the masks.
#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <thread>
#include <vector>

#include "catch.hpp"

namespace {

// A minimal IEEE binary16 type, standing in for a renderer's half (Imath::half and the like).
struct half16 {
    std::uint16_t bits = 0;
};
half16 to_half(float f) {  // round to nearest even; enough range for the test's values
    std::uint32_t x;
    std::memcpy(&x, &f, 4);
    const std::uint32_t sign = (x >> 16) & 0x8000u;
    const int e = static_cast<int>((x >> 23) & 0xff) - 127 + 15;
    std::uint32_t m = x & 0x7fffffu;
    if (e <= 0) return {static_cast<std::uint16_t>(sign)};  // flush tiny values to zero
    if (e >= 31) return {static_cast<std::uint16_t>(sign | 0x7c00u)};
    std::uint32_t h = sign | (static_cast<std::uint32_t>(e) << 10) | (m >> 13);
    const std::uint32_t rest = m & 0x1fffu;
    if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) ++h;
    return {static_cast<std::uint16_t>(h)};
}
float to_float(half16 v) {
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

}  // namespace

namespace {
std::size_t rows_converted = 0;  // how often the bulk hook ran
}

// The traits hook: how one half16 channel reads and writes as double, and (optional, the
// fast path of the standard-deviation pass) how a run of them converts to float.
template <>
struct firefly::channel_traits<half16> {
    static constexpr bool is_specialized = true;
    static double load(half16 v) noexcept { return ::to_float(v); }
    static half16 store(double v) noexcept { return to_half(static_cast<float>(v)); }
    static void to_float(const half16* in, float* out, std::size_t n) noexcept {
        ++rows_converted;
        for (std::size_t i = 0; i < n; ++i) out[i] = ::to_float(in[i]);
    }
};

using namespace firefly;

namespace {
sim::frame scene(int w, int h) {
    sim::frame f = sim::simulate(sim::named_scene("production", w, h, 23));
    f.alpha.clear();
    return f;
}
std::vector<float> packed_run(const sim::frame& f, std::vector<std::uint8_t>* masks = nullptr) {
    std::vector<float> c[2] = {f.color[0], f.color[1]}, v[2] = {f.variance[0], f.variance[1]};
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        hb[k].color = *make_image_view(c[k].data(), f.width, f.height, 3);
        hb[k].variance = *make_image_view(v[k].data(), f.width, f.height, 3);
    }
    detector d;
    if (masks) {
        masks[0].assign(f.pixels(), 0);
        masks[1].assign(f.pixels(), 0);
        (void)d.process(hb[0], hb[1], *make_image_view(masks[0].data(), f.width, f.height),
                        *make_image_view(masks[1].data(), f.width, f.height));
    } else {
        (void)d.process(hb[0], hb[1]);
    }
    std::vector<float> out = c[0];
    out.insert(out.end(), c[1].begin(), c[1].end());
    return out;
}
}  // namespace

TEST_CASE("planar buffers (one plane per channel) give the packed result", "[integration]") {
    const int w = 80, h = 60;
    const sim::frame f = scene(w, h);
    const std::vector<float> ref = packed_run(f);
    const std::size_t n = f.pixels();
    std::vector<float> planes[2], vplanes[2];
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        planes[k].resize(n * 3);
        vplanes[k].resize(n * 3);
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t c = 0; c < 3; ++c) {
                planes[k][c * n + i] = f.color[k][i * 3 + c];
                vplanes[k][c * n + i] = f.variance[k][i * 3 + c];
            }
        hb[k].color = *make_planar_view(planes[k].data(), w, h, 3);
        hb[k].variance = *make_planar_view(vplanes[k].data(), w, h, 3);
    }
    detector d;
    REQUIRE(d.process(hb[0], hb[1]).ok());
    for (int k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t c = 0; c < 3; ++c) REQUIRE(planes[k][c * n + i] == ref[k * n * 3 + i * 3 + c]);
}

TEST_CASE("RGBA colour with its alpha as coverage, in one line", "[integration]") {
    const int w = 64, h = 48;
    const sim::frame f = scene(w, h);
    std::vector<float> rgba[2], var[2];
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        rgba[k].resize(f.pixels() * 4);
        for (std::size_t i = 0; i < f.pixels(); ++i) {
            for (std::size_t c = 0; c < 3; ++c) rgba[k][i * 4 + c] = f.color[k][i * 3 + c];
            rgba[k][i * 4 + 3] = (i % static_cast<std::size_t>(w)) < 8 ? 0.0f : 1.0f;  // a transparent strip
        }
        var[k] = f.variance[k];
        const image_view<float> all = *make_image_view(rgba[k].data(), w, h, 4);
        hb[k].color = *all.channel_range(0, 3);
        hb[k].variance = *make_image_view(var[k].data(), w, h, 3);
        hb[k].alpha = all.channel_range(3, 1).value();  // the 4th channel as coverage
    }
    detector d;
    const frame_report r = d.process(hb[0], hb[1]);
    REQUIRE(r.ok());
    CHECK(r.half[0].ignored >= static_cast<std::size_t>(8 * h));  // the strip is out of the statistics
    for (int k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < f.pixels(); ++i) REQUIRE(rgba[k][i * 4 + 3] == ((i % static_cast<std::size_t>(w)) < 8 ? 0.0f : 1.0f));
}

TEST_CASE("a tile of a larger framebuffer, through a strided sub-view", "[integration]") {
    // The renderer's framebuffer is 100 x 70 with rows padded to 128 pixels; the frame
    // handed to firefly is the 64 x 48 tile at (20, 10).
    const int fw = 128, fh = 70, tw = 64, th = 48, tx = 20, ty = 10;
    const sim::frame f = scene(tw, th);
    const std::vector<float> ref = packed_run(f);
    std::vector<float> fb[2], fv[2];
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        fb[k].assign(static_cast<std::size_t>(fw * fh * 3), -7.0f);
        fv[k].assign(static_cast<std::size_t>(fw * fh * 3), -7.0f);
        const image_view<float> cbuf = *make_image_view(fb[k].data(), fw, fh, 3);
        const image_view<float> vbuf = *make_image_view(fv[k].data(), fw, fh, 3);
        hb[k].color = *cbuf.subview(tx, ty, tw, th);
        hb[k].variance = *vbuf.subview(tx, ty, tw, th);
        for (int y = 0; y < th; ++y)
            for (int x = 0; x < tw; ++x)
                for (int c = 0; c < 3; ++c) {
                    const std::size_t i = (static_cast<std::size_t>(y) * tw + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c);
                    hb[k].color(x, y, c) = f.color[k][i];
                    hb[k].variance(x, y, c) = f.variance[k][i];
                }
    }
    detector d;
    REQUIRE(d.process(hb[0], hb[1]).ok());
    for (int k = 0; k < 2; ++k)
        for (int y = 0; y < fh; ++y)
            for (int x = 0; x < fw; ++x) {
                const bool inside = x >= tx && y >= ty && x < tx + tw && y < ty + th;
                for (int c = 0; c < 3; ++c) {
                    const float got = fb[k][(static_cast<std::size_t>(y) * fw + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c)];
                    if (!inside) {
                        REQUIRE(got == -7.0f);  // nothing outside the tile is touched
                    } else {
                        const std::size_t i = (static_cast<std::size_t>(y - ty) * tw + static_cast<std::size_t>(x - tx)) * 3 + static_cast<std::size_t>(c);
                        REQUIRE(got == ref[static_cast<std::size_t>(k) * f.pixels() * 3 + i]);
                    }
                }
            }
}

TEST_CASE("float colour, half-float variance and a double alpha buffer", "[integration]") {
    const int w = 64, h = 48;
    sim::frame f = scene(w, h);
    for (int k = 0; k < 2; ++k)
        for (float& v : f.variance[k]) v = to_float(to_half(v));  // what half storage keeps
    const std::vector<float> ref = packed_run(f);
    std::vector<float> col[2];
    std::vector<half16> var[2];
    std::vector<double> alpha(f.pixels(), 1.0);
    half_buffer<float, half16, const double> hb[2];
    for (int k = 0; k < 2; ++k) {
        col[k] = f.color[k];
        var[k].resize(f.variance[k].size());
        for (std::size_t i = 0; i < var[k].size(); ++i) var[k][i] = to_half(f.variance[k][i]);
        hb[k].color = *make_image_view(col[k].data(), w, h, 3);
        hb[k].variance = *make_image_view(var[k].data(), w, h, 3);
        hb[k].alpha = *make_image_view(static_cast<const double*>(alpha.data()), w, h, 1);
    }
    detector d;
    rows_converted = 0;
    const frame_report r = d.process(hb[0], hb[1]);
    REQUIRE(r.ok());
    CHECK(rows_converted == 0);  // a double alpha: value by value through the traits
    // without alpha (or with float alpha) the fast path converts each row once
    std::vector<float> col2[2] = {f.color[0], f.color[1]};
    std::vector<half16> var2[2];
    half_buffer<float, half16, const float> hf[2];
    for (int k = 0; k < 2; ++k) {
        for (const float v : f.variance[k]) var2[k].push_back(to_half(v));
        hf[k].color = *make_image_view(col2[k].data(), w, h, 3);
        hf[k].variance = *make_image_view(var2[k].data(), w, h, 3);
    }
    rows_converted = 0;
    detector d2;
    REQUIRE(d2.process(hf[0], hf[1]).ok());
    CHECK(rows_converted == static_cast<std::size_t>(2 * h));
    for (int k = 0; k < 2; ++k) CHECK(col2[k] == col[k]);  // both paths: the same bits
    // the same detections as the all-float run; values to the rounding of half storage
    std::size_t differ = 0;
    for (int k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < col[k].size(); ++i)
            differ += std::fabs(col[k][i] - ref[static_cast<std::size_t>(k) * f.pixels() * 3 + i]) > 1e-3f * (1.0f + std::fabs(col[k][i]));
    CHECK(differ == 0);
    CHECK(r.half[0].fireflies > 0);
}

TEST_CASE("the renderer's own thread pool through executor", "[integration]") {
    const int w = 96, h = 64;
    const sim::frame f = scene(w, h);
    const std::vector<float> ref = packed_run(f);
    // a job system: run(count, task) fans tasks out to its workers and waits
    std::atomic<int> jobs{0};
    executor pool([&](std::size_t count, const executor::task& task) {
        std::vector<std::thread> workers;
        for (std::size_t i = 0; i < count; ++i) workers.emplace_back([&task, i, &jobs] { ++jobs; task(i); });
        for (auto& t : workers) t.join();
    });
    std::vector<float> c[2] = {f.color[0], f.color[1]}, v[2] = {f.variance[0], f.variance[1]};
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        hb[k].color = *make_image_view(c[k].data(), w, h, 3);
        hb[k].variance = *make_image_view(v[k].data(), w, h, 3);
    }
    detector d(detector_options{}, pool);
    REQUIRE(d.process(hb[0], hb[1]).ok());
    CHECK(jobs.load() >= 4);
    for (int k = 0; k < 2; ++k)
        CHECK(std::memcmp(c[k].data(), ref.data() + static_cast<std::size_t>(k) * f.pixels() * 3, c[k].size() * 4) == 0);
}

TEST_CASE("the report and the masks, as a denoiser would use them", "[integration]") {
    const int w = 96, h = 64;
    const sim::frame f = scene(w, h);
    std::vector<std::uint8_t> m[2];
    const std::vector<float> out = packed_run(f, m);
    std::size_t fireflies = 0, other = 0, changed = 0, changed_unmarked = 0;
    for (int k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < f.pixels(); ++i) {
            fireflies += (m[k][i] & mask_bits::firefly) != 0;
            other += (m[k][i] & mask_bits::other_half) != 0;
            const bool ch = std::memcmp(&out[static_cast<std::size_t>(k) * f.pixels() * 3 + i * 3], &f.color[k][i * 3], 12) != 0;
            changed += ch;
            changed_unmarked += ch && !(m[k][i] & (mask_bits::firefly | mask_bits::nonfinite));
        }
    CHECK(fireflies > 0);
    CHECK(other > 0);  // pixels whose halves are now correlated: a denoiser's cross-validation skips them
    CHECK(changed > 0);
    CHECK(changed_unmarked == 0);  // every change is marked
}
