// Implausible values (implausible.hpp): a finite value that the other half (or the other
// buffers) shows no Monte Carlo estimate holds is rebuilt as a non-finite one is.
#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scenes.hpp>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include "catch.hpp"
#include "frame_views.hpp"

using namespace firefly;
using firefly_test::frame_views;

namespace {
constexpr double pi = 3.14159265358979323846;
const double nan_v = std::numeric_limits<double>::quiet_NaN();

// A simulated frame with the 24x20 tile at (40, 30) of half A's colour set to `value` (its
// variance kept), cleaned by a detector with the given options; its report.
struct tiled_frame {
    static constexpr int x0 = 40, y0 = 30, tw = 24, th = 20, w = 128, h = 96;
    frame_views v;
    std::vector<float> input[2];
    frame_report report;
    explicit tiled_frame(float value, const detector_options& o = {}, bool detect_only = false)
        : v(sim::simulate(sim::named_scene("sparse_fireflies", w, h, 4))) {
        for (int y = y0; y < y0 + th; ++y)
            for (int x = x0; x < x0 + tw; ++x)
                for (std::size_t c = 0; c < 3; ++c) v.f.color[0][v.at(x, y) * 3 + c] = value;
        input[0] = v.f.color[0], input[1] = v.f.color[1];
        detector d(o);
        report = detect_only ? v.detect(d) : v.process(d);
    }
    static bool in_tile(int x, int y) { return x >= x0 && x < x0 + tw && y >= y0 && y < y0 + th; }
};
}  // namespace

TEST_CASE("implausible_bound: 2 m / (pi alpha), a bad alpha taken as 0.05", "[implausible]") {
    CHECK(detail::implausible_bound(1000, 0.05) == Approx(2 * 1000 / (pi * 0.05)).epsilon(1e-15));
    CHECK(detail::implausible_bound(2048u * 1080u, 0.05) == Approx(2.816e7).epsilon(1e-3));
    CHECK(detail::implausible_bound(0, 0.05) == detail::implausible_bound(1, 0.05));
    for (const double bad : {0.0, -1.0, 1.0, nan_v}) CHECK(detail::implausible_bound(100, bad) == detail::implausible_bound(100, 0.05));
    CHECK(detail::implausible_bound(100, 0.01) > detail::implausible_bound(100, 0.1));  // stricter, higher
    CHECK(detail::implausible_bound(200, 0.05) > detail::implausible_bound(100, 0.05));
}

TEST_CASE("implausible_half: the t statistic against the bound, the larger magnitude chosen", "[implausible]") {
    // (the noise is at least the smaller level: with a half at 0 the t statistic alone)
    const double bound = 1e6;
    // z = |la - lb| / sqrt(va + vb): 1e6 exactly is not above the bound, a hair more is
    CHECK(detail::implausible_half(1e6 * std::sqrt(2.0) * 0.5, 0.0, 0.25, 0.25, bound) == -1);
    CHECK(detail::implausible_half(1.000001e6 * std::sqrt(0.5), 0.0, 0.25, 0.25, bound) == 0);
    CHECK(detail::implausible_half(0.3, 1e30, 0.01, 0.01, bound) == 1);
    CHECK(detail::implausible_half(-1e30, 0.3, 0.01, 0.01, bound) == 0);   // magnitude, either sign
    CHECK(detail::implausible_half(1e30, 0.3, 1e59, 0.01, bound) == -1);   // its variance allows it
    // no variance in either half says nothing (one sample a half, or no variance pass): at one
    // sample a half, the sun's edge (1e5 beside a sky of 1e-3) is no garbage
    CHECK(detail::implausible_half(1e30, 0.3, 0.0, 0.01, bound) == -1);
    CHECK(detail::implausible_half(1e30, 0.3, 0.01, 0.0, bound) == -1);
    CHECK(detail::implausible_half(1e5, 1e-3, 0.0, 0.0, 1e6) == -1);
    CHECK(detail::implausible_half(1e30, 0.3, nan_v, 0.01, bound) == -1);
    CHECK(detail::implausible_half(nan_v, 0.3, 0.01, 0.01, bound) == -1);
    // near DBL_MAX: no overflow in the gap or the noise
    CHECK(detail::implausible_half(DBL_MAX, 1.0, 1.0, 1.0, bound) == 0);
    CHECK(detail::implausible_half(DBL_MAX, 0.0, DBL_MAX, DBL_MAX, bound) == 0);    // z ~ 1.9e154
    CHECK(detail::implausible_half(DBL_MAX, -DBL_MAX, 1.0, 1.0, bound) == -1);     // neither dwarfs the other
    CHECK(detail::implausible_half(DBL_MAX, DBL_MAX, DBL_MAX, DBL_MAX, bound) == -1);  // they agree
    CHECK(detail::implausible_half(1.0, 1.0 + 1e-300, 1e-320, 1e-320, bound) == -1);  // denormals
    CHECK(detail::implausible_half(1.0, 1e-310, 4.9e-324, 4.9e-324, bound) == 0);    // z ~ 3e161
    // an emitter's edge at two samples a half: each half's samples nearly alike, so both
    // variances tiny (t ~ 2e7), but 10 is 200 times 0.05, far from implausible
    CHECK(detail::implausible_half(10.0, 0.05, 9.5e-7 * 9.5e-7 / 4, 7.45e-9 * 7.45e-9 / 4, 2.8e7) == -1);
    CHECK(detail::implausible_half(1e30, 0.05, 9.5e-7 * 9.5e-7 / 4, 7.45e-9 * 7.45e-9 / 4, 2.8e7) == 0);
}

TEST_CASE("implausible_buffers: buffers against the others, step-down", "[implausible][buffers]") {
    const double bound = 1e6;
    const bool all[8] = {true, true, true, true, true, true, true, true};
    const double none[8] = {nan_v, nan_v, nan_v, nan_v, nan_v, nan_v, nan_v, nan_v};  // no variance
    auto bits = [](std::initializer_list<int> b) {
        std::uint64_t m = 0;
        for (const int i : b) m |= std::uint64_t{1} << i;
        return m;
    };
    auto found = [&](const double* l, int k, const double* rv = nullptr, const bool* use = nullptr) {
        return detail::implausible_buffers(l, rv ? rv : none, use ? use : all, k, bound);
    };
    const double garbage[4] = {0.31, 1e30, 0.29, 0.30};
    CHECK(found(garbage, 4) == bits({1}));
    const double clean[4] = {0.31, 5.0, 0.29, 0.30};  // a firefly is for the step-down, not this
    CHECK(found(clean, 4) == 0);
    // a firefly over renders that agree to the last bit but one: R's level bounds the noise
    const double flat[8] = {0.5, 0.5, 0.5, 1000.0, 0.5, 0.5, 0.5, 0.5};
    CHECK(found(flat, 8) == 0);
    const double agree[4] = {0.0, 1e30, 0.0, 0.0};  // R black and in exact agreement: no test
    CHECK(found(agree, 4) == 0);
    CHECK(found(garbage, 2) == 0);  // |R| = 1
    const bool skip[4] = {true, false, true, true};
    CHECK(found(garbage, 4, nullptr, skip) == 0);  // the garbage not usable
    const double negative[3] = {-1e30, 0.3, 0.31};
    CHECK(found(negative, 3) == bits({0}));
    // two equal garbage values: the first step alone sees the other in R; the second finds both
    const double two[8] = {1e30, 0.3, 0.31, 1e30, 0.29, 0.3, 0.32, 0.28};
    CHECK(found(two, 8) == bits({0, 3}));
    const double four[8] = {1e30, 1e30, 1e30, 1e30, 0.29, 0.3, 0.32, 0.28};  // half: R holds the rest
    CHECK(found(four, 8) == bits({0, 1, 2, 3}));
    const double huge[4] = {DBL_MAX, -DBL_MAX, DBL_MAX, -DBL_MAX};  // spread near DBL_MAX: finite, no flag
    CHECK(found(huge, 4) == 0);
    const double at_max[4] = {DBL_MAX, 1.0, 2.0, 3.0};
    CHECK(found(at_max, 4) == bits({0}));
    const double shuffled[8] = {0.3, 0.28, 1e30, 0.31, 0.32, 0.29, 1e30, 0.3};  // any buffer order
    CHECK(found(shuffled, 8) == bits({2, 6}));
    // a tie in magnitude is never cut in two: the result follows the buffers when they are swapped
    const double tie[4] = {1e12, -1e12, 0.3, 0.31}, tie_swapped[4] = {-1e12, 1e12, 0.3, 0.31};
    const double rv_tie[4] = {1e-30, 10.0, 0.01, 0.01}, rv_tie_swapped[4] = {10.0, 1e-30, 0.01, 0.01};
    const std::uint64_t t = found(tie, 4, rv_tie), ts = found(tie_swapped, 4, rv_tie_swapped);
    CHECK(((t & 1u) != 0) == ((ts & 2u) != 0));
    CHECK(((t & 2u) != 0) == ((ts & 1u) != 0));
    // the same garbage in two buffers, one carrying a variance that holds it: the same bits in
    // either order (before, the one ranked second by index set the noise: 0 one way, 0x3 the other)
    const double same[6] = {1e30, 1e30, 1.0, 1.1, 0.9, 1.05};
    const double rv_same[6] = {1e-40, 1.0, 0.01, 0.01, 0.01, 0.01}, rv_same_swapped[6] = {1.0, 1e-40, 0.01, 0.01, 0.01, 0.01};
    CHECK(found(same, 6, rv_same) == found(same, 6, rv_same_swapped));
    const double rv_unknown[6] = {nan_v, 1e-40, 0.01, 0.01, 0.01, 0.01}, rv_unknown_swapped[6] = {1e-40, nan_v, 0.01, 0.01, 0.01, 0.01};
    CHECK(found(same, 6, rv_unknown) == found(same, 6, rv_unknown_swapped));
    // a variance unknown in R (a level of 0) leaves the candidate's own variance in charge: a
    // firefly carrying its variance is no garbage
    const double dark[4] = {0.0, 0.001, 0.0012, 2e5};
    const double rv_dark[4] = {nan_v, 0.01, 0.01, 0.9};
    CHECK(found(dark, 4, rv_dark) == 0);
    // with variances (relative, of the means): a firefly's own variance holds it, garbage's does not
    const double firefly[4] = {0.3, 1e7, 0.31, 0.29};
    const double rv_firefly[4] = {0.01, 0.75, 0.01, 0.01};
    CHECK(found(firefly, 4, rv_firefly) == 0);
    CHECK(found(firefly, 4) == bits({1}));  // the same value without variance: 3e7 times the level
    const double rv_garbage[4] = {0.01, 1e-62, 0.01, 0.01};
    CHECK(found(garbage, 4, rv_garbage) == bits({1}));
    const double rv_zero[4] = {0.01, 0.0, 0.01, 0.01};
    CHECK(found(garbage, 4, rv_zero) == 0);  // a variance of 0 says nothing
    CHECK(found(clean, 4, rv_zero) == 0);
}

TEST_CASE("a tile of 1e30 in half A is rebuilt from half B, exactly as a NaN tile", "[implausible][pipeline]") {
    // Before find_implausible the tile was kept at 1e30 and the pixels rebuilt beside it took
    // up to ~1e29 from it as a clean source (measured on cycles-caustics: 1.6e29).
    const tiled_frame bad(1e30f), nan_tile(std::numeric_limits<float>::quiet_NaN());
    REQUIRE(bad.report.ok());
    const std::size_t tile = tiled_frame::tw * tiled_frame::th;
    CHECK(bad.report.half[0].implausible == tile);
    CHECK(bad.report.half[1].implausible == 0);
    CHECK(bad.report.half[0].nonfinite == 0);
    CHECK(bad.report.half[0].repaired == tile);
    CHECK(nan_tile.report.half[0].nonfinite == tile);
    CHECK(bad.report.half[0].valid + bad.report.half[0].ignored + bad.report.half[0].implausible ==
          bad.report.half[0].pixels);
    CHECK(bad.report.half[0].fireflies == nan_tile.report.half[0].fireflies);
    CHECK(bad.report.half[1].fireflies == nan_tile.report.half[1].fireflies);
    for (int k = 0; k < 2; ++k) {
        CHECK(bad.v.f.color[k] == nan_tile.v.f.color[k]);  // bit for bit, both halves
        CHECK(bad.v.f.variance[k] == nan_tile.v.f.variance[k]);
        CHECK(bad.v.mask[k] == nan_tile.v.mask[k]);
    }
    float most = 0, most_in = 0;
    for (int y = 0; y < tiled_frame::h; ++y)
        for (int x = 0; x < tiled_frame::w; ++x)
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = bad.v.at(x, y) * 3 + static_cast<std::size_t>(c);
                most = std::max({most, bad.v.f.color[0][i], bad.v.f.color[1][i]});
                if (!tiled_frame::in_tile(x, y)) most_in = std::max({most_in, bad.input[0][i], bad.input[1][i]});
            }
    CHECK(most <= most_in);  // nothing of the tile anywhere
    CHECK((bad.v.mask[0][bad.v.at(tiled_frame::x0 + 5, tiled_frame::y0 + 5)] & mask_bits::nonfinite) != 0);
}

TEST_CASE("the simulator's garbage bucket is rebuilt as its failed (NaN) bucket is", "[implausible][pipeline][sim]") {
    const sim::scene garbage = sim::named_scene("garbage_bucket", 192, 128, 7);
    sim::scene failed = garbage;
    failed.effects = (failed.effects & ~static_cast<std::uint32_t>(sim::garbage_bucket)) | sim::failed_bucket;
    frame_views g(sim::simulate(garbage)), n(sim::simulate(failed));
    detector dg, dn;
    const frame_report rg = g.process(dg), rn = n.process(dn);
    REQUIRE(rg.ok());
    const std::size_t square = 24u * 24u;  // 1/8 of the width
    CHECK(rg.half[0].implausible == square);
    CHECK(rn.half[0].nonfinite == square);
    for (int k = 0; k < 2; ++k) {
        CHECK(g.f.color[k] == n.f.color[k]);
        CHECK(g.f.variance[k] == n.f.variance[k]);
        CHECK(g.mask[k] == n.mask[k]);
    }
    // the frame comes out about as well as the same frame with no bucket at all
    sim::scene intact_sc = garbage;
    intact_sc.effects &= ~static_cast<std::uint32_t>(sim::garbage_bucket);
    frame_views intact(sim::simulate(intact_sc));
    detector di;
    (void)intact.process(di);
    const sim::frame original = sim::simulate(garbage), intact_original = sim::simulate(intact_sc);
    const std::vector<float>* cleaned[2] = {&g.f.color[0], &g.f.color[1]};
    const std::vector<float>* cleaned_intact[2] = {&intact.f.color[0], &intact.f.color[1]};
    const double err = sim::evaluate(original, cleaned).relmse, err_intact = sim::evaluate(intact_original, cleaned_intact).relmse;
    INFO("relMSE " << err << ", intact " << err_intact);
    CHECK(err < 1.2 * err_intact);
}

TEST_CASE("find_implausible off, and detect(): the tile is found, or left", "[implausible][pipeline]") {
    detector_options off;
    off.find_implausible = false;
    const tiled_frame kept(1e30f, off);
    CHECK(kept.report.half[0].implausible == 0);
    // left at 1e30: its pixels are fireflies to the local test, rebuilt from the tile itself
    CHECK(kept.v.col(0, tiled_frame::x0 + 5, tiled_frame::y0 + 5) >= 0.99e30f);
    const tiled_frame found(1e30f, {}, true);
    CHECK(found.report.half[0].implausible == tiled_frame::tw * tiled_frame::th);
    CHECK(found.v.f.color[0] == found.input[0]);  // detect() writes nothing
    CHECK(found.report.half[0].repaired == 0);
}

TEST_CASE("frames without corruption lose no pixel to the test, at 2 to 64 samples per half",
          "[implausible][calibration]") {
    // The bound holds for Student's t at one degree of freedom (two samples per half); every
    // pixel of 240 frames of every effect but fireflies, exponential and gamma(4) samples.
    std::size_t frames = 0, found = 0;
    for (const int spp : {2, 4, 64})
        for (std::uint64_t seed = 1; seed <= 40; ++seed)
            for (const double shape : {1.0, 4.0}) {
                frame_views v(sim::simulate(sim::null_scene(seed, shape, spp, 64, 64)));
                detector d;
                const frame_report r = v.detect(d);
                ++frames;
                found += r.half[0].implausible + r.half[1].implausible > 0;
            }
    INFO(found << " of " << frames << " frames with an implausible pixel");
    CHECK(found == 0);  // the promise allows 0.05 of them; the Cauchy bound is far from any t here
    for (const std::string& name : sim::scene_names()) {
        frame_views v(sim::simulate(sim::named_scene(name, 256, 160, 5)));
        detector d;
        const frame_report r = v.detect(d);
        INFO(name);
        CHECK(r.half[0].implausible + r.half[1].implausible == 0);
    }
}

TEST_CASE("K buffers: a tile of 1e30 in one or two buffers is rebuilt from the others", "[implausible][buffers]") {
    const int w = 128, h = 96;
    for (const int k : {3, 4, 8}) {
        for (const int tiles : {1, 2}) {
            if (tiles == 2 && k < 8) continue;
            sim::buffers b = sim::simulate_buffers(sim::named_scene("sparse_fireflies", w, h, 3), k);
            for (int t = 0; t < tiles; ++t)
                for (int y = 30; y < 50; ++y)
                    for (int x = 40; x < 64; ++x)
                        for (std::size_t c = 0; c < 3; ++c)
                            b.color[static_cast<std::size_t>(t)][(static_cast<std::size_t>(y) * w + static_cast<std::size_t>(x)) * 3 + c] = 1e30f;
            std::vector<buffer_view<float>> views;
            std::vector<std::vector<std::uint8_t>> mk(static_cast<std::size_t>(k), std::vector<std::uint8_t>(b.pixels(), 0));
            std::vector<image_view<std::uint8_t>> masks;
            for (int i = 0; i < k; ++i) {
                views.push_back({*make_image_view(b.color[static_cast<std::size_t>(i)].data(), w, h, 3), {}});
                masks.push_back(*make_image_view(mk[static_cast<std::size_t>(i)].data(), w, h, 1));
            }
            cross_buffer_detector d;
            const cross_buffer_report r = d.process(views, masks);
            INFO("K = " << k << ", " << tiles << " tile(s)");
            REQUIRE(r.ok());
            CHECK(r.implausible == static_cast<std::size_t>(tiles) * 24u * 20u);
            CHECK(r.nonfinite == 0);
            float most = 0;
            for (const auto& c : b.color)
                for (const float v : c) most = std::max(most, v);
            CHECK(most < 1e3f);
            CHECK((mk[0][static_cast<std::size_t>(35) * w + 45] & mask_bits::nonfinite) != 0);
            CHECK(mk[static_cast<std::size_t>(k - 1)][static_cast<std::size_t>(35) * w + 45] == 0);
        }
    }
}
