// What a frame's cleaning may not depend on: which half is called A, the order of the colour
// channels, and the exposure.
//
// Exposure: a render's units are the renderer's (radiance in W, a normalised 0-1, a camera's
// exposure), so no decision may depend on them. Every test statistic is a ratio of the frame's
// own values, so a frame scaled by s (colour times s, variance times s^2) is cleaned to the
// same masks, and, where s is a power of two (every rounding scales with it), to exactly s
// times the same output, bit for bit. An absolute constant anywhere in the pipeline (a floor
// on a level, an epsilon on a variance) breaks this at some exposure.
#include <firefly/firefly.hpp>
#include <firefly/sim/scenes.hpp>

#include "buffer_views.hpp"
#include "catch.hpp"
#include "frame_views.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

using namespace firefly;

namespace {

// Every value of v times s, rounded to float (exact for a power of two within float's range).
void scale(std::vector<float>& v, double s) {
    for (float& x : v) x = static_cast<float>(static_cast<double>(x) * s);
}

// How many values of `got` differ from s times `base`: bit for bit (exact) or by more than
// 1e-3 of their size (else).
std::size_t scaled_differences(const std::vector<float>& base, const std::vector<float>& got, double s, bool exact) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < base.size(); ++i) {
        const float want = static_cast<float>(static_cast<double>(base[i]) * s);
        if (exact) n += std::memcmp(&want, &got[i], sizeof(float)) != 0;
        else
            n += !(std::fabs(static_cast<double>(want) - got[i]) <= 1e-3 * std::fabs(static_cast<double>(want)) + 1e-30);
    }
    return n;
}

std::size_t mask_differences(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < a.size(); ++i) n += a[i] != b[i];
    return n;
}

// Powers of two from 2^-40 to 2^40 (a firefly's variance at 2^40 stays below FLT_MAX), and
// three that are not.
const std::vector<double>& exposures() {
    static const std::vector<double> s = {std::ldexp(1.0, -40), std::ldexp(1.0, -7), 0.5, std::ldexp(1.0, 9),
                                          std::ldexp(1.0, 40), 3.7, 1e-3, 1e6};
    return s;
}

bool power_of_two(double s) {
    int e = 0;
    return std::frexp(s, &e) == 0.5;
}

// f(name, seed, frame) for every named scene at 64x48, seeds 1 to `seeds`.
template <class F>
void each_scene(std::uint64_t seeds, F&& f) {
    for (const std::string& name : sim::scene_names())
        for (std::uint64_t seed = 1; seed <= seeds; ++seed)
            f(name, seed, sim::simulate(sim::named_scene(name, 64, 48, seed)));
}

// Both halves cleaned by a fresh detector, its masks in v.mask.
frame_report clean(firefly_test::frame_views& v) {
    detector d;
    return v.process(d);
}

// K buffers cleaned in place by a fresh detector, its masks in m.
cross_buffer_report clean(firefly_test::frame_k& f, firefly_test::masks_k& m, bool with_variance) {
    cross_buffer_detector d;
    return d.process(f.views(with_variance), m.views);
}

}  // namespace

TEST_CASE("exposure: two halves scaled by s are cleaned to the same masks and s times the output", "[exposure]") {
    each_scene(2, [](const std::string& name, std::uint64_t seed, const sim::frame& base) {
        firefly_test::frame_views ref(base);
        const frame_report r0 = clean(ref);
        for (const double s : exposures()) {
            sim::frame g = base;
            for (int h = 0; h < 2; ++h) {
                scale(g.color[h], s);
                scale(g.variance[h], s * s);
            }
            firefly_test::frame_views fv(std::move(g));
            const frame_report r = clean(fv);
            const bool exact = power_of_two(s);
            INFO(name << " seed " << seed << " exposure " << s);
            CHECK(r.ok() == r0.ok());
            for (int h = 0; h < 2; ++h) {
                CHECK(r.half[h].fireflies == r0.half[h].fireflies);
                CHECK(r.half[h].highlights == r0.half[h].highlights);
                CHECK(mask_differences(ref.mask[h], fv.mask[h]) == 0);
                CHECK(scaled_differences(ref.f.color[h], fv.f.color[h], s, exact) == 0);
                CHECK(scaled_differences(ref.f.variance[h], fv.f.variance[h], s * s, exact) == 0);
            }
        }
    });
}

TEST_CASE("exposure: K buffers scaled by s are cleaned to the same masks and s times the output", "[exposure]") {
    for (const char* name : {"production", "caustics", "decades", "interior", "black_alpha", "null_k4_spp64"}) {
        for (const int k : {3, 4, 8}) {
            for (const bool with_variance : {false, true}) {
                const firefly_test::frame_k base =
                    firefly_test::from_sim(sim::simulate_buffers(sim::named_scene(name, 48, 40, 1), k));
                firefly_test::frame_k ref = base;
                firefly_test::masks_k ref_mask(k, base.w, base.h);
                const cross_buffer_report r0 = clean(ref, ref_mask, with_variance);
                for (const double s : exposures()) {
                    firefly_test::frame_k g = base;
                    for (auto& c : g.color) scale(c, s);
                    for (auto& v : g.variance) scale(v, s * s);
                    firefly_test::masks_k g_mask(k, base.w, base.h);
                    const cross_buffer_report r = clean(g, g_mask, with_variance);
                    INFO(name << " K " << k << " variance " << with_variance << " exposure " << s);
                    CHECK(r.ok() == r0.ok());
                    CHECK(r.fireflies == r0.fireflies);
                    for (int b = 0; b < k; ++b) {
                        const std::size_t i = static_cast<std::size_t>(b);
                        CHECK(mask_differences(ref_mask.mem[i], g_mask.mem[i]) == 0);
                        CHECK(scaled_differences(ref.color[i], g.color[i], s, power_of_two(s)) == 0);
                        if (with_variance)
                            CHECK(scaled_differences(ref.variance[i], g.variance[i], s * s, power_of_two(s)) == 0);
                    }
                }
            }
        }
    }
}

TEST_CASE("the halves exchanged give the same output exchanged, bit for bit", "[invariant]") {
    each_scene(2, [](const std::string& name, std::uint64_t seed, const sim::frame& base) {
        firefly_test::frame_views ab(base);
        const frame_report r0 = clean(ab);
        sim::frame g = base;
        std::swap(g.color[0], g.color[1]);
        std::swap(g.variance[0], g.variance[1]);
        firefly_test::frame_views ba(std::move(g));
        const frame_report r = clean(ba);
        INFO(name << " seed " << seed);
        CHECK(r.ok() == r0.ok());
        CHECK(r.both_outliers == r0.both_outliers);
        for (int h = 0; h < 2; ++h) {
            CHECK(r.half[h].fireflies == r0.half[1 - h].fireflies);
            CHECK(r.half[h].highlights == r0.half[1 - h].highlights);
            CHECK(ab.mask[h] == ba.mask[1 - h]);
            CHECK(std::memcmp(ab.f.color[h].data(), ba.f.color[1 - h].data(), ab.f.color[h].size() * sizeof(float)) == 0);
            CHECK(std::memcmp(ab.f.variance[h].data(), ba.f.variance[1 - h].data(),
                              ab.f.variance[h].size() * sizeof(float)) == 0);
        }
    });
}

TEST_CASE("the colour channels permuted give the same masks and the output permuted", "[invariant]") {
    // (a pixel's level is the channels' sum, taken in another order: the last bit may move)
    const int perm[3] = {2, 0, 1};
    each_scene(1, [&](const std::string& name, std::uint64_t, const sim::frame& base) {
        firefly_test::frame_views ref(base);
        (void)clean(ref);
        sim::frame g = base;
        for (int h = 0; h < 2; ++h)
            for (std::size_t i = 0; i < g.color[h].size(); i += 3)
                for (std::size_t c = 0; c < 3; ++c) {
                    g.color[h][i + c] = base.color[h][i + static_cast<std::size_t>(perm[c])];
                    g.variance[h][i + c] = base.variance[h][i + static_cast<std::size_t>(perm[c])];
                }
        firefly_test::frame_views fv(std::move(g));
        (void)clean(fv);
        INFO(name);
        for (int h = 0; h < 2; ++h) {
            CHECK(mask_differences(ref.mask[h], fv.mask[h]) == 0);
            std::vector<float> back(fv.f.color[h].size());  // the output's channels put back
            for (std::size_t i = 0; i < back.size(); i += 3)
                for (std::size_t c = 0; c < 3; ++c) back[i + static_cast<std::size_t>(perm[c])] = fv.f.color[h][i + c];
            CHECK(scaled_differences(ref.f.color[h], back, 1.0, false) == 0);
        }
    });
}
