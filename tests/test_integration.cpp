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

#include "../examples/half_float.hpp"
#include "catch.hpp"

using firefly_examples::half16;
using firefly_examples::to_half;
using firefly_examples::to_float;

using namespace firefly;

namespace {
sim::frame scene(int w, int h) {
    sim::frame f = sim::simulate(sim::named_scene("production", w, h, 23));
    f.alpha.clear();
    return f;
}
std::vector<float> packed_run(const sim::frame& f, std::vector<std::uint8_t>* masks = nullptr,
                              const detector_options& options = {}) {
    std::vector<float> c[2] = {f.color[0], f.color[1]}, v[2] = {f.variance[0], f.variance[1]};
    half_buffer<float> hb[2];
    for (int k = 0; k < 2; ++k) {
        hb[k].color = *make_image_view(c[k].data(), f.width, f.height, 3);
        hb[k].variance = *make_image_view(v[k].data(), f.width, f.height, 3);
    }
    detector d(options);
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
    // The energy return off in every run: it adds light where the return exceeds a pixel's
    // standard error, and a rebuilt pixel's variance, stored as half, may sit on either side
    // of that (here 2 of 3072 pixels: 0.003 added in one run, not in the other).
    detector_options o;
    o.return_energy = false;
    const std::vector<float> ref = packed_run(f, nullptr, o);
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
    detector d(o);
    firefly_examples::half16_rows_converted = 0;
    const frame_report r = d.process(hb[0], hb[1]);
    REQUIRE(r.ok());
    // Rows converted in bulk: the local test's levels convert each row of each half once; the
    // standard-deviation pass goes value by value with a double alpha ...
    CHECK(firefly_examples::half16_rows_converted == static_cast<std::size_t>(2 * h));
    // ... and without alpha (or with float alpha) takes the fast path: each row once more
    std::vector<float> col2[2] = {f.color[0], f.color[1]};
    std::vector<half16> var2[2];
    half_buffer<float, half16, const float> hf[2];
    for (int k = 0; k < 2; ++k) {
        for (const float v : f.variance[k]) var2[k].push_back(to_half(v));
        hf[k].color = *make_image_view(col2[k].data(), w, h, 3);
        hf[k].variance = *make_image_view(var2[k].data(), w, h, 3);
    }
    firefly_examples::half16_rows_converted = 0;
    detector d2(o);
    REQUIRE(d2.process(hf[0], hf[1]).ok());
    CHECK(firefly_examples::half16_rows_converted == static_cast<std::size_t>(4 * h));
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
    std::size_t fireflies = 0, other = 0, changed = 0, changed_unmarked = 0, energy = 0, lowered_by_energy = 0;
    for (int k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < f.pixels(); ++i) {
            fireflies += (m[k][i] & mask_bits::firefly) != 0;
            other += (m[k][i] & mask_bits::other_half) != 0;
            const bool ch = std::memcmp(&out[static_cast<std::size_t>(k) * f.pixels() * 3 + i * 3], &f.color[k][i * 3], 12) != 0;
            changed += ch;
            changed_unmarked += ch && !(m[k][i] & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::energy));
            energy += (m[k][i] & mask_bits::energy) != 0;
            // the energy return only adds light
            const float* o = &out[static_cast<std::size_t>(k) * f.pixels() * 3 + i * 3];
            const float* in = &f.color[k][i * 3];
            if ((m[k][i] & mask_bits::energy) && !(m[k][i] & mask_bits::firefly))
                lowered_by_energy += o[0] < in[0] || o[1] < in[1] || o[2] < in[2];
        }
    CHECK(fireflies > 0);
    CHECK(other > 0);  // pixels whose halves are now correlated: a denoiser's cross-validation skips them
    CHECK(changed > 0);
    CHECK(changed_unmarked == 0);  // every change is marked
    CHECK(energy > 0);
    CHECK(lowered_by_energy == 0);
}

TEST_CASE("half colour and variance: the bulk row path and value-by-value loading agree", "[integration]") {
    const int w = 80, h = 70, pad = 5;  // padded rows are not packed: value by value
    const sim::frame f = scene(w, h);
    std::vector<half16> packed[2][2], padded[2][2];
    half_buffer<const half16> fast[2], slow[2];
    const std::vector<float>* src[2][2] = {{&f.color[0], &f.variance[0]}, {&f.color[1], &f.variance[1]}};
    for (int k = 0; k < 2; ++k)
        for (int j = 0; j < 2; ++j) {
            for (const float v : *src[k][j]) packed[k][j].push_back(to_half(v));
            padded[k][j].assign(static_cast<std::size_t>(w * 3 + pad) * h, half16{});
            for (int y = 0; y < h; ++y)
                std::copy_n(&packed[k][j][static_cast<std::size_t>(y) * w * 3], w * 3,
                            &padded[k][j][static_cast<std::size_t>(y) * (w * 3 + pad)]);
        }
    const auto row = static_cast<std::ptrdiff_t>((w * 3 + pad) * sizeof(half16));
    for (int k = 0; k < 2; ++k) {
        fast[k] = {*make_image_view(static_cast<const half16*>(packed[k][0].data()), w, h, 3),
                   *make_image_view(static_cast<const half16*>(packed[k][1].data()), w, h, 3), {}};
        slow[k] = {*make_image_view(static_cast<const half16*>(padded[k][0].data()), w, h, 3, row),
                   *make_image_view(static_cast<const half16*>(padded[k][1].data()), w, h, 3, row), {}};
    }
    std::vector<std::uint8_t> m[2][2];
    frame_report r[2];
    for (int p = 0; p < 2; ++p) {
        for (auto& v : m[p]) v.assign(f.pixels(), 0);
        detector d;
        const half_buffer<const half16>* hb = p == 0 ? fast : slow;
        firefly_examples::half16_rows_converted = 0;
        r[p] = d.detect(hb[0], hb[1], *make_image_view(m[p][0].data(), w, h), *make_image_view(m[p][1].data(), w, h));
        REQUIRE(r[p].ok());
        CHECK((firefly_examples::half16_rows_converted > 0) == (p == 0));
    }
    CHECK(r[0].half[0].fireflies > 0);
    for (int k = 0; k < 2; ++k) {
        CHECK(m[0][k] == m[1][k]);
        CHECK(r[0].half[k].outliers == r[1].half[k].outliers);
        CHECK(r[0].half[k].median == r[1].half[k].median);
    }
}
